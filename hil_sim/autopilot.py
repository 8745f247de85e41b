"""An ArduCopter stand-in speaking MAVLink 2 (or 1) on a raw pseudo-terminal or UDP, for the companion's tests.

`AutopilotCore` is the vehicle in simulated time (no I/O): a scripted flight (pre-arm on the ground, arm,
take-off, survey lines with camera triggers, land, disarm), streams off until SET_MESSAGE_INTERVAL asks for
them (as ArduPilot: only its HEARTBEAT comes unasked), answers with COMMAND_ACK, and GPS_RTCM_DATA carrying
given RTCM3 messages as a ground station's inject forwarded by the autopilot (system 255, fragmented as MAVProxy
does): from a file, or live, message by message as the base station's stream arrives (`inject_rtcm`, fed by the
shell from a serial device, pty or TCP stream: a ground station reading the base's radio). With
`hold_until_go` it does not arm before `give_go` (the pre-flight page said "go"). Faults: link loss, reboot
(boot clock back to 0, streams off, a short silence), heartbeat stop, dropped and reordered fragments, MAVLink
1 only (v2 frames ignored). CAMERA_FEEDBACK comes per trigger of the simulated receiver's camera
(`camera_from_receiver`, a combined run: the autopilot logs the images the receiver's TimePulse triggered, at
the trigger's UTC) or, alone, on its own timer along the survey lines. It also records what it hears (heartbeats by sender, interval requests, anything
else sent to it), for tests: `report()`.

`AutopilotSim` is the thin shell: a pty (raw mode: in cooked mode almost no frame survives) or a UDP socket
sending to the companion, stepped every 10 ms of real time; simulated time runs `speed`× real time (or comes
from `time_source`, to share the receivers' clock). It reads the live RTCM stream in its own thread and turns a
go file appearing into `give_go`.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import logging
import math
import random
import select
import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from onboard.autopilot.rtcm_reassembly import fragment_rtcm
from onboard.errors import LinkLost
from onboard.formats.atomic import write_json_atomic
from onboard.gnsstime import GpsTime
from onboard.hw.ports import ByteStream

log = logging.getLogger(__name__)

MAVLINK2_MAGIC = 0xFD
COPTER_LOITER, COPTER_AUTO, COPTER_LAND = 5, 3, 9
MAV_TYPE_QUADROTOR, MAV_AUTOPILOT_ARDUPILOTMEGA = 2, 3
MAV_TYPE_GCS, MAV_AUTOPILOT_INVALID = 6, 8
MAV_STATE_STANDBY, MAV_STATE_ACTIVE = 3, 4
ARMED_FLAG, CUSTOM_MODE_FLAG = 128, 1
PREARM_CHECK = 0x10000000
MSG = {"HEARTBEAT": 0, "SYS_STATUS": 1, "SYSTEM_TIME": 2, "GPS_RAW_INT": 24, "ATTITUDE": 30,
       "GLOBAL_POSITION_INT": 33, "CAMERA_FEEDBACK": 180, "EXTENDED_SYS_STATE": 245}
SITE_LAT_DEG, SITE_LON_DEG, SITE_ALT_M = 45.0, 7.0, 300.0


@dataclass(frozen=True)
class AutopilotSimOptions:
    """The stand-in's flight and faults; times in simulated seconds from start."""

    system_id: int = 1
    component_id: int = 1
    arm_at_s: float = 10.0
    spool_s: float = 2.0
    takeoff_s: float = 4.0
    survey_s: float = 30.0
    landing_s: float = 5.0
    disarm_after_s: float = 3.0
    camera_period_s: float = 2.0
    repeat_after_s: float | None = None
    """Fly the script a second time, arming this many simulated s after the first disarm (None: once)."""
    mavlink1: bool = False
    gcs_heartbeat: bool = True
    """Also forward a ground station's heartbeat (system 255, type GCS): the companion must ignore it."""
    link_loss: tuple[tuple[float, float], ...] = ()
    heartbeat_stop: tuple[tuple[float, float], ...] = ()
    reboot_at_s: tuple[float, ...] = ()
    reboot_silence_s: float = 2.0
    rtcm_messages: tuple[bytes, ...] = ()
    rtcm_start_s: float = 1.0
    rtcm_interval_s: float = 0.5
    drop_fragment_rate: float = 0.0
    reorder_fragments: bool = False
    hold_until_go: bool = False
    """Stay disarmed on the ground until `AutopilotCore.give_go` (a pre-flight go). The short script is then
    flown from the go on (armed at max(arm_at_s, go)); the mission, tied to the receivers' world, cannot wait:
    a go after its arming time is reported as `go_late_s` and the vehicle arms at the go."""
    camera_from_receiver: bool = False
    """CAMERA_FEEDBACK once per trigger pulse of the simulated receiver's camera (`AutopilotCore.camera_trigger`,
    fed by `hil_sim.receiver.ReceiverCore.on_camera_pulse`) instead of the stand-in's own timer on the survey
    lines: in a combined run the autopilot logs exactly the images the receiver's camera was triggered for."""
    camera_latency_s: tuple[float, float] = (0.005, 0.030)
    """Range (s, uniform) from the trigger to the CAMERA_FEEDBACK leaving the autopilot (its scheduler loop and
    the telemetry queue); with `camera_from_receiver`."""
    camera_time_sigma_s: float = 0.001
    """1-σ error (s, Gaussian) of the autopilot's own GPS-derived UTC at the trigger (`time_usec`: ArduPilot
    stamps the image with its GPS time extrapolated on its own clock); with `camera_from_receiver`."""
    seed: int = 1
    utc_start: _dt.datetime = field(default_factory=lambda: _dt.datetime.now(_dt.UTC))


def _in(windows: tuple[tuple[float, float], ...], t: float) -> bool:
    return any(at <= t < at + dur for at, dur in windows)


class _Collect:
    def __init__(self) -> None:
        self.out: list[bytes] = []

    def write(self, data: bytes) -> int:
        self.out.append(bytes(data))
        return len(data)


class ScriptedFlight:
    """A short scripted flight: ground, arm, spool, take-off climb to 40 m, lawn-mower lines at 5 m/s, land,
    disarm (times from `AutopilotSimOptions`)."""

    def __init__(self, o: AutopilotSimOptions) -> None:
        self.o = o
        self.camera_period_s = o.camera_period_s
        self.utc_start = o.utc_start
        self.gps_start = GpsTime.from_utc(o.utc_start)
        """GPS time of simulated time 0."""
        self.t_takeoff = o.arm_at_s + o.spool_s
        self.t_air = self.t_takeoff + o.takeoff_s
        self.t_land = self.t_air + o.survey_s
        self.t_down = self.t_land + o.landing_s

    def _fold(self, t: float) -> float:
        """The second flight (`repeat_after_s`) replays the first: its time mapped onto the first's."""
        if self.o.repeat_after_s is None:
            return t
        rearm = self.t_down + self.o.disarm_after_s + self.o.repeat_after_s
        return t - (rearm - self.o.arm_at_s) if t >= rearm else t

    arm_s_movable = True
    """The script can be flown later (after a late go); the mission cannot (the receivers' world flies on)."""

    @property
    def arm_s(self) -> float:
        """Simulated time of arming (s)."""
        return self.o.arm_at_s

    def phase(self, t: float) -> tuple[bool, int, int]:
        """(armed, landed_state, custom_mode) at simulated time `t`."""
        t = self._fold(t)
        if t < self.o.arm_at_s:
            return False, 1, COPTER_LOITER
        if t < self.t_takeoff:
            return True, 1, COPTER_AUTO
        if t < self.t_air:
            return True, 3, COPTER_AUTO
        if t < self.t_land:
            return True, 2, COPTER_AUTO
        if t < self.t_down:
            return True, 4, COPTER_LAND
        return t < self.t_down + self.o.disarm_after_s, 1, COPTER_LAND

    def camera_active(self, t: float) -> bool:
        """Whether the camera triggers at `t` (on the survey lines)."""
        return self.phase(t)[1] == 2

    def pose(self, t: float) -> Pose:
        """Where the vehicle is and how it is turned at `t`."""
        _, landed, _ = self.phase(t)
        t = self._fold(t)
        east = north = up = yaw = 0.0
        if landed == 3:
            up = 40.0 * (t - self.t_takeoff) / self.o.takeoff_s
        elif landed == 4:
            up = 40.0 * (1 - (t - self.t_land) / self.o.landing_s)
        elif landed == 2:
            s = 5.0 * (t - self.t_air)  # 5 m/s along 50 m lines, 10 m apart
            line, along = divmod(s, 50.0)
            east, north, up = (along if int(line) % 2 == 0 else 50.0 - along), 10.0 * line, 40.0
            yaw = math.pi / 2 if int(line) % 2 == 0 else -math.pi / 2
        lat = SITE_LAT_DEG + north / 111_320.0
        lon = SITE_LON_DEG + east / (111_320.0 * math.cos(math.radians(SITE_LAT_DEG)))
        roll = 0.05 * math.sin(t) if landed == 2 else 0.0
        return Pose(lat, lon, SITE_ALT_M + up, up, roll, 0.02, yaw)


class MissionFlight:
    """The receiver's simulated mission (`hil_sim.flight.Trajectory` of a `Scenario`): armed `spool_s` before
    the climb until `disarm_after_s` after touchdown; landed_state TAKEOFF for the first 2 m of the climb,
    LANDING on the descent; attitude and position from the trajectory; camera triggers on the survey lines."""

    def __init__(self, scenario: Any, spool_s: float = 2.0, disarm_after_s: float = 3.0) -> None:
        from hil_sim.flight import Trajectory
        from onboard.rtk.geodesy import ecef_to_llh

        self.traj = Trajectory(scenario.flight, scenario.start, scenario.site_lat_deg, scenario.site_lon_deg,
                               scenario.site_h_m)
        self._llh = ecef_to_llh
        self.site_h_m = scenario.site_h_m
        self.spool_s, self.disarm_after_s = spool_s, disarm_after_s
        self.camera_period_s = scenario.camera.period_s
        self.utc_start = scenario.start.to_utc()
        self.gps_start: GpsTime = scenario.start
        """GPS time of simulated time 0 (the scenario's start, the receivers' clock)."""

    arm_s_movable = False

    @property
    def arm_s(self) -> float:
        """Simulated time of arming (s since the scenario's start)."""
        return float(self.traj.takeoff_s - self.spool_s)

    def phase(self, t: float) -> tuple[bool, int, int]:
        """(armed, landed_state, custom_mode) at simulated time `t` (s since the scenario's start)."""
        st = self.traj.state_at_s(t)
        takeoff, landing = self.traj.takeoff_s, self.traj.landing_s
        armed = bool(takeoff - self.spool_s <= t < landing + self.disarm_after_s)
        if st.phase == "climb":
            return True, (3 if st.pos_enu_m[2] < 2.0 else 2), COPTER_AUTO
        if st.phase == "descent":
            return True, 4, COPTER_LAND
        if st.phase == "ground":
            return armed, 1, (COPTER_LAND if t >= landing else COPTER_AUTO if armed else COPTER_LOITER)
        return True, 2, COPTER_AUTO

    def camera_active(self, t: float) -> bool:
        """Whether the camera triggers at `t` (on the survey lines)."""
        return self.traj.state_at_s(t).phase == "line"

    def pose(self, t: float) -> Pose:
        """The trajectory's antenna position and body attitude at `t`."""
        st = self.traj.state_at_s(t)
        lat, lon, h = self._llh(st.pos_ecef_m)
        return Pose(math.degrees(lat), math.degrees(lon), float(h), float(st.pos_enu_m[2]), st.roll_rad,
                    st.pitch_rad, st.yaw_rad)


@dataclass(frozen=True)
class Pose:
    """Position (deg, m above the ellipsoid, m above take-off) and attitude (rad) of the vehicle."""

    lat_deg: float
    lon_deg: float
    alt_m: float
    relative_alt_m: float
    roll_rad: float
    pitch_rad: float
    yaw_rad: float


class AutopilotCore:
    """The vehicle in simulated time (see module doc). `step(t_s)` → packets to send; `receive(data, t_s)`."""

    def __init__(self, options: AutopilotSimOptions, flight: ScriptedFlight | MissionFlight | None = None) -> None:
        from pymavlink.dialects.v20 import ardupilotmega as mavlink

        self.o = options
        self.flight = flight or ScriptedFlight(options)
        self.mavlink = mavlink
        self._out = _Collect()
        self.mav = mavlink.MAVLink(self._out, srcSystem=options.system_id, srcComponent=options.component_id)
        self.gcs = mavlink.MAVLink(self._out, srcSystem=255, srcComponent=190)
        self.parser = mavlink.MAVLink(None)
        self.parser.robust_parsing = True
        self.rng = random.Random(options.seed)
        self.boot_t = 0.0
        self.silent_until = -1.0
        self.intervals: dict[int, float] = {}
        self._next: dict[int, float] = {}
        self._next_hb = 0.3
        self._next_gcs_hb = 0.0  # the ground station's first: a companion must not take it for the autopilot
        self._next_rtcm = options.rtcm_start_s
        self._rtcm_index = 0
        self._rtcm_seq = 0
        self._camera_next: float | None = None
        self._img_idx = 0
        self._triggers: deque[GpsTime] = deque()  # the receiver camera's pulses (its thread), taken by step()
        self._trigger_due_s: float | None = None
        self._camera_rng = random.Random(options.seed * 1000 + 180)  # apart from the fragment faults' draws
        self.camera_truth = {"triggers": 0, "without_flash": 0, "unseen_in_reboot": 0, "feedback_sent": 0}
        self._reboots_done = 0
        self.heard: dict[str, dict[str, Any]] = {}
        self.interval_requests: list[dict[str, Any]] = []
        self.other_messages: dict[str, int] = {}
        self.ignored_v2 = 0
        self.sent: dict[str, int] = {}
        self.rtcm_intact: list[int] = []
        self.rtcm_broken: list[int] = []
        self._live: deque[bytes] = deque()  # appended by the shell's reader thread, taken by step()
        self.rtcm_live = {"messages": 0, "intact": 0, "broken": 0, "bytes": 0, "too_long": 0}
        self.rtcm_fragments = 0
        self.go_s: float | None = None
        self.utc_start = self.flight.utc_start

    # -- the flight --------------------------------------------------------------------------------------
    def phase(self, t: float) -> tuple[bool, int, int]:
        """(armed, landed_state, custom_mode) at simulated time `t` (disarmed on the ground while waiting for
        the go, with `hold_until_go`)."""
        if self.o.hold_until_go and (self.go_s is None or t < self.go_s):
            return False, 1, COPTER_LOITER
        return self.flight.phase(self._flight_t(t))

    def give_go(self, t: float) -> None:
        """The pre-flight check said go at simulated time `t` (the first call counts)."""
        if self.go_s is None:
            self.go_s = t
            log.info("go at %.1f s (arming planned at %.1f s)", t, self.flight.arm_s)

    def _flight_t(self, t: float) -> float:
        """The flight's own time at `t`: the short script is flown later after a late go (held before its
        arming until then); the mission keeps the receivers' time."""
        if not self.o.hold_until_go or not self.flight.arm_s_movable:
            return t
        if self.go_s is None:
            return min(t, self.flight.arm_s - 1e-3)
        return t - max(0.0, self.go_s - self.flight.arm_s)

    def camera_trigger(self, event: Any) -> None:
        """The receiver's camera was triggered (a `hil_sim.camera.CameraEvent`, from any thread; with
        `camera_from_receiver`): CAMERA_FEEDBACK for it follows after `camera_latency_s`."""
        self.camera_truth["triggers"] += 1
        self.camera_truth["without_flash"] += getattr(event, "flash_time", None) is None
        self._triggers.append(event.pulse_time)

    def inject_rtcm(self, message: bytes) -> None:
        """One RTCM3 message of the live stream (from any thread): sent as GPS_RTCM_DATA at the next step."""
        self._live.append(bytes(message))

    # -- I/O of the core -----------------------------------------------------------------------------------
    def receive(self, data: bytes, t: float) -> None:
        """Bytes from the companion."""
        if t < self.silent_until or _in(self.o.link_loss, t):
            return
        for msg in self.parser.parse_buffer(data) or []:
            kind = msg.get_type()
            if kind == "BAD_DATA":
                continue
            if self.o.mavlink1 and msg.get_msgbuf()[0] == MAVLINK2_MAGIC:
                self.ignored_v2 += 1
                continue
            version = 2 if msg.get_msgbuf()[0] == MAVLINK2_MAGIC else 1
            if kind == "HEARTBEAT":
                key = f"{msg.get_srcSystem()}/{msg.get_srcComponent()}/{msg.type}/{msg.autopilot}/v{version}"
                entry = self.heard.setdefault(key, {"system_id": msg.get_srcSystem(),
                                                    "component_id": msg.get_srcComponent(), "type": msg.type,
                                                    "autopilot": msg.autopilot, "mavlink_version": version,
                                                    "count": 0})
                entry["count"] += 1
            elif kind == "COMMAND_LONG" and msg.command == 511:
                self._set_interval(msg, t)
            else:
                name = kind if kind != "COMMAND_LONG" else f"COMMAND_LONG {msg.command}"
                self.other_messages[name] = self.other_messages.get(name, 0) + 1

    def _set_interval(self, msg: Any, t: float) -> None:
        msg_id, interval_us = int(msg.param1), msg.param2
        self.interval_requests.append({"t_s": round(t, 3), "message_id": msg_id, "interval_us": interval_us,
                                       "from": f"{msg.get_srcSystem()}/{msg.get_srcComponent()}"})
        if interval_us < 0:
            self.intervals.pop(msg_id, None)
        else:
            self.intervals[msg_id] = interval_us / 1e6 if interval_us > 0 else 1.0
            self._next[msg_id] = t
        self._send(self.mav.command_ack_encode(511, 0))

    def step(self, t: float) -> list[bytes]:
        """Everything due by simulated time `t`, as packed frames."""
        o = self.o
        if self._reboots_done < len(o.reboot_at_s) and t >= o.reboot_at_s[self._reboots_done]:
            self._reboots_done += 1
            self.boot_t = t
            self.silent_until = t + o.reboot_silence_s
            self.intervals.clear()
            self._next.clear()
            self._img_idx = 0  # ArduPilot's image counter starts again at boot
            log.info("autopilot reboot at %.1f s", t)
        if t < self.silent_until:
            self._out.out.clear()
            return []
        if t >= self._next_hb:
            self._next_hb = t + self.intervals.get(0, 1.0)
            if not _in(o.heartbeat_stop, t):
                armed, _, mode = self.phase(t)
                self._send(self.mav.heartbeat_encode(MAV_TYPE_QUADROTOR, MAV_AUTOPILOT_ARDUPILOTMEGA,
                                                     CUSTOM_MODE_FLAG | (ARMED_FLAG if armed else 0), mode,
                                                     MAV_STATE_ACTIVE if armed else MAV_STATE_STANDBY))
        if o.gcs_heartbeat and t >= self._next_gcs_hb:
            self._next_gcs_hb = t + 1.0
            self._send(self.gcs.heartbeat_encode(MAV_TYPE_GCS, MAV_AUTOPILOT_INVALID, 0, 0, MAV_STATE_ACTIVE),
                       self.gcs)
        for msg_id, interval in list(self.intervals.items()):
            if msg_id == 0 or msg_id == MSG["CAMERA_FEEDBACK"]:
                continue
            if t >= self._next.get(msg_id, t):
                self._next[msg_id] = t + interval
                self._stream(msg_id, t)
        self._camera(t)
        self._rtcm(t)
        out = list(self._out.out)
        self._out.out.clear()
        if _in(o.link_loss, t):
            return []
        return out

    def _send(self, msg: Any, owner: Any = None) -> None:
        """Pack `msg` as the autopilot's (or `owner`'s: the forwarded ground station's) next packet."""
        self.sent[msg.get_type()] = self.sent.get(msg.get_type(), 0) + 1
        owner = owner or self.mav
        buf = msg.pack(owner, force_mavlink1=self.o.mavlink1)
        owner.seq = (owner.seq + 1) % 256
        self._out.out.append(bytes(buf))

    def _boot_ms(self, t: float) -> int:
        return int((t - self.boot_t) * 1000)

    def _stream(self, msg_id: int, t: float) -> None:
        mav = self.mav
        _, landed, _ = self.phase(t)
        p = self.flight.pose(self._flight_t(t))
        lat, lon = round(p.lat_deg * 1e7), round(p.lon_deg * 1e7)
        boot = self._boot_ms(t)
        if msg_id == MSG["EXTENDED_SYS_STATE"]:
            self._send(mav.extended_sys_state_encode(0, landed))
        elif msg_id == MSG["ATTITUDE"]:
            self._send(mav.attitude_encode(boot, p.roll_rad, p.pitch_rad, p.yaw_rad, 0.0, 0.0, 0.0))
        elif msg_id == MSG["GLOBAL_POSITION_INT"]:
            self._send(mav.global_position_int_encode(boot, lat, lon, round(p.alt_m * 1e3),
                                                      round(p.relative_alt_m * 1e3), 0, 0, 0,
                                                      round(math.degrees(p.yaw_rad) * 100) % 36000))
        elif msg_id == MSG["GPS_RAW_INT"]:
            self._send(mav.gps_raw_int_encode(int(t * 1e6), 6, lat, lon, round(p.alt_m * 1e3), 70, 110, 0, 0, 17,
                                              h_acc=20, v_acc=30))
        elif msg_id == MSG["SYS_STATUS"]:
            present = PREARM_CHECK | 0x3F
            self._send(mav.sys_status_encode(present, present, present, 250, 12600 - int(t), 850, 87,
                                             0, 0, 0, 0, 0, 0))
        elif msg_id == MSG["SYSTEM_TIME"]:
            utc = self.utc_start + _dt.timedelta(seconds=t)
            usec = (utc - _dt.datetime(1970, 1, 1, tzinfo=_dt.UTC)) // _dt.timedelta(microseconds=1)
            self._send(mav.system_time_encode(usec, boot))

    def _camera_from_receiver(self, t: float) -> None:
        """CAMERA_FEEDBACK for each trigger of the receiver's camera, as ArduPilot reports a trigger: `time_usec`
        its GPS-derived UTC µs at the trigger, img_idx counting up, position and attitude at the trigger; sent
        `camera_latency_s` after it. A trigger while the autopilot reboots is never seen."""
        while self._triggers:
            pulse = self._triggers[0]
            pulse_s = pulse.diff_s(self.flight.gps_start)
            if self._trigger_due_s is None:
                self._trigger_due_s = pulse_s + self._camera_rng.uniform(*self.o.camera_latency_s)
            if t < self._trigger_due_s:
                return
            self._triggers.popleft()
            self._trigger_due_s = None
            if self.boot_t <= pulse_s < self.silent_until:
                self.camera_truth["unseen_in_reboot"] += 1
                continue
            self._img_idx += 1
            if MSG["CAMERA_FEEDBACK"] not in self.intervals:
                continue  # ArduPilot sends it on the links asking for it
            stamp = pulse.add_ns(round(self._camera_rng.gauss(0.0, self.o.camera_time_sigma_s) * 1e9))
            usec = (stamp.to_utc() - _dt.datetime(1970, 1, 1, tzinfo=_dt.UTC)) // _dt.timedelta(microseconds=1)
            self._send_camera_feedback(usec, self.flight.pose(self._flight_t(pulse_s)))
            self.camera_truth["feedback_sent"] += 1

    def _send_camera_feedback(self, time_usec: int, p: Pose) -> None:
        self._send(self.mav.camera_feedback_encode(time_usec, 0, 0, self._img_idx, round(p.lat_deg * 1e7),
                                                   round(p.lon_deg * 1e7), p.alt_m, p.relative_alt_m,
                                                   math.degrees(p.roll_rad), math.degrees(p.pitch_rad),
                                                   math.degrees(p.yaw_rad), 0.0, 0))

    def _camera(self, t: float) -> None:
        """The stand-in's own camera (without `camera_from_receiver`): a trigger every camera period on the
        survey lines, stamped with the simulated time in µs (µs since boot for the companion, until a reboot)."""
        if self.o.camera_from_receiver:
            self._camera_from_receiver(t)
            return
        if not self.phase(t)[0] or not self.flight.camera_active(self._flight_t(t)):
            self._camera_next = None
            return
        if self._camera_next is None:
            self._camera_next = t
        if t < self._camera_next:
            return
        self._camera_next += self.flight.camera_period_s
        self._img_idx += 1
        if MSG["CAMERA_FEEDBACK"] not in self.intervals:
            return  # ArduPilot sends it on the links asking for it
        self._send_camera_feedback(int(t * 1e6), self.flight.pose(self._flight_t(t)))

    def _rtcm(self, t: float) -> None:
        o = self.o
        while self._rtcm_index < len(o.rtcm_messages) and t >= self._next_rtcm:
            self._next_rtcm += o.rtcm_interval_s
            index = self._rtcm_index
            self._rtcm_index += 1
            (self.rtcm_intact if self._inject(o.rtcm_messages[index]) else self.rtcm_broken).append(index)
        live = self.rtcm_live
        while self._live:
            message = self._live.popleft()
            live["messages"] += 1
            live["bytes"] += len(message)
            try:
                live["intact" if self._inject(message) else "broken"] += 1
            except ValueError:  # over 4 × 180 bytes: no ground station can inject it either
                live["too_long"] += 1

    def _inject(self, message: bytes) -> bool:
        """Send one RTCM message as the ground station's GPS_RTCM_DATA fragments, losing and shuffling them as
        the faults say; True when every fragment was sent."""
        o = self.o
        fragments = fragment_rtcm(message, self._rtcm_seq)
        self._rtcm_seq = (self._rtcm_seq + 1) % 32
        kept = [f for f in fragments if self.rng.random() >= o.drop_fragment_rate]
        if o.reorder_fragments and len(kept) > 1:
            self.rng.shuffle(kept)
        self.rtcm_fragments += len(fragments)
        for flags, data in kept:
            self._send(self.gcs.gps_rtcm_data_encode(flags, len(data), data.ljust(180, b"\0")), self.gcs)
        return len(kept) == len(fragments)

    def report(self) -> dict[str, Any]:
        """What the stand-in heard and sent (JSON-able)."""
        return {"heard_heartbeats": list(self.heard.values()), "interval_requests": self.interval_requests,
                "other_messages": self.other_messages, "ignored_mavlink2": self.ignored_v2, "sent": self.sent,
                "reboots": self._reboots_done, "rtcm_sent": self._rtcm_index, "rtcm_intact": self.rtcm_intact,
                "rtcm_broken": self.rtcm_broken, "rtcm_live": dict(self.rtcm_live),
                "rtcm_fragments": self.rtcm_fragments, "go_s": self.go_s, "camera": dict(self.camera_truth),
                "arm_s": self.flight.arm_s, "go_late_s": None if self.go_s is None or self.flight.arm_s_movable
                else round(max(0.0, self.go_s - self.flight.arm_s), 3)}


class AutopilotSim:
    """The shell: the core on a raw pty (`start()` returns its slave path) or sending to UDP `udp_target`.

    `rtcm_stream` opens the live RTCM3 source (a ground station's serial port on the base's radio, or a TCP
    caster: `onboard.hw.net_stream.open_base_stream`), read in its own thread, reopened when lost; `go_file`
    gives the go when it appears; `time_source` returns the simulated seconds since the flight's start (the
    receivers' clock), instead of this shell's own."""

    def __init__(self, options: AutopilotSimOptions, speed: float = 1.0, udp_target: tuple[str, int] | None = None,
                 report_path: Path | None = None, report_interval_s: float = 0.5,
                 flight: ScriptedFlight | MissionFlight | None = None,
                 rtcm_stream: Callable[[], ByteStream] | None = None, go_file: Path | None = None,
                 time_source: Callable[[], float] | None = None) -> None:
        self.core = AutopilotCore(options, flight)
        self.rtcm_stream = rtcm_stream
        self.go_file = go_file
        self.time_source = time_source
        self.rtcm_stream_bytes = 0
        self.rtcm_stream_error: str | None = None
        self._reader: threading.Thread | None = None
        self.speed = speed
        self.udp_target = udp_target
        self.report_path = report_path
        self.report_interval_s = report_interval_s
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._pty: Any = None
        self._sock: socket.socket | None = None
        self.error: BaseException | None = None
        self._t0 = 0.0

    def start(self) -> str:
        """Open the pty or socket and start; returns the pty slave path or "udp:HOST:PORT"."""
        if self.udp_target is None:
            from hil_sim.pty_server import PtyPort

            self._pty = PtyPort()
            where = self._pty.open(921600)  # raw mode (tty.setraw)
        else:
            self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self._sock.bind(("127.0.0.1", 0))
            self._sock.setblocking(False)
            where = f"udp:{self.udp_target[0]}:{self.udp_target[1]}"
        self._t0 = time.monotonic()
        self._thread = threading.Thread(target=self._run, name="hil-autopilot", daemon=True)
        self._thread.start()
        if self.rtcm_stream is not None:
            self._reader = threading.Thread(target=self._read_rtcm, name="hil-autopilot-rtcm", daemon=True)
            self._reader.start()
        return where

    def sim_time(self) -> float:
        """Simulated seconds since start (or `time_source()`)."""
        if self.time_source is not None:
            return self.time_source()
        return (time.monotonic() - self._t0) * self.speed

    def give_go(self) -> None:
        """The go, now (see `AutopilotCore.give_go`)."""
        self.core.give_go(self.sim_time())

    def stop(self) -> None:
        """Stop, write the last report, close."""
        self._stop.set()
        for thread in (self._thread, self._reader):
            if thread is not None:
                thread.join(timeout=5)
        self._write_report()
        if self._pty is not None:
            self._pty.close()
        if self._sock is not None:
            self._sock.close()

    def report(self) -> dict[str, Any]:
        """The core's report with the shell's counters (JSON-able)."""
        return {**self.core.report(), "sim_time_s": round(self.sim_time(), 3),
                "rtcm_stream_bytes": self.rtcm_stream_bytes, "rtcm_stream_error": self.rtcm_stream_error}

    def _write_report(self) -> None:
        if self.report_path is not None:
            write_json_atomic(self.report_path, self.report(), fsync=False)

    def _read_rtcm(self) -> None:
        """The live RTCM source → whole, CRC-valid RTCM3 messages → the core's inject (what a ground station does
        with the base's serial stream); anything else in the stream is skipped."""
        from onboard.receiver.framing import Protocol, StreamFramer

        assert self.rtcm_stream is not None
        framer = StreamFramer()
        port: ByteStream | None = None
        while not self._stop.is_set():
            if port is None:
                try:
                    port = self.rtcm_stream()
                    self.rtcm_stream_error = None
                except LinkLost as exc:
                    self.rtcm_stream_error = str(exc)
                    self._stop.wait(0.5)
                    continue
            try:
                data = port.read(4096)
            except LinkLost as exc:
                self.rtcm_stream_error = str(exc)
                port.close()
                port = None
                continue
            self.rtcm_stream_bytes += len(data)
            for frame in framer.feed(data):
                if frame.protocol is Protocol.RTCM3:
                    self.core.inject_rtcm(bytes(frame.raw))
        if port is not None:
            port.close()

    def _run(self) -> None:
        next_report = next_go_check = 0.0
        try:
            while not self._stop.is_set():
                t = self.sim_time()
                if self.go_file is not None and self.core.go_s is None and time.monotonic() >= next_go_check:
                    next_go_check = time.monotonic() + 0.1
                    if self.go_file.exists():
                        self.core.give_go(t)
                for data in self._read():
                    self.core.receive(data, t)
                for frame in self.core.step(t):
                    self._write(frame)
                if self.report_path is not None and time.monotonic() >= next_report:
                    next_report = time.monotonic() + self.report_interval_s
                    self._write_report()
                self._wait(0.01)
        except Exception as exc:  # the shell reports any failure of the simulation and stops
            log.exception("autopilot stand-in failed")
            self.error = exc

    def _wait(self, timeout_s: float) -> None:
        fd = self._pty.master_fd if self._pty is not None else self._sock.fileno()  # type: ignore[union-attr]
        select.select([fd], [], [], timeout_s)

    def _read(self) -> list[bytes]:
        if self._pty is not None:
            data = self._pty.read()
            return [data] if data else []
        assert self._sock is not None
        out = []
        while True:
            try:
                out.append(self._sock.recv(65535))
            except (BlockingIOError, ConnectionRefusedError):
                return out

    def _write(self, frame: bytes) -> None:
        if self._pty is not None:
            self._pty.write(frame)
            return
        assert self._sock is not None and self.udp_target is not None
        try:
            self._sock.sendto(frame, self.udp_target)
        except (BlockingIOError, ConnectionRefusedError):
            pass  # nobody listening yet: a real radio loses these too


def rtcm_messages_from_file(path: Path) -> tuple[bytes, ...]:
    """The checksum-valid RTCM3 messages of a file of RTCM3 bytes, in order."""
    from onboard.receiver.framing import Protocol, StreamFramer

    framer = StreamFramer()
    return tuple(bytes(f.raw) for f in framer.feed(Path(path).read_bytes()) if f.protocol is Protocol.RTCM3)


def options_from_args(args: Any) -> AutopilotSimOptions:
    """The stand-in's options from `python -m hil_sim autopilot` arguments."""
    rtcm = rtcm_messages_from_file(args.rtcm) if args.rtcm else ()
    return dataclasses.replace(
        AutopilotSimOptions(), hold_until_go=bool(getattr(args, "go_file", None)), system_id=args.system_id,
        arm_at_s=args.arm_at, survey_s=args.survey,
        mavlink1=args.mavlink1, link_loss=tuple(args.link_loss), heartbeat_stop=tuple(args.heartbeat_stop),
        reboot_at_s=tuple(args.reboot_at), rtcm_messages=rtcm, rtcm_start_s=args.rtcm_start,
        rtcm_interval_s=args.rtcm_interval,
        drop_fragment_rate=args.drop_fragment_rate, reorder_fragments=args.reorder_fragments, seed=args.seed,
        gcs_heartbeat=not args.no_gcs_heartbeat, repeat_after_s=getattr(args, "repeat_after", None))

