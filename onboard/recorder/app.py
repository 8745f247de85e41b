"""The recorder's composition root: real hardware (pyserial, gpiozero pins, sd_notify) and the features the
configuration asks for, assembled into one `Recorder` and run."""

from __future__ import annotations

import asyncio
import sys
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from onboard.hw.ports import ByteStream, EdgeSource
from onboard.recorder.daemon import Recorder, RecorderDeps
from onboard.recorder.feature import RecorderFeature
from onboard.recorder.sdnotify import SdNotifier
from onboard.recorder.settings import (
    MAVLINK_BASE_STREAM,
    Settings,
    receiver_options,
    rtk_engine_options,
    takeoff_position_ecef_m,
)

if TYPE_CHECKING:
    from onboard.autopilot.feature import AutopilotFeature
    from onboard.hw.ports import Clock
    from onboard.realtime.service import RtkFeature, RtkServiceOptions


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
        from onboard.hw.gpio_edges import GpioEdgeSource, pin_factory

        factory = pin_factory(settings.gpio_pin_factory)
        sources = [GpioEdgeSource(settings.gpio_pps_pin, factory, line="pps")]
        if trigger:
            sources.append(GpioEdgeSource(settings.gpio_trigger_pin, factory, line="trigger"))
        if flash:
            # the hot-shoe pulls the line low: an internal pull-up holds it high between flashes
            sources.append(GpioEdgeSource(settings.gpio_flash_pin, factory, line="flash", pull_up=True))
        return sources

    return open_sources


def run_recorder(settings: Settings, deps: RecorderDeps | None = None) -> int:
    """Run the recorder (with the features the settings ask for) to completion in a fresh event loop; returns the
    exit code. A data directory in use by another recorder: the error line on stderr and exit 2."""
    if deps is None:
        deps = RecorderDeps(open_port=serial_port_opener(settings), notifier=SdNotifier())
    return run(recorder_for(settings, deps, settings.rtk_base_stream or None), "run")


def run(recorder: Recorder, command: str) -> int:
    """Run an assembled recorder in a fresh event loop; returns its exit code (a refusal to start is printed as
    `directgeo: <command>: error: ...`)."""
    code = asyncio.run(recorder.run())
    if recorder.refused is not None:
        print(f"directgeo: {command}: error: {recorder.refused}", file=sys.stderr)
    return code


def rtk_feature(settings: Settings, deps: RecorderDeps, base_stream: str,
                options: RtkServiceOptions | None = None,
                open_base: Callable[[], ByteStream] | None = None) -> RtkFeature:
    """Real-time RTK on the corrections of `base_stream` (`serial:DEV[@BAUD]`, `tcp://HOST:PORT`,
    `ntrip://[USER:PASS@]HOST[:PORT]/MOUNT`; ValueError if malformed) or of `open_base` when given (the
    autopilot's GPS_RTCM_DATA), with the settings' engine options."""
    from onboard.hw.net_stream import open_base_stream
    from onboard.realtime.service import RtkFeature, RtkServiceOptions

    options = options or RtkServiceOptions(engine=rtk_engine_options(settings),
                                           max_base_age_s=settings.rtk_max_base_age_s,
                                           preflight_base_timeout_s=settings.rtk_preflight_base_timeout_s,
                                           takeoff_position_ecef_m=takeoff_position_ecef_m(settings),
                                           receiver_systems=rtk_receiver_systems(settings))
    return RtkFeature(options, open_base or open_base_stream(base_stream), deps.clock)


def rtk_receiver_systems(settings: Settings) -> dict[str, str]:
    """The real-time engine's constellations by the rover's raw message (`RtkServiceOptions.receiver_systems`):
    an RXM-RAWX receiver (M8T) those of `receiver.gnss`, an RXM-RAW one (LEA-6T) GPS; empty (the engine's
    `[rtk.engine] systems` for any receiver) when that key is set."""
    from onboard.receiver.profiles import RAW_MESSAGES, rtk_systems

    if "systems" in settings.rtk_engine:
        return {}
    gnss = receiver_options(settings).gnss
    return {raw: rtk_systems(raw, gnss) for raw in RAW_MESSAGES}


def autopilot_feature(settings: Settings, clock: Clock | None = None,
                      with_corrections: bool = False) -> AutopilotFeature:
    """The autopilot link of `autopilot.link` (ValueError if malformed); `with_corrections`: its reassembled
    GPS_RTCM_DATA go to a `CorrectionsPipe` (`feature.corrections`) for real-time RTK."""
    from onboard.autopilot.corrections import CorrectionsPipe
    from onboard.autopilot.feature import AutopilotFeature, AutopilotOptions
    from onboard.hw.mavlink_link import open_mavlink_link

    options = AutopilotOptions(system_id=settings.autopilot_system_id,
                               fast_interval_s=settings.autopilot_fast_interval_s,
                               slow_interval_s=settings.autopilot_slow_interval_s,
                               link_timeout_s=settings.autopilot_link_timeout_s,
                               rerequest_s=settings.autopilot_rerequest_s,
                               settle_s=settings.autopilot_settle_s)
    return AutopilotFeature(options, open_mavlink_link(settings.autopilot_link), clock, settings.autopilot_link,
                            CorrectionsPipe() if with_corrections else None)


def recorder_for(settings: Settings, deps: RecorderDeps, base_stream: str | None,
                 options: RtkServiceOptions | None = None,
                 features: Sequence[RecorderFeature] = ()) -> Recorder:
    """The composition root's one call: the recorder with `features` (e.g. the base station's), plus the
    autopilot link when `autopilot.link` is set, plus real-time RTK when a base stream is named (see
    `rtk_feature`; "mavlink": the autopilot link's GPS_RTCM_DATA)."""
    assembled = list(features)
    open_base: Callable[[], ByteStream] | None = None
    if settings.autopilot_link:
        autopilot = autopilot_feature(settings, deps.clock, with_corrections=base_stream == MAVLINK_BASE_STREAM)
        assembled.append(autopilot)
        if autopilot.corrections is not None:
            open_base = autopilot.corrections.open
    elif base_stream == MAVLINK_BASE_STREAM:
        raise ValueError('rtk.base_stream = "mavlink" needs autopilot.link')
    if base_stream:
        assembled.append(rtk_feature(settings, deps, base_stream, options, open_base))
    return Recorder(settings, deps, features=assembled)
