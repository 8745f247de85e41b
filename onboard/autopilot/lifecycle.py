"""The flight's lifecycle from the autopilot's messages (pure: times are passed in, no I/O).

Armed comes from the autopilot's HEARTBEAT (`base_mode & MAV_MODE_FLAG_SAFETY_ARMED`), never from a ground
station's or a companion's heartbeat on the same link; flight phase from EXTENDED_SYS_STATE.landed_state. Events:

    armed / disarmed     heartbeat armed flag changes (armed also when the first heartbeat seen is armed)
    takeoff              landed_state reaches IN_AIR (2) while not yet flying
    landed               landed_state back to ON_GROUND (1) after take-off
    reboot               the autopilot's time_boot_ms went back (it restarted: its streams are off again)

Each event carries the monotonic ns it was seen at and the GPS time when SYSTEM_TIME has given one
(`BootTimeMap`). Also here: packet loss from MAVLink sequence numbers (`SequenceLoss`).
"""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass
from typing import Any

from onboard.gnsstime import GpsTime

MAV_MODE_FLAG_SAFETY_ARMED = 128
MAV_TYPE_GCS = 6
MAV_TYPE_ONBOARD_CONTROLLER = 18
MAV_AUTOPILOT_INVALID = 8
MAV_TYPE_GIMBAL = 26
MAV_TYPE_ADSB = 27
MAV_TYPE_CAMERA = 30
NOT_AUTOPILOT_TYPES = frozenset({MAV_TYPE_GCS, MAV_TYPE_ONBOARD_CONTROLLER, MAV_TYPE_GIMBAL, MAV_TYPE_ADSB,
                                 MAV_TYPE_CAMERA})
LANDED_UNDEFINED, LANDED_ON_GROUND, LANDED_IN_AIR, LANDED_TAKEOFF, LANDED_LANDING = 0, 1, 2, 3, 4
LANDED_STATE_NAMES = {0: "undefined", 1: "on_ground", 2: "in_air", 3: "takeoff", 4: "landing"}
REBOOT_BACKSTEP_MS = 2000
"""time_boot_ms this much (ms) lower than the highest seen means a reboot (not a reordered packet)."""

_UNIX_EPOCH = _dt.datetime(1970, 1, 1, tzinfo=_dt.UTC)


def is_autopilot_heartbeat(mav_type: int, autopilot: int) -> bool:
    """Whether a HEARTBEAT comes from a flight controller (not a GCS, companion, gimbal, camera, ADS-B)."""
    return autopilot != MAV_AUTOPILOT_INVALID and mav_type not in NOT_AUTOPILOT_TYPES


@dataclass(frozen=True)
class LifecycleEvent:
    """One lifecycle event: `event` name, `monotonic_ns` seen at, `gpst` (None before SYSTEM_TIME), details."""

    event: str
    monotonic_ns: int
    gpst: GpsTime | None = None
    detail: dict[str, Any] | None = None

    def to_record(self) -> dict[str, Any]:
        """The events.jsonl record (`type` "autopilot")."""
        rec: dict[str, Any] = {"type": "autopilot", "event": self.event, "monotonic_ns": self.monotonic_ns,
                               "gpst": None if self.gpst is None else str(self.gpst),
                               "gps_week": None if self.gpst is None else self.gpst.week,
                               "gps_tow_ns": None if self.gpst is None else self.gpst.tow_ns}
        if self.detail:
            rec.update(self.detail)
        return rec


class BootTimeMap:
    """The autopilot's boot clock → UTC → GPS time, from SYSTEM_TIME (`time_unix_usec`, `time_boot_ms`).

    Keeps the GPS time of the autopilot's boot and the latest (monotonic ns, GPS time) pair, so that messages
    with a `time_boot_ms` and events seen at a host monotonic instant both land on the receiver's timeline.
    `time_unix_usec` 0 (the autopilot has no GPS time yet) gives nothing.
    """

    def __init__(self) -> None:
        self.boot_gpst: GpsTime | None = None
        self._anchor: tuple[int, GpsTime] | None = None

    def update(self, time_unix_usec: int, time_boot_ms: int, rx_monotonic_ns: int) -> GpsTime | None:
        """One SYSTEM_TIME; returns its GPS time (None when the autopilot has no UTC yet)."""
        if time_unix_usec <= 0:
            return None
        utc = _UNIX_EPOCH + _dt.timedelta(microseconds=int(time_unix_usec))
        gpst = GpsTime.from_utc(utc)
        self.boot_gpst = gpst.add_ns(-int(time_boot_ms) * 1_000_000)
        self._anchor = (rx_monotonic_ns, gpst)
        return gpst

    def reset(self) -> None:
        """The autopilot rebooted: its boot clock restarted."""
        self.boot_gpst = None
        self._anchor = None

    def gpst_at_boot_ms(self, time_boot_ms: int) -> GpsTime | None:
        """GPS time of an autopilot `time_boot_ms` (None before SYSTEM_TIME)."""
        return None if self.boot_gpst is None else self.boot_gpst.add_ns(int(time_boot_ms) * 1_000_000)

    def gpst_at_monotonic(self, monotonic_ns: int) -> GpsTime | None:
        """GPS time of a host monotonic instant, through the latest SYSTEM_TIME (its link latency, ms, included)."""
        if self._anchor is None:
            return None
        mono, gpst = self._anchor
        return gpst.add_ns(monotonic_ns - mono)


class SequenceLoss:
    """Packets lost on the link from one sender's MAVLink sequence numbers (0–255, +1 per packet). Across a
    link outage (`restart`) the count is unknowable (the numbers wrap every 256 packets): the outage is the
    link's down time, not packet loss."""

    def __init__(self) -> None:
        self.received = 0
        self.lost = 0
        self._last: int | None = None

    def update(self, seq: int) -> None:
        """One packet with sequence number `seq`."""
        if self._last is not None:
            gap = (seq - self._last - 1) & 0xFF
            if gap < 128:  # a larger jump is a restart of the sender's counter, not 200 lost packets
                self.lost += gap
        self._last = seq
        self.received += 1

    def restart(self) -> None:
        """The link was down: the next packet starts a new count of gaps."""
        self._last = None

    @property
    def loss_ratio(self) -> float:
        """Lost / (received + lost); 0 before any packet."""
        total = self.received + self.lost
        return self.lost / total if total else 0.0


class FlightLifecycle:
    """Armed / in-air state and its events (see module doc); feed the autopilot's messages in arrival order."""

    def __init__(self, times: BootTimeMap | None = None) -> None:
        self.times = times or BootTimeMap()
        self.armed: bool | None = None
        self.landed_state: int = LANDED_UNDEFINED
        self.flying = False
        self.flown = False
        """Whether landed_state reached IN_AIR since the link came up (a flight was flown)."""
        self.reboots = 0
        self._max_boot_ms: int | None = None
        self._last_boot: tuple[int, int] | None = None  # (time_boot_ms, monotonic ns it arrived at)

    def gpst_at(self, now_ns: int) -> GpsTime | None:
        """GPS time of host instant `now_ns`: on the autopilot's own clock (its latest time_boot_ms, plus the
        host time since that message arrived), else through the latest SYSTEM_TIME's arrival; None before
        SYSTEM_TIME."""
        if self._last_boot is not None:
            boot_ms, rx_ns = self._last_boot
            at_boot = self.times.gpst_at_boot_ms(boot_ms)
            if at_boot is not None:
                return at_boot.add_ns(now_ns - rx_ns)
        return self.times.gpst_at_monotonic(now_ns)

    def _event(self, name: str, now_ns: int, **detail: Any) -> LifecycleEvent:
        return LifecycleEvent(name, now_ns, self.gpst_at(now_ns), detail or None)

    def on_heartbeat(self, base_mode: int, now_ns: int) -> list[LifecycleEvent]:
        """The autopilot's HEARTBEAT (the caller filters out other senders: `is_autopilot_heartbeat`)."""
        armed = bool(base_mode & MAV_MODE_FLAG_SAFETY_ARMED)
        before, self.armed = self.armed, armed
        if armed and before is not True:
            return [self._event("armed", now_ns)]
        if not armed and before is True:
            return [self._event("disarmed", now_ns)]
        return []

    def on_landed_state(self, landed_state: int, now_ns: int) -> list[LifecycleEvent]:
        """EXTENDED_SYS_STATE.landed_state."""
        self.landed_state = landed_state
        if landed_state == LANDED_IN_AIR and not self.flying:
            self.flying = self.flown = True
            return [self._event("takeoff", now_ns)]
        if landed_state == LANDED_ON_GROUND and self.flying:
            self.flying = False
            return [self._event("landed", now_ns)]
        return []

    def on_boot_ms(self, time_boot_ms: int, now_ns: int) -> list[LifecycleEvent]:
        """Any message's `time_boot_ms` (ATTITUDE, GLOBAL_POSITION_INT, SYSTEM_TIME): detects a reboot."""
        if self._max_boot_ms is not None and time_boot_ms + REBOOT_BACKSTEP_MS < self._max_boot_ms:
            previous = self._max_boot_ms
            self._max_boot_ms = time_boot_ms
            self.reboots += 1
            event = self._event("reboot", now_ns, previous_boot_ms=previous, time_boot_ms=time_boot_ms)
            self.times.reset()
            self._last_boot = (time_boot_ms, now_ns)
            return [event]
        self._last_boot = (time_boot_ms, now_ns)
        self._max_boot_ms = time_boot_ms if self._max_boot_ms is None else max(self._max_boot_ms, time_boot_ms)
        return []


class FlightCloser:
    """When the flight is over (pure: times passed in): after a disarm, with the autopilot's landed_state
    ON_GROUND (or UNDEFINED: an autopilot that never reports it) and its link alive, held for `settle_ns`.

    A flight is closable once it was flown: landed_state reached IN_AIR since it opened, or, for an autopilot
    that never reports landed_state, it was armed; `resumed` (a flight resumed after a crash or power cut, whose
    past is unknown) counts as flown. Arming, leaving the ground, or the link going down restarts the wait: a
    silent link says nothing about whether the vehicle re-armed. `closed()` starts the count afresh for the
    next flight.
    """

    def __init__(self, settle_ns: int, resumed: bool = False) -> None:
        self.settle_ns = settle_ns
        self.flown = resumed
        self._landed_reported = False
        self._since_ns: int | None = None

    def update(self, armed: bool | None, landed_state: int, link_up: bool, now_ns: int) -> bool:
        """Feed the latest state (after every message and periodically); True when the flight should close now."""
        if landed_state != LANDED_UNDEFINED:
            self._landed_reported = True
        in_air = landed_state in (LANDED_IN_AIR, LANDED_TAKEOFF, LANDED_LANDING)
        if in_air or (armed and not self._landed_reported):
            self.flown = True
        settled = (self.flown and link_up and armed is False
                   and landed_state in (LANDED_ON_GROUND, LANDED_UNDEFINED))
        if not settled:
            self._since_ns = None
            return False
        if self._since_ns is None:
            self._since_ns = now_ns
        return now_ns - self._since_ns >= self.settle_ns

    @property
    def settling_since_ns(self) -> int | None:
        """Monotonic ns since which the close conditions hold (None: they do not)."""
        return self._since_ns

    def closed(self) -> None:
        """The flight was closed: the next one must be flown before it can close."""
        self.flown = False
        self._since_ns = None
