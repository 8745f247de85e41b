"""`python -m onboard check`: verify recorded flights against their manifests (read-only)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

EXIT_USAGE = 2


def add_check_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:  # type: ignore[type-arg]
    """Register `check` (verify recorded flights against their manifests)."""
    p = subparsers.add_parser("check", help="verify flights: segment hashes, index, torn tails",
                              description="Check recorded flights against their manifests (read-only).")
    p.add_argument("flights", nargs="+", type=Path, metavar="FLIGHT_DIR")
    p.add_argument("--json", action="store_true", help="print the full report as JSON")
    p.set_defaults(func=_check)
    return p


def _check(args: argparse.Namespace) -> int:
    import json

    from onboard.logger.check import check_flight

    code = 0
    for flight in args.flights:
        if not flight.is_dir():
            print(f"check: {flight}: not a directory", file=sys.stderr)
            code = EXIT_USAGE
            continue
        result = check_flight(flight)
        if args.json:
            print(json.dumps(result.to_json(), indent=1))
        else:
            total = sum(s.bytes for s in result.segments)
            torn = [s.name for s in result.segments if s.torn_tail_bytes]
            print(f"{flight}: {len(result.segments)} segments, {total} bytes, "
                  f"{sum(s.frames for s in result.segments)} frames, {result.events} events, "
                  f"{'closed' if result.closed else 'NOT closed (power cut or running)'}"
                  + (f", torn tails in {', '.join(torn)}" if torn else ""))
            for problem in result.problems:
                print(f"  PROBLEM: {problem}")
        if not result.ok:
            code = 1
    return code
