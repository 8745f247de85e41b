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
import sys
from collections.abc import Sequence

log = logging.getLogger("onboard")

EXIT_USAGE = 2

# Sub-commands: (name, "module:function" registrar), the registrar adding its parser to the sub-parsers and
# setting `func(args) -> exit code`. Adding a command (`rtk`, `base`, ...) is one line here.
COMMANDS: tuple[tuple[str, str], ...] = (
    ("run", "onboard.recorder.cli:add_run_parser"),
    ("check", "onboard.postpro.check_cli:add_check_parser"),
    ("convert", "onboard.postpro.convert:add_convert_parser"),
    ("rtk", "onboard.postpro.rtk_cli:add_rtk_parser"),
    ("base", "onboard.base.cli:add_base_parser"),
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
