"""Camera cross-check: the autopilot's camera events beside our TIM-TM2 flash marks (pure: times passed in).

The autopilot reports each image it triggered: ArduPilot CAMERA_FEEDBACK (180; `time_usec` UNIX-epoch µs from
its GPS without a feedback pin, µs since boot with one), PX4 CAMERA_TRIGGER (112; `time_usec` µs since boot).
Boot times go to GPS time through the link's `BootTimeMap` (SYSTEM_TIME), UNIX times through UTC → GPS time;
the caller hands `CameraShot`s with their GPS time. Flash marks are TIM-TM2 EXTINT0 falling edges
(`onboard.timepulse.marks`: channel 0, hot-shoe pulls the line low).

Pairing rule: a shot and a flash pair when the flash is within `tolerance_ns` (default 0.5 s) of the shot's GPS
time, nearest first, each at most once. Why 0.5 s: the flash follows the autopilot's trigger by the camera's
shutter delay (50–250 ms on the survey cameras we use; hil_sim 60–150 ms) and the boot → GPS mapping adds
the SYSTEM_TIME latency (tens of ms, its `time_unix_usec` comes from the autopilot's own GPS); the next
image is a camera period (2–3 s, never below 1 s) away, so 0.5 s keeps every true pair and never reaches a
neighbour's flash. A shot or flash is decided once the newest time seen is `decide_after_ns` past it (a
TIM-TM2 report arrives in the next navigation epoch, ≤ 1 s; MAVLink adds tens of ms): the pair's partner
can no longer come.

The autopilot's attitude at the exposure (the flash time when matched, else the shot's) is interpolated
linearly between the ATTITUDE samples around it (yaw across ±180°), when they are at most
`attitude_max_gap_ns` apart; otherwise it is null. It is a prior for geotag exports before a bundle
adjustment: body attitude of the flight controller, not of the camera (the gimbal and boresight are not in it).

Event-log record (events.jsonl, `kind` "camera_check", format version 1; GPS times as week + ns of week):

    result            "matched" | "shot_without_flash" | "flash_without_shot"
    shot_source       "CAMERA_FEEDBACK" | "CAMERA_TRIGGER" | null;  shot_index (img_idx / seq) | null
    shot_week, shot_tow_ns      the autopilot's event time in GPS time | null
    flash_week, flash_tow_ns, flash_count    the TIM-TM2 flash mark | null
    delay_ns          flash − shot (ns) when matched, else null
    exposure_week, exposure_tow_ns  the time the attitude is for (flash if any, else shot)
    roll_deg, pitch_deg, yaw_deg    the autopilot's ATTITUDE at the exposure (yaw 0–360) | null
    tolerance_ns      the pairing tolerance used
"""

from __future__ import annotations

from bisect import bisect_left, insort
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from onboard.gnsstime import GpsTime

CAMERA_CHECK_KIND = "camera_check"
CAMERA_CHECK_VERSION = 1
MATCHED, SHOT_WITHOUT_FLASH, FLASH_WITHOUT_SHOT = "matched", "shot_without_flash", "flash_without_shot"
UNIX_TIME_MIN_US = 10**15
"""A camera `time_usec` at least this (µs, 2001-09-09 as UNIX time; 31 years as a boot time) is UNIX-epoch time."""


@dataclass(frozen=True)
class CameraCheckOptions:
    """Pairing rules (see module doc for the tolerance)."""

    tolerance_ns: int = 500_000_000
    decide_after_ns: int = 2_000_000_000
    attitude_max_gap_ns: int = 1_000_000_000
    attitude_buffer: int = 400
    """ATTITUDE samples kept (at 4 Hz: 100 s, far more than `decide_after_ns`)."""


@dataclass(frozen=True)
class CameraShot:
    """One image the autopilot says it triggered: `source` message name, `index` its img_idx/seq, `time` GPS."""

    source: str
    index: int
    time: GpsTime


@dataclass(frozen=True)
class Attitude:
    """The autopilot's body attitude (deg; roll, pitch ±180, yaw 0–360) at a GPS time."""

    time: GpsTime
    roll_deg: float
    pitch_deg: float
    yaw_deg: float


@dataclass
class CameraCheckCounts:
    """Counters for autopilot.json's `camera_check`."""

    shots: int = 0
    flashes: int = 0
    matched: int = 0
    shots_without_flash: int = 0
    flashes_without_shot: int = 0
    untimed_shots: int = 0
    """Shots before SYSTEM_TIME gave a boot → GPS mapping (not paired: their time is unknown)."""
    last_delay_ms: float | None = None
    tolerance_ms: float = 0.0


def _wrap_deg(a: float) -> float:
    return (a + 180.0) % 360.0 - 180.0


def interpolate_attitude(before: Attitude, after: Attitude, t: GpsTime) -> Attitude:
    """Linear interpolation between two samples at `t` (yaw along the shorter arc, returned 0–360)."""
    span = after.time.total_ns - before.time.total_ns
    w = 0.0 if span == 0 else (t.total_ns - before.time.total_ns) / span
    dyaw = _wrap_deg(after.yaw_deg - before.yaw_deg)
    return Attitude(t, _wrap_deg(before.roll_deg + w * _wrap_deg(after.roll_deg - before.roll_deg)),
                    before.pitch_deg + w * (after.pitch_deg - before.pitch_deg),
                    (before.yaw_deg + w * dyaw) % 360.0)


@dataclass
class CameraCrossCheck:
    """Shots, flashes and attitude in; `camera_check` records out (`poll(now)`), counters in `counts`."""

    options: CameraCheckOptions = field(default_factory=CameraCheckOptions)

    def __post_init__(self) -> None:
        self.counts = CameraCheckCounts(tolerance_ms=self.options.tolerance_ns / 1e6)
        self._shots: list[CameraShot] = []
        self._flashes: list[tuple[GpsTime, int | None]] = []
        self._attitude: deque[Attitude] = deque(maxlen=self.options.attitude_buffer)
        self._newest_ns: int | None = None

    def _seen(self, t: GpsTime) -> None:
        self._newest_ns = t.total_ns if self._newest_ns is None else max(self._newest_ns, t.total_ns)

    def add_shot(self, shot: CameraShot) -> None:
        """An autopilot camera event with its GPS time."""
        self.counts.shots += 1
        insort(self._shots, shot, key=lambda s: s.time.total_ns)
        self._seen(shot.time)

    def add_untimed_shot(self) -> None:
        """An autopilot camera event that cannot be placed in GPS time (no SYSTEM_TIME yet)."""
        self.counts.shots += 1
        self.counts.untimed_shots += 1

    def add_flash(self, time: GpsTime, count: int | None = None) -> None:
        """A TIM-TM2 flash mark (channel 0 falling edge) in GPS time, with the receiver's edge counter."""
        self.counts.flashes += 1
        insort(self._flashes, (time, count), key=lambda f: f[0].total_ns)
        self._seen(time)

    def add_attitude(self, sample: Attitude) -> None:
        """An ATTITUDE sample in GPS time (samples may come slightly out of order)."""
        if self._attitude and sample.time.total_ns < self._attitude[-1].time.total_ns:
            items = sorted([*self._attitude, sample], key=lambda a: a.time.total_ns)
            self._attitude.clear()
            self._attitude.extend(items)
        else:
            self._attitude.append(sample)
        self._seen(sample.time)

    def attitude_at(self, t: GpsTime) -> Attitude | None:
        """The autopilot's attitude at `t`: interpolated between the samples around it, None when they are
        missing or further apart than `attitude_max_gap_ns`."""
        times = [a.time.total_ns for a in self._attitude]
        i = bisect_left(times, t.total_ns)
        if i < len(times) and times[i] == t.total_ns:
            return self._attitude[i]
        if i == 0 or i == len(times):
            return None
        before, after = self._attitude[i - 1], self._attitude[i]
        if times[i] - times[i - 1] > self.options.attitude_max_gap_ns:
            return None
        return interpolate_attitude(before, after, t)

    def poll(self, now: GpsTime | None = None, final: bool = False) -> list[dict[str, Any]]:
        """Records of every shot and flash that can be decided at `now` (default: the newest time seen); all
        of them when `final` (the flight closes)."""
        if now is not None:
            self._seen(now)
        if self._newest_ns is None:
            return []
        horizon = None if final else self._newest_ns - self.options.decide_after_ns
        tol = self.options.tolerance_ns
        out: list[dict[str, Any]] = []
        while self._shots or self._flashes:
            first_shot = self._shots[0].time.total_ns if self._shots else None
            first_flash = self._flashes[0][0].total_ns if self._flashes else None
            first = min(t for t in (first_shot, first_flash) if t is not None)
            if horizon is not None and first > horizon:
                break
            if first_shot is not None and first_shot == first:
                shot = self._shots.pop(0)
                # the flash nearest the shot within the tolerance, unless a later shot is nearer to it
                best = None
                for k, (ft, _) in enumerate(self._flashes):
                    d = abs(ft.total_ns - shot.time.total_ns)
                    if d <= tol and (best is None or d < best[1]):
                        best = (k, d)
                if best is not None and self._shots:
                    flash_ns = self._flashes[best[0]][0].total_ns
                    if abs(self._shots[0].time.total_ns - flash_ns) < best[1]:
                        best = None
                if best is None:
                    out.append(self._record(SHOT_WITHOUT_FLASH, shot, None))
                else:
                    out.append(self._record(MATCHED, shot, self._flashes.pop(best[0])))
            else:
                out.append(self._record(FLASH_WITHOUT_SHOT, None, self._flashes.pop(0)))
        return out

    def _record(self, result: str, shot: CameraShot | None,
                flash: tuple[GpsTime, int | None] | None) -> dict[str, Any]:
        c = self.counts
        delay_ns = None
        if result == MATCHED:
            assert shot is not None and flash is not None
            c.matched += 1
            delay_ns = flash[0].total_ns - shot.time.total_ns
            c.last_delay_ms = round(delay_ns / 1e6, 3)
        elif result == SHOT_WITHOUT_FLASH:
            c.shots_without_flash += 1
        else:
            c.flashes_without_shot += 1
        exposure = flash[0] if flash is not None else shot.time  # type: ignore[union-attr]
        att = self.attitude_at(exposure)
        return {
            "v": CAMERA_CHECK_VERSION, "kind": CAMERA_CHECK_KIND, "result": result,
            "shot_source": None if shot is None else shot.source, "shot_index": None if shot is None else shot.index,
            "shot_week": None if shot is None else shot.time.week,
            "shot_tow_ns": None if shot is None else shot.time.tow_ns,
            "flash_week": None if flash is None else flash[0].week,
            "flash_tow_ns": None if flash is None else flash[0].tow_ns,
            "flash_count": None if flash is None else flash[1],
            "delay_ns": delay_ns,
            "exposure_week": exposure.week, "exposure_tow_ns": exposure.tow_ns,
            "roll_deg": None if att is None else round(att.roll_deg, 4),
            "pitch_deg": None if att is None else round(att.pitch_deg, 4),
            "yaw_deg": None if att is None else round(att.yaw_deg, 4),
            "tolerance_ns": self.options.tolerance_ns,
        }


def camera_time_gpst(time_usec: int, boot_to_gpst: Any) -> GpsTime | None:
    """GPS time of a CAMERA_FEEDBACK / CAMERA_TRIGGER `time_usec`: UNIX-epoch µs (≥ UNIX_TIME_MIN_US) via UTC,
    else µs since the autopilot's boot through `boot_to_gpst(time_boot_ms)` (a `BootTimeMap.gpst_at_boot_ms`;
    None before SYSTEM_TIME). The sub-ms part of a boot time is kept."""
    import datetime as dt

    if time_usec <= 0:
        return None
    if time_usec >= UNIX_TIME_MIN_US:
        utc = dt.datetime(1970, 1, 1, tzinfo=dt.UTC) + dt.timedelta(microseconds=int(time_usec))
        return GpsTime.from_utc(utc)
    at_ms = boot_to_gpst(int(time_usec) // 1000)
    return None if at_ms is None else at_ms.add_ns((int(time_usec) % 1000) * 1000)
