"""The TimePulse → camera → flash chain as pure functions (no clocks, no I/O; random draws from a seed).

The receiver's TIMEPULSE fires every `period_s` on the GPS-time grid, at `phase_offset_s` past it (a real
receiver leaves the pulse phase where its configuration puts it, not on the whole second): pulse k is at
GPS time k·period + phase (ns since the GPS epoch). Pulses before the receiver has valid time (scenario start +
`valid_after_s`) are suppressed. The pulse triggers the camera; the shutter opens `shutter_delay_mean_s`
(± Gaussian jitter `shutter_jitter_sigma_s`) later and the flash (hot-shoe falling edge) marks the exposure.
A flash may be missed (`missed_flash_probability`) or bounce (a second edge within `bounce_delay_max_s`).
The emulator turns events into TIM-TM2 reports: channel 0 = flash, channel 1 = trigger pulse when routed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hil_sim.scenario import CameraPlan
from onboard.gnsstime import NS_PER_S, GpsTime


@dataclass(frozen=True)
class CameraEvent:
    """One trigger pulse and what the camera did with it.

    `pulse_time` GPS time of the TimePulse edge; `flash_time` the hot-shoe flash edge = exposure (None when
    missed); `delay_s` flash − pulse (s; None when missed); `bounce_time` a spurious second flash edge
    (None normally); `index` the pulse number k (pulse_time = k·period + phase on the GPS time scale).
    """

    pulse_time: GpsTime
    flash_time: GpsTime | None
    delay_s: float | None
    bounce_time: GpsTime | None = None
    index: int = 0


def pulse_index_range(plan: CameraPlan, t0: GpsTime, t1: GpsTime) -> range:
    """Indices k of the pulses with t0 ≤ pulse < t1 (pulse k at k·period + phase, GPS epoch based)."""
    period_ns = round(plan.period_s * NS_PER_S)
    phase_ns = round(plan.phase_offset_s * NS_PER_S) % period_ns
    k0 = -((phase_ns - t0.total_ns) // period_ns)  # ceil((t0 − phase) / period)
    k1 = -((phase_ns - t1.total_ns) // period_ns)
    return range(k0, k1)


def pulse_time(plan: CameraPlan, k: int) -> GpsTime:
    """GPS time of pulse k."""
    period_ns = round(plan.period_s * NS_PER_S)
    phase_ns = round(plan.phase_offset_s * NS_PER_S) % period_ns
    return GpsTime.from_total_ns(k * period_ns + phase_ns)


def camera_event(plan: CameraPlan, k: int, seed: int) -> CameraEvent:
    """The camera's response to pulse k; the random draws depend only on (seed, k)."""
    t_pulse = pulse_time(plan, k)
    rng = np.random.default_rng([seed & 0xFFFFFFFF, 0xCA3E, k & 0xFFFFFFFF, (k >> 32) & 0xFFFFFFFF])
    jitter, miss, bounce, bounce_frac = rng.standard_normal(), rng.random(), rng.random(), rng.random()
    if miss < plan.missed_flash_probability:
        return CameraEvent(t_pulse, None, None, None, k)
    delay_s = plan.shutter_delay_mean_s + plan.shutter_jitter_sigma_s * jitter
    t_flash = t_pulse.add_ns(round(delay_s * NS_PER_S))
    delay_s = t_flash.diff_s(t_pulse)  # the ns-rounded delay the timestamps carry
    bounce_t = None
    if bounce < plan.bounce_probability:
        bounce_t = t_flash.add_ns(max(1, round((0.1 + 0.9 * bounce_frac) * plan.bounce_delay_max_s * NS_PER_S)))
    return CameraEvent(t_pulse, t_flash, delay_s, bounce_t, k)


def camera_events(plan: CameraPlan, t0: GpsTime, t1: GpsTime, valid_from: GpsTime, seed: int) -> list[CameraEvent]:
    """Every camera event whose pulse falls in [t0, t1), pulses before `valid_from` suppressed."""
    start = max(t0, valid_from)
    return [camera_event(plan, k, seed) for k in pulse_index_range(plan, start, t1)]
