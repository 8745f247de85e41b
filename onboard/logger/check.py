"""Check a recorded flight: segments against the manifest (size, SHA-256) and their numbering, each segment's
index (present, in order, within the data), the event log (present, every line a record), torn tails.

Pure reading: never modifies the flight. Used by `python -m onboard check FLIGHT_DIR` and by the ground before
import. What a power cut leaves is reported, not an error (every reader stops cleanly at it): a torn frame at a
segment's end, a torn index record, an event line cut short (printable JSON text that stops early). Anything
else is a problem: a missing segment, index or event log, lines of garbage, a closed flight's log cut short.
"""

from __future__ import annotations

import hashlib
import itertools
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from onboard.logger.events import read_events
from onboard.logger.journal import (
    EVENTS_NAME,
    INDEX_RECORD,
    list_segments,
    numbering_gaps,
    read_index,
    read_manifest,
)
from onboard.receiver.framing import StreamFramer


@dataclass
class SegmentCheck:
    """One segment: `bytes` on disk, `listed` in the manifest, `hash_ok` (None if unlisted), frames found,
    `torn_tail_bytes` bytes after the last complete frame, `index_records` and whether they cover the file."""

    name: str
    bytes: int
    listed: bool
    hash_ok: bool | None
    frames: int
    torn_tail_bytes: int
    index_records: int
    index_torn_bytes: int
    index_ok: bool


@dataclass
class FlightCheck:
    """The whole flight; `problems` are real faults (hash mismatch, unlisted segment, index beyond data)."""

    flight: str
    closed: bool
    segments: list[SegmentCheck] = field(default_factory=list)
    events: int = 0
    events_skipped_lines: int = 0
    events_torn_lines: int = 0
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True when nothing but torn tails was found."""
        return not self.problems

    def to_json(self) -> dict[str, Any]:
        """JSON-able dict."""
        return {
            "flight": self.flight, "closed": self.closed, "ok": self.ok, "problems": self.problems,
            "events": self.events, "events_skipped_lines": self.events_skipped_lines,
            "events_torn_lines": self.events_torn_lines,
            "segments": [vars(s) for s in self.segments],
        }


def check_flight(flight_dir: Path) -> FlightCheck:
    """Check every segment of `flight_dir` (see the module docstring)."""
    flight_dir = Path(flight_dir)
    manifest = read_manifest(flight_dir)
    result = FlightCheck(flight_dir.name, bool(manifest and manifest.closed))
    if manifest is None:
        result.problems.append("manifest.json missing or unreadable")
    listed = {s.name: s for s in manifest.segments} if manifest else {}
    segments = list_segments(flight_dir)
    result.problems += numbering_gaps(segments)
    for path in segments:
        data = path.read_bytes()
        framer = StreamFramer()
        frames = len(framer.feed(data))
        entry = listed.get(path.name)
        hash_ok = None if entry is None else (entry.bytes == len(data)
                                              and entry.sha256 == hashlib.sha256(data).hexdigest())
        idx_path = path.with_suffix(".idx")
        records = read_index(idx_path)
        idx_size = idx_path.stat().st_size if idx_path.exists() else 0
        index_ok = all(r.offset < len(data) for r in records) and all(
            a.offset < b.offset and a.monotonic_ns <= b.monotonic_ns for a, b in itertools.pairwise(records)
        )
        seg = SegmentCheck(path.name, len(data), entry is not None, hash_ok, frames, framer.pending,
                           len(records), idx_size % INDEX_RECORD.size, index_ok)
        result.segments.append(seg)
        if entry is None and manifest is not None and manifest.closed:
            result.problems.append(f"{path.name}: not listed in the closed manifest")
        if hash_ok is False:
            result.problems.append(f"{path.name}: size or SHA-256 differs from the manifest")
        if not idx_path.exists():
            result.problems.append(f"{idx_path.name}: index missing (the host times of {path.name} are lost)")
        elif not index_ok:
            result.problems.append(f"{idx_path.name}: index points beyond the data or goes backwards")
        elif seg.index_torn_bytes and entry is not None and not entry.recovered and result.closed:
            # a segment closed cleanly had its index fsync'd whole: a partial record is damage, not a power cut
            result.problems.append(f"{idx_path.name}: truncated or extended ({idx_size} bytes, not whole "
                                   f"{INDEX_RECORD.size}-byte records) in a cleanly closed segment")
    for name in listed:
        if not (flight_dir / name).exists():
            result.problems.append(f"{name}: listed in the manifest but missing")
    _check_events(flight_dir / EVENTS_NAME, result)
    return result


def _is_torn_record(line: bytes) -> bool:
    """A record line cut short by a power cut: the recorder's JSON (`{"...`, printable ASCII) stopping early."""
    return line.startswith(b'{"') and all(0x20 <= c < 0x7F for c in line)


def _check_events(path: Path, result: FlightCheck) -> None:
    """Count the event records; a missing log, garbage lines, or a closed flight's log cut short are problems."""
    if not path.exists():
        result.problems.append(f"{EVENTS_NAME}: event log missing (the camera marks and configuration results "
                               "are lost)")
        return
    found = read_events(path)
    result.events = len(found.records)
    result.events_skipped_lines = found.skipped_lines
    if not found.skipped_lines:
        if result.closed and path.stat().st_size and not path.read_bytes().endswith(b"\n"):
            result.problems.append(f"{EVENTS_NAME}: cut short (a closed flight's log ends within a line)")
        return
    data = path.read_bytes()
    garbage: list[int] = []
    offset = 0
    for line in data.split(b"\n"):
        text = line.strip()
        if text and not _parses(text):
            if _is_torn_record(text):
                result.events_torn_lines += 1
            else:
                garbage.append(offset)
        offset += len(line) + 1
    if garbage:
        where = ", ".join(str(o) for o in garbage[:5]) + (f" and {len(garbage) - 5} more" if len(garbage) > 5 else "")
        result.problems.append(f"{EVENTS_NAME}: {len(garbage)} line{'s' if len(garbage) > 1 else ''} of garbage "
                               f"(not event records) at byte {where}")
    if result.closed and not data.endswith(b"\n"):
        result.problems.append(f"{EVENTS_NAME}: cut short (a closed flight's log ends within a line)")


def _parses(line: bytes) -> bool:
    try:
        return isinstance(json.loads(line), dict)
    except ValueError:
        return False
