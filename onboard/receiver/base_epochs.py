"""Base observations from a correction stream: RTCM3 frames (and a raw UBX relay) → time-ordered base epochs.

Pure: frames in, typed values out; no I/O, no clock. RTCM epochs carry no GPS week: it is resolved from a
reference time (the rover's first epoch, then the stream's own epochs). Messages of one epoch (several legacy or
MSM messages sharing a time tag) are merged into one epoch.

Two views of the same stream: `RtcmCollected.epochs`, the GPS epochs (GPS satellites only) that today's GPS
engine pairs with the rover, exactly as before multi-GNSS decoding; and `RtcmCollected.gnss_epochs`, every
system's observations reassembled per epoch time (`EpochAssembler`). A real base sends one MSM message per
system per epoch, all but the last with the multiple-message bit (DF393) set; a radio loses some of them. Each
message is put into the epoch of its time (GLONASS time of day and BeiDou time converted to GPS time first),
whatever arrived before or is missing: a lost GPS message leaves that epoch GLONASS-only, never lost, and it
says so (`BaseEpoch.complete` False, `BaseEpoch.systems`), so a pairing can take each system from the latest
base epoch that has it (`latest_base_epoch`) instead of a rover epoch meeting half a base.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from onboard.gnsstime import GpsTime
from onboard.receiver.framing import Frame, Protocol, StreamFramer
from onboard.receiver.rtcm import (
    BasePosition,
    GlonassChannel,
    GlonassCodePhaseBias,
    ObsMessageInfo,
    RtcmDecoder,
)
from onboard.rtk.types import Ephemeris, ObsEpoch

log = logging.getLogger(__name__)

EPOCH_MERGE_TOLERANCE_NS = 1_000_000
"""RTCM observation messages of one epoch (several MSM/legacy messages) share a time tag to the ms."""
RTCM_POSITION = frozenset({1005, 1006})
"""Base position messages (antenna reference point): decodable without a time reference."""


@dataclass(frozen=True)
class BaseEpoch:
    """One base epoch reassembled from the observation messages of its time (every system).

    `obs` the observations (GPS time; systems in message order, satellites sorted within each), `messages` the
    message numbers that made it, in arrival order, `complete` True when its last message (multiple-message bit
    clear) arrived: False means a message after the last one received is missing (a lost GPS or GLONASS part)
    or the stream ended; which systems are present is `systems`.
    """

    obs: ObsEpoch
    messages: tuple[int, ...]
    complete: bool

    @property
    def time(self) -> GpsTime:
        """The epoch (GPS time)."""
        return self.obs.time

    @property
    def systems(self) -> frozenset[int]:
        """u-blox gnssIds present."""
        return self.obs.systems()


@dataclass
class RtcmCollected:
    """What an RTCM3 stream held: GPS epochs (time order), every system's epochs reassembled per epoch time
    (`gnss_epochs`, time order), ephemerides, the last base position, the last GLONASS code-phase biases (1230),
    the GLONASS frequency channels learned (slot → k, from MSM5/7 and 1020), counts (`late_messages`:
    observation messages of an epoch already passed, dropped)."""

    epochs: list[ObsEpoch] = field(default_factory=list)
    gnss_epochs: list[BaseEpoch] = field(default_factory=list)
    ephemerides: list[Ephemeris] = field(default_factory=list)
    base_position: BasePosition | None = None
    glonass_biases: GlonassCodePhaseBias | None = None
    glo_fcn: dict[int, int] = field(default_factory=dict)
    frames: int = 0
    messages: dict[int, int] = field(default_factory=dict)
    undecodable: int = 0
    late_messages: int = 0


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


class EpochAssembler:
    """Observation messages → `BaseEpoch`s, one per epoch time (pure, incremental; feed in stream order).

    A message joins the open epoch when of its time (within EPOCH_MERGE_TOLERANCE_NS), else closes it and opens
    a new one; satellites already present are not added twice. An epoch closes as complete when a message with
    the multiple-message bit clear joins it, as incomplete when a message of another epoch arrives first (its
    last message was lost) or at `flush()`. A message is late, dropped and counted in `late`, only when its own
    system already closed an epoch at or after its time: one system's odd time tags (a stream writing GPS time
    into BeiDou's DF427, 14 s off) never cost the other systems their epochs. Closed epochs therefore come in
    stream order, which is time order for a sane stream (`RtcmCollector` files them by time).
    """

    def __init__(self) -> None:
        self._open: tuple[ObsEpoch, list[int]] | None = None  # the epoch under construction, its messages
        self._last_closed: dict[int, GpsTime] = {}  # per system
        self.late = 0

    def add(self, obs: ObsEpoch, info: ObsMessageInfo) -> list[BaseEpoch]:
        """Add one message's epoch; returns the epochs it closed (in closing order)."""
        t = obs.time
        last = self._last_closed.get(info.gnss_id)
        if last is not None and t.diff_ns(last) < EPOCH_MERGE_TOLERANCE_NS:
            self.late += 1
            log.warning("RTCM %d of epoch %s arrived after that epoch was closed: dropped", info.number, t)
            return []
        closed: list[BaseEpoch] = []
        if self._open is not None and abs(t.diff_ns(self._open[0].time)) >= EPOCH_MERGE_TOLERANCE_NS:
            closed.append(self._close(complete=False))  # another epoch began: the open one lost its last message
        if self._open is not None:
            ep, numbers = self._open
            self._open = (_merge(ep, obs), [*numbers, info.number])
        else:
            self._open = (obs, [info.number])
        if not info.more_follow:
            closed.append(self._close(complete=True))
        return closed

    def flush(self) -> list[BaseEpoch]:
        """Close the open epoch, if any (end of the stream): as incomplete."""
        return [self._close(complete=False)] if self._open is not None else []

    @property
    def pending(self) -> BaseEpoch | None:
        """The epoch still open (its last message not yet arrived), as it stands (incomplete); None if none."""
        return None if self._open is None else BaseEpoch(self._open[0], tuple(self._open[1]), False)

    def _close(self, complete: bool) -> BaseEpoch:
        assert self._open is not None
        obs, numbers = self._open
        self._open = None
        for g in obs.systems():
            self._last_closed[g] = obs.time
        return BaseEpoch(obs, tuple(numbers), complete)


def pairing_base_epoch(epochs: Sequence[BaseEpoch], t: GpsTime, systems: frozenset[int],
                       tolerance_s: float = 0.0) -> BaseEpoch | None:
    """The base epoch a single-base-epoch engine pairs with rover time `t`: the latest one not after `t` +
    `tolerance_s` that holds every system of `systems` (the engine's, u-blox gnssIds) which any of `epochs`
    holds; None if there is none (or the epochs hold none of `systems`).

    A half epoch (one system's message lost on the radio) is passed over for the whole one before it: the engine
    evaluates all of a base epoch at its one time, so a GPS part of the epoch before cannot stand in for the
    lost one; the older epoch is carried forward by the engine's correction rates (`max_age_s`). A system that
    none of `epochs` holds (a base that does not send Galileo, or whose GLONASS messages have all been lost for
    as long as `epochs` reach back) is not waited for.
    """
    sent = frozenset().union(*(e.systems for e in epochs)) & systems
    if not sent:
        return None
    limit = t.add_s(tolerance_s)
    for ep in reversed(epochs):
        if ep.time <= limit and sent <= ep.systems:
            return ep
    return None


def latest_base_epoch(epochs: list[BaseEpoch], t: GpsTime, gnss_id: int, max_age_s: float,
                      tolerance_s: float = 0.0) -> BaseEpoch | None:
    """The latest base epoch not after `t` + `tolerance_s` that has observations of system `gnss_id`, and is at
    most `max_age_s` older than `t`; None if there is none. Per system: a rover epoch after a lost GPS message
    takes its GPS base from the epoch before and its GLONASS from the newest."""
    limit = t.add_s(tolerance_s)
    for ep in reversed(epochs):
        if ep.time > limit:
            continue
        if t.diff_s(ep.time) > max_age_s:
            return None
        if gnss_id in ep.systems:
            return ep
    return None


class RtcmCollector:
    """Incremental RTCM3 stream → `RtcmCollected` (feed frames in stream order). Pure: no I/O.

    The one set of epoch rules for post-processing (`collect_rtcm`) and real time
    (`onboard.realtime.service.BaseStream`): messages of one time tag (within EPOCH_MERGE_TOLERANCE_NS) merge
    into one epoch; an epoch not after the last one is dropped (logged); the GPS week of an RTCM epoch is
    resolved from `reference`, which then follows the stream's own epochs (a long log never drifts past half a
    week). `reference` None (real time before the rover's first epoch): only 1005/1006 (which carry no time)
    are decoded until `set_reference`. `max_epochs` keeps only the newest epochs (real time; None: all).
    GPS epochs (`out.epochs`) appear as their message arrives; the reassembled epochs of every system
    (`out.gnss_epochs`, `EpochAssembler`) when they close: at their last message, else when the next epoch's
    first message arrives, else at `flush()` (`collect_rtcm` calls it at the end of the stream).
    `glo_fcn` (slot → channel k) gives the GLONASS frequency channels beforehand, for MSM4 streams without 1020.
    """

    def __init__(self, reference: GpsTime | None, max_epochs: int | None = None,
                 glo_fcn: dict[int, int] | None = None) -> None:
        self.reference = reference
        self.max_epochs = max_epochs
        self.decoder = RtcmDecoder(glo_fcn)
        self.assembler = EpochAssembler()
        self.out = RtcmCollected()
        self.out.glo_fcn = self.decoder.glo_fcn
        self.epoch_count = 0
        """Epochs appended since the start (the kept list may be shorter, see `max_epochs`)."""

    def set_reference(self, reference: GpsTime) -> None:
        """Give the week reference if none was given yet (the rover's first epoch); later calls change nothing."""
        if self.reference is None:
            self.reference = reference

    def add(self, frame: Frame) -> ObsEpoch | BasePosition | Ephemeris | GlonassCodePhaseBias | GlonassChannel | None:
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
            self.add_epoch(item.gps_only())
            info = self.decoder.last_obs_info
            if len(item) and info is not None:
                self._closed(self.assembler.add(item, info))
        elif isinstance(item, Ephemeris):
            out.ephemerides.append(item)
        elif isinstance(item, BasePosition):
            out.base_position = item
        elif isinstance(item, GlonassCodePhaseBias):
            out.glonass_biases = item
        return item

    def flush(self) -> None:
        """End of the stream: close the epochs still waiting for a message (incomplete)."""
        self._closed(self.assembler.flush())

    def add_whole_epoch(self, epoch: ObsEpoch) -> bool:
        """One epoch of every system at once (a raw UBX relay's RXM-RAWX): its GPS part by `add_epoch`'s rules,
        the epoch itself into `out.gnss_epochs` as complete; True if its GPS part is a new epoch."""
        new = self.add_epoch(epoch.gps_only())
        if len(epoch):
            self._closed([BaseEpoch(epoch, (), True)])
        return new

    def _closed(self, epochs: list[BaseEpoch]) -> None:
        out = self.out
        out.late_messages = self.assembler.late
        kept = out.gnss_epochs
        for ep in epochs:
            # by time: after the last one in any sane stream; an epoch of the same time is merged into
            k = len(kept)
            while k > 0 and kept[k - 1].time.diff_ns(ep.time) >= EPOCH_MERGE_TOLERANCE_NS:
                k -= 1
            if k > 0 and abs(kept[k - 1].time.diff_ns(ep.time)) < EPOCH_MERGE_TOLERANCE_NS:
                old = kept[k - 1]
                kept[k - 1] = BaseEpoch(_merge(old.obs, ep.obs), old.messages + ep.messages,
                                        old.complete or ep.complete)
            else:
                kept.insert(k, ep)
        if self.max_epochs is not None and len(out.gnss_epochs) > self.max_epochs:
            del out.gnss_epochs[: len(out.gnss_epochs) - self.max_epochs]

    def add_epoch(self, epoch: ObsEpoch) -> bool:
        """Add one GPS base epoch by the rules above (also for epochs of a raw UBX relay); True if it is a new one."""
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


def collect_rtcm(chunks: Iterable[bytes], reference: GpsTime, glo_fcn: dict[int, int] | None = None) -> RtcmCollected:
    """Decode every RTCM3 frame in a byte stream (other protocols interleaved are skipped); `glo_fcn` as
    `RtcmCollector`."""
    framer = StreamFramer()
    col = RtcmCollector(reference, glo_fcn=glo_fcn)
    for chunk in chunks:
        for frame in framer.feed(chunk):
            col.add(frame)
    for frame in framer.flush():
        col.add(frame)
    col.flush()
    return col.out


def count_protocols(data: bytes) -> dict[Protocol, int]:
    """Number of checksum-valid frames per protocol in a byte sample (to tell what a file is)."""
    counts: dict[Protocol, int] = {}
    framer = StreamFramer()
    for frame in [*framer.feed(data), *framer.flush()]:
        counts[frame.protocol] = counts.get(frame.protocol, 0) + 1
    return counts


