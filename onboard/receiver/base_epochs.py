"""Base observations from a correction stream: RTCM3 frames (and a raw UBX relay) → time-ordered base epochs.

Pure: frames in, typed values out; no I/O, no clock. RTCM epochs carry no GPS week: it is resolved from a
reference time (the rover's first epoch, then the stream's own epochs). Messages of one epoch (several legacy or
MSM messages sharing a time tag) are merged into one epoch.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from onboard.gnsstime import GpsTime
from onboard.receiver.framing import Frame, Protocol, StreamFramer
from onboard.receiver.rtcm import BasePosition, RtcmDecoder
from onboard.rtk.types import Ephemeris, ObsEpoch

log = logging.getLogger(__name__)

EPOCH_MERGE_TOLERANCE_NS = 1_000_000
"""RTCM observation messages of one epoch (several MSM/legacy messages) share a time tag to the ms."""
RTCM_POSITION = frozenset({1005, 1006})
"""Base position messages (antenna reference point): decodable without a time reference."""


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
    """Incremental RTCM3 stream → `RtcmCollected` (feed frames in stream order). Pure: no I/O.

    The one set of epoch rules for post-processing (`collect_rtcm`) and real time
    (`onboard.realtime.service.BaseStream`): messages of one time tag (within EPOCH_MERGE_TOLERANCE_NS) merge
    into one epoch; an epoch not after the last one is dropped (logged); the GPS week of an RTCM epoch is
    resolved from `reference`, which then follows the stream's own epochs (a long log never drifts past half a
    week). `reference` None (real time before the rover's first epoch): only 1005/1006 (which carry no time)
    are decoded until `set_reference`. `max_epochs` keeps only the newest epochs (real time; None: all).
    """

    def __init__(self, reference: GpsTime | None, max_epochs: int | None = None) -> None:
        self.reference = reference
        self.max_epochs = max_epochs
        self.decoder = RtcmDecoder()
        self.out = RtcmCollected()
        self.epoch_count = 0
        """Epochs appended since the start (the kept list may be shorter, see `max_epochs`)."""

    def set_reference(self, reference: GpsTime) -> None:
        """Give the week reference if none was given yet (the rover's first epoch); later calls change nothing."""
        if self.reference is None:
            self.reference = reference

    def add(self, frame: Frame) -> ObsEpoch | BasePosition | Ephemeris | None:
        """Decode one frame (non-RTCM frames are ignored); returns what it decoded to."""
        if frame.protocol is not Protocol.RTCM3:
            return None
        out = self.out
        out.frames += 1
        out.messages[frame.msg_id] = out.messages.get(frame.msg_id, 0) + 1
        reference = self.reference
        if reference is None:
            if frame.msg_id not in RTCM_POSITION:
                return None  # no week to resolve yet
            reference = GpsTime(0, 0)  # a position message carries no time
        before = self.decoder.errors
        item = self.decoder.decode(frame, reference)
        out.undecodable += self.decoder.errors - before
        if isinstance(item, ObsEpoch):
            self.add_epoch(item)
        elif isinstance(item, Ephemeris):
            out.ephemerides.append(item)
        elif isinstance(item, BasePosition):
            out.base_position = item
        return item

    def add_epoch(self, epoch: ObsEpoch) -> bool:
        """Add one base epoch by the rules above (also for epochs of a raw UBX relay); True if it is a new one."""
        if len(epoch) == 0:
            return False
        self.reference = epoch.time
        epochs = self.out.epochs
        last = epochs[-1] if epochs else None
        if last is not None and abs(epoch.time.diff_ns(last.time)) < EPOCH_MERGE_TOLERANCE_NS:
            epochs[-1] = _merge(last, epoch)
            return False
        if last is not None and epoch.time <= last.time:
            log.warning("RTCM epoch %s not after %s: dropped", epoch.time, last.time)
            return False
        epochs.append(epoch)
        self.epoch_count += 1
        if self.max_epochs is not None and len(epochs) > self.max_epochs:
            del epochs[: len(epochs) - self.max_epochs]
        return True


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


