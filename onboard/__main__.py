"""`python -m onboard <command>`: the onboard command line.

Commands register in `COMMANDS` as (name, "module:function" registrar); adding one (e.g. `rtk`, `base`) is one
line. Nothing happens at import: `main()` builds the parser, importing only the chosen command's module (a
command's start-up then pays for its own imports alone: `rtk` needs neither pyubx2 nor the web server);
`--help` and unknown commands import every registrar so that all commands are listed.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from onboard.errors import ConfigFileError

log = logging.getLogger("onboard")

EXIT_USAGE = 2

def add_run_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:  # type: ignore[type-arg]
    """Register `run` (the recorder daemon)."""
    from onboard.settings import add_recorder_arguments

    p = subparsers.add_parser("run", help="record: the onboard recorder daemon",
                              description="Record every byte from the receiver into a crash-safe journal, "
                                          "configure and monitor the receiver, write a status snapshot.")
    p.add_argument("--port", help="receiver serial device (overrides port.device)")
    add_recorder_arguments(p)
    p.set_defaults(func=_run)
    return p


def _run(args: argparse.Namespace) -> int:
    from onboard.daemon import (
        EXIT_DISK_FULL,
        RecorderDeps,
        gpio_edge_sources,
        run_recorder,
        serial_port_opener,
    )
    from onboard.logger.files import FileLayer, OsFileLayer, SyncLogFileLayer
    from onboard.sdnotify import SdNotifier
    from onboard.settings import load_settings, recorder_overrides

    try:
        settings = load_settings(args.config, overrides=recorder_overrides(args))
    except ConfigFileError as exc:
        print(f"configuration error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    # Test hook: a file layer that logs every fsync'd length, so a power-cut test can cut files back to it.
    sync_log = os.environ.get("ONBOARD_TEST_SYNC_LOG")
    files: FileLayer = SyncLogFileLayer(Path(sync_log)) if sync_log else OsFileLayer()
    deps = RecorderDeps(open_port=serial_port_opener(settings), files=files, notifier=SdNotifier(),
                        edge_sources=gpio_edge_sources(settings))
    code = run_recorder(settings, deps)
    if code == EXIT_DISK_FULL:
        print("recorder stopped: free disk space below journal.disk_floor_mb (see the status snapshot)",
              file=sys.stderr)
    return code


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


# Sub-commands: (name, "module:function" registrar), the registrar adding its parser to the sub-parsers and
# setting `func(args) -> exit code`. Adding a command (`rtk`, `base`, ...) is one line here.
COMMANDS: tuple[tuple[str, str], ...] = (
    ("run", "onboard.__main__:add_run_parser"),
    ("check", "onboard.__main__:add_check_parser"),
    ("convert", "onboard.convert:add_convert_parser"),
    ("rtk", "onboard.rtk_cli:add_rtk_parser"),
    ("base", "onboard.base_cli:add_base_parser"),
    ("web", "onboard.web.cli:add_web_parser"),
)


def _chosen_command(argv: Sequence[str] | None) -> str | None:
    """The command named in `argv` (its first non-option word: the top level has only flags), if known."""
    if argv is None:
        return None
    names = {name for name, _ in COMMANDS}
    for arg in argv:
        if arg in ("-h", "--help"):
            return None
        if not arg.startswith("-"):
            return arg if arg in names else None
    return None


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The argument parser: with `argv` naming a command, only that command is registered (its module alone is
    imported); otherwise every registered command (for `--help` and the usage error of an unknown command)."""
    parser = argparse.ArgumentParser(prog="python -m onboard", description="directgeo onboard tools")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    chosen = _chosen_command(argv)
    for name, spec in COMMANDS:
        if chosen is not None and name != chosen:
            continue
        module_name, func_name = spec.split(":")
        getattr(importlib.import_module(module_name), func_name)(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    if argv is None:
        argv = sys.argv[1:]
    args = build_parser(argv).parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    code: int = args.func(args)
    return code


if __name__ == "__main__":
    sys.exit(main())
