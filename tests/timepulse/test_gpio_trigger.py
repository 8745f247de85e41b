"""Trigger pulses measured on a GPIO (D's gpiozero EdgeSource on a MockFactory), mapped to GPS time through PPS
edges on another GPIO, paired with TIM-TM2 flash marks."""

from __future__ import annotations

import time

import pytest

from onboard.gnsstime import GpsTime
from onboard.rtk.types import CameraMark
from onboard.timepulse.marks import TickAnchor, gpio_mark, pair_marks, pps_anchors

mock = pytest.importorskip("gpiozero.pins.mock")
gpio_edges = pytest.importorskip("onboard.hw.gpio_edges")


@pytest.mark.slow
def test_gpio_trigger_edges_pair_with_flashes_at_the_delay() -> None:
    factory = mock.MockFactory()
    try:
        pps = gpio_edges.GpioEdgeSource(4, factory, line="pps")
        trig = gpio_edges.GpioEdgeSource(17, factory, line="trigger")
        gps_second = GpsTime(2345, 200_000 * 10**9)
        factory.pin(4).drive_high()  # PPS edge = top of gps_second
        factory.pin(4).drive_low()
        time.sleep(0.3)
        factory.pin(17).drive_high()  # the camera trigger pulse, ~0.3 s into the second
        time.sleep(0.05)
        factory.pin(17).drive_low()
        time.sleep(0.65)
        factory.pin(4).drive_high()  # next PPS
        pps_edges = [e for e in iter(lambda: pps.get(0.2), None) if e.rising]
        trig_edges = list(iter(lambda: trig.get(0.2), None))
        pps.close()
        trig.close()
    finally:
        factory.reset()
    assert len(pps_edges) == 2 and [e.rising for e in trig_edges] == [True, False]
    # Coarse host↔GPS relation: a nav epoch for gps_second arrived 40 ms after the first PPS edge.
    coarse = TickAnchor(pps_edges[0].monotonic_ns + 40_000_000, gps_second)
    anchors = pps_anchors([e.monotonic_ns for e in pps_edges], coarse)
    assert [a.time for a in anchors] == [gps_second, gps_second.add_s(1)]
    pulse_mark = gpio_mark(1, trig_edges[0].rising, trig_edges[0].monotonic_ns, 0, anchors)
    assert pulse_mark.valid and pulse_mark.source == "gpio"
    assert 0.25 < pulse_mark.time.diff_s(gps_second) < 0.6  # type: ignore[union-attr]
    flash = CameraMark(0, "falling", 7, pulse_mark.time.add_ns(61_234_567), 20, 1, True)  # type: ignore[union-attr]
    [pair] = pair_marks([pulse_mark, flash])
    assert (pair.delay_ns, pair.pulse_source, pair.flags) == (61_234_567, "gpio", ())
