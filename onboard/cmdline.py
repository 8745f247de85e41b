"""The shape every `python -m onboard` command shares: exit codes, the error line, the argument parser.

Exit codes (systemd restarts the recorder on 1, never on 2): `EXIT_OK` 0, `EXIT_FAILURE` 1 (a runtime failure:
a full disk, a lost port), `EXIT_USAGE` 2 (bad arguments or configuration: retrying cannot help),
`EXIT_REFUSED` 3 (the data cannot support an answer, e.g. no epoch with a solution). Every error a user sees is
one line `directgeo: <command>: error: <message>` on stderr (`error_line`, and `CommandParser.error` for the usage
errors argparse finds). Command-line shells only: nothing here is imported by a core.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2
EXIT_REFUSED = 3

PROGRAM = "directgeo"

# A value made of numbers, commas and spaces that starts with "-" is a value, not an option: argparse's own test
# (`-\d+` or `-\d*.\d+` alone) makes `--base-pos -3976219.1,3382371.6,3652511.1` a missing argument (any
# position west of Greenwich has a negative X or Y).
_NUMBERS_RE = re.compile(r"^-(\d|\.\d)[\d.eE+\-, ]*$")
# argparse's "argument --elmask: 95: must be 0–90°" for a rejected `type=` value, shown as "--elmask 95: must be …"
_TYPE_ERROR_RE = re.compile(r"^argument (\S+): (.*: must be .*)$", re.DOTALL)


def error_line(command: str, message: str) -> str:
    """The one error format of every command: `directgeo: <command>: error: <message>` (one line)."""
    return f"{PROGRAM}: {command}: error: {' '.join(str(message).split())}"


def report_error(command: str, message: str, code: int) -> int:
    """Print `error_line(command, message)` on stderr and return `code` (for `return report_error(...)`)."""
    print(error_line(command, message), file=sys.stderr)
    return code


class CommandParser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors read `directgeo: <command>: error: ...` (exit 2), whose sub-parsers
    are of the same class, and that takes a negative number list such as `-3976219.1,3382371.6,3652511.1` as a
    value. `command` (default: the last word of `prog`) names the command in error lines."""

    def __init__(self, *args: Any, command: str | None = None, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NUMBERS_RE
        self.command = command or self.prog.split()[-1]

    def error(self, message: str) -> NoReturn:
        """Print the error line and where to find the usage, exit 2 (argparse's contract: never returns)."""
        m = _TYPE_ERROR_RE.match(message)
        if m:
            option = max(m.group(1).split("/"), key=len)
            message = f"{option} {m.group(2)}"
        self.exit(EXIT_USAGE, f"{error_line(self.command, message)}\n(usage: {self.prog} --help)\n")


def coordinate_action(check: Callable[..., Any]) -> type[argparse.Action]:
    """An argparse action (use with `nargs="+"`) for X,Y,Z-like values given as one word `X,Y,Z` or as words
    `X Y Z` (pasted from a survey report): the words are joined and checked once by `check` (a function of
    `onboard.validate`), so a bad value is a usage error naming the option and the rule."""

    class _CoordinateAction(argparse.Action):
        def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                     values: str | Sequence[Any] | None, option_string: str | None = None) -> None:
            words = [values] if isinstance(values, str) else list(values or [])
            text = ",".join(p for w in words for p in str(w).replace(" ", ",").split(",") if p)
            try:
                value = check(text, name=None)
            except ValueError as exc:
                raise argparse.ArgumentError(self, str(exc)) from None
            setattr(namespace, self.dest, value)

    return _CoordinateAction


def add_command(subparsers: argparse._SubParsersAction, name: str, *, summary: str,  # type: ignore[type-arg]
                description: str, epilog: str = "") -> argparse.ArgumentParser:
    """Add a sub-command whose `--help` shows `description` and `epilog` (examples) as written."""
    return subparsers.add_parser(name, help=summary, description=description, epilog=epilog or None,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)


def output_file(text: str) -> Path:
    """argparse `type=` for an output file path: not empty, not a directory, in an existing directory."""
    if not text.strip() or "\x00" in text:
        raise argparse.ArgumentTypeError(f"{text!r}: must be a file path")
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: must be a file path, not a directory")
    parent = path.parent
    if not parent.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: must be a file in an existing directory ({parent} "
                                         f"{'is not a directory' if parent.exists() else 'does not exist'})")
    return path


def output_dir(text: str) -> Path:
    """argparse `type=` for an output directory (created when missing): not empty, not an existing file."""
    if not text.strip() or "\x00" in text:
        raise argparse.ArgumentTypeError(f"{text!r}: must be a directory path")
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: must be a directory, not a file")
    for parent in path.parents:
        if parent.exists() and not parent.is_dir():
            raise argparse.ArgumentTypeError(f"{text}: must be a directory ({parent} is a file)")
    return path


def warning_line(command: str, message: str) -> str:
    """A warning in the same shape: `directgeo: <command>: warning: <message>` (something was skipped or lost)."""
    return f"{PROGRAM}: {command}: warning: {' '.join(str(message).split())}"
