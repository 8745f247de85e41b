"""`python -m onboard rtk`: post-process rover + base observations into an RTKLIB-compatible .pos file.

Thin shell: reads the inputs (RINEX 2/3 obs/nav, gzip accepted; UBX logs), builds the engine's typed inputs,
runs `onboard.rtk.postpro.postprocess` and writes `onboard.formats.pos`. Register with
`add_rtk_parser(subparsers)`; the parsed namespace goes to `rtk_main(args)`.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from onboard.errors import InputError
from onboard.postpro.inputs import is_rinex, read_base_observations, read_navigation, read_observations
from onboard.rtk.geodesy import parse_xyz_m
from onboard.rtk.options import AR_MODES, RtkOptions
from onboard.rtk.postpro import DIRECTIONS, postprocess
from onboard.rtk.types import Q_FIX, Q_FLOAT, Q_SINGLE

log = logging.getLogger(__name__)


def _xyz(text: str) -> np.ndarray:
    try:
        return np.array(parse_xyz_m(text))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_rtk_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the `rtk` subcommand on an argparse subparsers object; returns its parser."""
    p = subparsers.add_parser("rtk", help="post-process rover + base observations (GPS L1 RTK) into a .pos file",
                              description=__doc__)
    p.add_argument("--rover", required=True, help="rover observations: RINEX 2.11/3.0x obs (gzip ok) or UBX log")
    p.add_argument("--base", required=True,
                   help="base observations: RINEX obs, UBX log, RTCM3 stream (gzip ok) or a journal folder")
    p.add_argument("--nav", action="append", default=[], help="RINEX navigation file (repeatable)")
    p.add_argument("--base-pos", nargs="+", metavar="X,Y,Z",
                   help="base antenna L1 phase centre, ECEF m: X,Y,Z or X Y Z (use --base-pos=X,Y,Z when X < 0)")
    p.add_argument("--init-pos", nargs="+", metavar="X,Y,Z",
                   help="surveyed take-off antenna position, ECEF m (same forms as --base-pos)")
    p.add_argument("--ar-mode", choices=[m for m in AR_MODES if m != "off"], default="fix-and-hold")
    p.add_argument("--elmask", type=float, default=15.0, help="elevation mask (deg, default 15)")
    p.add_argument("--direction", choices=DIRECTIONS, default="forward")
    p.add_argument("--velocity", action="store_true", help="append RTKLIB's velocity columns")
    p.add_argument("--llh", action="store_true", help="write latitude/longitude/height instead of ECEF")
    p.add_argument("--calendar", action="store_true", help="time as yyyy/mm/dd hh:mm:ss GPST instead of week tow")
    p.add_argument("--static-start", action="store_true", help="rover static on the ground until take-off")
    p.add_argument("--no-progress", action="store_true", help="no progress bar even on a terminal")
    p.add_argument("-o", "--output", required=True, help="output .pos file")
    p.set_defaults(func=rtk_main)
    return p


def rtk_main(args: argparse.Namespace) -> int:
    """Run the command; returns the process exit code (0 ok, 2 unusable input). Prints a summary."""
    try:
        for name in ("base_pos", "init_pos"):
            value = getattr(args, name, None)
            if isinstance(value, list):
                setattr(args, name, _xyz(",".join(value).replace(",,", ",")))
    except argparse.ArgumentTypeError as exc:
        print(f"onboard rtk: error: {exc}", file=sys.stderr)
        return 2
    try:
        return _run(args)
    except InputError as exc:
        print(f"onboard rtk: error: {exc}", file=sys.stderr)
        return 2


def _run(args: argparse.Namespace) -> int:
    rover = read_observations(args.rover)
    base_path = Path(args.base)
    if base_path.is_file() and is_rinex(base_path):
        base = read_observations(base_path)  # without loading the RTCM3 decoders (start-up time)
    else:
        # the base may also be an RTCM3 stream or a journal folder (e.g. the rover's radio/ journal)
        base = read_base_observations(args.base, rover.epochs[0].time if rover.epochs else None)
    nav = read_navigation(args.nav, rover.ephemerides + base.ephemerides)
    if len(nav.store) == 0:
        raise InputError("no GPS ephemeris: give --nav FILE (RINEX navigation) or logs with RXM-SFRB(X)/AID-EPH")
    base_pos = args.base_pos if args.base_pos is not None else base.antenna_pos_ecef_m
    if base_pos is None:
        raise InputError(f"no base position: {args.base} has none in its header; give --base-pos X,Y,Z")
    rov_gps = [e for e in rover.epochs if len(e.gps_only())]
    bas_gps = [e for e in base.epochs if len(e.gps_only())]
    if not rov_gps:
        raise InputError(f"{args.rover}: no GPS observations")
    if not bas_gps:
        raise InputError(f"{args.base}: no GPS observations")
    t0 = max(rov_gps[0].time, bas_gps[0].time)
    t1 = min(rov_gps[-1].time, bas_gps[-1].time)
    if t1.diff_s(t0) < -30.0:
        raise InputError(f"rover ({rov_gps[0].time}..{rov_gps[-1].time}) and base ({bas_gps[0].time}.."
                         f"{bas_gps[-1].time}) have no common epochs")
    options = replace(RtkOptions(), elmask_deg=args.elmask, ar_elmask_deg=max(args.elmask, 15.0),
                      ar_mode=args.ar_mode, static_start=args.static_start or args.init_pos is not None)
    passes = 2 if args.direction == "combined" else 1
    bar = None
    progress = None
    if not args.no_progress and sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(total=len(rov_gps) * passes, unit="epoch", desc="rtk")
        progress = bar.update
    try:
        sols, stats = postprocess(rov_gps, bas_gps, nav, base_pos, options, args.direction, args.init_pos,
                                  progress)
    finally:
        if bar is not None:
            bar.close()
    from onboard.formats.pos import write_pos

    bx, by, bz = base_pos
    info = [
        "program   : directgeo onboard rtk (GPS L1)",
        f"inp file  : {args.rover}",
        f"inp file  : {args.base}",
        *(f"inp file  : {n}" for n in args.nav),
        "pos mode  : kinematic",
        f"solution  : {args.direction}",
        f"elev mask : {args.elmask:.1f} deg",
        f"amb res   : {args.ar_mode}",
        f"ref pos   : {bx:14.4f} {by:14.4f} {bz:14.4f}",
        "",
        "(x/y/z-ecef=WGS84,Q=1:fix,2:float,5:single,sdx/sdy/sdz=std(m))",
        "",
    ]
    write_pos(args.output, sols, info, llh=args.llh, velocity=args.velocity, calendar=args.calendar)
    q = np.array([s.q for s in sols])
    n = max(len(sols), 1)
    print(f"{len(sols)} epochs: fix {np.sum(q == Q_FIX)} ({100 * np.sum(q == Q_FIX) / n:.1f} %), "
          f"float {np.sum(q == Q_FLOAT)}, single {np.sum(q == Q_SINGLE)}; slips {sum(s.slips for s in stats)}; "
          f"written {args.output}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Stand-alone entry (`python -m onboard.postpro.rtk_cli ...`), same arguments as `onboard rtk`."""
    parser = argparse.ArgumentParser(prog="onboard")
    sub = parser.add_subparsers(dest="command", required=True)
    add_rtk_parser(sub)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())
