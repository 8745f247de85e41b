"""`python -m onboard <command>`: the onboard command line.

Commands register in `COMMANDS` as (name, "module:function" registrar); adding one (e.g. `rtk`, `base`) is one
line. Nothing happens at import: `main()` builds the parser, importing only the chosen command's module (a
command's start-up then pays for its own imports alone: `rtk` needs neither pyubx2 nor the web server);
`--help` and unknown commands import every registrar so that all commands are listed.

Every command answers with the exit codes of `onboard.cmdline` (0 done, 1 runtime failure, 2 usage or
configuration error, 3 refused by a data rule) and error lines `directgeo: <command>: error: <message>`; an
unexpected exception (a bug) is logged with its traceback at debug level (`-v` shows it) and reported in one line.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence

from onboard.cmdline import EXIT_FAILURE, EXIT_USAGE, CommandParser, report_error

log = logging.getLogger("onboard")

EPILOG = """examples:
  python -m onboard run --config /etc/directgeo/onboard.toml
  python -m onboard check /data/flights/flight-20260501T101500Z
  python -m onboard convert /data/flights/flight-20260501T101500Z -o rinex/
  python -m onboard rtk --rover rinex/rover.obs --base base.obs --nav rinex/rover.nav -o rover.pos
  python -m onboard <command> --help   (each command's options, units and examples)"""

# Sub-commands: (name, "module:function" registrar), the registrar adding its parser to the sub-parsers and
# setting `func(args) -> exit code`. Adding a command (`rtk`, `base`, ...) is one line here.
COMMANDS: tuple[tuple[str, str], ...] = (
    ("run", "onboard.recorder.cli:add_run_parser"),
    ("check", "onboard.postpro.check_cli:add_check_parser"),
    ("convert", "onboard.postpro.convert:add_convert_parser"),
    ("rtk", "onboard.postpro.rtk_cli:add_rtk_parser"),
    ("base", "onboard.base.cli:add_base_parser"),
    ("web", "onboard.web.cli:add_web_parser"),
    ("upload-daemon", "onboard.upload.cli:add_upload_daemon_parser"),
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


def build_parser(argv: Sequence[str] | None = None) -> CommandParser:
    """The argument parser: with `argv` naming a command, only that command is registered (its module alone is
    imported); otherwise every registered command (for `--help` and the usage error of an unknown command)."""
    parser = CommandParser(prog="python -m onboard", command="onboard", epilog=EPILOG,
                           formatter_class=argparse.RawDescriptionHelpFormatter,
                           description="directgeo onboard tools: record the receiver on the drone, check and "
                                       "convert the recorded flights, post-process them to RTK positions.")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging (and tracebacks of bugs)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    chosen = _chosen_command(argv)
    for name, spec in COMMANDS:
        if chosen is not None and name != chosen:
            continue
        module_name, func_name = spec.split(":")
        getattr(importlib.import_module(module_name), func_name)(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit code (never raises: usage errors return 2, bugs 1 with one line)."""
    if argv is None:
        argv = sys.argv[1:]
    argv = list(argv)
    try:
        args = build_parser(argv).parse_args(argv)
    except SystemExit as exc:  # --help (0) or a usage error (2), already printed by CommandParser
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    try:
        code: int = args.func(args)
    except KeyboardInterrupt:
        return report_error(args.command, "interrupted", EXIT_FAILURE)
    except OSError as exc:  # a failure of the machine (full disk, permissions), not of the program
        log.debug("%s failed", args.command, exc_info=True)
        where = f" {exc.filename}" if getattr(exc, "filename", None) else ""
        return report_error(args.command, f"cannot access{where}: {exc.strerror or exc}", EXIT_FAILURE)
    except Exception as exc:  # a bug: its traceback goes to the debug log, the user gets one line
        log.debug("%s: unexpected %s", args.command, type(exc).__name__, exc_info=True)
        return report_error(args.command, f"unexpected {type(exc).__name__}: {exc} (a bug; run with -v for "
                                          "the traceback)", EXIT_FAILURE)
    return code


if __name__ == "__main__":
    sys.exit(main())
