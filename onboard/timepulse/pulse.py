"""TimePulse field values: the 1 PPS reference pulse and the camera trigger pulse (CFG-TP5 and legacy CFG-TP).

Field names are the u-blox ones as pyubx2 1.4.0 spells them (CFG-TP5 flag bits split out: `active`,
`lockGnssFreq`, `lockedOtherSet`, `isFreq`, `isLength`, `alignToTow`, `polarity`, `gridUtcGnss`, `syncMode`).
Units are those of the message: periods and lengths in µs, delays in ns.

Why these settings (u-blox 6 receiver description, u-blox M8 receiver description, shared/docs/ublox.md):
- `lockedOtherSet` with `pulseLenRatio = 0` and the real length in `pulseLenRatioLock`: no pulse, hence no
  photo, until the receiver has valid GPS time. The factory NEO-M8T TIMEPULSE does exactly this (flags 0xF7).
- A 2–3 s period cannot be aligned to the top of a second: we ask for `alignToTow` and expect the receiver
  may clear it; the camera pulses then sit at an unknown phase of the GPS grid and must be measured.
- TIM-TM2 uses TIMEPULSE's time base, so TIMEPULSE stays at 1 PPS on the GPS grid when TIMEPULSE2 drives
  the camera.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

US_PER_S = 1_000_000

# Camera period limits (issue: 2–3 s) and the receiver's high/low phase floor (≥ 100 ns, so ≥ 1 µs in µs units).
CAMERA_PERIOD_MIN_S = 2.0
CAMERA_PERIOD_MAX_S = 3.0
TIMEPULSE = 0
TIMEPULSE2 = 1
GRID_GPS = 1
TIME_REF_GPS = 1  # legacy CFG-TP timeRef
CABLE_DELAY_MIN_NS, CABLE_DELAY_MAX_NS = -32768, 32767
"""antCableDelay (CFG-TP5) and antennaCableDelay (legacy CFG-TP) are I2 fields, ns."""


@dataclass(frozen=True, slots=True)
class PulseSpec:
    """One pulse train: period and locked pulse length in µs, polarity, cable delay in ns."""

    period_us: int
    length_us: int
    rising: bool
    ant_cable_delay_ns: int = 50

    def __post_init__(self) -> None:
        if self.period_us <= 0:
            raise ValueError(f"pulse period must be > 0 µs, got {self.period_us}")
        if not 0 < self.length_us < self.period_us:
            raise ValueError(f"pulse length must be > 0 and < the period ({self.period_us} µs), got {self.length_us}")
        if (isinstance(self.ant_cable_delay_ns, bool) or not isinstance(self.ant_cable_delay_ns, int)
                or not CABLE_DELAY_MIN_NS <= self.ant_cable_delay_ns <= CABLE_DELAY_MAX_NS):
            raise ValueError(f"antenna cable delay must be an integer number of ns within {CABLE_DELAY_MIN_NS}–"
                             f"{CABLE_DELAY_MAX_NS} (a 16-bit field), got {self.ant_cable_delay_ns!r}")


def _finite(name: str, value: object) -> float:
    """`value` as a finite float; ValueError naming the setting for NaN, ±inf, a bool or a non-number."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def camera_pulse_spec(period_s: float, pulse_len_ms: float, rising: bool, ant_cable_delay_ns: int = 50) -> PulseSpec:
    """The camera trigger pulse from user units (s, ms, ns); ValueError naming the setting for a non-finite or
    non-numeric value, a period outside 2–3 s, a length not within (0, period), a cable delay out of range."""
    period_s = _finite("camera_period_s", period_s)
    pulse_len_ms = _finite("pulse_len_ms", pulse_len_ms)
    if not isinstance(rising, bool):
        raise ValueError(f"pulse_rising must be true or false, got {rising!r}")  # noqa: TRY004 (settings errors are ValueError)
    if not CAMERA_PERIOD_MIN_S <= period_s <= CAMERA_PERIOD_MAX_S:
        raise ValueError(f"camera_period_s must be within {CAMERA_PERIOD_MIN_S}–{CAMERA_PERIOD_MAX_S} s, got {period_s}")
    period_us = round(period_s * US_PER_S)
    length_us = round(pulse_len_ms * 1000)
    if not 0 < length_us < period_us:
        raise ValueError(f"pulse_len_ms must be > 0 and shorter than the period, got {pulse_len_ms}")
    return PulseSpec(period_us, length_us, rising, ant_cable_delay_ns)


def pps_pulse_spec(ant_cable_delay_ns: int = 50) -> PulseSpec:
    """TIMEPULSE as the factory NEO-M8T has it: 1 PPS, 100 ms long once locked, rising at the top of the second."""
    return PulseSpec(US_PER_S, 100_000, True, ant_cable_delay_ns)


def tp5_fields(tp_idx: int, spec: PulseSpec, version: int) -> dict[str, int]:
    """CFG-TP5 SET fields for `spec` on pulse `tp_idx` (0 TIMEPULSE, 1 TIMEPULSE2).

    Period and length in µs (isFreq = 0, isLength = 1); no pulses until locked (`lockedOtherSet`,
    `pulseLenRatio` 0); aligned to the GPS grid. `version` 0 on u-blox 6, 1 on u-blox 8.
    """
    return {
        "tpIdx": tp_idx,
        "version": version,
        "antCableDelay": spec.ant_cable_delay_ns,
        "rfGroupDelay": 0,
        "freqPeriod": spec.period_us,
        "freqPeriodLock": spec.period_us,
        "pulseLenRatio": 0,
        "pulseLenRatioLock": spec.length_us,
        "userConfigDelay": 0,
        "active": 1,
        "lockGnssFreq": 1,
        "lockedOtherSet": 1,
        "isFreq": 0,
        "isLength": 1,
        "alignToTow": 1,
        "polarity": 1 if spec.rising else 0,
        "gridUtcGnss": GRID_GPS,
        "syncMode": 0,
    }


def tp5_flags_byte(fields: dict[str, int]) -> int:
    """The CFG-TP5 `flags` word from split bits (bit0 active … bit6 polarity, bits 7–10 grid, 11–13 syncMode)."""
    return (
        fields["active"]
        | fields["lockGnssFreq"] << 1
        | fields["lockedOtherSet"] << 2
        | fields["isFreq"] << 3
        | fields["isLength"] << 4
        | fields["alignToTow"] << 5
        | fields["polarity"] << 6
        | fields["gridUtcGnss"] << 7
        | fields["syncMode"] << 11
    )


def legacy_tp_fields(spec: PulseSpec) -> dict[str, int]:
    """Legacy u-blox 6 CFG-TP fields for `spec` on TIMEPULSE (the only pulse CFG-TP addresses).

    `status` +1/−1 polarity; `timeRef` 1 GPS; `flags` bit0 syncMode = 1: pulses only while synchronised to
    GPS time (the closest CFG-TP comes to "no pulses until valid time"; *check on hardware*).
    """
    return {
        "interval": spec.period_us,
        "length": spec.length_us,
        "status": 1 if spec.rising else -1,
        "timeRef": TIME_REF_GPS,
        "flags": 1,
        "antennaCableDelay": spec.ant_cable_delay_ns,
        "rfGroupDelay": 0,
        "userDelay": 0,
    }
