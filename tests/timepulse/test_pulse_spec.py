"""`camera_pulse_spec` refuses what a receiver cannot be given, itself, with the setting named."""

from __future__ import annotations

import math

import pytest

from onboard.timepulse.pulse import PulseSpec, camera_pulse_spec, pps_pulse_spec


def test_valid_values_in_message_units() -> None:
    spec = camera_pulse_spec(2.5, 50.0, False, -120)
    assert spec == PulseSpec(2_500_000, 50_000, False, -120)
    assert camera_pulse_spec(2, 100, True).period_us == 2_000_000  # integers are numbers too


@pytest.mark.parametrize(("args", "match"), [
    ((math.nan, 50.0, True), "camera_period_s must be a finite number"),
    ((math.inf, 50.0, True), "camera_period_s must be a finite number"),
    ((-math.inf, 50.0, True), "camera_period_s must be a finite number"),
    (("2.0", 50.0, True), "camera_period_s must be a finite number"),
    ((True, 50.0, True), "camera_period_s must be a finite number"),
    ((None, 50.0, True), "camera_period_s must be a finite number"),
    ((2.0, math.nan, True), "pulse_len_ms must be a finite number"),
    ((2.0, math.inf, True), "pulse_len_ms must be a finite number"),
    ((2.0, -math.inf, True), "pulse_len_ms must be a finite number"),
    ((2.0, 50.0, 1), "pulse_rising must be true or false"),
    ((1.999, 50.0, True), "camera_period_s must be within 2.0–3.0 s"),
    ((3.001, 50.0, True), "camera_period_s must be within 2.0–3.0 s"),
    ((-2.0, 50.0, True), "camera_period_s must be within"),
    ((2.0, 0.0, True), "pulse_len_ms must be > 0"),
    ((2.0, -5.0, True), "pulse_len_ms must be > 0"),
    ((2.0, 0.0004, True), "pulse_len_ms must be > 0"),  # rounds to 0 µs
    ((2.0, 2000.0, True), "pulse_len_ms must be > 0 and shorter than the period"),
    ((2.0, 1e300, True), "pulse_len_ms must be > 0 and shorter than the period"),
    ((2.0, 50.0, True, 40000), "antenna cable delay must be an integer number of ns within -32768–32767"),
    ((2.0, 50.0, True, -40000), "antenna cable delay"),
    ((2.0, 50.0, True, 50.5), "antenna cable delay"),
    ((2.0, 50.0, True, math.nan), "antenna cable delay"),
])
def test_refused_with_a_clear_value_error(args: tuple[object, ...], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        camera_pulse_spec(*args)  # type: ignore[arg-type]


def test_pps_cable_delay_checked_too() -> None:
    assert pps_pulse_spec(-32768).ant_cable_delay_ns == -32768
    with pytest.raises(ValueError, match="antenna cable delay"):
        pps_pulse_spec(32768)
