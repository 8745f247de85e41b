"""`python -m onboard check`: verify recorded flights against their manifests (read-only)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from onboard.cmdline import EXIT_FAILURE, EXIT_OK, EXIT_USAGE, add_command, error_line

COMMAND = "check"

DESCRIPTION = """\
Check recorded flights (read-only): each journal segment against the manifest's size and SHA-256, the
segment numbering (none missing), each segment's index (present, in order, within the data) and the event
log (present, every line a record). A torn tail from a power cut is reported, not a problem; everything
else found is printed as a PROBLEM line."""

EPILOG = """\
examples:
  python -m onboard check /data/flights/flight-20260501T101500Z
  python -m onboard check /data/flights/flight-* --json > report.json

exit codes: 0 every flight is whole, 1 a flight has a problem, 2 an argument is not a flight directory."""


def add_check_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:  # type: ignore[type-arg]
    """Register `check` (verify recorded flights against their manifests)."""
    p = add_command(subparsers, COMMAND, summary="verify flights: segment hashes, numbering, index, event log",
                    description=DESCRIPTION, epilog=EPILOG)
    p.add_argument("flights", nargs="+", type=Path, metavar="FLIGHT_DIR",
                   help="a flight directory (flight-YYYYmmddTHHMMSSZ holding NNNNNN.ubx segments); repeatable")
    p.add_argument("--json", action="store_true", help="print the full report of each flight as JSON")
    p.set_defaults(func=_check)
    return p


def _check(args: argparse.Namespace) -> int:
    import json

    from onboard.logger.check import check_flight

    code = EXIT_OK
    for flight in args.flights:
        if not flight.is_dir():
            print(error_line(COMMAND, f"{flight}: not a flight directory"), file=sys.stderr)
            code = EXIT_USAGE
            continue
        result = check_flight(flight)
        if args.json:
            print(json.dumps(result.to_json(), indent=1))
        else:
            total = sum(s.bytes for s in result.segments)
            torn = [s.name for s in result.segments if s.torn_tail_bytes]
            torn_events = f", {result.events_torn_lines} torn event lines" if result.events_torn_lines else ""
            print(f"{flight}: {len(result.segments)} segments, {total} bytes, "
                  f"{sum(s.frames for s in result.segments)} frames, {result.events} events, "
                  f"{'closed' if result.closed else 'NOT closed (power cut or running)'}"
                  + (f", torn tails in {', '.join(torn)}" if torn else "") + torn_events)
            for problem in result.problems:
                print(f"  PROBLEM: {problem}")
        if not result.ok:
            n = len(result.problems)
            print(error_line(COMMAND, f"{flight}: {n} problem{'s' if n > 1 else ''} (see the PROBLEM lines)"),
                  file=sys.stderr)
            if code == EXIT_OK:
                code = EXIT_FAILURE
    return code
