"""Durable JSON-lines event log (`events.jsonl`): one JSON object a line, same fsync policy as the journal.

The record contents (time marks, pulse/flash pairs, configuration results) are defined by their producers
(`onboard.timepulse`); this module only makes them durable and reads them back tolerating a torn last line.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from onboard.hw.ports import Clock
from onboard.logger.files import AppendFile, FileLayer, OsFileLayer

log = logging.getLogger(__name__)


class EventLog:
    """Append-only `events.jsonl` writer.

    An existing file (a resumed flight) is appended to; if a power cut tore its last line, a newline is
    written first so the torn line stays a separate (skipped) line and never corrupts the next record.
    """

    def __init__(
        self, path: Path, clock: Clock, sync_interval_s: float = 0.5, files: FileLayer | None = None
    ) -> None:
        self.path = Path(path)
        self.clock = clock
        self.sync_interval_s = sync_interval_s
        self.files: FileLayer = files if files is not None else OsFileLayer()
        self._file: AppendFile = self.files.open_append(self.path)
        self._dirty = False
        self._last_sync_mono_ns = clock.monotonic_ns()
        self.records = 0
        if self._file.size and not _ends_with_newline(self.path):
            self._file.append(b"\n")
            self._dirty = True

    def append(self, record: Mapping[str, Any]) -> None:
        """Append one record (a JSON object) as a line; durable at the next sync."""
        line = json.dumps(record, separators=(",", ":"), sort_keys=True, default=str).encode() + b"\n"
        self._file.append(line)
        self.records += 1
        self._dirty = True

    def maybe_sync(self) -> bool:
        """fsync when dirty and `sync_interval_s` elapsed since the last sync."""
        if self._dirty and self.clock.monotonic_ns() - self._last_sync_mono_ns >= self.sync_interval_s * 1e9:
            self.sync_now()
            return True
        return False

    def sync_now(self) -> None:
        """fsync now (after each time mark)."""
        if self._dirty:
            self._file.fsync()
            self._dirty = False
        self._last_sync_mono_ns = self.clock.monotonic_ns()

    def close(self) -> None:
        """fsync and close."""
        self._dirty = True
        self.sync_now()
        self._file.close()


def _ends_with_newline(path: Path) -> bool:
    with open(path, "rb") as f:
        f.seek(-1, 2)
        return f.read(1) == b"\n"


@dataclass(frozen=True, slots=True)
class EventRead:
    """What `read_events` found: the records in order and how many lines it had to skip (torn/corrupt)."""

    records: list[dict[str, Any]]
    skipped_lines: int


def read_events(path: Path) -> EventRead:
    """Every complete JSON object line of an events log; torn or corrupt lines are skipped and counted."""
    records: list[dict[str, Any]] = []
    skipped = 0
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        return EventRead([], 0)
    for line in data.split(b"\n"):
        if not line.strip():
            continue
        try:
            obj = json.loads(line)
        except ValueError:
            skipped += 1
            continue
        if isinstance(obj, dict):
            records.append(obj)
        else:
            skipped += 1
    return EventRead(records, skipped)
