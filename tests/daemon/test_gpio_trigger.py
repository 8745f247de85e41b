"""Trigger pulses measured on a GPIO (receiver.trigger = "gpio"), timed through PPS edges on another GPIO."""

from __future__ import annotations

import time
from pathlib import Path
from types import MappingProxyType

import numpy as np
import pytest

from onboard.gnsstime import GpsTime
from onboard.hw.fake import FakeByteStream
from onboard.hw.ports import Edge
from onboard.logger.events import read_events
from onboard.recorder.daemon import GpioTiming, RecorderDeps
from onboard.rtk.types import ObsEpoch
from tests.daemon.helpers import RunningRecorder, make_settings, status, wait_until

T0 = GpsTime.from_week_tow_s(2300, 1000.0)
S = 1_000_000_000


def test_trigger_interpolated_between_pps_anchors() -> None:
    g = GpioTiming(wait_ns=2 * S)
    g.set_coarse(10 * S, T0)  # host tick 10 s ↔ GPS tow 1000 s (coarse: ms off)
    assert g.add(Edge("pps", True, 10 * S + 30_000_000), 10 * S) == []  # PPS at GPS 1000 s (host clock +30 ms)
    assert g.add(Edge("trigger", True, 10 * S + 530_000_000), 10 * S) == []  # waits for the next PPS
    out = g.add(Edge("pps", True, 11 * S + 30_000_100), 11 * S)  # host clock runs 100 ns/s fast
    assert len(out) == 1
    mark, tick = out[0]
    assert tick == 10 * S + 530_000_000 and mark.channel == 1 and mark.edge == "rising" and mark.valid
    assert mark.source == "gpio" and mark.count == 1
    want = T0.add_ns(round(500_000_000 * S / (S + 100)))
    assert abs(mark.time.diff_ns(want)) <= 1  # type: ignore[union-attr]


def test_trigger_without_pps_gets_no_time_after_waiting() -> None:
    g = GpioTiming(wait_ns=2 * S)
    assert g.add(Edge("trigger", True, 5 * S), 5 * S) == []
    assert g.release(6 * S) == []
    [(mark, _)] = g.release(7 * S)
    assert not mark.valid and mark.time is None  # no anchor: better no time than a wrong one


def _epoch_frame(t: GpsTime) -> bytes:
    from hil_sim.ubx_encode import rxm_raw

    n = 5
    epoch = ObsEpoch(
        time=t, gnss_id=np.zeros(n, np.int8), sv_id=np.arange(1, n + 1, dtype=np.int16),
        pr_m=np.full(n, 2.2e7), cp_cyc=np.full(n, 1.1e8), dop_hz=np.zeros(n), cn0_dbhz=np.full(n, 42.0),
        lock_ms=np.full(n, np.nan), lli=np.zeros(n, np.uint8),
    )
    return rxm_raw(epoch)


@pytest.mark.slow
@pytest.mark.timeout(60)
def test_recorder_times_gpio_trigger_pulses(tmp_path: Path) -> None:
    """In-process recorder with gpiozero MockFactory pins: a raw epoch gives the coarse anchor, PPS edges the
    fine ones, and the trigger pulse lands in events.jsonl as a GPS-timed mark paired with nothing yet."""
    pytest.importorskip("hil_sim.ubx_encode")
    from gpiozero.pins.mock import MockFactory

    from onboard.hw.gpio_edges import GpioEdgeSource

    factory = MockFactory()
    stream = FakeByteStream()
    sources = [GpioEdgeSource(23, factory, line="trigger"), GpioEdgeSource(24, factory, line="pps")]
    settings = make_settings(
        tmp_path, receiver_configure=False, gpio_trigger_pin=23, gpio_pps_pin=24,
        receiver_options=MappingProxyType({"trigger": "gpio"}),
    )
    run = RunningRecorder(settings, RecorderDeps(open_port=lambda: stream, edge_sources=lambda: sources))
    try:
        wait_until(lambda: status(settings.status_path).get("port_open"), what="port open")
        pps, trig = factory.pin(24), factory.pin(23)
        t_epoch = T0.add_s(-0.05)  # the epoch tag 50 ms before the coming PPS second
        stream.feed(_epoch_frame(t_epoch))
        wait_until(lambda: status(settings.status_path).get("epochs") == 1, what="epoch decoded")
        pps.drive_high()
        pps.drive_low()
        time.sleep(0.3)
        trig.drive_high()
        trig.drive_low()
        time.sleep(0.7)
        pps.drive_high()
        pps.drive_low()
        wait_until(lambda: status(settings.status_path).get("time_marks", 0) >= 2, what="trigger marks")
        assert run.stop() == 0
    finally:
        factory.reset()
    flight = next(settings.data_dir.glob("flight-*"))
    records = read_events(flight / "events.jsonl").records
    marks = [r for r in records if r["kind"] == "mark" and r["source"] == "gpio"]
    rising = [m for m in marks if m["edge"] == "rising"]
    assert len(rising) == 1 and rising[0]["valid"] and rising[0]["channel"] == 1
    # ~0.3 s after the PPS at the whole second T0 (sleep jitter allowed; exactness is the pure test above)
    offset_s = GpsTime(rising[0]["week"], rising[0]["tow_ns"]).diff_s(T0)
    assert 0.25 < offset_s < 0.6
    pairings = [r for r in records if r["kind"] == "pairing"]
    assert pairings and pairings[0]["pulse_source"] == "gpio" and "pulse_without_flash" in pairings[0]["flags"]


@pytest.mark.slow
@pytest.mark.timeout(60)
def test_gpio_flash_edge_paired_with_gpio_trigger_and_fsynced_at_once(tmp_path: Path) -> None:
    """gpio.flash_pin: a hot-shoe falling edge on a pulled-up MockFactory pin becomes a GPS-timed flash mark
    (channel 0, source gpio), is fsynced to events.jsonl at once (the manual clock never lets the periodic
    sync run), and is paired with the GPIO trigger pulse before it: the image's delay is the two edges'
    tick difference mapped through the PPS anchors."""
    pytest.importorskip("hil_sim.ubx_encode")
    from gpiozero.pins.mock import MockFactory

    from onboard.hw.fake import ManualClock
    from onboard.hw.gpio_edges import GpioEdgeSource
    from onboard.logger.files import RecordingFileLayer

    factory = MockFactory()
    stream = FakeByteStream()
    clock = ManualClock(monotonic_ns=time.monotonic_ns())
    files = RecordingFileLayer()
    sources = [GpioEdgeSource(23, factory, line="trigger"), GpioEdgeSource(24, factory, line="pps"),
               GpioEdgeSource(25, factory, line="flash", pull_up=True)]
    settings = make_settings(
        tmp_path, receiver_configure=False, gpio_trigger_pin=23, gpio_pps_pin=24, gpio_flash_pin=25,
        journal_sync_interval_s=1.0, receiver_options=MappingProxyType({"trigger": "gpio"}),
    )
    run = RunningRecorder(settings, RecorderDeps(open_port=lambda: stream, clock=clock, files=files,
                                                 edge_sources=lambda: sources))
    try:
        wait_until(lambda: status(settings.status_path).get("port_open"), what="port open")
        pps, trig, flash = factory.pin(24), factory.pin(23), factory.pin(25)
        clock.advance_ns(time.monotonic_ns() - clock.monotonic_ns())  # the epoch's bytes arrive "now"
        stream.feed(_epoch_frame(T0.add_s(-0.05)))
        wait_until(lambda: status(settings.status_path).get("epochs") == 1, what="epoch decoded")
        pps_s = [time.monotonic()]
        pps.drive_high()
        pps_s[0] = (pps_s[0] + time.monotonic()) / 2  # the edge's tick, to the bracket's width
        pps.drive_low()
        time.sleep(0.3)
        trig.drive_high()
        time.sleep(0.06)
        flash.drive_low()  # the flash: the hot shoe pulls the line low
        time.sleep(0.004)
        flash.drive_high()
        trig.drive_low()
        time.sleep(0.6)
        pps_s.append(time.monotonic())
        pps.drive_high()
        pps_s[1] = (pps_s[1] + time.monotonic()) / 2
        pps.drive_low()
        wait_until(lambda: status(settings.status_path).get("time_marks", 0) >= 4, what="trigger and flash marks")
        events_path = next(settings.data_dir.glob("flight-*")) / "events.jsonl"
        assert files.synced_bytes.get(events_path) == events_path.stat().st_size  # no mark waits for a sync
        assert run.stop() == 0
    finally:
        factory.reset()
    records = read_events(events_path).records
    marks = [r for r in records if r["kind"] == "mark"]
    [flash_mark] = [m for m in marks if m["channel"] == 0 and m["edge"] == "falling"]
    [pulse_mark] = [m for m in marks if m["channel"] == 1 and m["edge"] == "rising"]
    assert flash_mark["source"] == pulse_mark["source"] == "gpio" and flash_mark["valid"] and flash_mark["count"] == 1
    [pairing] = [r for r in records if r["kind"] == "pairing"]
    assert pairing["flags"] == [] and pairing["pulse_source"] == "gpio"
    assert (pairing["flash_week"], pairing["flash_tow_ns"]) == (flash_mark["week"], flash_mark["tow_ns"])
    assert pairing["delay_ns"] == flash_mark["tow_ns"] - pulse_mark["tow_ns"]
    tick_delay_ns = flash_mark["tick_ns"] - pulse_mark["tick_ns"]
    assert 0.055e9 < tick_delay_ns < 0.5e9
    # host ticks scaled by the PPS anchors' rate (the two PPS edges are one GPS second apart)
    assert abs(pairing["delay_ns"] - tick_delay_ns / (pps_s[1] - pps_s[0])) <= 20_000


def test_production_edge_sources_follow_the_settings(tmp_path: Path) -> None:
    """The composition root opens PPS + flash (pulled up: the hot shoe pulls the line low) for gpio.flash_pin,
    PPS + trigger for receiver.trigger = "gpio", and no GPIO at all otherwise."""
    from onboard.recorder.app import gpio_edge_sources

    assert gpio_edge_sources(make_settings(tmp_path)) is None
    flash_only = make_settings(tmp_path, gpio_pps_pin=24, gpio_flash_pin=25, gpio_pin_factory="mock")
    opener = gpio_edge_sources(flash_only)
    assert opener is not None
    sources = opener()
    try:
        assert [s.line for s in sources] == ["pps", "flash"]  # type: ignore[attr-defined]
        flash_device = sources[1]._device  # type: ignore[attr-defined]
        assert flash_device.pull_up is True and flash_device.pin.state == 1  # idle high until a flash
    finally:
        for s in sources:
            s.close()
    both = make_settings(tmp_path, gpio_trigger_pin=23, gpio_pps_pin=24, gpio_flash_pin=25,
                         gpio_pin_factory="mock", receiver_options=MappingProxyType({"trigger": "gpio"}))
    sources = gpio_edge_sources(both)()  # type: ignore[misc]
    try:
        assert [s.line for s in sources] == ["pps", "trigger", "flash"]  # type: ignore[attr-defined]
    finally:
        for s in sources:
            s.close()
