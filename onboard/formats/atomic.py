"""Atomic file outputs: written under a temporary name in the target's directory, fsync'd, then renamed.

A reader (or the next run after a power cut or a full disk) sees either the previous complete file or the new
complete one, never a truncated file under the final name. On failure the temporary file is removed and the
previous file is left as it was; the error propagates (the caller says what was not written).
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any


def _fsync_dir(directory: Path) -> None:
    """Make the rename itself durable (the directory entry), where the platform allows opening a directory."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_output(path: str | Path, mode: str = "w", *, fsync: bool = True,
                  encoding: str | None = "utf-8") -> Iterator[IO[Any]]:
    """Open a temporary file beside `path` for writing (`mode` "w" text or "wb" binary); on a clean exit of the
    block it is flushed, fsync'd (unless `fsync` is False) and renamed over `path`. An exception inside the block,
    or while syncing/renaming, removes the temporary file and leaves `path` untouched."""
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_output mode must be 'w' or 'wb', not {mode!r}")
    target = Path(path)
    if target.is_dir():
        raise IsADirectoryError(f"{target} is a directory")
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    f = open(tmp, mode, encoding=None if "b" in mode else encoding)  # noqa: SIM115 (closed below)
    try:
        yield f
        f.flush()
        if fsync:
            os.fsync(f.fileno())
        f.close()
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):  # closing flushes the buffer, which fails again on a full disk
            f.close()
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    if fsync:
        _fsync_dir(target.parent)


def write_atomic(path: str | Path, data: bytes | str, *, fsync: bool = True) -> None:
    """Write `data` (bytes, or text as UTF-8) to `path` atomically (see `atomic_output`)."""
    raw = data.encode() if isinstance(data, str) else data
    with atomic_output(path, "wb", fsync=fsync) as f:
        f.write(raw)


def write_json_atomic(path: str | Path, obj: Any, *, fsync: bool = True) -> None:
    """`obj` as indented, key-sorted JSON with a final newline, written atomically."""
    write_atomic(path, json.dumps(obj, indent=1, sort_keys=True) + "\n", fsync=fsync)
