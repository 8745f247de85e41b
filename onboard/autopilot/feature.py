"""The autopilot link as a recorder feature: MAVLink 2 over TELEM2 or UDP, read-only toward the autopilot.

One thread (`autopilot-link`) owns the link:

    open the link (onboard.hw.mavlink_link; reopened after `reopen_s` when it fails) → import the MAVLink 2
    ardupilotmega dialect (here, not on the recorder's start-up path: ≈0.2–0.3 s) → read → every packet into
    `<flight>/autopilot.tlog` (fsync'd every journal.sync_interval_s) → the autopilot's HEARTBEAT,
    EXTENDED_SYS_STATE, SYSTEM_TIME, ... into `FlightLifecycle` and the status → lifecycle events to the
    flight's events.jsonl (through `FlightContext.append_event`, on the recorder's loop) → GPS_RTCM_DATA
    (from any sender: a ground station's inject, forwarded) through `GpsRtcmReassembler` into a
    `CorrectionsPipe` (the real-time RTK base source "mavlink")
    every 1 s: our HEARTBEAT (MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID, the vehicle's system id,
    component MAV_COMP_ID_ONBOARD_COMPUTER 191; MAVLink 1 framing when the autopilot talks only MAVLink 1)
    SET_MESSAGE_INTERVAL for every stream we read: when the autopilot appears, after its reboot
    (time_boot_ms going back), and when a requested stream stays silent `rerequest_s` (a reboot with its
    streams off, a ground station overriding our rates)

The end of a flight: after a disarm, with landed_state ON_GROUND (or never reported) and the link up for
`settle_s` (`FlightCloser`), a `flight_over` event goes to events.jsonl and the recorder is asked to close the
flight and continue into a new one (`FlightContext.close_flight`); across that roll-over the link stays open
and only the tlog moves to the new flight (`switch_flight`). A flight resumed after a power cut counts as flown.

Every timeout is on the recorder's monotonic clock (never pymavlink's `recv_match`, which uses wall time). We
send only HEARTBEAT and COMMAND_LONG(SET_MESSAGE_INTERVAL): never corrections, positions or commands that
change the flight.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from onboard.autopilot.camera import Attitude, CameraCrossCheck, CameraShot, camera_time_gpst
from onboard.autopilot.corrections import CorrectionsPipe
from onboard.autopilot.lifecycle import (
    LANDED_STATE_NAMES,
    MAV_AUTOPILOT_INVALID,
    MAV_TYPE_ONBOARD_CONTROLLER,
    FlightCloser,
    FlightLifecycle,
    LifecycleEvent,
    SequenceLoss,
    is_autopilot_heartbeat,
)
from onboard.autopilot.rtcm_reassembly import GpsRtcmReassembler
from onboard.autopilot.tlog import TlogWriter, next_tlog_path
from onboard.errors import LinkLost
from onboard.hw.ports import ByteStream, Clock, SystemClock
from onboard.recorder.feature import FlightContext, RecorderFeature, is_rollover, rollover_reason
from onboard.timepulse.marks import FLASH_CHANNEL

log = logging.getLogger(__name__)

AUTOPILOT_STATUS_NAME = "autopilot.json"
MAV_COMP_ID_ONBOARD_COMPUTER = 191
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_STATE_ACTIVE = 4
MAV_SYS_STATUS_PREARM_CHECK = 0x10000000
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_AUTOPILOT_PX4 = 12
MAVLINK1_MAGIC = 0xFE

# message name → id, for the requests (ids from common.xml / ardupilotmega.xml)
STREAMS: dict[str, int] = {
    "HEARTBEAT": 0, "SYS_STATUS": 1, "SYSTEM_TIME": 2, "GPS_RAW_INT": 24, "ATTITUDE": 30,
    "GLOBAL_POSITION_INT": 33, "CAMERA_FEEDBACK": 180, "EXTENDED_SYS_STATE": 245,
}
PX4_CAMERA_STREAM = ("CAMERA_TRIGGER", 112)
"""PX4 reports its camera triggers as CAMERA_TRIGGER (common.xml) instead of ArduPilot's CAMERA_FEEDBACK."""
EVENT_DRIVEN = frozenset({"CAMERA_FEEDBACK", "CAMERA_TRIGGER"})
"""Sent per camera trigger, not at a rate: its silence says nothing about the stream requests."""
_ARDUPILOT_MODE_ENUMS = {1: "PLANE_MODE", 2: "COPTER_MODE", 3: "COPTER_MODE", 4: "COPTER_MODE",
                         13: "COPTER_MODE", 14: "COPTER_MODE", 15: "COPTER_MODE", 10: "ROVER_MODE",
                         11: "ROVER_MODE", 12: "SUB_MODE"}


@dataclass(frozen=True)
class AutopilotOptions:
    """The link's settings (keys `autopilot.*`, see default_config.toml)."""

    system_id: int = 0
    """The vehicle's MAVLink system id our heartbeat carries; 0: the autopilot's, learnt from its heartbeat
    (we send nothing before)."""
    fast_interval_s: float = 0.25
    """Interval requested for ATTITUDE and GLOBAL_POSITION_INT (s)."""
    slow_interval_s: float = 1.0
    """Interval requested for HEARTBEAT, EXTENDED_SYS_STATE, SYS_STATUS, SYSTEM_TIME, GPS_RAW_INT,
    CAMERA_FEEDBACK (CAMERA_TRIGGER on PX4) (s)."""
    heartbeat_interval_s: float = 1.0
    link_timeout_s: float = 3.0
    """The link is down when the autopilot's last heartbeat is older than this (s)."""
    rerequest_s: float = 5.0
    """A requested stream silent this long (s) while the autopilot's heartbeat comes: request them again."""
    reopen_s: float = 1.0
    read_bytes: int = 4096
    settle_s: float = 20.0
    """The flight is over when the autopilot was disarmed and on the ground this long with the link up (s;
    `FlightCloser`)."""

    def interval_s(self, name: str) -> float:
        """The interval requested for message `name` (s)."""
        return self.fast_interval_s if name in ("ATTITUDE", "GLOBAL_POSITION_INT") else self.slow_interval_s


def mode_name(mavlink_module: Any, mav_type: int, autopilot: int, custom_mode: int) -> str:
    """The flight mode's name from HEARTBEAT.custom_mode: ArduPilot's COPTER/PLANE/ROVER/SUB_MODE enums of the
    dialect; PX4 main/sub mode numbers; otherwise the number."""
    if autopilot == MAV_AUTOPILOT_ARDUPILOTMEGA and mav_type in _ARDUPILOT_MODE_ENUMS:
        enum_name = _ARDUPILOT_MODE_ENUMS[mav_type]
        entry = mavlink_module.enums.get(enum_name, {}).get(custom_mode)
        if entry is not None:
            return str(entry.name).removeprefix(enum_name + "_")
    if autopilot == MAV_AUTOPILOT_PX4:
        return f"PX4 main {(custom_mode >> 16) & 0xFF} sub {(custom_mode >> 24) & 0xFF}"
    return f"custom {custom_mode}"


@dataclass
class LinkStatus:
    """What autopilot.json shows (JSON-able via `to_json`)."""

    link: str = ""
    link_open: bool = False
    link_error: str | None = None
    link_up: bool = False
    heartbeat_age_s: float | None = None
    autopilot: dict[str, Any] | None = None
    mavlink_version: int | None = None
    armed: bool | None = None
    mode: str | None = None
    custom_mode: int | None = None
    system_status: int | None = None
    landed_state: str = "undefined"
    flown: bool = False
    packets: int = 0
    packets_lost: int = 0
    packet_loss: float = 0.0
    bad_bytes: int = 0
    battery: dict[str, Any] | None = None
    prearm_ok: bool | None = None
    gps: dict[str, Any] | None = None
    attitude: dict[str, Any] | None = None
    position: dict[str, Any] | None = None
    time_synced: bool = False
    camera_feedback: int = 0
    last_camera_feedback: dict[str, Any] | None = None
    camera_check: dict[str, Any] | None = None
    """`onboard.autopilot.camera.CameraCheckCounts`: autopilot camera events vs TIM-TM2 flash marks."""
    settling_s: float | None = None
    """How long (s) the flight-over conditions have held (disarmed, on the ground, link up); None: they do not."""
    flights_closed: int = 0
    """Flights closed by a roll-over since the recorder started."""
    rtcm: dict[str, int] = field(default_factory=dict)
    heartbeats_sent: int = 0
    interval_requests: int = 0
    interval_acks: int = 0
    reboots: int = 0
    events: int = 0
    tlog: str | None = None
    tlog_bytes: int = 0
    pymavlink_import_s: float | None = None
    errors: int = 0

    def to_json(self) -> dict[str, Any]:
        """A JSON-able copy."""
        return dict(self.__dict__)


class _LinkWriter:
    """pymavlink's `file` for sending: writes to the current ByteStream."""

    def __init__(self, port: ByteStream) -> None:
        self.port = port

    def write(self, data: bytes) -> int:
        return self.port.write(bytes(data))


class AutopilotLink:
    """The link worker (see module doc): `start(flight_dir, append_event)`, `snapshot()`, `stop()`."""

    def __init__(self, options: AutopilotOptions, open_link: Callable[[], ByteStream], clock: Clock | None = None,
                 link_name: str = "", corrections: CorrectionsPipe | None = None,
                 sync_interval_s: float = 0.5,
                 camera_sink: Callable[[dict[str, Any]], None] | None = None) -> None:
        self.options = options
        self.camera_sink = camera_sink
        """Receives the `camera_check` records (from the link thread or the caller of `on_flash_marks`)."""
        self._open_link = open_link
        self.clock = clock or SystemClock()
        self.corrections = corrections
        self.sync_interval_s = sync_interval_s
        self.lifecycle = FlightLifecycle()
        self.reassembler = GpsRtcmReassembler()
        self.loss = SequenceLoss()
        self.camera = CameraCrossCheck()
        self._status = LinkStatus(link=link_name)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._tlog: TlogWriter | None = None
        self._emit: Callable[[dict[str, Any]], None] | None = None
        self._autopilot: tuple[int, int] | None = None
        self._last_heartbeat_ns: int | None = None
        self._last_packet_ns: int | None = None
        self._last_seen_ns: dict[str, int] = {}
        self._last_request_ns: int | None = None
        self._last_sent_heartbeat_ns: int | None = None
        self._request_needed = True
        self._mavlink1 = False
        self._mav: Any = None
        self._mavlink: Any = None
        self._flight_over: Callable[[str], None] | None = None
        self.closer = FlightCloser(round(options.settle_s * 1e9))

    # -- lifecycle --------------------------------------------------------------------------------------
    def start(self, flight_dir: Path, emit_event: Callable[[dict[str, Any]], None] | None,
              flight_over: Callable[[str], None] | None = None, resumed: bool = False) -> None:
        """Open the flight's tlog and start the link thread; `emit_event(record)` receives lifecycle events
        (from the link thread: the caller hands them to the recorder's loop); `flight_over(reason)` is called
        (from the link thread) when the flight is over (`FlightCloser`; None: never decided here); `resumed`:
        the flight was resumed after an unclean stop (it may have been flown)."""
        self._tlog = TlogWriter(next_tlog_path(Path(flight_dir)), self.clock, self.sync_interval_s)
        self._status.tlog = self._tlog.path.name
        self._emit = emit_event
        self._flight_over = flight_over
        self.closer = FlightCloser(round(self.options.settle_s * 1e9), resumed)
        self._thread = threading.Thread(target=self._run, name="autopilot-link", daemon=True)
        self._thread.start()

    def switch_flight(self, flight_dir: Path) -> None:
        """The recorder rolled over to a new flight: the tlog continues in `flight_dir` (the swap happens
        between two packets, so none is lost), the link and its state stay as they are."""
        tlog = TlogWriter(next_tlog_path(Path(flight_dir)), self.clock, self.sync_interval_s)
        with self._lock:
            old, self._tlog = self._tlog, tlog
            self._status.tlog = tlog.path.name
            self._status.flights_closed += 1
        if old is not None:
            try:
                old.close()
            except OSError as exc:
                log.error("autopilot tlog close failed: %s", exc)

    def stop_thread(self) -> None:
        """Stop the link thread (idempotent); the tlog stays open until `stop`."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)

    def final_camera_checks(self) -> list[dict[str, Any]]:
        """Every camera shot and flash not yet decided, decided now (`CameraCrossCheck.poll(final=True)`): the
        recording stops, no partner can come any more. Call after `stop_thread`."""
        with self._lock:
            return self.camera.poll(self.lifecycle.gpst_at(self.clock.monotonic_ns()), final=True)

    def stop(self) -> None:
        """Stop the thread, close the tlog (fsync'd)."""
        self.stop_thread()
        if self._tlog is not None:
            try:
                self._tlog.close()
            except OSError as exc:
                log.error("autopilot tlog close failed: %s", exc)
            self._tlog = None

    def snapshot(self) -> dict[str, Any]:
        """The link's status as a JSON-able dict."""
        now = self.clock.monotonic_ns()
        with self._lock:
            st = self._status
            if self._last_heartbeat_ns is not None:
                st.heartbeat_age_s = round((now - self._last_heartbeat_ns) / 1e9, 3)
                st.link_up = st.heartbeat_age_s <= self.options.link_timeout_s
            st.camera_check = dict(self.camera.counts.__dict__)
            st.rtcm = {"fragments": self.reassembler.stats.fragments, "messages": self.reassembler.stats.messages,
                       "dropped": self.reassembler.stats.dropped, "bytes": self.reassembler.stats.bytes_out}
            if self.corrections is not None:
                st.rtcm["queue_dropped"] = self.corrections.dropped_blocks
            if self._tlog is not None:
                st.tlog_bytes = self._tlog.bytes_written
            return st.to_json()

    # -- the thread -------------------------------------------------------------------------------------
    def _run(self) -> None:
        try:
            self._run_link()
        except Exception as exc:  # a bug: logged with its traceback; recording goes on without the link
            log.exception("autopilot link stopped by an internal error")
            with self._lock:
                self._status.link_open, self._status.link_error = False, f"internal error: {exc!r}"
                self._status.errors += 1

    def _run_link(self) -> None:
        t0 = time.perf_counter()
        try:
            from pymavlink.dialects.v20 import ardupilotmega as mavlink  # MAVLink 2, the ArduPilot dialect
        except ImportError as exc:
            log.error("autopilot link: pymavlink is not installed (%s)", exc)
            with self._lock:
                self._status.link_error = f"pymavlink is not installed: {exc}"
            return
        self._mavlink = mavlink
        with self._lock:
            self._status.pymavlink_import_s = round(time.perf_counter() - t0, 3)
        port: ByteStream | None = None
        while not self._stop.is_set():
            if port is None:
                try:
                    port = self._open_link()
                except LinkLost as exc:
                    with self._lock:
                        self._status.link_open, self._status.link_error = False, str(exc)
                    self._stop.wait(self.options.reopen_s)
                    continue
                self._mav = mavlink.MAVLink(_LinkWriter(port), srcSystem=self.options.system_id,
                                            srcComponent=MAV_COMP_ID_ONBOARD_COMPUTER)
                self._mav.robust_parsing = True
                with self._lock:
                    self._status.link_open, self._status.link_error = True, None
            try:
                data = port.read(self.options.read_bytes)
                if data:
                    self._on_data(data)
                self._periodic()
            except LinkLost as exc:
                log.warning("autopilot link lost: %s", exc)
                port.close()
                port = None
                self.reassembler.flush()
                with self._lock:
                    self._status.link_open, self._status.link_error = False, str(exc)
                self._stop.wait(self.options.reopen_s)
            except OSError as exc:  # the tlog's disk: the recorder's own journal reports it; keep the link
                with self._lock:
                    self._status.errors += 1
                log.error("autopilot tlog: %s", exc)
        if port is not None:
            port.close()
        with self._lock:
            self._status.link_open = False

    def _on_data(self, data: bytes) -> None:
        now = self.clock.monotonic_ns()
        wall = self.clock.wall_ns()
        msgs = self._mav.parse_buffer(data) or []
        events: list[LifecycleEvent] = []
        with self._lock:
            for msg in msgs:
                events.extend(self._on_message(msg, now, wall))
        for ev in events:
            log.info("autopilot: %s", ev.event)
            if self._emit is not None:
                self._emit(ev.to_record())

    def _on_message(self, msg: Any, now: int, wall: int) -> list[LifecycleEvent]:
        kind = msg.get_type()
        if kind == "BAD_DATA":
            self._status.bad_bytes += len(msg.get_msgbuf())
            return []
        assert self._tlog is not None
        self._tlog.append(bytes(msg.get_msgbuf()), wall)
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if kind == "GPS_RTCM_DATA":
            for block in self.reassembler.feed(msg.flags, bytes(msg.data[:msg.len])):
                if self.corrections is not None:
                    self.corrections.put(block)
            return []
        if kind == "HEARTBEAT":
            if not is_autopilot_heartbeat(msg.type, msg.autopilot):
                return []
            if self._autopilot is None and self.options.system_id in (0, src[0]):
                self._autopilot = src
                self._status.autopilot = {"system_id": src[0], "component_id": src[1], "type": msg.type,
                                          "autopilot": msg.autopilot}
                if self.options.system_id == 0:
                    self._mav.srcSystem = src[0]
                log.info("autopilot %d/%d (type %d, autopilot %d)", src[0], src[1], msg.type, msg.autopilot)
        if src != self._autopilot:
            return []
        last = self._last_packet_ns
        if last is not None and now - last > self.options.link_timeout_s * 1e9:
            self.loss.restart()  # after an outage the sequence gap says nothing about the link's quality
        self._last_packet_ns = now
        self.loss.update(msg.get_seq())
        self._status.packets, self._status.packets_lost = self.loss.received, self.loss.lost
        self._status.packet_loss = round(self.loss.loss_ratio, 4)
        self._last_seen_ns[kind] = now
        return self._autopilot_message(kind, msg, now)

    def _autopilot_message(self, kind: str, msg: Any, now: int) -> list[LifecycleEvent]:
        st = self._status
        lc = self.lifecycle
        events: list[LifecycleEvent] = []
        if kind == "HEARTBEAT":
            if self._last_heartbeat_ns is None or now - self._last_heartbeat_ns > self.options.link_timeout_s * 1e9:
                self._request_needed = True  # the link (re)appeared: ask for our streams
            self._last_heartbeat_ns = now
            self._mavlink1 = msg.get_msgbuf()[0] == MAVLINK1_MAGIC
            st.mavlink_version = 1 if self._mavlink1 else 2
            events += lc.on_heartbeat(msg.base_mode, now)
            st.armed = lc.armed
            st.custom_mode = msg.custom_mode
            st.mode = mode_name(self._mavlink, msg.type, msg.autopilot, msg.custom_mode)
            st.system_status = msg.system_status
        elif kind == "EXTENDED_SYS_STATE":
            events += lc.on_landed_state(msg.landed_state, now)
            st.landed_state = LANDED_STATE_NAMES.get(lc.landed_state, str(lc.landed_state))
            st.flown = lc.flown
        elif kind == "SYSTEM_TIME":
            events += self._boot_ms(msg.time_boot_ms, now)
            st.time_synced = lc.times.update(msg.time_unix_usec, msg.time_boot_ms, now) is not None
        elif kind == "ATTITUDE":
            events += self._boot_ms(msg.time_boot_ms, now)
            st.attitude = {"roll_deg": _deg(msg.roll), "pitch_deg": _deg(msg.pitch), "yaw_deg": _deg(msg.yaw)}
            at = lc.times.gpst_at_boot_ms(msg.time_boot_ms)
            if at is not None:
                self.camera.add_attitude(Attitude(at, st.attitude["roll_deg"], st.attitude["pitch_deg"],
                                                  st.attitude["yaw_deg"] % 360.0))
        elif kind == "GLOBAL_POSITION_INT":
            events += self._boot_ms(msg.time_boot_ms, now)
            st.position = {"lat_deg": msg.lat / 1e7, "lon_deg": msg.lon / 1e7, "alt_m": msg.alt / 1e3,
                           "relative_alt_m": msg.relative_alt / 1e3}
        elif kind == "GPS_RAW_INT":
            st.gps = {"fix_type": msg.fix_type, "satellites": msg.satellites_visible,
                      "hdop": None if msg.eph == 65535 else msg.eph / 100,
                      "h_acc_m": getattr(msg, "h_acc", 0) / 1e3, "v_acc_m": getattr(msg, "v_acc", 0) / 1e3}
        elif kind == "SYS_STATUS":
            st.battery = {"voltage_v": None if msg.voltage_battery == 65535 else msg.voltage_battery / 1e3,
                          "current_a": None if msg.current_battery == -1 else msg.current_battery / 100,
                          "remaining_pct": None if msg.battery_remaining == -1 else msg.battery_remaining}
            if msg.onboard_control_sensors_present & MAV_SYS_STATUS_PREARM_CHECK:
                st.prearm_ok = bool(msg.onboard_control_sensors_health & MAV_SYS_STATUS_PREARM_CHECK)
        elif kind in ("CAMERA_FEEDBACK", "CAMERA_TRIGGER"):
            index = msg.img_idx if kind == "CAMERA_FEEDBACK" else msg.seq
            st.camera_feedback += 1
            st.last_camera_feedback = {"source": kind, "img_idx": index, "time_usec": msg.time_usec}
            if kind == "CAMERA_FEEDBACK":
                st.last_camera_feedback.update(lat_deg=msg.lat / 1e7, lon_deg=msg.lng / 1e7)
            at = camera_time_gpst(msg.time_usec, lc.times.gpst_at_boot_ms)
            if at is None:
                self.camera.add_untimed_shot()
            else:
                self.camera.add_shot(CameraShot(kind, int(index), at))
        elif kind == "COMMAND_ACK" and msg.command == MAV_CMD_SET_MESSAGE_INTERVAL:
            st.interval_acks += msg.result == 0
        st.events += len(events)
        st.reboots = lc.reboots
        return events

    def _boot_ms(self, time_boot_ms: int, now: int) -> list[LifecycleEvent]:
        events = self.lifecycle.on_boot_ms(time_boot_ms, now)
        if events:
            self._request_needed = True  # a reboot turned the autopilot's streams off
            self._status.time_synced = False
        return events

    def on_flash_marks(self, marks: Any) -> None:
        """TIM-TM2 marks (`CameraMark`s, from the recorder's loop): the flash edges join the camera cross-check."""
        with self._lock:
            for m in marks:
                if m.channel == FLASH_CHANNEL and m.edge == "falling" and m.valid and m.time is not None:
                    self.camera.add_flash(m.time, m.count)
        self.emit_camera_checks()

    def emit_camera_checks(self) -> None:
        """Hand the camera checks that can be decided now to `camera_sink`."""
        with self._lock:
            records = self.camera.poll(self.lifecycle.gpst_at(self.clock.monotonic_ns()))
        if self.camera_sink is not None:
            for rec in records:
                self.camera_sink(rec)

    def _periodic(self) -> None:
        now = self.clock.monotonic_ns()
        self.emit_camera_checks()
        with self._lock:
            if self._tlog is not None:
                self._tlog.maybe_sync()
            over = self._flight_over_now(now)
        if over is not None:
            log.info("autopilot: flight over (%s)", over.detail)
            if self._emit is not None:
                self._emit(over.to_record())
            if self._flight_over is not None:
                self._flight_over(rollover_reason(f"disarmed and on the ground for {self.options.settle_s:g} s"))
        if self._mav.srcSystem == 0:
            return  # the vehicle's system id is not known yet: a heartbeat from system 0 would be wrong
        if (self._last_sent_heartbeat_ns is None
                or now - self._last_sent_heartbeat_ns >= self.options.heartbeat_interval_s * 1e9):
            self._last_sent_heartbeat_ns = now
            self._mav.heartbeat_send(MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID, 0, 0, MAV_STATE_ACTIVE,
                                     force_mavlink1=self._mavlink1)
            with self._lock:
                self._status.heartbeats_sent += 1
        with self._lock:
            due = self._requests_due(now)
        if due:
            self._request_streams(now)

    def _flight_over_now(self, now: int) -> LifecycleEvent | None:
        """The `flight_over` event when the closer says the flight is over now (under the lock)."""
        if self._flight_over is None:
            return None
        lc = self.lifecycle
        link_up = (self._last_heartbeat_ns is not None
                   and now - self._last_heartbeat_ns <= self.options.link_timeout_s * 1e9)
        due = self.closer.update(lc.armed, lc.landed_state, link_up, now)
        since = self.closer.settling_since_ns
        self._status.settling_s = None if since is None else round((now - since) / 1e9, 3)
        if not due:
            return None
        self.closer.closed()
        self._status.settling_s = None
        self._status.events += 1
        return LifecycleEvent("flight_over", now, lc.gpst_at(now), {"settle_s": self.options.settle_s})

    def _requests_due(self, now: int) -> bool:
        if self._autopilot is None or self._last_heartbeat_ns is None:
            return False
        if now - self._last_heartbeat_ns > self.options.link_timeout_s * 1e9:
            return False  # nobody to ask
        if self._request_needed:
            return True
        assert self._last_request_ns is not None
        rerequest_ns = self.options.rerequest_s * 1e9
        if now - self._last_request_ns < rerequest_ns:
            return False
        return any(now - self._last_seen_ns.get(name, 0) > rerequest_ns for name in STREAMS
                   if name not in EVENT_DRIVEN)

    def _request_streams(self, now: int) -> None:
        assert self._autopilot is not None
        system, component = self._autopilot
        streams = dict(STREAMS)
        if (self._status.autopilot or {}).get("autopilot") == MAV_AUTOPILOT_PX4:
            del streams["CAMERA_FEEDBACK"]
            streams[PX4_CAMERA_STREAM[0]] = PX4_CAMERA_STREAM[1]
        for name, msg_id in streams.items():
            interval_us = round(self.options.interval_s(name) * 1e6)
            self._mav.command_long_send(system, component, MAV_CMD_SET_MESSAGE_INTERVAL, 0, msg_id, interval_us,
                                        0, 0, 0, 0, 0, force_mavlink1=self._mavlink1)
        with self._lock:
            self._status.interval_requests += 1
            self._request_needed = False
            self._last_request_ns = now
        log.info("asked autopilot %d/%d for %d streams", system, component, len(STREAMS))


def _deg(rad: float) -> float:
    return round(rad * 57.29577951308232, 3)


class AutopilotFeature(RecorderFeature):
    """The autopilot link as a recorder feature: `AutopilotLink` started when the flight opens (its tlog in the
    flight directory), its lifecycle events appended to events.jsonl on the recorder's loop, its snapshot
    `autopilot.json`, stopped when the flight closes. `corrections` (when RTK takes its base from MAVLink)
    receives the reassembled RTCM3.

    The link's records (lifecycle events, camera checks) wait in a queue that the recorder's loop empties into
    events.jsonl (`_drain`, posted per record); when the flight closes (`on_flight_closing`, the event log still
    open) the queue is emptied into it at once, so none is lost or lands in the wrong flight: at a stop the
    link thread is stopped first and every undecided camera check is decided (final: the recording ends); at a
    roll-over the checks decidable now are written and the undecided ones (a shot whose flash mark may still
    come) stay pending, decided in the next flight."""

    name = "autopilot"
    status_name = AUTOPILOT_STATUS_NAME

    def __init__(self, options: AutopilotOptions, open_link: Callable[[], ByteStream], clock: Clock | None = None,
                 link_name: str = "", corrections: CorrectionsPipe | None = None) -> None:
        self._args = (options, open_link, clock, link_name, corrections)
        self.corrections = corrections
        self.link: AutopilotLink | None = None
        self._rolling_over = False
        self._records: deque[dict[str, Any]] = deque()  # from the link thread, written on the loop
        self._append: Callable[[dict[str, Any]], None] | None = None

    def _drain(self) -> None:
        """The queued records into the current flight's events.jsonl (on the recorder's loop)."""
        while self._records:
            record = self._records.popleft()
            if self._append is not None:
                self._append(record)

    def on_flight_opened(self, flight: FlightContext) -> None:
        if self.link is not None and self._rolling_over:
            # a roll-over: the link, its thread and its state go on; only the tlog moves to the new flight
            self._rolling_over = False
            self.link.switch_flight(flight.flight_dir)
            return
        options, open_link, clock, link_name, corrections = self._args
        emit = None
        if flight.append_event is not None:
            def emit(record: dict[str, Any]) -> None:
                self._records.append(record)
                flight.post(self._drain)
        self._append = flight.append_event
        self.link = AutopilotLink(options, open_link, clock or flight.clock, link_name, corrections,
                                  flight.journal_options.sync_interval_s, camera_sink=emit)
        close = flight.close_flight
        over = None if close is None else (lambda reason: flight.post(close, reason))
        self.link.start(flight.flight_dir, emit, over, flight.resumed)

    def on_decoded(self, item: Any) -> None:
        marks = getattr(item, "marks", None)  # TimeMarks (TIM-TM2): flash edges for the camera cross-check
        if self.link is not None and marks:
            self.link.on_flash_marks(marks)

    def status(self) -> dict[str, Any] | None:
        return None if self.link is None else self.link.snapshot()

    def on_flight_closing(self, reason: str) -> None:
        if self.link is None:
            return
        if is_rollover(reason):
            self.link.emit_camera_checks()
        else:
            self.link.stop_thread()  # nothing more comes from the link: its queue is complete
            self._records.extend(self.link.final_camera_checks())
        self._drain()

    def on_flight_closed(self, reason: str) -> None:
        if is_rollover(reason):
            self._rolling_over = True  # keep the link; the tlog stays in the old flight until the next opens
            return
        if self.link is not None:
            self.link.stop()
