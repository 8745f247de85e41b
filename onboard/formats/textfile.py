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
    which decoder modules) it needs. Gzip data cut short or damaged within the first `n_bytes` gives what
    decompressed before (the file's reader salvages and reports the damage); nothing decompressing is an
    InputError, as is an unreadable file.
    """
    try:
        with open(path, "rb") as f:
            magic = f.read(2)
            f.seek(0)
            if magic != b"\x1f\x8b":
                return f.read(n_bytes)
            d = zlib.decompressobj(wbits=31)
            out = b""
            while len(out) < n_bytes and not d.eof and (piece := f.read(4096)):
                try:
                    out += d.decompress(piece, n_bytes - len(out))
                except zlib.error as exc:
                    if not out:
                        raise InputError(f"{path}: gzip data is corrupt ({exc})") from exc
                    break
                while d.unconsumed_tail and len(out) < n_bytes:
                    out += d.decompress(d.unconsumed_tail, n_bytes - len(out))
            if not out and not d.eof:
                raise InputError(f"{path}: gzip data is truncated (nothing decompressed)")
            return out
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from exc
