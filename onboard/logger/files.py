"""The file layer under the journal: append, fsync, rename, fsync(dir) behind one small seam.

`OsFileLayer` is the real thing. `RecordingFileLayer` keeps every fsync'd length in memory so a test can cut
every file back to what a power loss would have kept (`cut_to_sync_points`); `SyncLogFileLayer` writes the same
sync points to a side file so a test can do the cut after SIGKILLing a daemon running in another process.
A SIGKILL alone leaves the page cache intact and therefore cannot catch a missing fsync; these layers can.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol


class AppendFile(Protocol):
    """An append-only file opened by a `FileLayer`."""

    path: Path

    @property
    def size(self) -> int:
        """Bytes written so far (synced or not)."""
        ...

    def append(self, data: bytes) -> None: ...

    def fsync(self) -> None: ...

    def close(self) -> None: ...


class FileLayer(Protocol):
    """Create append-only files, fsync them, replace files atomically and fsync directories."""

    def create(self, path: Path) -> AppendFile:
        """Create `path` exclusively (FileExistsError if it exists) and open it for appending."""
        ...

    def open_append(self, path: Path) -> AppendFile:
        """Open `path` for appending, creating it if missing (its current length counts as durable)."""
        ...

    def replace(self, src: Path, dst: Path) -> None: ...

    def fsync_dir(self, path: Path) -> None: ...


class _OsAppendFile:
    """A file descriptor opened O_APPEND; writes loop until every byte is handed to the kernel."""

    def __init__(self, path: Path, layer: OsFileLayer, exclusive: bool = True) -> None:
        self.path = path
        self._layer = layer
        flags = os.O_WRONLY | os.O_CREAT | os.O_APPEND | os.O_CLOEXEC | (os.O_EXCL if exclusive else 0)
        self._fd = os.open(path, flags, 0o644)
        self._size = os.fstat(self._fd).st_size

    @property
    def size(self) -> int:
        """Bytes written so far (synced or not)."""
        return self._size

    def append(self, data: bytes) -> None:
        """Append every byte of `data` (raises OSError, e.g. ENOSPC, leaving `size` at what was written)."""
        view = memoryview(data)
        while view:
            n = os.write(self._fd, view)
            self._size += n
            view = view[n:]

    def fsync(self) -> None:
        """Flush the file's data and metadata to stable storage."""
        os.fsync(self._fd)
        self._layer._synced(self.path, self._size)

    def close(self) -> None:
        """Close the descriptor (no implicit fsync: callers decide durability)."""
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


class OsFileLayer:
    """The real operating-system file layer."""

    def create(self, path: Path) -> AppendFile:
        """Create `path` exclusively and open it for appending."""
        return _OsAppendFile(Path(path), self)

    def open_append(self, path: Path) -> AppendFile:
        """Open `path` for appending (created if missing)."""
        handle = _OsAppendFile(Path(path), self, exclusive=False)
        self._synced(handle.path, handle.size)
        return handle

    def replace(self, src: Path, dst: Path) -> None:
        """Atomically rename `src` over `dst` (durable only after `fsync_dir`)."""
        os.replace(src, dst)
        self._renamed(Path(src), Path(dst))

    def fsync_dir(self, path: Path) -> None:
        """fsync a directory so that creations and renames in it survive power loss."""
        fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)

    # Hooks for the recording layers; the real layer records nothing.
    def _synced(self, path: Path, size: int) -> None:
        pass

    def _renamed(self, src: Path, dst: Path) -> None:
        pass


@dataclass
class RecordingFileLayer(OsFileLayer):
    """An OS file layer that remembers, per path, the length at its last fsync (test power-cut model)."""

    synced_bytes: dict[Path, int] = field(default_factory=dict)
    created: set[Path] = field(default_factory=set)

    def create(self, path: Path) -> AppendFile:
        """Create and remember the file (a never-synced file is cut to nothing)."""
        handle = super().create(path)
        self.created.add(Path(path))
        return handle

    def open_append(self, path: Path) -> AppendFile:
        """Open and remember the file; what it already holds counts as durable."""
        handle = super().open_append(path)
        self.created.add(Path(path))
        return handle

    def _synced(self, path: Path, size: int) -> None:
        self.synced_bytes[path] = size

    def _renamed(self, src: Path, dst: Path) -> None:
        # The renamed file keeps the synced length its data had under the old name.
        self.synced_bytes[dst] = self.synced_bytes.pop(src, 0)
        self.created.discard(src)
        self.created.add(dst)

    def cut_to_sync_points(self) -> dict[Path, int]:
        """Truncate every file this layer touched to its last fsync'd length; returns the lengths cut to."""
        return cut_files(
            {p: self.synced_bytes.get(p, 0) for p in self.created | set(self.synced_bytes)},
        )


class SyncLogFileLayer(OsFileLayer):
    """An OS file layer that appends `sync <len> <path>` / `rename <src>\\t<dst>` lines to a side log.

    The side log is written with plain `write` (no fsync): it only has to survive SIGKILL, not power loss,
    because the test itself replays it to model the power loss. Used by the daemon in test mode
    (`ONBOARD_TEST_SYNC_LOG=<file>`).
    """

    def __init__(self, log_path: Path) -> None:
        self._log_fd = os.open(log_path, os.O_WRONLY | os.O_CREAT | os.O_APPEND | os.O_CLOEXEC, 0o644)

    def create(self, path: Path) -> AppendFile:
        """Create the file and log it (a never-synced file is cut to nothing)."""
        handle = super().create(path)
        os.write(self._log_fd, f"create\t{Path(path).resolve()}\n".encode())
        return handle

    def open_append(self, path: Path) -> AppendFile:
        """Open the file for appending and log its current length as durable."""
        handle = _OsAppendFile(Path(path), self, exclusive=False)
        os.write(self._log_fd, f"create\t{handle.path.resolve()}\n".encode())
        self._synced(handle.path, handle.size)
        return handle

    def _synced(self, path: Path, size: int) -> None:
        os.write(self._log_fd, f"sync\t{size}\t{path.resolve()}\n".encode())

    def _renamed(self, src: Path, dst: Path) -> None:
        os.write(self._log_fd, f"rename\t{src.resolve()}\t{dst.resolve()}\n".encode())


def sync_points_from_log(log_path: Path) -> dict[Path, int]:
    """Replay a `SyncLogFileLayer` side log: the fsync'd length of every file it created (0 if never synced)."""
    synced: dict[Path, int] = {}
    for line in Path(log_path).read_text().splitlines():
        parts = line.split("\t")
        if parts[0] == "create" and len(parts) == 2:
            synced.setdefault(Path(parts[1]), 0)
        elif parts[0] == "sync" and len(parts) == 3:
            synced[Path(parts[2])] = int(parts[1])
        elif parts[0] == "rename" and len(parts) == 3:
            synced[Path(parts[2])] = synced.pop(Path(parts[1]), 0)
    return synced


def cut_files(lengths: dict[Path, int]) -> dict[Path, int]:
    """Truncate each existing file to the given length (power-cut model); returns what was applied."""
    applied: dict[Path, int] = {}
    for path, length in lengths.items():
        if path.exists():
            if path.stat().st_size > length:
                os.truncate(path, length)
            applied[path] = length
    return applied
