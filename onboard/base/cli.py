"""`python -m onboard base`: command-line shell of base-station mode (see `onboard.base.station`).

Kept apart from `onboard.base.station` so that registering the command imports nothing heavy.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import TYPE_CHECKING

from onboard.cmdline import EXIT_USAGE, report_error
from onboard.recorder.settings import add_recorder_arguments
from onboard.validate import arg_type, ecef_position_m, integer, number, positive

if TYPE_CHECKING:
    from onboard.base.station import BaseOptions
    from onboard.hw.ports import ByteStream
    from onboard.recorder.daemon import Recorder, RecorderDeps
    from onboard.recorder.settings import Settings


def add_base_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:  # type: ignore[type-arg]
    """Register `base` (base-station mode)."""
    p = subparsers.add_parser("base", help="base station: record the base receiver and send RTCM3 by radio",
                              description="Record the base receiver's raw journal and send RTCM3 1004/1002, "
                                          "1006 and 1019 (or a raw UBX relay) over the telemetry radio within "
                                          "a byte budget.")
    p.add_argument("--port", required=True, help="base receiver serial device")
    p.add_argument("--radio", required=True, help="telemetry radio serial device")
    p.add_argument("--radio-baud", type=arg_type(integer, minimum=1200, maximum=4_000_000), default=57600,
                   help="telemetry radio line rate, baud (default 57600)")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--position", type=arg_type(ecef_position_m), metavar="X,Y,Z",
                       help='surveyed base antenna position, ECEF metres: X,Y,Z or "X Y Z"')
    where.add_argument("--survey-in", type=arg_type(positive, unit=" s", maximum=86400.0), metavar="SECONDS",
                       help="position = mean of single-point fixes over SECONDS s")
    p.add_argument("--antenna-height", type=arg_type(number, unit=" m", minimum=0.0, maximum=100.0), default=0.0,
                   help="ARP to phase centre, m (sent in 1006)")
    p.add_argument("--station-id", type=arg_type(integer, minimum=0, maximum=4095), default=0,
                   help="RTCM reference station id, 0–4095 (default 0)")
    p.add_argument("--message", type=int, choices=(1002, 1004), default=1004,
                   help="RTCM3 GPS observation message: 1004 (L1+L2, default) or 1002 (L1)")
    p.add_argument("--budget", type=arg_type(positive, unit=" B/s"), default=600.0,
                   help="radio byte budget, B/s (default 600)")
    p.add_argument("--obs-interval", type=arg_type(positive, unit=" s", maximum=3600.0), default=1.0,
                   help="send observations every S s (default 1)")
    p.add_argument("--relay", choices=("rtcm", "ubx"), default="rtcm", help="RTCM3 (default) or raw UBX relay")
    add_recorder_arguments(p)
    p.set_defaults(func=base_main)
    return p


def base_main(args: argparse.Namespace) -> int:
    """Run the base station; returns the exit code. With `rtk.base_stream` set, the base also solves its own
    real-time RTK against that second base (both snapshots, base.json and rtk.json, are written)."""
    from onboard.base.station import BaseOptions
    from onboard.errors import ConfigFileError
    from onboard.hw.serial_port import SerialByteStream
    from onboard.recorder.app import run, serial_port_opener
    from onboard.recorder.daemon import RecorderDeps
    from onboard.recorder.sdnotify import SdNotifier
    from onboard.recorder.settings import load_settings, recorder_overrides

    try:
        settings = load_settings(args.config, overrides=recorder_overrides(args))
        options = BaseOptions(station_id=args.station_id, obs_message=args.message,
                              radio_budget_bytes_s=args.budget, relay=args.relay,
                              obs_interval_s=args.obs_interval, position_ecef_m=args.position,
                              antenna_height_m=args.antenna_height, survey_in_s=args.survey_in or 0.0)
    except (ConfigFileError, ValueError) as exc:
        return report_error("base", str(exc), EXIT_USAGE)
    deps = RecorderDeps(open_port=serial_port_opener(settings), notifier=SdNotifier())

    def open_radio() -> ByteStream:
        return SerialByteStream(args.radio, args.radio_baud, 0.1)

    try:
        recorder = base_recorder(settings, deps, options, open_radio)
    except ValueError as exc:  # a malformed rtk.base_stream
        return report_error("base", str(exc), EXIT_USAGE)
    return run(recorder, "base")


def base_recorder(settings: Settings, deps: RecorderDeps, options: BaseOptions,
                  open_radio: Callable[[], ByteStream]) -> Recorder:
    """Base-station mode's composition: the recorder with the base-station feature, and real-time RTK too when
    `rtk.base_stream` names a second base (ValueError if malformed)."""
    from onboard.base.station import BaseStationFeature
    from onboard.recorder.app import recorder_for

    return recorder_for(settings, deps, settings.rtk_base_stream or None,
                        features=[BaseStationFeature(options, open_radio)])
