"""`python -m onboard rtk`: post-process rover + base observations into an RTKLIB-compatible .pos file.

Thin shell: reads the inputs (RINEX 2/3 obs/nav, gzip accepted; UBX logs; RTCM3 streams and journal folders
for the base), builds the engine's typed inputs, runs `onboard.rtk.postpro.postprocess` and writes
`onboard.formats.pos` atomically. Exit codes: 0 written, 1 cannot write, 2 unusable arguments or inputs,
3 refused by a data rule (no epoch with a solution, a base position the data contradicts).
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from onboard.cmdline import (
    EXIT_FAILURE,
    EXIT_OK,
    EXIT_REFUSED,
    EXIT_USAGE,
    CommandParser,
    add_command,
    coordinate_action,
    output_file,
    report_error,
)
from onboard.errors import DataRefused, InputError
from onboard.postpro.inputs import load_rtk_inputs
from onboard.rtk.options import AR_MODES, RtkOptions
from onboard.rtk.postpro import DIRECTIONS, postprocess
from onboard.rtk.types import Q_FIX, Q_FLOAT, Q_SINGLE
from onboard.validate import arg_type, ecef_position_m, elevation_mask_deg, gnss_systems

log = logging.getLogger(__name__)

COMMAND = "rtk"

DESCRIPTION = """\
Post-process a drone's GNSS observations against a base station's (L1 carrier-phase RTK; GPS unless
--systems names more constellations) and write one position per rover epoch to an RTKLIB-compatible .pos
file (ECEF X/Y/Z in metres by default, or latitude/longitude/height with --llh; GPS time). Q is 1 fixed, 2 float, 5 single; epochs without a
solution are not written.

Inputs: RINEX 2.11/3.0x observation files (.gz accepted) or UBX logs with RXM-RAW/RXM-RAWX (a flight's
journal converted with `onboard convert`, or the raw log); the base may also be an RTCM3 stream or a
journal folder such as the rover's radio/ journal. Ephemerides come from --nav and from the logs."""

EPILOG = """\
examples:
  python -m onboard rtk --rover rover.obs --base base.obs --nav rover.nav -o rover.pos
  python -m onboard rtk --rover rover.obs --base base.rtcm3 --nav rover.nav \\
      --base-pos=-3976219.1,3382371.6,3652511.1 --direction combined --llh -o rover.pos
  python -m onboard rtk --rover flight/rinex/rover.obs --base flight/radio --nav flight/rinex/rover.nav \\
      --init-pos "3774088.99 -601661.82 5089321.39" --static-start -o rover.pos

exit codes: 0 written, 1 cannot write the output, 2 bad arguments or unusable input files,
3 refused by the data (no epoch has a solution, or the base position contradicts the base's data)."""


def add_rtk_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:  # type: ignore[type-arg]
    """Register the `rtk` subcommand on an argparse subparsers object; returns its parser."""
    p = add_command(subparsers, COMMAND, summary="post-process rover + base observations (GPS L1 RTK) into a .pos "
                    "file", description=DESCRIPTION, epilog=EPILOG)
    p.add_argument("--rover", required=True, metavar="FILE",
                   help="rover observations: RINEX 2.11/3.0x obs (gzip ok) or UBX log")
    p.add_argument("--base", required=True, metavar="FILE_OR_DIR",
                   help="base observations: RINEX obs, UBX log, RTCM3 stream (gzip ok) or a journal folder")
    p.add_argument("--nav", action="append", default=[], metavar="FILE",
                   help="RINEX navigation file of the observations' day (repeatable; gzip ok)")
    xyz = coordinate_action(ecef_position_m)
    p.add_argument("--base-pos", nargs="+", action=xyz, metavar="X,Y,Z",
                   help="base antenna L1 phase centre, ECEF metres: X,Y,Z or \"X Y Z\" (default: the base "
                        "file's header or RTCM 1005/1006 position)")
    p.add_argument("--init-pos", nargs="+", action=xyz, metavar="X,Y,Z",
                   help="surveyed take-off antenna position, ECEF metres (same forms as --base-pos); implies "
                        "--static-start")
    p.add_argument("--systems", type=arg_type(gnss_systems), default="G", metavar="LETTERS",
                   help="constellations used, RINEX letters: G GPS, R GLONASS, E Galileo, C BeiDou, J QZSS (default "
                        "G; e.g. GR for an M8P, GREJ for an M8T); read from the observation and navigation files")
    p.add_argument("--ar-mode", choices=[m for m in AR_MODES if m != "off"], default="fix-and-hold",
                   help="integer ambiguity resolution: continuous, instantaneous or fix-and-hold (default)")
    p.add_argument("--elmask", type=_elmask_deg, default=15.0, metavar="DEG",
                   help="elevation mask, degrees above the horizon, 0 to below 90 (default 15)")
    p.add_argument("--direction", choices=DIRECTIONS, default="forward",
                   help="filter in time order (forward, default), reverse (backward) or both combined")
    p.add_argument("--velocity", action="store_true", help="append RTKLIB's velocity columns (m/s)")
    p.add_argument("--llh", action="store_true", help="write latitude/longitude (deg)/height (m) instead of ECEF")
    p.add_argument("--calendar", action="store_true", help="time as yyyy/mm/dd hh:mm:ss GPST instead of week tow")
    p.add_argument("--static-start", action="store_true", help="rover static on the ground until take-off")
    p.add_argument("--no-progress", action="store_true", help="no progress bar even on a terminal")
    p.add_argument("-o", "--output", required=True, type=output_file, metavar="FILE.pos",
                   help="output .pos file (replaced only once complete)")
    p.set_defaults(func=rtk_main)
    return p


def _elmask_deg(text: str) -> float:
    """argparse type of --elmask: `onboard.validate.elevation_mask_deg`, and below 90° (the engine's rule: a mask
    at the zenith leaves no satellite)."""
    value = arg_type(elevation_mask_deg)(text)
    if value >= 90.0:
        raise argparse.ArgumentTypeError(f"{text}: must be below 90° (a mask at the zenith leaves no satellite)")
    return value


def rtk_main(args: argparse.Namespace) -> int:
    """Run the command; returns the process exit code (see the module docstring). Prints a summary."""
    inputs = [Path(args.rover), Path(args.base), *(Path(n) for n in args.nav)]
    out = Path(args.output)
    if any(out.exists() and p.exists() and out.resolve() == p.resolve() for p in inputs):
        return report_error(COMMAND, f"-o {out}: is one of the inputs (it would be overwritten)", EXIT_USAGE)
    try:
        return _run(args)
    except InputError as exc:
        return report_error(COMMAND, str(exc), EXIT_USAGE)
    except DataRefused as exc:
        return report_error(COMMAND, str(exc), EXIT_REFUSED)
    except OSError as exc:
        kept = "the previous file is unchanged" if out.exists() else "nothing written"
        return report_error(COMMAND, f"cannot write {out}: {exc.strerror or exc} ({kept})", EXIT_FAILURE)


def _run(args: argparse.Namespace) -> int:
    run = load_rtk_inputs(args.rover, args.base, args.nav, args.base_pos, systems=args.systems)
    rov_gps, bas_gps, nav, base_pos = run.rover, run.base, run.nav, run.base_pos_ecef_m
    try:
        options = replace(RtkOptions(), systems=args.systems, elmask_deg=args.elmask,
                          ar_elmask_deg=max(args.elmask, 15.0), ar_mode=args.ar_mode, static_start=args.static_start or args.init_pos is not None)
    except ValueError as exc:  # an option the engine's own checks refuse
        raise InputError(f"options refused by the engine: {exc}") from None
    init_pos = np.array(args.init_pos) if args.init_pos is not None else None
    passes = 2 if args.direction == "combined" else 1
    bar = None
    progress = None
    if not args.no_progress and sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(total=len(rov_gps) * passes, unit="epoch", desc="rtk")
        progress = bar.update
    try:
        sols, stats = postprocess(rov_gps, bas_gps, nav, base_pos, options, args.direction, init_pos, progress)
    except ValueError as exc:  # the engine's data rules (e.g. a base position its own data contradicts)
        raise DataRefused(str(exc)) from exc
    finally:
        if bar is not None:
            bar.close()
    from onboard.formats.pos import is_position, write_pos

    solved = [s for s in sols if is_position(s)]
    if not solved:
        raise DataRefused(f"no epoch has a solution ({len(sols)} rover epochs): check that the base position "
                      f"and the navigation files belong to these observations; nothing written")
    bx, by, bz = base_pos
    info = [
        f"program   : directgeo onboard rtk (L1, systems {args.systems})",
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
    write_pos(args.output, solved, info, llh=args.llh, velocity=args.velocity, calendar=args.calendar)
    q = np.array([s.q for s in solved])
    n = max(len(sols), 1)
    unsolved = len(sols) - len(solved)
    if unsolved:
        print(f"{unsolved} of {len(sols)} epochs have no solution: not written", file=sys.stderr)
    print(f"{len(sols)} epochs: fix {np.sum(q == Q_FIX)} ({100 * np.sum(q == Q_FIX) / n:.1f} %), "
          f"float {np.sum(q == Q_FLOAT)}, single {np.sum(q == Q_SINGLE)}; slips {sum(s.slips for s in stats)}; "
          f"written {args.output}")
    if args.direction == "combined" and any(s.disputed for s in stats):
        print(f"fixes the two passes dispute, written as float: {stats[0].disputed} forward, {stats[1].disputed} "
              "backward (one pass's integers contradicted by the other's fixes, held under "
              f"{options.handover_min_run_s:g} s, or next to an epoch where the passes disagree)", file=sys.stderr)
    return EXIT_OK


def main(argv: Sequence[str] | None = None) -> int:
    """Stand-alone entry (`python -m onboard.postpro.rtk_cli rtk ...`), same arguments as `onboard rtk`."""
    parser = CommandParser(prog="onboard", command="onboard")
    sub = parser.add_subparsers(dest="command", required=True)
    add_rtk_parser(sub)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    logging.basicConfig(level=logging.WARNING)
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())
