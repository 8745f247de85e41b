"""Reading text inputs (RINEX and the like) whole, gzip or plain, with errors callers can show."""

from __future__ import annotations

import gzip
from pathlib import Path

from onboard.errors import InputError


def read_text_lines(path: Path, what: str) -> list[str]:
    """The lines of a plain or gzip-compressed ASCII file; `what` names it in errors ("navigation file").

    Raises InputError for an unreadable file or corrupt gzip data; undecodable bytes become U+FFFD.
    """
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read {what} {path}: {exc}") from exc
    if raw[:2] == b"\x1f\x8b":
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError) as exc:
            raise InputError(f"{path}: corrupt gzip data: {exc}") from exc
    return raw.decode("ascii", errors="replace").splitlines()
