"""Real-time RTK in the recorder: base corrections from the telemetry radio, one solution per rover epoch.

Two threads beside the recorder's own, so the engine can never delay or block recording:

    radio thread:   radio ByteStream → radio journal (`<flight>/radio/`, the recorder's `Journal`: bytes are
                    on their way to disk before anything parses them) → framer → RTCM3 (1002/1004/1074/1077,
                    1005/1006, 1019) or a UBX relay (RXM-RAW/RAWX, SFRB(X), AID-EPH) → latest base epochs,
                    base position, ephemerides; reopens a vanished radio with backoff
    engine thread:  rover items from a bounded queue (`submit`, non-blocking: a full queue drops and counts)
                    → `rtk_pos` with the latest base epoch at or before the rover epoch (waiting at most
                    `base_wait_s` for the matching one, the radio's latency) → `<flight>/solution.pos`
                    → `snapshot()` (Q, ratio, satellites, age of corrections, baseline, time to first fix)

Radio gaps: while the newest base epoch is at most `max_base_age_s` old (default 30 s, settings key
`rtk.max_base_age_s`, RTKLIB's maxtdiff) the engine keeps differencing the rover with it, carried forward
along each satellite's correction rate (`onboard.rtk.rtkpos._extrapolated_base`): the solution stays float or
keeps its held fix through 5-20 s gaps (hil_sim: no wrong fix, fixed throughout). Older corrections are not
used (single-point solution) and the filter's ambiguities wait, slips watched, for the base to return.
`rtk.json` shows the age of the newest base epoch (`age_s`) in both cases.

The base's position (its 1005/1006, or `base_pos_ecef_m`) is checked as post-processing checks it
(`onboard.rtk.postpro.check_base_position`: the median single-point solution of the buffered base epochs,
`RtkOptions.max_base_spp_offset_m`) before any epoch is differenced against it, again whenever it changes: a
rejected position is never used (single-point solutions, no fix against it), `rtk.json` says why
(`base_position_check` "rejected: ..."), and the recorder's event log gets a `base_position_rejected` event.

Wiring into the recorder: `RtkFeature` (a `onboard.recorder.feature.RecorderFeature`) starts the service when
the flight opens (`start(flight_dir)`), hands it every decoded item (`submit`), writes its snapshot as `rtk.json`
beside the status snapshot and stops it when the flight closes; the composition root (`onboard.recorder.app`)
adds it when `rtk.base_stream` names the corrections: `onboard.hw.net_stream.open_base_stream`
("serial:/dev/ttyUSB0@57600", "tcp://HOST:PORT" or "ntrip://USER:PASS@HOST:PORT/MOUNT").
"""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from onboard.errors import LinkLost
from onboard.gnsstime import GpsTime
from onboard.hw.ports import ByteStream, Clock, SystemClock
from onboard.logger.journal import RADIO_DIR, SOLUTION_NAME, Journal, JournalOptions
from onboard.receiver.base_epochs import RtcmCollector
from onboard.receiver.framing import Frame, Protocol, StreamFramer
from onboard.receiver.rtcm import BasePosition
from onboard.recorder.feature import FlightContext, RecorderFeature
from onboard.recorder.status import RTK_STATUS_NAME
from onboard.rtk.ephemeris import EphemerisStore
from onboard.rtk.options import RtkOptions
from onboard.rtk.rtkpos import Nav, RtkState, rtk_init, rtk_pos
from onboard.rtk.types import Q_FIX, Q_FLOAT, Q_NONE, Q_SINGLE, Ephemeris, ObsEpoch, Solution

log = logging.getLogger(__name__)

Arr = npt.NDArray[np.float64]
GAP_NO_WAIT_S = 2.0
"""Base data this much (s) later than its own interval are in a radio gap: the engine stops waiting for them."""


@dataclass(frozen=True)
class RtkServiceOptions:
    """Real-time RTK settings. `base_pos_ecef_m` overrides the position the base sends (1005/1006)."""

    engine: RtkOptions = field(default_factory=RtkOptions)
    max_base_age_s: float = 30.0
    """Base epochs up to this old (s) are used through a radio gap (float or held fix); older: single. Was 5 s
    when the engine differenced aged base epochs raw: on hil_sim a 20 s gap then ended in wrong fixes."""
    base_wait_s: float = 0.5
    queue_max_items: int = 64
    base_buffer_epochs: int = 30
    base_pos_ecef_m: tuple[float, float, float] | None = None
    radio_read_bytes: int = 4096
    radio_reopen_s: float = 1.0
    journal: JournalOptions = field(default_factory=JournalOptions)
    restart_after_outage: bool = False
    """Restart the filter when corrections return after an outage. Off: on the hil_sim flight the engine kept
    its ambiguities across 15-20 s gaps and fixed again at once, correctly, while a cold restart 170 s into the
    flight fixed 5 m off (reported to the engine's owner)."""
    takeoff_position_ecef_m: tuple[float, float, float] | None = None
    """Surveyed take-off antenna position (ECEF m, settings key `rtk.takeoff_position`): the engine starts
    static there with its ambiguities computed from it (Daakir 2015 eq. 2) and fixes at the first epoch,
    whatever the baseline. None: a cold start."""
    preflight_base_timeout_s: float | None = None
    """Base corrections older than this (s, settings key `rtk.preflight_base_timeout_s`) make the pre-flight page
    a no-go; published in rtk.json for it (None: the page's default)."""
    lock_rules: Any = None
    """`onboard.receiver.decode.LockTrackerOptions` for the rover's RXM-RAWX phase validity and slips (None:
    RTKLIB's Gen8 thresholds, the same rules `onboard rtk` applies to a journal)."""


@dataclass
class RtkStatus:
    """What the status snapshot shows about real-time RTK (JSON-able via `to_json`)."""

    running: bool = False
    radio_open: bool = False
    radio_error: str | None = None
    radio_bytes: int = 0
    base_frames: int = 0
    base_epochs: int = 0
    base_position_ecef_m: list[float] | None = None
    epochs: int = 0
    dropped_epochs: int = 0
    fixed: int = 0
    float_: int = 0
    single: int = 0
    q: int = Q_NONE
    ratio: float = 0.0
    ns: int = 0
    age_s: float | None = None
    baseline_m: float | None = None
    max_first_fix_baseline_km: float | None = None
    """The engine's limit for a first fix from a cold start (RtkOptions.max_first_fix_baseline_km; 0: none)."""
    preflight_base_timeout_s: float | None = None
    """`RtkServiceOptions.preflight_base_timeout_s`: the pre-flight page's no-go age of the corrections (s)."""
    last_gpst: str | None = None
    ttff_s: float | None = None
    engine_ms_last: float = 0.0
    engine_ms_max: float = 0.0
    errors: int = 0
    restarts: int = 0
    base_position_check: str | None = None
    """The base position against the base's own single-point solution: None (no position yet), "pending" (no
    single-point solution of the base yet: the base is not used), "ok: N m" or "rejected: <why>"."""

    def to_json(self) -> dict[str, Any]:
        """JSON-able dict (field `float_` as "float")."""
        d = dict(self.__dict__)
        d["float"] = d.pop("float_")
        return d


class BaseStream:
    """Radio bytes → base epochs / position / ephemerides (pure: no I/O, no clock, no threads).

    RTCM3 frames go through the post-processing collector (`onboard.receiver.base_epochs.RtcmCollector`: the
    same merge, order and week rules as `onboard rtk` on the radio journal; GPS week from the rover's first
    epoch, then from the stream); UBX frames (a raw relay) through the UBX decoder with RTKLIB's lock rules,
    their GPS part into the same collector. `epochs` keeps the newest `buffer_epochs`.
    """

    def __init__(self, buffer_epochs: int = 30) -> None:
        from onboard.receiver.decode import DecodeStats, LockTracker
        from onboard.rtk.lnav import LnavAssembler

        self.framer = StreamFramer()
        self.collector = RtcmCollector(None, max_epochs=buffer_epochs)
        self.ubx_stats = DecodeStats()
        self.tracker = LockTracker()
        self.lnav = LnavAssembler()
        self.frames = 0

    @property
    def epochs(self) -> list[ObsEpoch]:
        """The newest base epochs, in time order."""
        return self.collector.out.epochs

    @property
    def epoch_count(self) -> int:
        """Base epochs received since the start."""
        return self.collector.epoch_count

    @property
    def position(self) -> BasePosition | None:
        """The last base position (1005/1006) received."""
        return self.collector.out.base_position

    @property
    def ephemerides(self) -> list[Ephemeris]:
        """Every ephemeris received (1019, or LNAV subframes / AID-EPH of a UBX relay), in arrival order."""
        return self.collector.out.ephemerides

    def feed(self, data: bytes, reference: GpsTime | None) -> int:
        """Decode what `data` completes; returns the number of new base epochs. `reference` (the latest rover
        epoch time, None before the first) gives the collector its week reference once."""
        if reference is not None:
            self.collector.set_reference(reference)
        before = self.collector.epoch_count
        for frame in self.framer.feed(data):
            self._frame(frame)
        return self.collector.epoch_count - before

    def _frame(self, frame: Frame) -> None:
        from onboard.receiver.decode import SubframeWords, decode_frame, ephemeris_from_subframe

        self.frames += 1
        if frame.protocol is Protocol.RTCM3:
            self.collector.add(frame)
            return
        if frame.protocol is not Protocol.UBX:
            return
        item: Any = decode_frame(frame, self.ubx_stats)
        if isinstance(item, SubframeWords):
            item = ephemeris_from_subframe(self.lnav, item, self.ubx_stats.reference_week)
        if isinstance(item, ObsEpoch):
            # the engine is GPS L1 (RTCM epochs are GPS already): a relay's other systems are left out here
            self.collector.add_epoch(self.tracker.update(item).gps_only())
        elif isinstance(item, Ephemeris):
            self.ephemerides.append(item)

    def latest_at(self, t: GpsTime, tolerance_s: float) -> ObsEpoch | None:
        """Latest base epoch with time ≤ t + tolerance (None when none is buffered)."""
        limit = t.add_s(tolerance_s)
        for ep in reversed(self.epochs):
            if ep.time <= limit:
                return ep
        return None


class RtkService:
    """The real-time RTK worker (see module doc). Thread-safe `submit`/`snapshot`; `start`/`stop` once."""

    def __init__(self, options: RtkServiceOptions, open_radio: Callable[[], ByteStream] | None,
                 clock: Clock | None = None, on_event: Callable[[dict[str, Any]], None] | None = None) -> None:
        self.options = options
        self.on_event = on_event
        """Receives the service's events (a rejected base position) from the engine thread."""
        self._checked_base_pos: tuple[float, ...] | None = None
        self._base_pos_ok = False
        self._open_radio = open_radio
        self.clock = clock or SystemClock()
        self.engine_options = replace(options.engine, max_age_s=options.max_base_age_s)
        self._queue: queue.Queue[Any] = queue.Queue(options.queue_max_items)
        self._stop = threading.Event()
        self._cond = threading.Condition()
        self._base = BaseStream(options.base_buffer_epochs)
        self._reference: GpsTime | None = None
        self._status = RtkStatus(max_first_fix_baseline_km=self.engine_options.max_first_fix_baseline_km,
                                 preflight_base_timeout_s=options.preflight_base_timeout_s)
        self._threads: list[threading.Thread] = []
        self._journal: Journal | None = None
        self._pos_file: Any = None
        self.flight_dir: Path | None = None
        self.solutions_written = 0
        self._last_base_time: GpsTime | None = None

    # -- lifecycle ----------------------------------------------------------------------------------------
    def start(self, flight_dir: Path) -> None:
        """Open the radio journal and solution file in `flight_dir` and start both threads."""
        from onboard.formats.pos import pos_header_lines

        self.flight_dir = Path(flight_dir)
        new_file = not (self.flight_dir / SOLUTION_NAME).exists()
        self._pos_file = open(self.flight_dir / SOLUTION_NAME, "a", encoding="ascii")  # noqa: SIM115
        if new_file:
            info = ["program   : directgeo onboard real-time RTK (GPS L1)", "pos mode  : kinematic",
                    f"elev mask : {np.rad2deg(self.engine_options.elmask_rad):.1f} deg",
                    f"amb res   : {self.engine_options.ar_mode}", ""]
            for line in pos_header_lines(info=info):
                self._pos_file.write(line + "\n")
            self._pos_file.flush()
        self._status.running = True
        engine = threading.Thread(target=self._engine_thread, name="rtk-engine", daemon=True)
        self._threads = [engine]
        if self._open_radio is not None:
            self._journal = Journal(self.flight_dir / RADIO_DIR, self.clock, self.options.journal)
            self._threads.append(threading.Thread(target=self._radio_thread, name="rtk-radio", daemon=True))
        for t in self._threads:
            t.start()

    def stop(self) -> None:
        """Stop both threads, close the radio journal (manifest) and the solution file."""
        self._stop.set()
        with self._cond:
            self._cond.notify_all()
        for t in self._threads:
            t.join(timeout=5.0)
        if self._journal is not None:
            try:
                self._journal.close("stopped")
            except OSError as exc:
                log.error("radio journal close failed: %s", exc)
        if self._pos_file is not None:
            self._pos_file.close()
            self._pos_file = None
        self._status.running = False

    # -- rover side (called from the recorder's loop: never blocks) -----------------------------------------
    def submit(self, item: Any) -> bool:
        """Hand over one decoded rover item (ObsEpoch, Ephemeris, SubframeWords); False when dropped."""
        from onboard.receiver.decode import SubframeWords

        if not isinstance(item, (ObsEpoch, Ephemeris, SubframeWords)):
            return True
        try:
            self._queue.put_nowait(item)
            return True
        except queue.Full:
            if isinstance(item, ObsEpoch):
                self._status.dropped_epochs += 1
            return False

    def snapshot(self) -> dict[str, Any]:
        """The current RTK status as a JSON-able dict."""
        return self._status.to_json()

    # -- radio thread ---------------------------------------------------------------------------------------
    def _radio_thread(self) -> None:
        assert self._open_radio is not None and self._journal is not None
        port: ByteStream | None = None
        st = self._status
        while not self._stop.is_set():
            if port is None:
                try:
                    port = self._open_radio()
                    st.radio_open, st.radio_error = True, None
                except LinkLost as exc:
                    st.radio_open, st.radio_error = False, str(exc)
                    self._stop.wait(self.options.radio_reopen_s)
                    continue
            try:
                data = port.read(self.options.radio_read_bytes)
            except LinkLost as exc:
                port.close()
                port = None
                st.radio_open, st.radio_error = False, str(exc)
                log.warning("radio lost: %s", exc)
                continue
            try:
                if data:
                    self._journal.append(data, self.clock.monotonic_ns(), self.clock.wall_ns())
                self._journal.maybe_sync()
            except OSError as exc:  # the recorder's own journal reports the disk; keep correcting
                st.errors += 1
                log.error("radio journal: %s", exc)
            if not data:
                continue
            st.radio_bytes += len(data)
            with self._cond:
                new = self._base.feed(data, self._reference)
                if new:
                    self._cond.notify_all()
            st.base_frames = self._base.frames
            st.base_epochs = self._base.epoch_count
            pos = self._base.position
            st.base_position_ecef_m = None if pos is None else [float(v) for v in pos.phase_centre_ecef_m]
        if port is not None:
            port.close()
        st.radio_open = False

    # -- engine thread --------------------------------------------------------------------------------------
    def _new_state(self) -> RtkState:
        """The engine state at the start: from the surveyed take-off point (static) when one is set."""
        takeoff = self.options.takeoff_position_ecef_m
        if takeoff is None:
            return rtk_init(self.engine_options)
        return rtk_init(replace(self.engine_options, static_start=True), np.array(takeoff, float))

    def _engine_thread(self) -> None:
        from onboard.receiver.decode import (
            LockTracker,
            LockTrackerOptions,
            SubframeWords,
            ephemeris_from_subframe,
        )
        from onboard.rtk.lnav import LnavAssembler

        state = self._new_state()
        store = EphemerisStore()
        nav = Nav(store)
        tracker = LockTracker(self.options.lock_rules or LockTrackerOptions())
        lnav = LnavAssembler()
        n_base_eph = 0
        outage_epochs = 0
        first_time: GpsTime | None = None
        while not self._stop.is_set():
            try:
                item = self._queue.get(timeout=0.2)
            except queue.Empty:
                continue
            if isinstance(item, Ephemeris):
                store.add(item)
                continue
            if isinstance(item, SubframeWords):
                week = self._reference.week if self._reference is not None else None
                eph = ephemeris_from_subframe(lnav, item, week)
                if eph is not None:
                    store.add(eph)
                continue
            rover = tracker.update(item)
            self._reference = rover.time
            if first_time is None:
                first_time = rover.time
            base, base_pos = self._wait_base(rover.time)
            with self._cond:
                ephs = self._base.ephemerides[n_base_eph:]
                n_base_eph = len(self._base.ephemerides)
            for eph in ephs:
                store.add(eph)
            if len(store) == 0:
                continue
            if base is None and state.initialized:
                outage_epochs += 1
            elif base is not None and outage_epochs and self.options.restart_after_outage:
                # Optional: the filter's ambiguities were not checked across the outage.
                log.info("%s: corrections back after %d epochs without: filter restarted", rover.time,
                         outage_epochs)
                state = rtk_init(self.engine_options)  # mid-flight: the take-off point no longer applies
                self._status.restarts += 1
                outage_epochs = 0
            if base_pos is not None and not self._base_position_usable(base_pos, nav, rover.time):
                base = None  # unchecked or rejected: never a solution differenced against it
            t0 = self.clock.monotonic_ns()
            try:
                sol = rtk_pos(state, rover, base, nav, base_pos)
            except (ValueError, ArithmeticError, IndexError, np.linalg.LinAlgError) as exc:
                self._status.errors += 1
                log.error("rtk_pos at %s: %s", rover.time, exc)
                continue
            ms = (self.clock.monotonic_ns() - t0) / 1e6
            self._publish(sol, base, base_pos, first_time, ms)

    def _base_position_usable(self, base_pos: Arr, nav: Nav, t: GpsTime) -> bool:
        """Whether `base_pos` passed the post-processing check against the buffered base epochs' single-point
        solutions (decided once per position; pending while no base epoch solves)."""
        from onboard.rtk.postpro import base_spp_offset_m, check_base_position
        from onboard.rtk.types import BasePositionRejected

        key = tuple(float(v) for v in base_pos)
        if key == self._checked_base_pos:
            return self._base_pos_ok
        if self.engine_options.max_base_spp_offset_m <= 0.0:
            self._checked_base_pos, self._base_pos_ok = key, True
            self._status.base_position_check = "ok: check disabled (max_base_spp_offset_m = 0)"
            return True
        with self._cond:
            epochs = list(self._base.epochs)
        found = base_spp_offset_m(epochs, nav, base_pos, self.engine_options)
        if found is None:
            self._status.base_position_check = "pending"
            return False
        try:
            check_base_position(epochs, nav, base_pos, self.engine_options)
        except BasePositionRejected as exc:
            self._checked_base_pos, self._base_pos_ok = key, False
            self._status.base_position_check = f"rejected: {exc}"
            log.error("%s: real-time RTK refuses the base: %s", t, exc)
            if self.on_event is not None:
                self.on_event({"type": "rtk", "event": "base_position_rejected", "gpst": str(t),
                               "base_pos_ecef_m": [round(v, 3) for v in key], "offset_m": round(exc.offset_m, 1),
                               "bound_m": exc.bound_m, "epochs": exc.epochs, "detail": str(exc)})
            return False
        self._checked_base_pos, self._base_pos_ok = key, True
        self._status.base_position_check = f"ok: {found[0]:.1f} m from the base's single-point position"
        return True

    def _wait_base(self, t: GpsTime) -> tuple[ObsEpoch | None, Arr | None]:
        """The base epoch for rover time `t`: wait up to `base_wait_s` for one at ≥ t − tolerance to arrive."""
        tol = self.engine_options.pair_tolerance_s
        deadline = self.clock.monotonic_ns() + round(self.options.base_wait_s * 1e9)
        with self._cond:
            while True:
                eps = self._base.epochs
                newest = eps[-1] if eps else None
                if newest is not None:
                    # the base may send at a lower rate than the rover: wait only if its next epoch is due by t
                    interval_s = newest.time.diff_s(eps[-2].time) if len(eps) >= 2 else 0.0
                    if newest.time.diff_s(t) + interval_s > tol:
                        break
                    if t.diff_s(newest.time) > interval_s + GAP_NO_WAIT_S:
                        break  # a radio gap: waiting for each rover epoch would only make the engine lag
                left = (deadline - self.clock.monotonic_ns()) / 1e9
                if left <= 0 or self._stop.is_set():
                    break
                self._cond.wait(min(left, 0.1))
            base = self._base.latest_at(t, tol)
            pos = self._base.position
        if self.options.base_pos_ecef_m is not None:
            base_pos: Arr | None = np.array(self.options.base_pos_ecef_m, float)
        else:
            base_pos = None if pos is None else pos.phase_centre_ecef_m
        self._last_base_time = None if base is None else base.time
        if base is not None and t.diff_s(base.time) > self.options.max_base_age_s:
            base = None  # stale: the engine reports single rather than filtering on old corrections
        return base, base_pos

    def _publish(self, sol: Solution, base: ObsEpoch | None, base_pos: Arr | None, first: GpsTime,
                 engine_ms: float) -> None:
        from onboard.formats.pos import format_solution

        st = self._status
        st.epochs += 1
        st.q, st.ratio, st.ns = int(sol.q), float(sol.ratio), int(sol.ns)
        # the age of the newest base epoch, also once it is too old to be used (the operator sees the gap)
        st.age_s = float(sol.age_s) if base is not None else (
            None if self._last_base_time is None else round(sol.time.diff_s(self._last_base_time), 3))
        st.fixed += sol.q == Q_FIX
        st.float_ += sol.q == Q_FLOAT
        st.single += sol.q == Q_SINGLE
        st.last_gpst = str(sol.time)
        st.engine_ms_last = engine_ms
        st.engine_ms_max = max(st.engine_ms_max, engine_ms)
        if base_pos is not None and sol.q in (Q_FIX, Q_FLOAT):
            st.baseline_m = float(np.linalg.norm(sol.pos_ecef_m - base_pos))
        if sol.q == Q_FIX and st.ttff_s is None:
            st.ttff_s = sol.time.diff_s(first)
        if sol.q == Q_NONE or self._pos_file is None:
            return
        try:
            self._pos_file.write(format_solution(sol) + "\n")
            self._pos_file.flush()
            self.solutions_written += 1
        except OSError as exc:
            st.errors += 1
            log.error("solution file: %s", exc)


class RtkFeature(RecorderFeature):
    """Real-time RTK as a recorder feature: `RtkService` started when the flight opens (radio journal and
    solution.pos in the flight directory), fed every decoded item, stopped when the flight closes; its
    snapshot is `rtk.json` beside the status snapshot."""

    name = "rtk"
    status_name = RTK_STATUS_NAME

    def __init__(self, options: RtkServiceOptions, open_radio: Callable[[], ByteStream] | None,
                 clock: Clock | None = None) -> None:
        self.rtk = RtkService(options, open_radio, clock)
        self._started = False

    def on_flight_opened(self, flight: FlightContext) -> None:
        if self._started:  # a roll-over: the stopped service cannot start again; a fresh one for the new flight
            self.rtk = RtkService(self.rtk.options, self.rtk._open_radio, self.rtk.clock)
        append = flight.append_event
        if append is not None:
            self.rtk.on_event = lambda record: flight.post(append, record)  # events.jsonl, on the recorder's loop
        self.rtk.start(flight.flight_dir)
        self._started = True

    def on_decoded(self, item: Any) -> None:
        self.rtk.submit(item)

    def status(self) -> dict[str, Any] | None:
        return self.rtk.snapshot() if self._started else None

    def on_flight_closed(self, reason: str) -> None:
        if self._started:
            self.rtk.stop()
