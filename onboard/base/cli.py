"""`python -m onboard base`: command-line shell of base-station mode (see `onboard.base.station`).

Kept apart from `onboard.base.station` so that registering the command imports nothing heavy.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import TYPE_CHECKING

from onboard.cmdline import EXIT_USAGE, report_error
from onboard.recorder.settings import BASE_OBSERVATIONS as OBS_MESSAGES
from onboard.recorder.settings import add_recorder_arguments
from onboard.validate import arg_type, ecef_position_m, integer, number, positive

RECEIVER_DESCRIPTORS = {"m8t": "u-blox LEA-M8T", "lea6t": "u-blox LEA-6T", "auto": "u-blox"}
"""receiver.model → the 1033 receiver type sent by default."""

if TYPE_CHECKING:
    from onboard.base.station import BaseOptions
    from onboard.hw.ports import ByteStream
    from onboard.recorder.daemon import Recorder, RecorderDeps
    from onboard.recorder.settings import Settings


def add_base_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:  # type: ignore[type-arg]
    """Register `base` (base-station mode)."""
    p = subparsers.add_parser("base", help="base station: record the base receiver and send RTCM3 by radio",
                              description="Record the base receiver's raw journal and send RTCM3 over the "
                                          "telemetry radio within a byte budget: MSM4/5/7 of every constellation, "
                                          "1006, 1033, 1230 and the ephemerides 1019/1020/1042/1044/1046 (or the "
                                          "GPS-only 1004/1002 + 1006 + 1019, or a raw UBX relay); see "
                                          "docs/base-rtcm.md.")
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
    # the defaults of these are the [base] section's (onboard/recorder/default_config.toml)
    p.add_argument("--message", choices=OBS_MESSAGES, default=None,
                   help="observations (base.observations): msm4 (default), msm5 or msm7 of every constellation, "
                        "or GPS-only 1004 (L1+L2 fields) / 1002 (L1)")
    p.add_argument("--budget", type=arg_type(positive, unit=" B/s"), default=None,
                   help="radio byte budget, B/s (base.budget_bytes_s; default 1000: ~20 %% of a 57600-baud SiK)")
    p.add_argument("--obs-interval", type=arg_type(positive, unit=" s", maximum=3600.0), default=None,
                   help="send observations every S s (base.obs_interval_s; default 1)")
    p.add_argument("--position-interval", type=arg_type(positive, unit=" s", maximum=3600.0), default=None,
                   help="send 1006 (and 1033) every S s (base.position_interval_s; default 10)")
    p.add_argument("--ephemeris-interval", type=arg_type(positive, unit=" s", maximum=3600.0), default=None,
                   help="send each observed satellite's ephemeris again every S s (base.ephemeris_interval_s; "
                        "default 30; a new one at once)")
    p.add_argument("--glonass-bias-interval", type=arg_type(positive, unit=" s", maximum=3600.0), default=None,
                   help="send 1230 every S s (base.glonass_bias_interval_s; default 10)")
    p.add_argument("--receiver-descriptor", default=None, metavar="TEXT",
                   help="receiver type sent in 1033 (base.receiver_descriptor; default auto: from "
                        "receiver.model; \"\" sends no 1033)")
    p.add_argument("--relay", choices=("rtcm", "ubx"), default="rtcm", help="RTCM3 (default) or raw UBX relay")
    add_recorder_arguments(p)
    p.set_defaults(func=base_main)
    return p


def base_main(args: argparse.Namespace) -> int:
    """Run the base station; returns the exit code. With `rtk.base_stream` set, the base also solves its own
    real-time RTK against that second base (both snapshots, base.json and rtk.json, are written)."""
    from onboard.errors import ConfigFileError
    from onboard.hw.serial_port import SerialByteStream
    from onboard.recorder.app import run, serial_port_opener
    from onboard.recorder.daemon import RecorderDeps
    from onboard.recorder.sdnotify import SdNotifier
    from onboard.recorder.settings import load_settings, recorder_overrides

    try:
        settings = load_settings(args.config, overrides={**recorder_overrides(args), **base_overrides(args)})
        options = base_options(settings, args)
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


def base_overrides(args: argparse.Namespace) -> dict[str, object]:
    """The `[base]` settings the command line overrides (None = not given)."""
    return {"base.observations": args.message, "base.budget_bytes_s": args.budget,
            "base.obs_interval_s": args.obs_interval, "base.position_interval_s": args.position_interval,
            "base.ephemeris_interval_s": args.ephemeris_interval,
            "base.glonass_bias_interval_s": args.glonass_bias_interval,
            "base.receiver_descriptor": args.receiver_descriptor}


def base_options(settings: Settings, args: argparse.Namespace) -> BaseOptions:
    """BaseOptions from the `[base]` settings and the position, station and relay flags (ValueError if bad)."""
    from onboard.base.station import BaseOptions

    descriptor = settings.base_receiver_descriptor
    if descriptor == "auto":
        descriptor = RECEIVER_DESCRIPTORS.get(settings.receiver_model, "u-blox")
    return BaseOptions(station_id=args.station_id, obs_message=settings.base_observations,
                       radio_budget_bytes_s=settings.base_budget_bytes_s, relay=args.relay,
                       obs_interval_s=settings.base_obs_interval_s, position_ecef_m=args.position,
                       antenna_height_m=args.antenna_height, survey_in_s=args.survey_in or 0.0,
                       position_interval_s=settings.base_position_interval_s,
                       ephemeris_interval_s=settings.base_ephemeris_interval_s,
                       glonass_bias_interval_s=settings.base_glonass_bias_interval_s,
                       receiver_descriptor=descriptor)


def base_recorder(settings: Settings, deps: RecorderDeps, options: BaseOptions,
                  open_radio: Callable[[], ByteStream]) -> Recorder:
    """Base-station mode's composition: the recorder with the base-station feature, and real-time RTK too when
    `rtk.base_stream` names a second base (ValueError if malformed)."""
    from onboard.base.station import BaseStationFeature
    from onboard.recorder.app import recorder_for

    return recorder_for(settings, deps, settings.rtk_base_stream or None,
                        features=[BaseStationFeature(options, open_radio)])
