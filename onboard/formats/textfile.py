"""Reading text inputs (RINEX and the like) whole, gzip or plain, with errors callers can show."""

from __future__ import annotations

import gzip
import zlib
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


def read_head_bytes(path: Path, n_bytes: int) -> bytes:
    """Up to the first `n_bytes` of a plain or gzip-compressed file (decompressed), to tell what it holds.

    Light on imports on purpose: `onboard rtk` sniffs every input with it before deciding which reader (and
    which decoder modules) it needs. Raises InputError for an unreadable file and for gzip data that is
    corrupt or ends within the first `n_bytes` (the messages of the UBX log reader's).
    """
    try:
        with open(path, "rb") as f:
            magic = f.read(2)
            f.seek(0)
            if magic != b"\x1f\x8b":
                return f.read(n_bytes)
            with gzip.GzipFile(fileobj=f) as gz:
                try:
                    return gz.read(n_bytes)
                except EOFError as exc:
                    raise InputError(f"{path}: gzip data is truncated ({exc})") from exc
                except (OSError, zlib.error) as exc:
                    raise InputError(f"{path}: gzip data is corrupt ({exc})") from exc
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from exc
