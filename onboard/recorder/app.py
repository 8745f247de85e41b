"""The recorder's composition root: real hardware (pyserial, gpiozero pins, sd_notify) and the features the
configuration asks for, assembled into one `Recorder` and run."""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from onboard.hw.ports import ByteStream, EdgeSource
from onboard.recorder.daemon import Recorder, RecorderDeps
from onboard.recorder.sdnotify import SdNotifier
from onboard.recorder.settings import Settings, receiver_options, rtk_engine_options, takeoff_position_ecef_m

if TYPE_CHECKING:
    from onboard.realtime.service import RtkServiceOptions


def serial_port_opener(settings: Settings) -> Callable[[], ByteStream]:
    """The production port factory: pyserial on `settings.port_device`."""

    def open_port() -> ByteStream:
        from onboard.hw.serial_port import SerialByteStream

        return SerialByteStream(settings.port_device, settings.port_baud, settings.port_read_timeout_s)

    return open_port


def gpio_edge_sources(settings: Settings) -> Callable[[], Sequence[EdgeSource]] | None:
    """The production GPIO edge sources: trigger (receiver.trigger = "gpio") and/or flash (gpio.flash_pin),
    with the PPS line that times them; None when no GPIO input is configured."""
    trigger = receiver_options(settings).trigger == "gpio"
    flash = settings.gpio_flash_pin >= 0
    if not (trigger or flash):
        return None

    def open_sources() -> Sequence[EdgeSource]:
        from onboard.hw.gpio_edges import GpioEdgeSource, lgpio_factory

        if settings.gpio_pin_factory == "mock":
            from gpiozero.pins.mock import MockFactory

            factory = MockFactory()
        else:
            factory = lgpio_factory()
        sources = [GpioEdgeSource(settings.gpio_pps_pin, factory, line="pps")]
        if trigger:
            sources.append(GpioEdgeSource(settings.gpio_trigger_pin, factory, line="trigger"))
        if flash:
            # the hot-shoe pulls the line low: an internal pull-up holds it high between flashes
            sources.append(GpioEdgeSource(settings.gpio_flash_pin, factory, line="flash", pull_up=True))
        return sources

    return open_sources


def run_recorder(settings: Settings, deps: RecorderDeps | None = None) -> int:
    """Run the recorder to completion in a fresh event loop; returns the exit code."""
    if deps is None:
        deps = RecorderDeps(open_port=serial_port_opener(settings), notifier=SdNotifier())
    return asyncio.run(recorder_for(settings, deps, settings.rtk_base_stream or None).run())


def recorder_for(settings: Settings, deps: RecorderDeps, base_stream: str | None,
                 options: RtkServiceOptions | None = None) -> Recorder:
    """The composition root's one call: the plain recorder, or with real-time RTK when a base stream is named
    (`serial:DEV[@BAUD]`, `tcp://HOST:PORT`, `ntrip://[USER:PASS@]HOST[:PORT]/MOUNT`; ValueError if malformed)."""
    if not base_stream:
        return Recorder(settings, deps)
    from onboard.hw.net_stream import open_base_stream
    from onboard.realtime.service import RtkRecorder, RtkServiceOptions

    options = options or RtkServiceOptions(engine=rtk_engine_options(settings),
                                           max_base_age_s=settings.rtk_max_base_age_s,
                                           takeoff_position_ecef_m=takeoff_position_ecef_m(settings))
    return RtkRecorder(settings, deps, options, open_base_stream(base_stream))
