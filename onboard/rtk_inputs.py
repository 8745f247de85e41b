"""Base-station inputs for RTK beyond RINEX and plain UBX logs: RTCM3 streams and mixed UBX/RTCM3 logs.

A base stream (a telemetry-radio journal, an NTRIP capture, the M8P base log with RTCM3 interleaved with UBX)
is decoded with the lead's `RtcmDecoder` (1002/1004/1074/1077 GPS → `ObsEpoch`, 1005/1006 → base position,
1019 → `Ephemeris`). RTCM epochs carry no GPS week: it is resolved from a reference time, normally the first
rover epoch. UBX epochs found in the same stream (RXM-RAW/RAWX) are used instead when they outnumber the
RTCM ones (a base that logs its own raw data at full rate is better than its lossy radio stream).

`read_base_observations(path, reference)` is the hook `onboard rtk` calls for its `--base` input; everything
else here is pure (bytes in, typed values out).
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from onboard.errors import InputError
from onboard.gnsstime import GpsTime
from onboard.receiver.framing import Frame, Protocol, StreamFramer
from onboard.receiver.rtcm import RTCM_GPS_OBS, BasePosition, RtcmDecoder
from onboard.rtk.types import Ephemeris, ObsEpoch

log = logging.getLogger(__name__)

EPOCH_MERGE_TOLERANCE_NS = 1_000_000
"""RTCM observation messages of one epoch (several MSM/legacy messages) share a time tag to the ms."""


@dataclass
class RtcmCollected:
    """What an RTCM3 stream held: GPS epochs (time order), ephemerides, the last base position, counts."""

    epochs: list[ObsEpoch] = field(default_factory=list)
    ephemerides: list[Ephemeris] = field(default_factory=list)
    base_position: BasePosition | None = None
    frames: int = 0
    messages: dict[int, int] = field(default_factory=dict)
    undecodable: int = 0


def _merge(a: ObsEpoch, b: ObsEpoch) -> ObsEpoch:
    """One epoch from two messages of the same time (satellites of `b` not already in `a` are added)."""
    from dataclasses import fields, replace

    have = set(zip(a.gnss_id.tolist(), a.sv_id.tolist()))
    keep = np.array([(g, s) not in have for g, s in zip(b.gnss_id.tolist(), b.sv_id.tolist())], bool)
    if not keep.any():
        return a
    extra = b.select(keep)
    cols: dict[str, Any] = {f.name: np.concatenate([getattr(a, f.name), getattr(extra, f.name)])
                            for f in fields(a) if isinstance(getattr(a, f.name), np.ndarray)}
    return replace(a, **cols)


class RtcmCollector:
    """Incremental RTCM3 stream → `RtcmCollected` (feed frames in stream order). Pure: no I/O."""

    def __init__(self, reference: GpsTime) -> None:
        self.reference = reference
        self.decoder = RtcmDecoder()
        self.out = RtcmCollected()

    def add(self, frame: Frame) -> ObsEpoch | BasePosition | Ephemeris | None:
        """Decode one frame (non-RTCM frames are ignored); returns what it decoded to."""
        if frame.protocol is not Protocol.RTCM3:
            return None
        out = self.out
        out.frames += 1
        out.messages[frame.msg_id] = out.messages.get(frame.msg_id, 0) + 1
        before = self.decoder.errors
        item = self.decoder.decode(frame, self.reference)
        out.undecodable += self.decoder.errors - before
        if isinstance(item, ObsEpoch):
            if len(item) == 0:
                return item
            # Keep the reference near the stream, so a long log never drifts past half a week.
            self.reference = item.time
            last = out.epochs[-1] if out.epochs else None
            if last is not None and abs(item.time.diff_ns(last.time)) < EPOCH_MERGE_TOLERANCE_NS:
                out.epochs[-1] = _merge(last, item)
            elif last is not None and item.time <= last.time:
                log.warning("RTCM epoch %s not after %s: dropped", item.time, last.time)
            else:
                out.epochs.append(item)
        elif isinstance(item, Ephemeris):
            out.ephemerides.append(item)
        elif isinstance(item, BasePosition):
            out.base_position = item
        return item


def collect_rtcm(chunks: Iterable[bytes], reference: GpsTime) -> RtcmCollected:
    """Decode every RTCM3 frame in a byte stream (other protocols interleaved are skipped)."""
    framer = StreamFramer()
    col = RtcmCollector(reference)
    for chunk in chunks:
        for frame in framer.feed(chunk):
            col.add(frame)
    for frame in framer.flush():
        col.add(frame)
    return col.out


def count_protocols(data: bytes) -> dict[Protocol, int]:
    """Number of checksum-valid frames per protocol in a byte sample (to tell what a file is)."""
    counts: dict[Protocol, int] = {}
    framer = StreamFramer()
    for frame in [*framer.feed(data), *framer.flush()]:
        counts[frame.protocol] = counts.get(frame.protocol, 0) + 1
    return counts


def read_base_observations(path: str | Path, reference: GpsTime | None):  # type: ignore[no-untyped-def]
    """Base input for `onboard rtk`: RINEX, UBX log, RTCM3 stream or mixed UBX/RTCM3 log → `ObsInput`.

    `reference` (normally the rover's first epoch time) resolves the GPS week of RTCM epochs; without it a
    pure RTCM stream is refused (its week would be a guess). The base position is the RINEX header's, else
    the stream's last 1005/1006 (phase centre = ARP + antenna height), else the median of the log's fixes.
    Raises InputError when the file holds no usable base observations.
    """
    from onboard.formats.textfile import read_head_bytes
    from onboard.rtk_cli import ObsInput, read_observations

    path = Path(path)
    if path.is_dir():  # a journal directory: the rover's radio journal (<flight>/radio) or a base flight
        return _read_journal_dir(path, reference)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    head = read_head_bytes(path, 65536)
    if b"RINEX VERSION" in head[:200]:
        return read_observations(path)
    from onboard.receiver.decode import iter_file_bytes

    counts = count_protocols(head)
    if not counts.get(Protocol.RTCM3):
        return read_observations(path)
    if reference is None:
        raise InputError(f"{path}: an RTCM3 stream carries no GPS week; a rover time reference is needed")
    rtcm = collect_rtcm(iter_file_bytes(path), reference)
    gps_msgs = sum(n for m, n in rtcm.messages.items() if m in RTCM_GPS_OBS)
    log.info("%s: %d RTCM3 frames (%s), %d GPS epochs, %d undecodable", path, rtcm.frames,
             ", ".join(f"{m}×{n}" for m, n in sorted(rtcm.messages.items())), len(rtcm.epochs), rtcm.undecodable)
    ubx: ObsInput | None = None
    if counts.get(Protocol.UBX):
        try:
            ubx = read_observations(path)
        except InputError:
            ubx = None  # no RXM-RAW(X) epochs: the RTCM part is all there is
    pos = rtcm.base_position.phase_centre_ecef_m if rtcm.base_position is not None else None
    if ubx is not None and len(ubx.epochs) >= len(rtcm.epochs):
        return ObsInput(ubx.epochs, ubx.ephemerides + rtcm.ephemerides,
                        pos if pos is not None else ubx.antenna_pos_ecef_m, "ubx+rtcm3")
    if not rtcm.epochs:
        raise InputError(f"{path}: RTCM3 stream without GPS observations (messages: "
                         f"{sorted(rtcm.messages) or 'none'}; GPS observation messages: {gps_msgs})")
    ephs = rtcm.ephemerides + (ubx.ephemerides if ubx is not None else [])
    return ObsInput(rtcm.epochs, ephs, pos, "rtcm3")


def _read_journal_dir(path: Path, reference: GpsTime | None):  # type: ignore[no-untyped-def]
    """Base input from a journal directory (segments in order, torn tail tolerated): RTCM3 or UBX inside."""
    from onboard.convert import collect
    from onboard.logger.journal import iter_journal_bytes
    from onboard.rtk_cli import ObsInput

    data = b"".join(iter_journal_bytes(path))
    counts = count_protocols(data)
    if counts.get(Protocol.RTCM3):
        if reference is None:
            raise InputError(f"{path}: an RTCM3 stream carries no GPS week; a rover time reference is needed")
        rtcm = collect_rtcm([data], reference)
        if rtcm.epochs:
            pos = rtcm.base_position.phase_centre_ecef_m if rtcm.base_position is not None else None
            return ObsInput(rtcm.epochs, rtcm.ephemerides, pos, "rtcm3")
    col = collect(iter([data]))
    if not col.epochs:
        raise InputError(f"{path}: journal without base observations (RTCM3 1002/1004/1074/1077 or UBX RXM-RAW(X))")
    pos = np.median(np.array(col.fixes_ecef_m), axis=0) if col.fixes_ecef_m else None
    return ObsInput(col.epochs, col.ephemerides, pos, "ubx")
