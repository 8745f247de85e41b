"""A UBX byte stream (a log, a journal's segments) decoded into what RINEX and post-processing need: raw epochs
with RTKLIB's loss-of-lock rules, camera marks, ephemerides, MON-VER, the receiver's own fixes, and the regions
of the stream that held no valid frame (corruption, torn tails) with their byte offsets. Pure: bytes in."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import dataclass, field

from onboard.receiver.decode import (
    DecodeStats,
    LockTracker,
    MonVer,
    NavFix,
    SubframeWords,
    TimeMarks,
    ephemeris_from_subframe,
    iter_decoded,
)
from onboard.receiver.framing import MAX_UBX_PAYLOAD, Frame, iter_frames
from onboard.rtk.types import CameraMark, Ephemeris, ObsEpoch

log = logging.getLogger(__name__)

MAX_FRAME_BYTES = MAX_UBX_PAYLOAD + 8
"""A region longer than the longest frame cannot be one torn frame: it is reported as corrupt."""


@dataclass
class Collected:
    """Everything one input contributed (pure data, filled by `collect`)."""

    epochs: list[ObsEpoch] = field(default_factory=list)
    marks: list[CameraMark] = field(default_factory=list)
    ephemerides: list[Ephemeris] = field(default_factory=list)
    mon_ver: MonVer | None = None
    fixes_ecef_m: list[tuple[float, float, float]] = field(default_factory=list)
    leap_s: int | None = None
    stats: DecodeStats = field(default_factory=DecodeStats)
    unframed: list[tuple[int, int]] = field(default_factory=list)
    """Regions (stream byte offset, length) that hold no valid frame of any protocol: corruption, torn tails."""
    stream_bytes: int = 0


@dataclass(frozen=True)
class StreamPlaces:
    """Where a byte of a concatenated input stream lives: the files (name, size in bytes) in stream order; a
    size None for the last file when it is not known (gzip)."""

    files: tuple[tuple[str, int | None], ...]

    def where(self, offset: int) -> str:
        """`name byte k` for stream byte `offset`."""
        start = 0
        for name, size in self.files:
            if size is None or offset < start + size:
                return f"{name} byte {offset - start}"
            start += size
        return f"byte {offset}"

    def ends(self) -> set[int]:
        """Stream offsets at which a file ends (a region ending there is that file's torn tail)."""
        out, start = set(), 0
        for _, size in self.files:
            if size is None:
                break
            start += size
            out.add(start)
        return out


class _UnframedBytes:
    """Finds the stream regions between consecutive UBX frames that are not NMEA/RTCM3 either (pass the chunks
    through `feed` and every frame to `frame`); only the bytes since the last frame are held."""

    def __init__(self) -> None:
        self.buf = bytearray()
        self.base = 0  # stream offset of buf[0]
        self.end = 0  # stream offset after the last frame
        self.total = 0
        self.regions: list[tuple[int, int]] = []

    def feed(self, chunks: Iterator[bytes]) -> Iterator[bytes]:
        for chunk in chunks:
            del self.buf[: self.end - self.base]  # once per chunk: the bytes before the last frame are done
            self.base = self.end
            self.buf += chunk
            self.total += len(chunk)
            yield chunk

    def frame(self, frame: Frame) -> None:
        if frame.offset > self.end:
            self._gap(self.end, frame.offset)
        self.end = frame.offset + len(frame.raw)

    def finish(self) -> list[tuple[int, int]]:
        if self.total > self.end:
            self._gap(self.end, self.total)
        return self.regions

    def _gap(self, start: int, stop: int) -> None:
        data = bytes(self.buf[start - self.base : stop - self.base])
        if sum(len(f.raw) for f in iter_frames(data)) < len(data):
            self.regions.append((start, stop - start))


def describe_unframed(collected: Collected, places: StreamPlaces, listed: int = 5) -> list[str]:
    """Sentences for the regions of `Collected.unframed`: torn tails (a region no longer than a frame ending
    where a file or the stream ends) one each, corrupt regions summed with the first `listed` named by place."""
    regions = collected.unframed
    ends = places.ends() | {collected.stream_bytes}
    out = []
    torn = [(o, n) for o, n in regions if o + n in ends and n <= MAX_FRAME_BYTES]
    for o, n in torn:
        out.append(f"torn tail: {n} bytes at {places.where(o)} are not a complete frame (skipped)")
    corrupt = [r for r in regions if r not in torn]
    if corrupt:
        shown = ", ".join(f"{places.where(o)} ({n} B)" for o, n in corrupt[:listed])
        more = f" and {len(corrupt) - listed} more" if len(corrupt) > listed else ""
        out.append(f"{sum(n for _, n in corrupt)} bytes in {len(corrupt)} region{'s' if len(corrupt) > 1 else ''} "
                   f"hold no valid frame (corrupt, skipped): at {shown}{more}")
    return out


def collect(chunks: Iterator[bytes], mark_edges: str = "falling") -> Collected:
    """Decode a byte stream into what the RINEX writers need (epochs with RTKLIB's LLI, marks, ephemerides),
    noting in `unframed` the regions that held no valid frame. `mark_edges`: which TIM-TM2 edges are kept
    ("falling" = a hot-shoe flash, "rising", or "both")."""
    from onboard.rtk.lnav import LnavAssembler

    out = Collected()
    unframed = _UnframedBytes()
    tracker = LockTracker()
    assembler = LnavAssembler()
    edges = ("falling", "rising") if mark_edges == "both" else (mark_edges,)
    last_time = None
    for item in iter_decoded(unframed.feed(chunks), out.stats, on_frame=unframed.frame):
        if isinstance(item, ObsEpoch):
            if last_time is not None and item.time <= last_time:
                log.warning("epoch %s not after %s: dropped", item.time, last_time)
                continue
            last_time = item.time
            out.epochs.append(tracker.update(item))
            if item.leap_s is not None:
                out.leap_s = item.leap_s
        elif isinstance(item, TimeMarks):
            out.marks += [m for m in item.marks if m.edge in edges]
        elif isinstance(item, SubframeWords):
            eph = ephemeris_from_subframe(assembler, item, out.stats.reference_week)
            if eph is not None:
                out.ephemerides.append(eph)
        elif isinstance(item, Ephemeris):
            out.ephemerides.append(item)
        elif isinstance(item, MonVer):
            out.mon_ver = item
        elif isinstance(item, NavFix) and (item.fix_type is None or item.fix_type >= 3):
            out.fixes_ecef_m.append(item.pos_ecef_m)
    out.unframed = unframed.finish()
    out.stream_bytes = unframed.total
    return out


