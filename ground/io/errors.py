"""Errors raised by the ground importers/exporters: each names the file (and line) it could not use."""

from __future__ import annotations

from pathlib import Path

from onboard.errors import InputError


class FormatError(InputError):
    """A file does not follow the format it claims (missing field, bad number, unknown layout)."""

    def __init__(self, path: str | Path, detail: str, line: int | None = None) -> None:
        self.path = str(path)
        self.line = line
        self.detail = detail
        where = f"{path}:{line}" if line is not None else str(path)
        super().__init__(f"{where}: {detail}")


class CrsError(InputError):
    """A coordinate transformation cannot be done exactly (unknown CRS, missing geoid grid, ballpark only)."""
