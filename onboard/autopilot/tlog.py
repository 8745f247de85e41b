"""The flight's `.tlog`: every MAVLink packet from the autopilot link, each after an 8-byte big-endian
timestamp in µs since the Unix epoch (host wall clock), the format pymavlink's `mavlink_connection(path)`,
MAVProxy and Mission Planner read. fsync'd at least every `sync_interval_s` (monotonic), like the journal."""

from __future__ import annotations

import struct
from pathlib import Path

from onboard.hw.ports import Clock
from onboard.logger.files import AppendFile, FileLayer, OsFileLayer

TLOG_STEM = "autopilot"


def tlog_record(wall_us: int, packet: bytes) -> bytes:
    """One tlog record: `>Q` timestamp (µs since 1970, UTC) then the packet's bytes."""
    return struct.pack(">Q", wall_us) + packet


def next_tlog_path(flight_dir: Path) -> Path:
    """`autopilot.tlog`, or `autopilot-N.tlog` when a resumed flight already has one (a torn tail is never
    appended to: its last record may be cut)."""
    path = flight_dir / f"{TLOG_STEM}.tlog"
    n = 1
    while path.exists():
        n += 1
        path = flight_dir / f"{TLOG_STEM}-{n}.tlog"
    return path


class TlogWriter:
    """Append-only tlog writer (one per flight run)."""

    def __init__(self, path: Path, clock: Clock, sync_interval_s: float, files: FileLayer | None = None) -> None:
        self.path = Path(path)
        self.clock = clock
        self.sync_interval_ns = round(sync_interval_s * 1e9)
        self._file: AppendFile = (files or OsFileLayer()).create(self.path)
        self._dirty = False
        self._last_sync_ns = clock.monotonic_ns()
        self.packets = 0

    @property
    def bytes_written(self) -> int:
        """Size of the tlog so far."""
        return self._file.size

    def append(self, packet: bytes, wall_ns: int) -> None:
        """One packet received at host wall time `wall_ns`."""
        self._file.append(tlog_record(wall_ns // 1000, packet))
        self.packets += 1
        self._dirty = True

    def maybe_sync(self) -> None:
        """fsync when dirty and `sync_interval_s` has passed since the last one."""
        now = self.clock.monotonic_ns()
        if self._dirty and now - self._last_sync_ns >= self.sync_interval_ns:
            self._file.fsync()
            self._dirty = False
            self._last_sync_ns = now

    def close(self) -> None:
        """fsync and close."""
        if self._dirty:
            self._file.fsync()
            self._dirty = False
        self._file.close()
