"""Base-station mode, `python -m onboard base`: the recorder on a static LEA-6T/M8T plus an RTCM3 sender.

Neither receiver transmits RTCM3 itself. The daemon records the base's raw journal as on the drone (same
`Recorder`: configuration profile, journal, status) and, from the epochs it decodes, sends corrections over
the telemetry radio within a byte budget. With `obs_message` "msm4" (default), "msm5" or "msm7"
(docs/base-rtcm.md):

    one MSM per constellation of the epoch (107x GPS, 108x GLONASS, 109x Galileo, 111x QZSS, 112x BeiDou),
        the multiple-message bit on all but the last — every epoch, never dropped (MSM7 → MSM5 → MSM4 when
        they do not fit the second's budget, counted in `obs_downgraded`)
    1006 (+ 1033 when `receiver_descriptor` is set) every `position_interval_s` (10 s)
    1230 (GLONASS code−phase biases: aligned, 0 m) every `glonass_bias_interval_s` while GLONASS is observed
    1019/1020/1042/1044/1046 per observed satellite: a new issue at once, then every `ephemeris_interval_s`
        (the ephemerides of every constellation decoded from the base's RXM-SFRBX)

each second's bytes held to `radio_budget_bytes_s` (`onboard.base.schedule`: observations first, then the
others in the order above while they fit, the rest deferred and counted; the position alone goes over the budget
when never sent yet or a whole interval overdue, counted in `over_budget_s`: a rover can use nothing without it). With `obs_message` "1004" or "1002"
(GPS only, the LEA-6T's legacy set): 1004/1002 every epoch, 1006 and 1019 under a token bucket of
`radio_budget_bytes_s` with `radio_burst_bytes` of burst (`CorrectionScheduler`). Or, with `relay="ubx"`, a
compact raw UBX relay (RXM-RAW/RAWX always, navigation frames within the budget).
The base position is `--position` or the mean of single-point positions over `--survey-in` seconds; nothing is
sent before it is known (a rover cannot use corrections without it). What was sent is also written to
`radio-tx.rtcm3` (or `.ubx`) in the flight directory.

Pure parts: `CorrectionScheduler`, `onboard.base.schedule`, `SurveyIn`, `BaseCore` (decoded items and frames in,
frames out). Shell: `RadioSender`
(a thread with a bounded queue: a slow or unplugged radio never stalls recording) and `BaseStationFeature`, the
recorder feature (`onboard.recorder.feature`) that feeds the core from the recorder's frames and decoded items,
opens the radio when the flight opens and writes `base.json` beside the status snapshot.
"""

from __future__ import annotations

import copy
import logging
import math
import queue
import threading
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from onboard.base.schedule import EphemerisRotation, SecondBudget
from onboard.errors import LinkLost
from onboard.gnsstime import GpsTime
from onboard.hw.ports import ByteStream, Clock
from onboard.receiver.framing import Frame, Protocol
from onboard.receiver.rtcm import (
    MSM_SYSTEMS,
    BasePosition,
    GlonassCodePhaseBias,
    MsmEncoder,
    encode_base_position,
    encode_ephemeris,
    encode_glonass_biases,
    encode_gps_observations,
    encode_receiver_descriptor,
    msm_with_multiple_message_bit,
)
from onboard.receiver.rtcm_nav import encode_nav_message, nav_message_number
from onboard.receiver.sfrbx import DEFAULT_LEAP_S, decode_sfrbx
from onboard.recorder.feature import FlightContext, RecorderFeature
from onboard.rtk.ephemeris import EphemerisStore, satellite_states
from onboard.rtk.navdecode import NavMessageDecoder
from onboard.rtk.navstore import AnyEphemeris, BroadcastNavigation, is_healthy, sat_key
from onboard.rtk.pntpos import pntpos
from onboard.rtk.types import (
    GNSS_GLONASS,
    GNSS_GPS,
    LLI_HALF_CYCLE,
    LLI_SLIP,
    Ephemeris,
    GlonassEphemeris,
    ObsEpoch,
)

log = logging.getLogger(__name__)

Arr = npt.NDArray[np.float64]
UBX_OBS = frozenset({(0x02, 0x10), (0x02, 0x15)})  # RXM-RAW, RXM-RAWX
UBX_NAV = frozenset({(0x02, 0x11), (0x02, 0x13), (0x0B, 0x31)})  # RXM-SFRB, RXM-SFRBX, AID-EPH
LOCK_GAP_S = 5.0
"""A satellite unseen for longer than this restarts its synthetic lock time (RXM-RAW)."""
BASE_STATUS_NAME = "base.json"
"""Written beside the recorder's status snapshot."""
PRIORITY = {"obs": 0, "position": 1, "ephemeris": 2}
"""Lower sends first and is dropped last; observations are never dropped."""
OBS_MESSAGES = ("msm4", "msm5", "msm7", "1004", "1002")
"""`BaseOptions.obs_message` values: MSM of every constellation, or the legacy GPS-only messages (the settings'
base.observations values, onboard.recorder.settings.BASE_OBSERVATIONS, which a test holds equal)."""
MSM_ORDER = tuple(MSM_SYSTEMS[n] for n in sorted(MSM_SYSTEMS))
"""gnssIds in message-number order (GPS, GLONASS, Galileo, QZSS, BeiDou): the MSMs of an epoch go out so."""


@dataclass(frozen=True)
class BaseOptions:
    """What the base sends and how much the radio may carry."""

    station_id: int = 0
    obs_message: str = "msm4"
    """One of OBS_MESSAGES (docs/base-rtcm.md: MSM4 of GPS+GLONASS+Galileo+BeiDou fits 1000 B/s with room for
    the ephemerides; MSM7 adds ~65 %, over the default budget with four constellations)."""
    obs_interval_s: float = 1.0
    """Observations are sent at most this often (the receiver may measure at 5 Hz for the rover profile)."""
    position_interval_s: float = 10.0
    ephemeris_interval_s: float = 30.0
    glonass_bias_interval_s: float = 10.0
    """RTCM 1230 (MSM modes, while GLONASS is observed)."""
    receiver_descriptor: str = ""
    """Receiver type sent in RTCM 1033 with the position (e.g. "u-blox LEA-M8T"); "" sends no 1033."""
    radio_budget_bytes_s: float = 1000.0
    """Bytes per second the base may put on the radio (docs/base-rtcm.md: ~20 % of a 57600-baud SiK link)."""
    radio_burst_bytes: int = 1024
    """Token-bucket burst of the legacy 1004/1002 mode and the UBX relay (MSM modes hold every second)."""
    relay: str = "rtcm"
    position_ecef_m: tuple[float, float, float] | None = None
    antenna_height_m: float = 0.0
    survey_in_s: float = 0.0
    survey_elmask_deg: float = 15.0

    def __post_init__(self) -> None:
        if self.obs_message not in OBS_MESSAGES:
            raise ValueError(f"obs_message must be one of {', '.join(OBS_MESSAGES)}, not {self.obs_message!r}")
        if self.relay not in ("rtcm", "ubx"):
            raise ValueError(f"relay must be 'rtcm' or 'ubx', not {self.relay!r}")
        if self.position_ecef_m is None and self.survey_in_s <= 0 and self.relay == "rtcm":
            raise ValueError("give the base position or a survey-in duration > 0 s")
        if self.radio_budget_bytes_s <= 0 or self.radio_burst_bytes <= 0 or self.obs_interval_s < 0:
            raise ValueError("radio budget and burst must be > 0, obs_interval_s ≥ 0")
        if min(self.position_interval_s, self.ephemeris_interval_s, self.glonass_bias_interval_s) < 0:
            raise ValueError("position, ephemeris and GLONASS bias intervals must be ≥ 0 s")

    @property
    def msm_kind(self) -> int | None:
        """4, 5 or 7 in an MSM mode, None in the legacy 1004/1002 one."""
        return int(self.obs_message[3]) if self.obs_message.startswith("msm") else None


@dataclass
class SchedulerCounts:
    """Bytes and messages sent and messages deferred (not sent when due, for the budget) per kind."""

    sent_bytes: int = 0
    sent: dict[str, int] = field(default_factory=dict)
    deferred: dict[str, int] = field(default_factory=dict)


class CorrectionScheduler:
    """Token bucket over the radio budget with priorities (pure; time is any monotonic timeline in s).

    `offer(t_s, items)` takes (kind, frame) pairs due now and returns the frames to send, in priority order:
    "obs" always (the bucket may go into debt, paid back before anything else is sent), then "position",
    then "ephemeris" while the bucket holds enough bytes. Deferred items are counted; the caller offers them
    again when they are next due.
    """

    def __init__(self, budget_bytes_s: float, burst_bytes: int) -> None:
        self.budget_bytes_s = budget_bytes_s
        self.burst_bytes = burst_bytes
        self.credit_bytes = float(burst_bytes)
        self._t_s: float | None = None
        self.counts = SchedulerCounts()

    def offer(self, t_s: float, items: list[tuple[str, bytes]]) -> list[tuple[str, bytes]]:
        """The subset of `items` to send at `t_s` (see class doc)."""
        if self._t_s is not None and t_s > self._t_s:
            self.credit_bytes = min(float(self.burst_bytes),
                                    self.credit_bytes + (t_s - self._t_s) * self.budget_bytes_s)
        self._t_s = t_s if self._t_s is None else max(self._t_s, t_s)
        out = []
        for kind, frame in sorted(items, key=lambda kv: PRIORITY[kv[0]]):
            if kind == "obs" or self.credit_bytes >= len(frame):
                self.credit_bytes -= len(frame)
                out.append((kind, frame))
                self.counts.sent[kind] = self.counts.sent.get(kind, 0) + 1
                self.counts.sent_bytes += len(frame)
            else:
                self.counts.deferred[kind] = self.counts.deferred.get(kind, 0) + 1
        return out


def spp_position(epoch: ObsEpoch, store: EphemerisStore, iono: tuple | None = None,
                 elmask_deg: float = 15.0) -> Arr | None:
    """Single-point position (ECEF m) of one epoch's GPS pseudoranges, None when it fails."""
    gps = epoch.gps_only()
    if len(gps) < 4:
        return None
    sats = satellite_states(store, gps.sv_id, gps.time, gps.pr_m)
    if int(np.sum(sats.ok)) < 4:
        return None
    sol = pntpos(gps.pr_m, sats, gps.time.tow_s, np.deg2rad(elmask_deg), None, iono)
    return sol.pos_ecef_m if sol.ok else None


class SurveyIn:
    """Mean of single-point positions over `duration_s` of GPS time (pure)."""

    def __init__(self, duration_s: float) -> None:
        self.duration_s = duration_s
        self._first: GpsTime | None = None
        self.count = 0
        """Single-point fixes taken so far."""
        self.result_ecef_m: Arr | None = None
        self.spread_m = float("nan")
        self._positions: list[Arr] = []

    def add(self, time: GpsTime, pos_ecef_m: Arr) -> Arr | None:
        """Add one fix; returns the mean once `duration_s` has elapsed since the first (then stays fixed)."""
        if self.result_ecef_m is not None:
            return self.result_ecef_m
        if self._first is None:
            self._first = time
        self._positions.append(np.asarray(pos_ecef_m, float))
        self.count = len(self._positions)
        if time.diff_s(self._first) >= self.duration_s and len(self._positions) >= 2:
            pts = np.array(self._positions)
            self.result_ecef_m = pts.mean(axis=0)
            self.spread_m = float(np.sqrt(np.mean(np.sum((pts - self.result_ecef_m) ** 2, axis=1))))
            log.info("survey-in done: %d fixes over %.0f s, 3D scatter %.2f m", len(pts),
                     time.diff_s(self._first), self.spread_m)
        return self.result_ecef_m


class BaseCore:
    """Decoded base receiver items → radio frames (pure). Feed `on_item` with the decoded items and `on_frame`
    with the receiver's frames (the RXM-SFRBX navigation of every constellation; the UBX relay's frames)."""

    def __init__(self, options: BaseOptions) -> None:
        from onboard.rtk.lnav import LnavAssembler

        self.options = options
        self.scheduler = CorrectionScheduler(options.radio_budget_bytes_s, options.radio_burst_bytes)
        self.store = EphemerisStore()
        self._lnav = LnavAssembler()
        self._week: int | None = None
        self.survey = SurveyIn(options.survey_in_s) if options.position_ecef_m is None else None
        self.position: BasePosition | None = None
        if options.position_ecef_m is not None:
            x, y, z = (float(v) for v in options.position_ecef_m)
            self.position = BasePosition(options.station_id, (x, y, z), options.antenna_height_m)
        self._next_position_s: float | None = None
        self._last_obs_s: float | None = None
        self.over_budget = False
        self._next_eph_s: dict[int, float] = {}
        self.encode_errors = 0
        self._lock_track: dict[tuple[int, int], tuple[GpsTime, GpsTime]] = {}
        self._half_pending: set[tuple[int, int]] = set()
        """Satellites whose carrier phase has an unresolved half cycle (withheld from 1002/1004 until it resolves)."""
        self._arc_start: dict[tuple[int, int], GpsTime] = {}
        """Satellites whose phase arc restarted at a half-cycle resolution the receiver's lock time does not show."""
        # MSM modes
        self.nav = BroadcastNavigation()
        """Every constellation's ephemerides (from RXM-SFRBX frames and decoded GPS ones)."""
        self._nav_decoder = NavMessageDecoder(DEFAULT_LEAP_S)
        self._time: GpsTime | None = None
        self.budget = SecondBudget(options.radio_budget_bytes_s)
        self.rotation = EphemerisRotation(options.ephemeris_interval_s)
        self._msm = MsmEncoder(options.station_id)
        self._eph_frames: dict[tuple[int, int], tuple[tuple[int, int], bytes]] = {}
        """Satellite → (issue, frame) of the ephemeris last encoded for it."""
        self._next_bias_s: float | None = None
        self.obs_downgraded: dict[str, int] = {}
        """Epochs whose observations went out as a smaller MSM than configured, to fit the budget (by message)."""
        self.obs_over_budget_epochs = 0
        """Epochs whose observations exceeded the second's budget even as MSM4 (sent all the same)."""

    def _add_ephemeris(self, eph: AnyEphemeris) -> None:
        self.nav.add(eph)
        if isinstance(eph, Ephemeris) and eph.gnss_id == GNSS_GPS and self.store.add(eph):
            self._next_eph_s.pop(eph.prn, None)  # a new issue goes out at the next chance

    def on_item(self, item: Any) -> list[tuple[str, bytes]]:
        """One decoded item (ObsEpoch, Ephemeris, SubframeWords); returns (kind, frame) to send now."""
        from onboard.receiver.decode import SubframeWords, ephemeris_from_subframe

        if isinstance(item, (Ephemeris, GlonassEphemeris)):
            self._add_ephemeris(item)
            return []
        if isinstance(item, SubframeWords):
            eph = ephemeris_from_subframe(self._lnav, item, self._week)
            if eph is not None:
                self._add_ephemeris(eph)
            return []
        if not isinstance(item, ObsEpoch):
            return []
        self._week = item.time.week
        self._time = item.time
        if item.leap_s is not None:
            self._nav_decoder.leap_s = item.leap_s
        if self.position is None:
            self._survey(item)
            if self.position is None:
                return []
        if self.options.relay == "ubx":
            return []  # the raw frames go out through on_frame
        if self.options.msm_kind is not None:
            return self._msm_corrections(item)
        return self._corrections(item)

    def _survey(self, epoch: ObsEpoch) -> None:
        assert self.survey is not None
        pos = spp_position(epoch, self.store, None, self.options.survey_elmask_deg)
        if pos is None:
            return
        mean = self.survey.add(epoch.time, pos)
        if mean is not None:
            self.position = BasePosition(self.options.station_id, (float(mean[0]), float(mean[1]), float(mean[2])),
                                         self.options.antenna_height_m)

    def _corrections(self, epoch: ObsEpoch) -> list[tuple[str, bytes]]:
        o = self.options
        assert self.position is not None
        t_s = epoch.time.total_ns / 1e9
        epoch = self._with_lock_times(epoch, msm=False)  # every epoch: a slip in a decimated one resets the lock
        last = self._last_obs_s
        if last is not None and t_s - last < 0.9 * o.obs_interval_s:
            return []  # decimated: the radio carries one epoch per obs_interval_s
        self._last_obs_s = t_s
        due: list[tuple[str, bytes]] = []
        try:
            due.append(("obs", encode_gps_observations(epoch, o.station_id, int(o.obs_message))))
        except ValueError as exc:  # a value outside its RTCM field (corrupt epoch): skip the epoch, count it
            self.encode_errors += 1
            log.warning("epoch %s not encodable: %s", epoch.time, exc)
            return []
        if self._next_position_s is None or t_s >= self._next_position_s:
            due.append(("position", encode_base_position(self.position)))
        eph_prns = []
        for prn in sorted({int(s) for s in epoch.gps_only().sv_id}):
            if t_s < self._next_eph_s.get(prn, -np.inf):
                continue
            eph = self.store.select(prn, epoch.time)
            if eph is not None:
                due.append(("ephemeris", encode_ephemeris(eph)))
                eph_prns.append(prn)
        sent = self.scheduler.offer(t_s, due)
        obs_rate = len(due[0][1]) / max(o.obs_interval_s, t_s - last) if last is not None and t_s > last else 0.0
        if obs_rate > o.radio_budget_bytes_s and not self.over_budget:
            self.over_budget = True  # 1006/1019 can never be sent: the rover gets no base position this way
            log.warning("observations alone need %.0f B/s, over the radio budget of %.0f B/s: raise the budget "
                        "or obs_interval_s, or use 1002", obs_rate, o.radio_budget_bytes_s)
        sent_frames = {id(f) for _, f in sent}
        for kind, frame in due:
            if id(frame) not in sent_frames:
                continue
            if kind == "position":
                self._next_position_s = t_s + o.position_interval_s
        for prn, (_, frame) in zip(eph_prns, [d for d in due if d[0] == "ephemeris"]):
            if id(frame) in sent_frames:
                self._next_eph_s[prn] = t_s + o.ephemeris_interval_s
        return sent

    def _on_sfrbx(self, payload: bytes) -> None:
        from onboard.receiver.decode import DecodeError

        assert self._time is not None
        try:
            m = decode_sfrbx(payload)
        except DecodeError:
            return
        eph = self._nav_decoder.add(m.gnss_id, m.sv_id, m.sig_id, m.freq_id, m.words, self._time)
        if eph is not None:
            self._add_ephemeris(eph)

    def msm_frames(self, epoch: ObsEpoch, kind: int) -> list[bytes]:
        """One MSM`kind` frame per constellation of `epoch` (MSM_ORDER), the multiple-message bit on all but
        the last; the encoder's state (phase shifts, lock times) advances."""
        frames = [f for g in MSM_ORDER if np.any(epoch.gnss_id == g)
                  if (f := self._msm.encode(epoch, g, kind, more_follow=True)) is not None]
        if frames:
            frames[-1] = msm_with_multiple_message_bit(frames[-1], False)
        return frames

    def _msm_observations(self, epoch: ObsEpoch, t_s: float, reserve_bytes: int) -> list[bytes]:
        """The epoch's MSMs, in the configured kind or, when they and `reserve_bytes` (the station position when
        due: a rover without it cannot use them) do not fit the bytes left in this second, the next smaller one
        (7 → 5 → 4; each tried on a copy of the encoder so only the one sent moves its state)."""
        want = self.options.msm_kind
        assert want is not None
        left = self.budget.left_bytes(t_s) - reserve_bytes
        kinds = [k for k in (7, 5, 4) if k <= want]
        base = self._msm
        for k in kinds:
            self._msm = copy.deepcopy(base)
            try:
                frames = self.msm_frames(epoch, k)
            except ValueError as exc:  # a value outside its MSM field (corrupt epoch): skip the epoch, count it
                self._msm = base
                self.encode_errors += 1
                log.warning("epoch %s not encodable: %s", epoch.time, exc)
                return []
            if sum(len(f) for f in frames) <= left or k == 4:
                break
        if k != want:
            name = f"msm{k}"
            self.obs_downgraded[name] = self.obs_downgraded.get(name, 0) + 1
        if sum(len(f) for f in frames) > left:
            self.obs_over_budget_epochs += 1
            if not self.over_budget:
                self.over_budget = True
                log.warning("observations need %d B in a second (+ %d B of station position), over the radio "
                            "budget of %.0f B/s even as MSM4: sent anyway, what else is due is deferred; raise "
                            "the budget or obs_interval_s", sum(len(f) for f in frames), reserve_bytes,
                            self.options.radio_budget_bytes_s)
        return frames

    def _ephemeris_due(self, epoch: ObsEpoch, t_s: float, leap_s: int) -> list[tuple[tuple, tuple, bytes]]:
        """(satellite, issue, frame) of the observed satellites' ephemerides due now (EphemerisRotation)."""
        current: dict[tuple[int, int], tuple[int, int]] = {}
        chosen: dict[tuple[int, int], AnyEphemeris] = {}
        for g, sv in sorted({(int(g), int(v)) for g, v in zip(epoch.gnss_id, epoch.sv_id)}):
            eph = self.nav.select(g, sv, epoch.time)
            if eph is None or nav_message_number(eph) is None or not is_healthy(eph):
                continue
            current[sat_key(eph)] = (eph.toe.total_ns, eph.iode)
            chosen[sat_key(eph)] = eph
        out = []
        for key in self.rotation.due(t_s, current):
            issue = current[key]  # type: ignore[index]
            cached = self._eph_frames.get(key)  # type: ignore[arg-type]
            if cached is not None and cached[0] == issue:
                frame = cached[1]
            else:
                try:
                    frame = encode_nav_message(chosen[key], leap_s)  # type: ignore[index]
                except ValueError as exc:  # a field out of range (a corrupt decode): never sent, counted
                    self.encode_errors += 1
                    log.warning("ephemeris %s not encodable: %s", key, exc)
                    continue
                self._eph_frames[key] = (issue, frame)  # type: ignore[index]
            out.append((key, issue, frame))
        return out

    def _msm_corrections(self, epoch: ObsEpoch) -> list[tuple[str, bytes]]:
        o = self.options
        assert self.position is not None
        t_s = epoch.time.total_ns / 1e9
        epoch = self._with_lock_times(epoch, msm=True)
        last = self._last_obs_s
        if last is not None and t_s - last < 0.9 * o.obs_interval_s:
            return []
        self._last_obs_s = t_s
        optional: list[tuple[str, bytes]] = []
        position_due = self._next_position_s is None or t_s >= self._next_position_s
        position = encode_base_position(self.position) if position_due else b""
        obs = self._msm_observations(epoch, t_s, len(position))
        if not obs:
            return []
        required = [("obs", f) for f in obs]
        # the position is required (sent over the budget, counted) when never sent yet or overdue by a whole
        # interval: a rover can use nothing without it
        overdue = self._next_position_s is None or t_s - self._next_position_s >= o.position_interval_s
        if position_due:
            (required if overdue else optional).append(("position", position))
        if position_due and o.receiver_descriptor:
            optional.append(("descriptor", encode_receiver_descriptor(o.station_id, o.receiver_descriptor)))
        bias_due = np.any(epoch.gnss_id == GNSS_GLONASS) and (self._next_bias_s is None or t_s >= self._next_bias_s)
        if bias_due:
            optional.append(("glonass_bias", encode_glonass_biases(
                GlonassCodePhaseBias(o.station_id, True, 0.0, None, None, None))))
        leap_s = epoch.leap_s if epoch.leap_s is not None else self._nav_decoder.leap_s
        ephs = self._ephemeris_due(epoch, t_s, leap_s)
        optional += [("ephemeris", frame) for _, _, frame in ephs]
        sent = self.budget.offer(t_s, required, optional)
        sent_ids = {id(f) for _, f in sent}
        for kind, frame in required + optional:
            if id(frame) not in sent_ids:
                continue
            if kind == "position":
                self._next_position_s = t_s + o.position_interval_s
            elif kind == "glonass_bias":
                self._next_bias_s = t_s + o.glonass_bias_interval_s
        for key, issue, frame in ephs:
            if id(frame) in sent_ids:
                self.rotation.sent(key, issue, t_s)
        return sent

    def counts(self) -> dict[str, Any]:
        """What was sent and deferred (JSON-able), from the scheduler of the mode in use."""
        if self.options.msm_kind is not None and self.options.relay == "rtcm":
            c = self.budget.counts
            return {"sent_bytes": c.sent_bytes, "sent": dict(c.sent), "sent_bytes_by_kind": dict(c.sent_bytes_by_kind),
                    "deferred": dict(c.deferred), "over_budget_s": c.over_budget_s,
                    "obs_downgraded": dict(self.obs_downgraded)}
        s = self.scheduler.counts
        return {"sent_bytes": s.sent_bytes, "sent": dict(s.sent), "deferred": dict(s.deferred)}

    def _with_lock_times(self, epoch: ObsEpoch, msm: bool) -> ObsEpoch:
        """`epoch` as RTCM can carry it (its GPS part for 1002/1004, every system for MSM): a lock time for every
        satellite (RTCM conveys slips only that way) and, for 1002/1004, no phase with an unresolved half cycle
        (neither message can flag one; an MSM flags it in DF420 and keeps the phase).

        RXM-RAW (LEA-6T) reports no lock time, only the LLI slip bit: count the time since the satellite was
        first seen, since its last slip or since a gap longer than `LOCK_GAP_S`, so a slip at the base reaches
        the rover as a lock-time reset. Receiver lock times (RXM-RAWX) are passed on as they are. Phase flagged
        with an unresolved half cycle (LLI bit 1) is withheld; when the flag clears, the receiver may move the
        phase by half a cycle without a slip, so the lock time restarts there and the rover starts a new arc
        (sent as it was, the rover saw an unflagged half-cycle step in the base phase).
        """
        gps = epoch if msm else epoch.gps_only()
        lock = gps.lock_ms.copy()
        cp = gps.cp_cyc.copy()
        t = epoch.time
        for i, prn in enumerate(zip(gps.gnss_id.tolist(), gps.sv_id.tolist())):
            start, last = self._lock_track.get(prn, (t, t))
            half = bool(gps.lli[i] & LLI_HALF_CYCLE) and math.isfinite(cp[i])
            resolved = prn in self._half_pending and not half and math.isfinite(cp[i])
            new_arc = prn not in self._lock_track or bool(gps.lli[i] & LLI_SLIP) or t.diff_s(last) > LOCK_GAP_S
            if new_arc or resolved:
                start = t
            self._lock_track[prn] = (start, t)
            if half:
                self._half_pending.add(prn)
                if not msm:
                    cp[i] = math.nan
            elif math.isfinite(cp[i]):
                self._half_pending.discard(prn)
            if resolved:
                self._arc_start[prn] = t
            elif new_arc:
                self._arc_start.pop(prn, None)  # the receiver's own lock time restarts too
            if not np.isfinite(lock[i]):
                lock[i] = t.diff_s(start) * 1e3
            elif prn in self._arc_start:
                lock[i] = min(float(lock[i]), t.diff_s(self._arc_start[prn]) * 1e3)
        return replace(gps, lock_ms=lock, cp_cyc=cp)

    def on_frame(self, frame: Frame, t_s: float) -> list[tuple[str, bytes]]:
        """A receiver frame. RTCM modes: RXM-SFRBX → `nav` (nothing sent here). UBX relay: raw observation
        frames always, RTCM 1006 (once the position is known) every `position_interval_s` and navigation frames
        within the budget; `t_s` any monotonic time (s)."""
        if frame.protocol is not Protocol.UBX:
            return []
        key = (frame.msg_class, frame.msg_id)
        if self.options.relay != "ubx":
            if key == (0x02, 0x13) and self._time is not None:
                self._on_sfrbx(frame.payload)
            return []
        if key in UBX_OBS:
            due = [("obs", frame.raw)]
            if self.position is not None and (self._next_position_s is None or t_s >= self._next_position_s):
                due.append(("position", encode_base_position(self.position)))
            sent = self.scheduler.offer(t_s, due)
            if any(kind == "position" for kind, _ in sent):
                self._next_position_s = t_s + self.options.position_interval_s
            return sent
        if key in UBX_NAV:
            return self.scheduler.offer(t_s, [("ephemeris", frame.raw)])
        return []


class RadioSender:
    """Writes frames to the radio from its own thread (bounded queue: drops and counts when full).

    `open_radio` is called (again after LinkLost, with backoff) to get the ByteStream. Every frame handed
    queued is appended to `tx_log` (what the base sent to the radio), then written.
    """

    def __init__(self, open_radio: Callable[[], ByteStream], tx_log: Path | None = None, max_queue: int = 256,
                 reopen_s: float = 1.0) -> None:
        self._open = open_radio
        self._queue: queue.Queue[bytes | None] = queue.Queue(max_queue)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._tx_log = tx_log
        self._log_file: Any = None
        self.reopen_s = reopen_s
        self.bytes_written = 0
        self.frames_dropped = 0
        self.write_errors = 0
        self.radio_open = False

    def start(self) -> None:
        """Start the writer thread."""
        if self._tx_log is not None:
            self._log_file = open(self._tx_log, "ab")  # noqa: SIM115  (closed in stop())
        self._thread = threading.Thread(target=self._run, name="base-radio", daemon=True)
        self._thread.start()

    def send(self, frame: bytes) -> bool:
        """Queue one frame (and log it as sent); False (counted, not logged) when the queue is full."""
        try:
            self._queue.put_nowait(frame)
        except queue.Full:
            self.frames_dropped += 1
            return False
        if self._log_file is not None:
            try:
                self._log_file.write(frame)
                self._log_file.flush()
            except OSError as exc:
                log.warning("radio tx log: %s", exc)
        return True

    def _run(self) -> None:
        port: ByteStream | None = None
        while True:
            if port is None:
                if self._stop.is_set():
                    break  # no radio to flush to
                try:
                    port = self._open()
                    self.radio_open = True
                except LinkLost as exc:
                    log.warning("radio: %s", exc)
                    self._stop.wait(self.reopen_s)
                    continue
            try:
                frame = self._queue.get(timeout=0.2)
            except queue.Empty:
                if self._stop.is_set():
                    break
                continue
            if frame is None:
                break
            try:
                self.bytes_written += port.write(frame)
            except LinkLost as exc:
                self.write_errors += 1
                self.radio_open = False
                log.warning("radio write failed: %s", exc)
                port.close()
                port = None
        if port is not None:
            port.close()
        self.radio_open = False

    def stop(self) -> None:
        """Send what is queued (briefly), then stop and close."""
        self._stop.set()
        try:
            self._queue.put_nowait(None)
        except queue.Full:
            pass
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        if self._log_file is not None:
            self._log_file.close()
            self._log_file = None


class BaseStationFeature(RecorderFeature):
    """The base station as a recorder feature: the base receiver's decoded items (RTCM mode) or raw frames (UBX
    relay) → `BaseCore` → `RadioSender`. The radio and its tx log (`radio-tx.rtcm3` / `.ubx` in the flight
    directory) open when the flight opens; `base.json` is the snapshot."""

    name = "base"
    status_name = BASE_STATUS_NAME

    def __init__(self, options: BaseOptions, open_radio: Callable[[], ByteStream]) -> None:
        self.options = options
        self.core = BaseCore(options)
        self._open_radio = open_radio
        self.sender: RadioSender | None = None
        self._clock: Clock | None = None

    def on_flight_opened(self, flight: FlightContext) -> None:
        suffix = "ubx" if self.options.relay == "ubx" else "rtcm3"
        self._clock = flight.clock
        self.sender = RadioSender(self._open_radio, flight.flight_dir / f"radio-tx.{suffix}")
        self.sender.start()

    def on_frame(self, frame: Frame) -> None:
        if self.options.relay == "ubx" and self._clock is None:
            return
        t_s = self._clock.monotonic_ns() / 1e9 if self._clock is not None else 0.0
        self._send(self.core.on_frame(frame, t_s))

    def on_decoded(self, item: Any) -> None:
        # (In relay mode this only surveys and collects ephemerides; the frames go out from on_frame.)
        self._send(self.core.on_item(item))

    def _send(self, frames: list[tuple[str, bytes]]) -> None:
        if self.sender is None:
            return
        for _, frame in frames:
            self.sender.send(frame)

    def status(self) -> dict[str, Any]:
        """What the base sends (JSON-able): position, survey-in, bytes and messages sent/deferred, radio state."""
        pos = self.core.position
        survey = self.core.survey
        return {
            "relay": self.options.relay,
            "obs_message": self.options.obs_message,
            "budget_bytes_s": self.options.radio_budget_bytes_s,
            "position_ecef_m": None if pos is None else list(pos.arp_ecef_m),
            "survey_in": None if survey is None else {"fixes": survey.count, "spread_m": survey.spread_m,
                                                      "duration_s": survey.duration_s},
            **self.core.counts(),
            "radio_open": self.sender is not None and self.sender.radio_open,
            "radio_bytes_written": 0 if self.sender is None else self.sender.bytes_written,
            "queue_drops": 0 if self.sender is None else self.sender.frames_dropped,
            "encode_errors": self.core.encode_errors,
            "over_budget": self.core.over_budget,
        }

    def on_flight_closed(self, reason: str) -> None:
        if self.sender is None:
            return
        self.sender.stop()
        c = self.core.counts()
        log.info("base: sent %d B (%s), deferred %s, radio wrote %d B, queue drops %d", c["sent_bytes"],
                 c["sent"], c["deferred"], self.sender.bytes_written, self.sender.frames_dropped)
