"""Real-time RTK in the recorder: base corrections from the telemetry radio, one solution per rover epoch.

Two threads beside the recorder's own, so the engine can never delay or block recording:

    radio thread:   radio ByteStream → radio journal (`<flight>/radio/`, the recorder's `Journal`: bytes are
                    on their way to disk before anything parses them) → framer → RTCM3 (1002/1004, MSM4-7 of
                    GPS, GLONASS, Galileo, BeiDou, QZSS, 1005/1006, 1019/1020/1042/1044/1045/1046, 1230) or a
                    UBX relay (RXM-RAW/RAWX, SFRB(X), AID-EPH) → latest base epochs (one per time, reassembled
                    from its messages), base position, ephemerides; reopens a vanished radio with backoff
    engine thread:  rover items from a bounded queue (`submit` / `submit_frame`, non-blocking: a full queue
                    drops and counts) → `rtk_pos` with the latest whole base epoch at or before the rover epoch
                    (waiting at most `base_wait_s` for the matching one, the radio's latency) →
                    `<flight>/solution.pos` → `snapshot()` (Q, ratio, satellites, systems, age of corrections,
                    baseline, time to first fix)

Constellations: the engine's `systems` are decided at the rover's first epoch from the raw message its receiver
sends (`RtkServiceOptions.receiver_systems`, from `receiver.gnss` in the composition root: an M8T's RXM-RAWX
every system it is set to track, a LEA-6T's RXM-RAW GPS). GPS LNAV goes to the engine's EphemerisStore, every
other constellation's ephemerides (rover RXM-SFRBX, base RTCM) to `Nav.broadcast`. A base epoch one of whose
constellation messages was lost on the radio is never differenced with: the engine takes one base epoch at one
time, so each rover epoch gets the latest epoch holding every engine constellation the base sends
(`onboard.receiver.base_epochs.pairing_base_epoch`), older but whole, carried forward by the engine. On the
M8P Galway static rover and its base stream (about a quarter of the GPS and of the GLONASS messages lost;
the engine over all 1205 epochs, ephemerides known from the start) GPS+GLONASS fixed 1194 epochs this way, 949
when paired with the newest epoch holding GPS (GLONASS missing from a third of them), 1160 on GPS alone.

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
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from onboard.errors import LinkLost
from onboard.gnsstime import GpsTime
from onboard.hw.ports import ByteStream, Clock, SystemClock
from onboard.logger.journal import RADIO_DIR, SOLUTION_NAME, Journal, JournalOptions
from onboard.receiver.base_epochs import BaseEpoch, RtcmCollector, pairing_base_epoch
from onboard.receiver.framing import Frame, Protocol, StreamFramer
from onboard.receiver.rtcm import BasePosition
from onboard.receiver.rtcm_nav import RTCM_NAV_MESSAGES, RtcmNavError, decode_nav_message
from onboard.recorder.feature import FlightContext, RecorderFeature
from onboard.recorder.status import RTK_STATUS_NAME
from onboard.rtk.ephemeris import EphemerisStore
from onboard.rtk.gnss import SYSTEMS_BY_LETTER, system
from onboard.rtk.navstore import AnyEphemeris, BroadcastNavigation
from onboard.rtk.options import RtkOptions
from onboard.rtk.rtkpos import Nav, RtkState, rtk_init, rtk_pos
from onboard.rtk.types import GNSS_GPS, Q_FIX, Q_FLOAT, Q_NONE, Q_SINGLE, Ephemeris, ObsEpoch, Solution

log = logging.getLogger(__name__)

Arr = npt.NDArray[np.float64]
GAP_NO_WAIT_S = 2.0
"""Base data this much (s) later than its own interval are in a radio gap: the engine stops waiting for them."""
RXM_RAW, RXM_RAWX, RXM_SFRBX = (0x02, 0x10), (0x02, 0x15), (0x02, 0x13)
RAW_MESSAGE_NAMES = {RXM_RAW: "RXM-RAW", RXM_RAWX: "RXM-RAWX"}


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
    receiver_systems: Mapping[str, str] = field(default_factory=dict)
    """The engine's `systems` by the rover's raw observation message ("RXM-RAWX": u-blox 8, "RXM-RAW": u-blox 6),
    which the composition root derives from `receiver.gnss` (`onboard.receiver.profiles.rtk_systems`) unless
    `[rtk.engine] systems` is set. The engine starts on those of the first raw message the rover sends (which
    receiver is connected is known only then: `receiver.model = "auto"`, an M8 fallen back to RXM-RAW); a
    message not listed, or no frame seen (items submitted directly): `engine.systems`."""


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
    systems: str | None = None
    """The engine's constellations (RINEX letters), once the first rover epoch decided them."""
    base_systems: str | None = None
    """The constellations of the base epoch the last solution was differenced with (RINEX letters)."""
    base_ephemerides: int = 0
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
    epoch, then from the stream): every constellation's MSM, one epoch reassembled from its messages
    (`EpochAssembler`); 1019 and the other constellations' ephemerides (1020, 1042, 1044, 1045, 1046:
    `onboard.receiver.rtcm_nav`). UBX frames (a raw relay) through the UBX decoder with RTKLIB's lock rules:
    RXM-RAWX of every system as whole epochs, GPS subframes / AID-EPH and the other systems' RXM-SFRBX
    (`onboard.rtk.navdecode`). `epochs` keeps the newest `buffer_epochs`.
    """

    def __init__(self, buffer_epochs: int = 30) -> None:
        from onboard.receiver.decode import DecodeStats, LockTracker
        from onboard.receiver.sfrbx import DEFAULT_LEAP_S
        from onboard.rtk.lnav import LnavAssembler
        from onboard.rtk.navdecode import NavMessageDecoder

        self.framer = StreamFramer()
        self.collector = RtcmCollector(None, max_epochs=buffer_epochs)
        self.ubx_stats = DecodeStats()
        self.tracker = LockTracker()
        self.lnav = LnavAssembler()
        self.nav_decoder = NavMessageDecoder(DEFAULT_LEAP_S)
        self.leap_s = DEFAULT_LEAP_S
        """GPST − UTC (s) for GLONASS times: the rover's, once it reports it (the service sets it)."""
        self.ephemerides: list[AnyEphemeris] = []
        """Every ephemeris received (RTCM 1019/1020/1042/1044/1045/1046, or a UBX relay's), in arrival order."""
        self.nav_errors = 0
        self.frames = 0

    @property
    def epochs(self) -> list[ObsEpoch]:
        """The newest whole base epochs (every system; closed: their last message arrived, or the next
        epoch's first), in time order."""
        return [e.obs for e in self.collector.out.gnss_epochs]

    @property
    def epoch_count(self) -> int:
        """Base epochs with GPS observations received since the start."""
        return self.collector.epoch_count

    @property
    def position(self) -> BasePosition | None:
        """The last base position (1005/1006) received."""
        return self.collector.out.base_position

    def candidates(self) -> list[BaseEpoch]:
        """The buffered base epochs, in time order, and last the one still open (waiting for its last message)."""
        pending = self.collector.assembler.pending
        closed = self.collector.out.gnss_epochs
        return closed if pending is None else [*closed, pending]

    def pair(self, t: GpsTime, tolerance_s: float, systems: frozenset[int]) -> ObsEpoch | None:
        """The base epoch for rover time `t` (`pairing_base_epoch`: the latest holding every one of `systems`,
        u-blox gnssIds, that the base sends) restricted to `systems`; None when none is buffered."""
        ep = pairing_base_epoch(self.candidates(), t, systems, tolerance_s)
        if ep is None:
            return None
        if systems == {GNSS_GPS}:
            return ep.obs.gps_only()
        return ep.obs.select(np.isin(ep.obs.gnss_id, sorted(systems)))

    def waiting(self, t: GpsTime, tolerance_s: float, systems: frozenset[int], part_wait_over: bool) -> bool:
        """Whether a base epoch for rover time `t` may still arrive: the open epoch lacks some of `systems` the
        base sends (`part_wait_over`: its first message came `base_wait_s` ago, the rest is lost), or the next
        epoch is due by `t` and the radio is not in a gap."""
        eps = self.candidates()
        if not eps:
            return True
        newest = eps[-1]
        if not part_wait_over and not newest.complete and newest.time <= t.add_s(tolerance_s):
            sent = frozenset().union(*(e.systems for e in eps)) & systems
            if not sent <= newest.systems:
                return True
        # the base may send at a lower rate than the rover: wait only if its next epoch is due by t
        interval_s = newest.time.diff_s(eps[-2].time) if len(eps) >= 2 else 0.0
        if newest.time.diff_s(t) + interval_s > tolerance_s:
            return False
        return t.diff_s(newest.time) <= interval_s + GAP_NO_WAIT_S  # beyond: a radio gap, no waiting

    def feed(self, data: bytes, reference: GpsTime | None) -> int:
        """Decode what `data` completes; returns the number of new base epochs with GPS. `reference` (the latest
        rover epoch time, None before the first) gives the collector its week reference once."""
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
            got = self.collector.add(frame)
            if isinstance(got, Ephemeris):
                self.ephemerides.append(got)
            elif frame.msg_id in RTCM_NAV_MESSAGES and self.collector.reference is not None:
                try:
                    eph = decode_nav_message(frame, self.collector.reference, self.leap_s)
                except RtcmNavError as exc:
                    self.nav_errors += 1
                    log.debug("base %s", exc)
                    return
                if eph is not None:
                    self.ephemerides.append(eph)
            return
        if frame.protocol is not Protocol.UBX:
            return
        if (frame.msg_class, frame.msg_id) == RXM_SFRBX:
            self._relay_sfrbx(frame)
        item: Any = decode_frame(frame, self.ubx_stats)
        if isinstance(item, SubframeWords):
            item = ephemeris_from_subframe(self.lnav, item, self.ubx_stats.reference_week)
        if isinstance(item, ObsEpoch):
            self.collector.add_whole_epoch(self.tracker.update(item))
        elif isinstance(item, Ephemeris):
            self.ephemerides.append(item)

    def _relay_sfrbx(self, frame: Frame) -> None:
        """A relay's RXM-SFRBX of another system than GPS (GPS: decode_frame's LNAV path) → ephemerides."""
        from onboard.receiver.decode import DecodeError
        from onboard.receiver.sfrbx import decode_sfrbx

        reference = self.collector.reference
        try:
            m = decode_sfrbx(frame.payload)
        except DecodeError:
            return
        if m.gnss_id == GNSS_GPS or reference is None:
            return
        self.nav_decoder.leap_s = self.leap_s
        eph = self.nav_decoder.add(m.gnss_id, m.sv_id, m.sig_id, m.freq_id, m.words, reference)
        if eph is not None:
            self.ephemerides.append(eph)


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
        self._raw_message: str | None = None  # the rover's raw observation message, once seen (submit_frame)
        self._pending_key: int | None = None  # the open base epoch (its time, ns) and when it opened
        self._pending_since_ns = 0
        self._systems_ids = frozenset({GNSS_GPS})

    # -- lifecycle ----------------------------------------------------------------------------------------
    def start(self, flight_dir: Path) -> None:
        """Open the radio journal and solution file in `flight_dir` and start both threads."""
        from onboard.formats.pos import pos_header_lines

        self.flight_dir = Path(flight_dir)
        new_file = not (self.flight_dir / SOLUTION_NAME).exists()
        self._pos_file = open(self.flight_dir / SOLUTION_NAME, "a", encoding="ascii")  # noqa: SIM115
        if new_file:
            info = ["program   : directgeo onboard real-time RTK (L1)", "pos mode  : kinematic",
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

    def submit_frame(self, frame: Frame) -> None:
        """Hand over one rover frame (from the recorder's loop: never blocks): which raw observation message the
        rover sends (RXM-RAWX or RXM-RAW: the engine's systems, see `RtkServiceOptions.receiver_systems`) and the
        RXM-SFRBX of the systems other than GPS (GPS subframes come decoded, through `submit`)."""
        key = (frame.msg_class, frame.msg_id)
        if frame.protocol is not Protocol.UBX:
            return
        if key in RAW_MESSAGE_NAMES:
            name = RAW_MESSAGE_NAMES[key]
            if name != self._raw_message:
                try:
                    self._queue.put_nowait(_RawMessage(name))
                    self._raw_message = name
                except queue.Full:
                    pass  # the next raw frame tells it again
        elif key == RXM_SFRBX:
            from onboard.receiver.decode import DecodeError
            from onboard.receiver.sfrbx import decode_sfrbx

            try:
                words = decode_sfrbx(frame.payload)
            except DecodeError:
                return
            if words.gnss_id != GNSS_GPS:
                try:
                    self._queue.put_nowait(words)
                except queue.Full:
                    pass  # broadcast again within 30 s (GLONASS) to 12.5 min (LNAV-like frames)

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
                frames = self._base.frames
                self._base.feed(data, self._reference)
                pending = self._base.collector.assembler.pending
                key = None if pending is None else pending.time.total_ns
                if key != self._pending_key:
                    self._pending_key, self._pending_since_ns = key, self.clock.monotonic_ns()
                if self._base.frames != frames:
                    self._cond.notify_all()
            st.base_frames = self._base.frames
            st.base_epochs = self._base.epoch_count
            pos = self._base.position
            st.base_position_ecef_m = None if pos is None else [float(v) for v in pos.phase_centre_ecef_m]
        if port is not None:
            port.close()
        st.radio_open = False

    # -- engine thread --------------------------------------------------------------------------------------
    def _choose_systems(self, raw_message: str | None) -> None:
        """The engine's systems for the rover's raw message (RtkServiceOptions.receiver_systems), at its start."""
        systems = self.options.receiver_systems.get(raw_message or "", self.options.engine.systems)
        self.engine_options = replace(self.engine_options, systems=systems)
        self._systems_ids = frozenset(SYSTEMS_BY_LETTER[c].gnss_id for c in systems)
        self._status.systems = systems
        log.info("real-time RTK: rover sends %s: systems %s", raw_message or "observations", systems)

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
        from onboard.receiver.sfrbx import DEFAULT_LEAP_S, SfrbxWords
        from onboard.rtk.lnav import LnavAssembler
        from onboard.rtk.navdecode import NavMessageDecoder

        state: RtkState | None = None  # started at the first rover epoch, on the systems of its receiver
        raw_message: str | None = None
        store = EphemerisStore()
        nav = Nav(store, None, BroadcastNavigation())
        tracker = LockTracker(self.options.lock_rules or LockTrackerOptions())
        lnav = LnavAssembler()
        nav_decoder = NavMessageDecoder(DEFAULT_LEAP_S)
        n_base_eph = 0
        outage_epochs = 0
        first_time: GpsTime | None = None
        while not self._stop.is_set():
            try:
                item = self._queue.get(timeout=0.2)
            except queue.Empty:
                continue
            if isinstance(item, _RawMessage):
                if state is not None and item.name != raw_message:
                    log.warning("rover now sends %s: the engine keeps its systems %s", item.name,
                                self.engine_options.systems)
                raw_message = item.name
                continue
            if isinstance(item, Ephemeris):
                _add_ephemeris(nav, item)
                continue
            if isinstance(item, SubframeWords):
                week = self._reference.week if self._reference is not None else None
                eph = ephemeris_from_subframe(lnav, item, week)
                if eph is not None:
                    store.add(eph)
                continue
            if isinstance(item, SfrbxWords):
                if self._reference is not None:
                    eph_other = nav_decoder.add(item.gnss_id, item.sv_id, item.sig_id, item.freq_id, item.words,
                                                self._reference)
                    if eph_other is not None:
                        _add_ephemeris(nav, eph_other)
                continue
            rover = tracker.update(item)
            self._reference = rover.time
            if rover.leap_s is not None and rover.leap_s != nav_decoder.leap_s:
                nav_decoder.leap_s = rover.leap_s
                with self._cond:
                    self._base.leap_s = rover.leap_s
            if state is None:
                self._choose_systems(raw_message)
                state = self._new_state()
            if first_time is None:
                first_time = rover.time
            base, base_pos = self._wait_base(rover.time)
            with self._cond:
                ephs = self._base.ephemerides[n_base_eph:]
                n_base_eph = len(self._base.ephemerides)
            for base_eph in ephs:
                _add_ephemeris(nav, base_eph)
            self._status.base_ephemerides = n_base_eph
            if len(store) == 0 and not len(nav.broadcast or ()):
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
        """The base epoch for rover time `t` (`BaseStream.pair`: the latest whole one for the engine's systems):
        wait up to `base_wait_s` for the one at ≥ t − tolerance to arrive, and for the rest of an epoch whose
        first message arrived less than `base_wait_s` ago."""
        tol = self.engine_options.pair_tolerance_s
        wait_ns = round(self.options.base_wait_s * 1e9)
        deadline = self.clock.monotonic_ns() + wait_ns
        systems = self._systems_ids
        with self._cond:
            while True:
                now = self.clock.monotonic_ns()
                if not self._base.waiting(t, tol, systems, now - self._pending_since_ns >= wait_ns):
                    break
                left = (deadline - now) / 1e9
                if left <= 0 or self._stop.is_set():
                    break
                self._cond.wait(min(left, 0.1))
            base = self._base.pair(t, tol, systems)
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
        st.q, st.ratio, st.ns = int(sol.q), float(sol.ratio), int(sol.ns)
        st.base_systems = None if base is None else "".join(
            sorted((system(g).letter for g in base.systems()), key="GRECJ".find))
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
        # counted last: a reader that sees the epoch counted sees the epoch's status (its age, Q, ratio)
        st.epochs += 1
        if sol.q == Q_NONE or self._pos_file is None:
            return
        try:
            self._pos_file.write(format_solution(sol) + "\n")
            self._pos_file.flush()
            self.solutions_written += 1
        except OSError as exc:
            st.errors += 1
            log.error("solution file: %s", exc)


@dataclass(frozen=True)
class _RawMessage:
    """Queue marker: the rover sends this raw observation message ("RXM-RAWX" or "RXM-RAW")."""

    name: str


def _add_ephemeris(nav: Nav, eph: AnyEphemeris) -> None:
    """GPS LNAV into the engine's EphemerisStore, every other constellation's into `nav.broadcast`."""
    if isinstance(eph, Ephemeris) and eph.gnss_id == GNSS_GPS:
        nav.store.add(eph)
    elif nav.broadcast is not None:
        nav.broadcast.add(eph)


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

    def on_frame(self, frame: Frame) -> None:
        self.rtk.submit_frame(frame)

    def on_decoded(self, item: Any) -> None:
        self.rtk.submit(item)

    def status(self) -> dict[str, Any] | None:
        return self.rtk.snapshot() if self._started else None

    def on_flight_closed(self, reason: str) -> None:
        if self._started:
            self.rtk.stop()
