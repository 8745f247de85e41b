"""The raw journal: every byte read from the receiver port, appended before anything parses it.

A flight is a directory `flight-YYYYmmddTHHMMSSZ/` holding segments `NNNNNN.ubx` (plain receiver byte streams
whose names sort in recording order: RTKLIB convbin, pyubx2 and u-center read them directly), a sidecar index
`NNNNNN.idx` per segment (fixed 24-byte records: segment byte offset, host monotonic ns, host wall ns of the
read that delivered the bytes at that offset), `events.jsonl` and `manifest.json` (closed segments with size
and SHA-256, receiver information, configuration report; written atomically).

Durability: segment and index are fsync'd when `maybe_sync` finds `sync_interval_s` elapsed and immediately on
`sync_now` (after each time mark). A restart never appends to a possibly torn segment: it starts the next one,
and `recover` lists the torn previous segments in the manifest with their true size and hash.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import itertools
import json
import logging
import re
import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from onboard.hw.ports import Clock
from onboard.logger.files import AppendFile, FileLayer, OsFileLayer
from onboard.receiver.framing import Frame, StreamFramer

log = logging.getLogger(__name__)

SEGMENT_SUFFIX = ".ubx"
INDEX_SUFFIX = ".idx"
MANIFEST_NAME = "manifest.json"
EVENTS_NAME = "events.jsonl"
RADIO_DIR = "radio"
"""The flight's sub-journal (same format) of the base corrections as received, by radio or reassembled from
MAVLink GPS_RTCM_DATA (written by onboard.realtime)."""
SOLUTION_NAME = "solution.pos"
"""The flight's real-time RTK solution (written by onboard.realtime)."""
MANIFEST_FORMAT = "directgeo-flight/1"
INDEX_RECORD = struct.Struct("<Qqq")  # segment byte offset, monotonic ns, wall ns
_SEGMENT_RE = re.compile(r"^(\d{6})\.ubx$")


@dataclass(frozen=True, slots=True)
class JournalOptions:
    """How the journal syncs and rotates.

    `sync_interval_s`: longest time unsynced bytes may wait (the daemon calls `maybe_sync` often enough);
    `segment_max_bytes` / `segment_max_s`: rotate when either is reached (0 disables that rule).
    """

    sync_interval_s: float = 0.5
    segment_max_bytes: int = 64 * 1024 * 1024
    segment_max_s: float = 3600.0


@dataclass(frozen=True, slots=True)
class IndexRecord:
    """One sidecar-index record: the bytes from `offset` on arrived in a read at these host times."""

    offset: int
    monotonic_ns: int
    wall_ns: int


@dataclass
class SegmentInfo:
    """A segment as the manifest lists it."""

    name: str
    bytes: int
    sha256: str
    first_wall_ns: int | None = None
    last_wall_ns: int | None = None
    recovered: bool = False

    def to_json(self) -> dict[str, Any]:
        """JSON-able form."""
        return {
            "name": self.name,
            "index": self.name.replace(SEGMENT_SUFFIX, INDEX_SUFFIX),
            "bytes": self.bytes,
            "sha256": self.sha256,
            "first_wall_ns": self.first_wall_ns,
            "last_wall_ns": self.last_wall_ns,
            "recovered": self.recovered,
        }


@dataclass
class Manifest:
    """The per-flight manifest (rewritten atomically after every segment closes)."""

    flight: str
    created_wall_ns: int
    segments: list[SegmentInfo] = field(default_factory=list)
    receiver: dict[str, Any] | None = None
    config_report: dict[str, Any] | None = None
    closed: bool = False
    close_reason: str | None = None
    restarts: int = 0

    def to_json(self) -> dict[str, Any]:
        """JSON-able form."""
        return {
            "format": MANIFEST_FORMAT,
            "flight": self.flight,
            "created_wall_ns": self.created_wall_ns,
            "segments": [s.to_json() for s in self.segments],
            "total_bytes": sum(s.bytes for s in self.segments),
            "receiver": self.receiver,
            "config_report": self.config_report,
            "closed": self.closed,
            "close_reason": self.close_reason,
            "restarts": self.restarts,
        }

    @classmethod
    def from_json(cls, obj: dict[str, Any]) -> Manifest:
        """Parse a manifest written by `to_json`."""
        segs = [
            SegmentInfo(
                name=s["name"],
                bytes=int(s["bytes"]),
                sha256=s["sha256"],
                first_wall_ns=s.get("first_wall_ns"),
                last_wall_ns=s.get("last_wall_ns"),
                recovered=bool(s.get("recovered", False)),
            )
            for s in obj.get("segments", [])
        ]
        return cls(
            flight=obj["flight"],
            created_wall_ns=int(obj["created_wall_ns"]),
            segments=segs,
            receiver=obj.get("receiver"),
            config_report=obj.get("config_report"),
            closed=bool(obj.get("closed", False)),
            close_reason=obj.get("close_reason"),
            restarts=int(obj.get("restarts", 0)),
        )


def flight_name(wall_ns: int) -> str:
    """`flight-YYYYmmddTHHMMSSZ` for a host wall time in ns (UTC)."""
    t = _dt.datetime.fromtimestamp(wall_ns / 1e9, tz=_dt.UTC)
    return "flight-" + t.strftime("%Y%m%dT%H%M%SZ")


def segment_name(number: int) -> str:
    """`NNNNNN.ubx` (zero-padded so names sort in recording order)."""
    return f"{number:06d}{SEGMENT_SUFFIX}"


def is_segment_name(name: str) -> bool:
    """Whether a file name (one component) is a journal segment's, `NNNNNN.ubx`."""
    return _SEGMENT_RE.match(name) is not None


def list_segments(flight_dir: Path) -> list[Path]:
    """The flight's segment files in recording order."""
    return sorted(p for p in Path(flight_dir).iterdir() if _SEGMENT_RE.match(p.name))


def write_atomic(layer: FileLayer, path: Path, data: bytes) -> None:
    """Write `path` atomically and durably: temp file, fsync, rename, fsync(dir)."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.unlink(missing_ok=True)
    handle = layer.create(tmp)
    try:
        handle.append(data)
        handle.fsync()
    finally:
        handle.close()
    layer.replace(tmp, path)
    layer.fsync_dir(path.parent)


def read_manifest(flight_dir: Path) -> Manifest | None:
    """The flight's manifest, or None when absent or unreadable (a power cut before its first write)."""
    path = Path(flight_dir) / MANIFEST_NAME
    try:
        return Manifest.from_json(json.loads(path.read_bytes()))
    except FileNotFoundError:
        return None
    except (ValueError, KeyError, TypeError) as exc:
        log.warning("manifest %s unreadable (%s): rebuilding from the segments", path, exc)
        return None


def _file_digest(path: Path) -> tuple[int, str]:
    h = hashlib.sha256()
    size = 0
    with open(path, "rb") as f:
        while chunk := f.read(1 << 20):
            h.update(chunk)
            size += len(chunk)
    return size, h.hexdigest()


class Journal:
    """Append-only raw journal of one flight (see the module docstring).

    Parameters
    ----------
    flight_dir : the flight directory (created if missing; an existing flight is resumed with a new segment).
    clock : host clocks; `maybe_sync` measures the interval on `clock.monotonic_ns`.
    options : sync and rotation rules.
    files : the file layer (the OS by default; a recording layer in power-cut tests).
    """

    def __init__(
        self,
        flight_dir: Path,
        clock: Clock,
        options: JournalOptions = JournalOptions(),
        files: FileLayer | None = None,
    ) -> None:
        self.flight_dir = Path(flight_dir)
        self.clock = clock
        self.options = options
        self.files: FileLayer = files if files is not None else OsFileLayer()
        self.flight_dir.mkdir(parents=True, exist_ok=True)
        self.manifest = self.recover()
        self.bytes_written = 0
        self.syncs = 0
        self._seg: AppendFile | None = None
        self._idx: AppendFile | None = None
        self._seg_info: SegmentInfo | None = None
        self._hash = hashlib.sha256()
        self._seg_opened_mono_ns = 0
        self._last_sync_mono_ns = clock.monotonic_ns()
        self._dirty = False
        self._closed = False
        existing = list_segments(self.flight_dir)
        self._next_number = int(existing[-1].name[:6]) + 1 if existing else 0
        self._open_segment()
        self.write_manifest()

    # -- recovery ---------------------------------------------------------------------------------------
    def recover(self) -> Manifest:
        """Load the manifest and list every segment it lacks (or lists with a wrong size) with its true size/hash.

        Torn segments from a power cut are never modified: their bytes are the record, and every reader
        tolerates a torn last frame.
        """
        manifest = read_manifest(self.flight_dir)
        if manifest is None:
            manifest = Manifest(flight=self.flight_dir.name, created_wall_ns=self.clock.wall_ns())
        else:
            manifest.restarts += 1
            manifest.closed = False
            manifest.close_reason = None
        listed = {s.name: s for s in manifest.segments}
        changed = False
        for path in list_segments(self.flight_dir):
            size, digest = _file_digest(path)
            known = listed.get(path.name)
            if known is not None and known.bytes == size and known.sha256 == digest:
                continue
            records = read_index(path.with_suffix(INDEX_SUFFIX))
            info = SegmentInfo(
                name=path.name,
                bytes=size,
                sha256=digest,
                first_wall_ns=records[0].wall_ns if records else None,
                last_wall_ns=records[-1].wall_ns if records else None,
                recovered=True,
            )
            if known is not None:
                manifest.segments[manifest.segments.index(known)] = info
            else:
                manifest.segments.append(info)
            changed = True
            log.warning("recovered segment %s/%s: %d bytes", self.flight_dir.name, path.name, size)
        manifest.segments.sort(key=lambda s: s.name)
        if changed:
            log.info("flight %s: manifest rebuilt after an unclean stop", self.flight_dir.name)
        return manifest

    # -- writing ----------------------------------------------------------------------------------------
    def _open_segment(self) -> None:
        name = segment_name(self._next_number)
        self._next_number += 1
        self._seg = self.files.create(self.flight_dir / name)
        self._idx = self.files.create(self.flight_dir / name.replace(SEGMENT_SUFFIX, INDEX_SUFFIX))
        # The new names must survive a power cut too.
        self.files.fsync_dir(self.flight_dir)
        self._seg_info = SegmentInfo(name=name, bytes=0, sha256="")
        self._hash = hashlib.sha256()
        self._seg_opened_mono_ns = self.clock.monotonic_ns()
        log.info("journal segment %s/%s opened", self.flight_dir.name, name)

    @property
    def current_segment(self) -> Path | None:
        """Path of the segment being written."""
        return self._seg.path if self._seg is not None else None

    def append(self, data: bytes, rx_monotonic_ns: int, rx_wall_ns: int) -> None:
        """Append received bytes and their index record now (durable at the next sync).

        Raises OSError (e.g. ENOSPC) from the file layer; the caller closes the flight.
        """
        if self._closed:
            raise ValueError("journal is closed")
        if not data:
            return
        assert self._seg is not None and self._idx is not None and self._seg_info is not None
        if self._rotation_due(rx_monotonic_ns):
            self.rotate()
            assert self._seg is not None and self._idx is not None and self._seg_info is not None
        offset = self._seg.size
        self._seg.append(data)
        self._hash.update(data)
        self._idx.append(INDEX_RECORD.pack(offset, rx_monotonic_ns, rx_wall_ns))
        info = self._seg_info
        info.bytes = self._seg.size
        if info.first_wall_ns is None:
            info.first_wall_ns = rx_wall_ns
        info.last_wall_ns = rx_wall_ns
        self.bytes_written += len(data)
        self._dirty = True

    def _rotation_due(self, now_mono_ns: int) -> bool:
        assert self._seg is not None
        if self._seg.size == 0:
            return False
        opts = self.options
        if opts.segment_max_bytes and self._seg.size >= opts.segment_max_bytes:
            return True
        return bool(opts.segment_max_s) and (now_mono_ns - self._seg_opened_mono_ns) >= opts.segment_max_s * 1e9

    def maybe_sync(self) -> bool:
        """fsync when unsynced bytes exist and `sync_interval_s` has elapsed since the last sync."""
        if not self._dirty:
            return False
        if self.clock.monotonic_ns() - self._last_sync_mono_ns < self.options.sync_interval_s * 1e9:
            return False
        self.sync_now()
        return True

    def sync_now(self) -> None:
        """fsync the segment, then its index (call right after each time mark)."""
        if self._seg is None or self._idx is None:
            return
        if self._dirty:
            self._seg.fsync()
            self._idx.fsync()
            self.syncs += 1
            self._dirty = False
        self._last_sync_mono_ns = self.clock.monotonic_ns()

    def _finish_segment(self) -> None:
        assert self._seg is not None and self._idx is not None and self._seg_info is not None
        self._dirty = True  # always fsync on close, even an empty segment
        self.sync_now()
        self._seg.close()
        self._idx.close()
        self._seg_info.sha256 = self._hash.hexdigest()
        self.manifest.segments.append(self._seg_info)
        self._seg = self._idx = None
        self._seg_info = None

    def rotate(self) -> None:
        """Close the current segment, list it in the manifest and open the next one."""
        self._finish_segment()
        self._open_segment()
        self.write_manifest()

    def set_receiver(self, receiver: dict[str, Any] | None, config_report: dict[str, Any] | None) -> None:
        """Record receiver identity and configuration report in the manifest (written now)."""
        self.manifest.receiver = receiver
        self.manifest.config_report = config_report
        if not self._closed:
            self.write_manifest()

    def write_manifest(self) -> None:
        """Write the manifest atomically (closed segments plus the open one's name without a hash yet)."""
        obj = self.manifest.to_json()
        if self._seg_info is not None:
            obj["open_segment"] = self._seg_info.name
        write_atomic(self.files, self.flight_dir / MANIFEST_NAME, json.dumps(obj, indent=1).encode() + b"\n")

    def close(self, reason: str = "stopped") -> None:
        """Close the segment (fsync) and write the final manifest atomically."""
        if self._closed:
            return
        self._finish_segment()
        self.manifest.closed = True
        self.manifest.close_reason = reason
        self._closed = True
        self.write_manifest()
        log.info("flight %s closed (%s): %d bytes", self.flight_dir.name, reason, self.bytes_written)

    @property
    def closed(self) -> bool:
        """True once `close` ran."""
        return self._closed


# -- readers ----------------------------------------------------------------------------------------------
def read_index(path: Path) -> list[IndexRecord]:
    """Every complete record of a sidecar index (a torn last record is ignored; a missing file gives [])."""
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        return []
    whole = len(data) - len(data) % INDEX_RECORD.size
    return [IndexRecord(*rec) for rec in INDEX_RECORD.iter_unpack(data[:whole])]


def numbering_gaps(segments: list[Path]) -> list[str]:
    """Segments absent from the numbering of `segments` (as `list_segments` gives them), one sentence per gap:
    `segment 000002.ubx missing between 000001.ubx and 000003.ubx`."""
    gaps: list[str] = []
    numbers = [int(p.name[:6]) for p in segments]
    for a, b in itertools.pairwise(numbers):
        if b > a + 1:
            names = ", ".join(segment_name(n) for n in range(a + 1, min(b, a + 6)))
            more = f" and {b - a - 6} more" if b - a - 1 > 5 else ""
            gaps.append(f"segment{'s' if b - a > 2 else ''} {names}{more} missing between {segment_name(a)} and "
                        f"{segment_name(b)}")
    return gaps


def journal_gaps(flight_dir: Path) -> list[str]:
    """What is missing from the flight's journal, one sentence each: segments absent from the numbering
    (`numbering_gaps`), segments the manifest lists that are gone, and segments shorter than the manifest
    says (truncated). Empty for a complete journal."""
    flight_dir = Path(flight_dir)
    segments = list_segments(flight_dir)
    found = {p.name for p in segments}
    numbers = [int(p.name[:6]) for p in segments]
    gaps = numbering_gaps(segments)
    manifest = read_manifest(flight_dir)
    for seg in manifest.segments if manifest is not None else []:
        if seg.name in found:
            size = (flight_dir / seg.name).stat().st_size
            if size < seg.bytes:
                gaps.append(f"segment {seg.name} is truncated: {size} bytes, the manifest lists {seg.bytes}")
            continue
        number = int(seg.name[:6]) if _SEGMENT_RE.match(seg.name) else -1
        if not (numbers and numbers[0] < number < numbers[-1]):  # inside the numbering it is named above
            gaps.append(f"segment {seg.name} listed in the manifest is missing")
    return gaps


def iter_journal_bytes(flight_dir: Path, chunk_bytes: int = 1 << 20,
                       warn: Callable[[str], None] | None = None) -> Iterator[bytes]:
    """The flight's recorded bytes, segment after segment in recording order (torn tails included as-is).

    Feed them to `StreamFramer` (which drops a torn frame and resynchronises) or a UBX reader. Each gap of
    `journal_gaps` (a missing or truncated segment) goes to `warn` (default: a logged warning) before the first
    byte, so that a reader never returns part of a flight without saying so.
    """
    report = warn if warn is not None else log.warning
    for gap in journal_gaps(flight_dir):
        report(f"{Path(flight_dir)}: {gap}")
    for path in list_segments(Path(flight_dir)):
        with open(path, "rb") as f:
            while chunk := f.read(chunk_bytes):
                yield chunk


def locate_offset(records: list[IndexRecord], offset: int) -> IndexRecord | None:
    """The index record covering segment byte `offset` (the read that delivered it), or None if unindexed."""
    lo, hi = 0, len(records)
    while lo < hi:
        mid = (lo + hi) // 2
        if records[mid].offset <= offset:
            lo = mid + 1
        else:
            hi = mid
    return records[lo - 1] if lo else None


def iter_journal_frames(flight_dir: Path) -> Iterator[Frame]:
    """Every checksum-valid frame of the flight in order (offsets are in the concatenated segment stream).

    A frame torn by a power cut is skipped and the framer resynchronises on the next segment's bytes.
    """
    framer = StreamFramer()
    for chunk in iter_journal_bytes(flight_dir):
        yield from framer.feed(chunk)
    framer.flush()
