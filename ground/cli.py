"""`python -m ground adjust|calibrate|serve`: the thin shell around the importers, the adjustment core and the API.

`adjust` semantics for lever arm and delay: a value alone is fixed, a value with σ is a prior, `--estimate
lever-arm,delay` without a value leaves the parameter free. Outputs in OUTDIR: `results.json` (the core's
`to_dict()` plus inputs/matching/exports), the geotag exports and `report.html`.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ground.adjust.model import AdjustmentOptions, AdjustmentRefused, DelaySpec, LeverArmSpec
from ground.adjust.types import ImageEvent
from ground.io import crs as crsmod
from ground.io.errors import FormatError
from onboard.errors import ConfigFileError, InputError

log = logging.getLogger(__name__)

ESTIMABLE = ("lever-arm", "delay")


@dataclass(frozen=True)
class AdjustRequest:
    """Inputs of one adjustment run (paths and the parameter choices of the command line)."""

    trajectory: Path
    events: Path
    orientations: Path
    gcp: Path | None = None
    gcp_rel: Path | None = None
    gcp_crs: str = crsmod.WGS84_ECEF
    capture_times: Path | None = None
    images_dir: Path | None = None
    lever_arm_m: tuple[float, float, float] | None = None
    lever_arm_sigma_m: float | None = None
    delay_s: float | None = None
    delay_sigma_s: float | None = None
    estimate: tuple[str, ...] = ()
    crs: str = "EPSG:4979"
    relative_control: bool = False
    events_kind: str = "trigger"
    datum_tolerance_m: float = crsmod.MAX_DATUM_ERROR_M
    extra: dict[str, Any] = field(default_factory=dict)


def parameter_specs(req: AdjustRequest) -> tuple[LeverArmSpec, DelaySpec]:
    """Lever-arm and delay specs from the command-line rules (value → fixed, value + σ → prior, estimate → free)."""
    for e in req.estimate:
        if e not in ESTIMABLE:
            raise InputError(f"--estimate takes {','.join(ESTIMABLE)}, got {e!r}")
    if req.lever_arm_m is None:
        if req.lever_arm_sigma_m is not None:
            raise InputError("--lever-arm-sigma needs --lever-arm")
        lever = LeverArmSpec(mode="free")
        if "lever-arm" not in req.estimate:
            log.info("no --lever-arm given: the lever arm is estimated freely")
    elif req.lever_arm_sigma_m is not None:
        if req.lever_arm_sigma_m <= 0:
            raise InputError("--lever-arm-sigma must be positive")
        lever = LeverArmSpec(mode="prior", value_m=req.lever_arm_m, sigma_m=(req.lever_arm_sigma_m,) * 3)
    elif "lever-arm" in req.estimate:
        raise InputError("--estimate lever-arm with a --lever-arm value needs --lever-arm-sigma (a prior) "
                         "or drop the value to leave it free")
    else:
        lever = LeverArmSpec(mode="fixed", value_m=req.lever_arm_m)
    if req.delay_s is None:
        if req.delay_sigma_s is not None:
            raise InputError("--delay-sigma needs --delay")
        delay = DelaySpec(mode="free")
    elif req.delay_sigma_s is not None:
        if req.delay_sigma_s <= 0:
            raise InputError("--delay-sigma must be positive")
        delay = DelaySpec(mode="prior", value_s=req.delay_s, sigma_s=req.delay_sigma_s)
    elif "delay" in req.estimate:
        raise InputError("--estimate delay with a --delay value needs --delay-sigma (a prior) or drop the value")
    else:
        delay = DelaySpec(mode="fixed", value_s=req.delay_s)
    return lever, delay


def _read_events(req: AdjustRequest, images: list[str]) -> tuple[list[ImageEvent], dict[str, Any]]:
    from ground.io.events import (
        exif_capture_time,
        match_marks_to_images,
        read_capture_times,
        read_events_csv,
        read_marks_jsonl,
    )

    if req.events.suffix.lower() == ".jsonl":
        marks = read_marks_jsonl(req.events)
        caps = read_capture_times(req.capture_times) if req.capture_times else None
        if caps is None and req.images_dir is not None:
            found = {n: exif_capture_time(req.images_dir / n) for n in images}
            caps = {n: t for n, t in found.items() if t is not None}
            log.info("EXIF capture times read for %d of %d images in %s", len(caps), len(images), req.images_dir)
        try:
            rep = match_marks_to_images(marks, images, caps)
        except ValueError as exc:
            raise InputError(str(exc)) from exc
        return rep.events, rep.to_dict()
    events = read_events_csv(req.events, default_kind=req.events_kind)
    return events, {"method": "csv image names", "matched": len(events)}


def run_adjust(req: AdjustRequest, out_dir: Path) -> dict[str, Any]:
    """Read everything, adjust, write results.json, the exports and report.html into `out_dir`.

    Raises `InputError` (bad files/arguments), `AdjustmentRefused` (not solvable as posed) or `CrsError`.
    """
    from ground.adjust.solve import adjust, build_problem
    from ground.io.exporters import cameras_to_crs, write_all
    from ground.io.gcp import (
        merge_ground_and_relative,
        read_gcp_csv,
        read_micmac_gcp,
        read_odm_gcp_list,
        read_relative_csv,
        to_control_points,
    )
    from ground.io.orientations import read_orientations
    from ground.io.trajectory import read_trajectory
    from ground.report import write_report

    lever, delay = parameter_specs(req)
    crsmod.parse_crs(req.crs)  # fail before the work on an unknown CRS
    traj = read_trajectory(str(req.trajectory))
    oset = read_orientations(req.orientations)
    events, matching = _read_events(req, [p.image for p in oset.poses])
    origin = np.asarray(traj.pos_ecef_m[0], dtype=float)
    tol = req.datum_tolerance_m
    crsmod.ecef_to_crs(origin, req.crs, max_datum_error_m=tol)  # missing geoid grid / datum mix: fail now
    control = []
    if req.gcp is not None:
        suffix = req.gcp.suffix.lower()
        if suffix == ".csv":
            pts = read_gcp_csv(req.gcp, crs=req.gcp_crs)
        else:
            ground = read_micmac_gcp(req.gcp, req.gcp_crs) if suffix == ".xml" else read_odm_gcp_list(req.gcp)
            if req.gcp_rel is None:
                raise InputError(f"{req.gcp} has ground coordinates only: give --gcp-rel name,x_rel,y_rel,z_rel")
            pts = merge_ground_and_relative(ground, read_relative_csv(req.gcp_rel))
        control = to_control_points(pts, origin, max_datum_error_m=tol)
    problem = build_problem(oset.poses, events, traj, control, origin_ecef_m=origin)
    options = AdjustmentOptions(lever_arm=lever, delay=delay, relative_control=req.relative_control)
    result = adjust(problem, options)

    out_dir.mkdir(parents=True, exist_ok=True)
    centres_enu = result.corrected_positions_enu_m(problem.centre_rel)
    r_enu = np.einsum("ij,njk->nik", result.rotation, problem.r_cam_to_rel)
    sigma = np.sqrt(problem.antenna_sigma_enu_m**2 + options.camera_centre_sigma_m**2)
    cams = cameras_to_crs(problem.images, centres_enu, r_enu, origin, req.crs, sigma, max_datum_error_m=tol)
    exports = write_all(out_dir / "exports", cams, centres_enu, r_enu)
    results = result.to_dict()
    results["inputs"] = {
        "trajectory": str(req.trajectory), "events": str(req.events), "orientations": str(req.orientations),
        "orientation_format": oset.format, "gcp": str(req.gcp) if req.gcp else None, "gcp_crs": req.gcp_crs,
        "lever_arm": {"mode": lever.mode, "value_m": list(lever.value_m), "sigma_m": list(lever.sigma_m)},
        "delay": {"mode": delay.mode, "value_s": delay.value_s, "sigma_s": delay.sigma_s},
        "origin_ecef_m": [float(v) for v in origin], "export_crs": req.crs,
    }
    results["matching"] = matching
    results["skipped"] = [{"image": n, "reason": r} for n, r in problem.skipped]
    results["exports"] = {k: f"exports/{v}" if k != "micmac_frame" else v for k, v in exports.items()}
    results["cameras"] = [
        {"image": n, "x": float(p[0]), "y": float(p[1]), "z": float(p[2])} for n, p in zip(cams.images, cams.xyz)
    ]
    (out_dir / "results.json").write_text(json.dumps(results, indent=2), encoding="utf-8")
    write_report(out_dir / "report.html", results, problem=problem, trajectory=traj, origin_ecef_m=origin)
    return results


# ------------------------------------------------------------------------------------------------ API jobs


def _pick(files: dict[str, str | None], params: dict[str, Any], role: str) -> str | None:
    name = params.get(role)
    if name is not None:
        if name not in files:
            raise InputError(f"{role} file {name!r} is not a completely uploaded file of this flight")
        return str(name)
    named = sorted(n for n, r in files.items() if r == role)
    if len(named) > 1:
        raise InputError(f"several files have role {role!r} ({', '.join(named)}): name one in the job params")
    return named[0] if named else None


def adjust_job(settings: Any, params: dict[str, Any], files: dict[str, str | None], flight_dir: Path,
               out_dir: Path) -> str:
    """API job: the adjustment on a flight's uploaded files (params as `python -m ground adjust` options)."""
    chosen = {role: _pick(files, params, role) for role in ("trajectory", "events", "orientations", "gcp")}
    trajectory = flight_dir / str(chosen["trajectory"]) if chosen["trajectory"] else _reprocessed(out_dir)
    missing = [r for r in ("events", "orientations") if chosen[r] is None] + ([] if trajectory else ["trajectory"])
    if missing:
        raise InputError(f"missing uploaded {', '.join(missing)} (set roles in the manifest or name the files)")
    assert trajectory is not None
    lever = params.get("lever_arm")
    req = AdjustRequest(
        trajectory=trajectory,
        events=flight_dir / str(chosen["events"]),
        orientations=flight_dir / str(chosen["orientations"]),
        gcp=flight_dir / str(chosen["gcp"]) if chosen["gcp"] else None,
        gcp_crs=str(params.get("gcp_crs", crsmod.WGS84_ECEF)),
        lever_arm_m=tuple(float(v) for v in lever) if lever is not None else None,  # type: ignore[arg-type]
        lever_arm_sigma_m=_opt_float(params.get("lever_arm_sigma")),
        delay_s=_opt_float(params.get("delay")),
        delay_sigma_s=_opt_float(params.get("delay_sigma")),
        estimate=tuple(params.get("estimate", ())),
        crs=str(params.get("crs", "EPSG:4979")),
        datum_tolerance_m=float(params.get("datum_tolerance_m", crsmod.MAX_DATUM_ERROR_M)),
    )
    res = run_adjust(req, out_dir)
    lever_txt = ", ".join(_num(v, 1, ".4f") for v in res["lever_arm_m"])
    return (f"adjusted {res['n_images']} images: lever arm ({lever_txt}) m, "
            f"delay {_num(res['delay_s'], 1e3, '.1f')} ms, sigma0 {_num(res['sigma0'], 1, '.2f')}")


def _reprocessed(out_dir: Path) -> Path | None:
    """The newest `SOL.pos` written by an RTK job of the same flight (sibling job folders), if any."""
    sols = sorted(out_dir.parent.glob("*/SOL.pos"), key=lambda p: p.stat().st_mtime)
    return sols[-1] if sols else None


def _num(value: float | None, scale: float = 1.0, fmt: str = ".3f") -> str:
    """A result number for printing; None (σ of an undeterminable parameter in to_dict) prints as such."""
    return "undetermined" if value is None else format(value * scale, fmt)


def _opt_float(v: Any) -> float | None:
    return None if v is None else float(v)


def rtk_job(settings: Any, params: dict[str, Any], files: dict[str, str | None], flight_dir: Path,
            out_dir: Path) -> str:
    """API job: RTK re-processing of the uploaded rover/base observations with the onboard `rtk` command.

    Needs files with roles `rover_obs` and `base_obs` (RINEX obs or UBX logs) and optionally `nav` (RINEX nav);
    `params` may give `base_pos` "X,Y,Z" and `direction`. Writes `SOL.pos` (with velocities) in the job folder.
    """
    import contextlib
    import io

    from onboard.postpro.rtk_cli import add_rtk_parser, rtk_main

    chosen = {role: _pick(files, params, role) for role in ("rover_obs", "base_obs", "nav")}
    missing = [r for r in ("rover_obs", "base_obs") if chosen[r] is None]
    if missing:
        raise InputError(f"RTK re-processing needs uploaded {', '.join(missing)} (no base data: nothing to do)")
    argv = ["rtk", "--rover", str(flight_dir / str(chosen["rover_obs"])),
            "--base", str(flight_dir / str(chosen["base_obs"])), "--velocity", "--no-progress",
            "--direction", str(params.get("direction", "forward")), "-o", str(out_dir / "SOL.pos")]
    if chosen["nav"]:
        argv += ["--nav", str(flight_dir / str(chosen["nav"]))]
    if params.get("base_pos"):
        argv += [f"--base-pos={params['base_pos']}"]
    parser = argparse.ArgumentParser(prog="rtk-job")
    add_rtk_parser(parser.add_subparsers(dest="command", required=True))
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = rtk_main(parser.parse_args(argv))
    if rc != 0:
        raise InputError(err.getvalue().strip() or f"rtk exited with {rc}")
    return out.getvalue().strip()


# ------------------------------------------------------------------------------------------------ CLI


def _triple(text: str) -> tuple[float, float, float]:
    parts = [float(v) for v in text.split(",")]
    if len(parts) != 3:
        raise argparse.ArgumentTypeError("expected X,Y,Z")
    return parts[0], parts[1], parts[2]


def build_parser() -> argparse.ArgumentParser:
    """The `python -m ground` argument parser."""
    p = argparse.ArgumentParser(prog="python -m ground", description="directgeo ground app")
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = p.add_subparsers(dest="command", required=True)
    a = sub.add_parser(
        "adjust", help="final adjustment: similarity + lever arm + shutter delay",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Camera positions in your CRS from the RTK trajectory, the camera events and the bundle "
                    "adjustment's\norientations: estimates the similarity (relative frame → local ENU), the lever "
                    "arm and the\nshutter delay; GCPs enter the adjustment, check points never do.",
        epilog="lever arm and delay: a value alone is fixed; a value with its σ is a prior (estimated, pulled to "
               "the value);\n--estimate without a value leaves it free; with neither, both are free (a free lever "
               "arm needs ≥ 1 GCP).\n\nexample:\n  python -m ground adjust --trajectory SOL.pos --events "
               "events.jsonl --images photos/ \\\n    --orientations reconstruction.json --gcp gcp.csv "
               "--lever-arm 0.04,-0.11,-0.09 --lever-arm-sigma 0.005 \\\n    --estimate delay --crs EPSG:2154 "
               "-o out/\n\nwrites out/results.json, out/report.html and out/exports/ (geo.txt, Pix4D, Metashape, "
               "OPK CSV, MicMac).\nexit codes: 0 done, 2 bad input, 3 refused (the message says what to add)")
    a.add_argument("--trajectory", required=True, type=Path, help="antenna trajectory: RTKLIB .pos (xyz or llh, GPST week/tow or calendar, "
                   "velocity columns optional)")
    a.add_argument("--events", required=True, type=Path, help="camera events: the onboard events.jsonl, or a CSV "
                   "image,week,tow (GPS week, seconds of week)")
    a.add_argument("--events-kind", choices=("trigger", "flash"), default="trigger",
                   help="what the CSV times are: trigger pulses (t_d ≈ shutter lag) or flash marks "
                   "(t_d ≈ 0) (default: %(default)s)")
    a.add_argument("--capture-times", type=Path, help="CSV/JSON image→capture time (to match events.jsonl)")
    a.add_argument("--images", type=Path, help="folder of the photos: EXIF capture times to match events.jsonl")
    a.add_argument("--orientations", required=True, type=Path,
                   help="bundle adjustment: OpenSfM/ODM reconstruction.json, COLMAP images.txt, MicMac "
                   "Ori-* folder, Metashape camera .xml or OPK .csv (image,X,Y,Z,omega,phi,kappa; degrees)")
    a.add_argument("--gcp", type=Path, help="GCP CSV name,role,x_rel,y_rel,z_rel,X,Y,Z, ODM gcp_list.txt or "
                   "MicMac XML (then --gcp-rel)")
    a.add_argument("--gcp-rel", type=Path, help="CSV name,x_rel,y_rel,z_rel[,role] for ODM/MicMac GCP files")
    a.add_argument("--gcp-crs", default=crsmod.WGS84_ECEF, help="CRS of the GCP ground coordinates, EPSG:n or EPSG:h+v "
                   "(default: %(default)s, ECEF metres)")
    a.add_argument("--lever-arm", type=_triple, help="lever arm X,Y,Z (m): antenna phase centre − optical "
                   "centre in the camera frame (x right, y down, z forward), e.g. from `calibrate`")
    a.add_argument("--lever-arm-sigma", type=float, help="σ (m, each axis) making --lever-arm a prior")
    a.add_argument("--delay", type=float, help="shutter delay t_d (s): event time → exposure, e.g. 0.064")
    a.add_argument("--delay-sigma", type=float, help="σ (s) making --delay a prior")
    a.add_argument("--estimate", default="", help="leave these free: lever-arm, delay or "
                   "lever-arm,delay")
    a.add_argument("--relative-control", action="store_true", help="differenced aerial control between consecutive "
                   "images (float RTK or a GNSS bias; needs ≥ 1 GCP)")
    a.add_argument("--crs", default="EPSG:4979", help="CRS of the exports, EPSG:n or EPSG:h+v with "
                   "a geoid (its grid must be installed) (default: %(default)s, WGS 84 lat/lon/ellipsoidal h)")
    a.add_argument("--datum-tolerance-m", type=float, default=crsmod.MAX_DATUM_ERROR_M,
                   help="largest accepted error of a datum change (PROJ null shifts such as WGS 84 → RGF93 state "
                   "1 m and are refused by default)")
    a.add_argument("-o", "--out", required=True, type=Path, help="output folder (created)")
    k = sub.add_parser(
        "calibrate", help="lever arm from a ground (pseudo-materialization) acquisition",
        description="Lever arm O (antenna phase centre − optical centre, camera frame) with σ from targets on "
                    "the camera and on the receiver box measured in one photogrammetric acquisition of the "
                    "drone (Daakir 2016); prints the --lever-arm/--lever-arm-sigma options for `adjust`. "
                    "Exit codes: 0 done (stable), 1 the second acquisition differs beyond 3σ, 2 bad input.")
    k.add_argument("targets", type=Path, help="CSV target,group,x,y,z (m); group is camera_frame (camera "
                   "target in the calibrated camera frame), camera_acq / box_acq (the same targets in this "
                   "acquisition), box_frame (box targets, and one row named phase_centre)")
    k.add_argument("--compare", type=Path, help="a second acquisition (e.g. after landing) to check stability")
    k.add_argument("-o", "--out", type=Path, help="write the JSON result here")
    s = sub.add_parser(
        "serve", help="run the ground API (FastAPI + uvicorn)",
        description="Flight store and processing server: resumable checksummed uploads, RTK re-processing and "
                    "adjustment jobs, reports. Every flight route needs 'Authorization: Bearer TOKEN'; OpenAPI "
                    "at /docs and /openapi.json.")
    s.add_argument("--host", default="127.0.0.1", help="address to listen on (default: %(default)s)")
    s.add_argument("--port", type=int, default=8600, help="TCP port (default: %(default)s)")
    s.add_argument("--data-dir", type=Path, default=Path("ground-data"),
                   help="raw flight files and the default SQLite store (default: %(default)s)")
    s.add_argument("--token-file", type=Path, help="file holding the API token (else $DIRECTGEO_TOKEN)")
    s.add_argument("--database-url", help="SQLAlchemy URL (else $DATABASE_URL, else SQLite in the data dir)")
    s.add_argument("--max-chunk-mib", type=float, default=16.0, help="largest upload chunk (default: %(default)s MiB)")
    s.add_argument("--max-file-gib", type=float, default=8.0, help="largest uploaded file (default: %(default)s GiB)")
    return p


def _calibrate(args: argparse.Namespace) -> int:
    """`calibrate`: G's pseudo-materialization core on one (or two) target files; prints the adjust options."""
    from ground.adjust.calibration import CalibrationError, calibrate_lever_arm, compare_calibrations
    from ground.io.calibration_csv import read_calibration_csv

    try:
        first = calibrate_lever_arm(read_calibration_csv(args.targets))
        second = calibrate_lever_arm(read_calibration_csv(args.compare)) if args.compare else None
    except (InputError, CalibrationError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    out: dict[str, Any] = {"calibration": first.to_dict()}
    o, sd = first.lever_arm_m, first.sigma_m
    print("lever arm O (camera frame, antenna − optical centre): "
          + ", ".join(f"{v * 1000:+.1f} ± {e * 1000:.1f} mm" for v, e in zip(o, sd)))
    print(f"use: --lever-arm {o[0]:.4f},{o[1]:.4f},{o[2]:.4f} --lever-arm-sigma {max(float(sd.max()), 1e-4):.4f}")
    if second is not None:
        cmp = compare_calibrations(first, second)
        out["second"] = second.to_dict()
        out["comparison"] = cmp.to_dict()
        print(f"second acquisition differs by {cmp.abs_m * 1000:.1f} mm "
              f"({'stable' if cmp.stable else 'NOT stable'} within 3σ), box rotated {cmp.box_rotation_change_deg:.3f}°")
    if args.out is not None:
        args.out.write_text(json.dumps(out, indent=2), encoding="utf-8")
    return 0 if second is None or out["comparison"]["stable"] else 1


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the process exit code (2 bad input, 3 refused, 0 ok)."""
    import os

    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="%(levelname)s %(name)s: %(message)s")
    if args.command == "adjust":
        req = AdjustRequest(
            trajectory=args.trajectory, events=args.events, orientations=args.orientations, gcp=args.gcp,
            gcp_rel=args.gcp_rel, gcp_crs=args.gcp_crs, capture_times=args.capture_times, images_dir=args.images,
            lever_arm_m=args.lever_arm, lever_arm_sigma_m=args.lever_arm_sigma, delay_s=args.delay,
            delay_sigma_s=args.delay_sigma, estimate=tuple(e for e in args.estimate.split(",") if e),
            crs=args.crs, relative_control=args.relative_control, events_kind=args.events_kind,
            datum_tolerance_m=args.datum_tolerance_m,
        )
        try:
            res = run_adjust(req, args.out)
        except (InputError, FormatError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        except AdjustmentRefused as exc:
            print(f"refused: {exc}", file=sys.stderr)
            return 3
        lv, lvs = res["lever_arm_m"], res["lever_arm_sigma_m"]
        print(f"{res['n_images']} images, sigma0 {_num(res['sigma0'], 1, '.3f')}")
        print("lever arm (m): " + ", ".join(f"{_num(v, 1, '+.4f')} ± {_num(s, 1, '.4f')}" for v, s in zip(lv, lvs)))
        print(f"delay: {_num(res['delay_s'], 1e3, '+.2f')} ± {_num(res['delay_sigma_s'], 1e3, '.2f')} ms")
        for w in res["warnings"]:
            print(f"warning: {w}")
        print(f"wrote {args.out / 'results.json'}, {args.out / 'report.html'}, {args.out / 'exports'}")
        return 0
    if args.command == "calibrate":
        return _calibrate(args)
    if args.command == "serve":
        import uvicorn

        from ground.api.app import create_app
        from ground.api.settings import ApiSettings, load_token

        try:
            settings = ApiSettings(
                data_dir=args.data_dir, token=load_token(args.token_file),
                database_url=args.database_url or os.environ.get("DATABASE_URL"),
                max_chunk_bytes=int(args.max_chunk_mib * 1024**2), max_file_bytes=int(args.max_file_gib * 1024**3),
            )
        except (InputError, ConfigFileError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        from sqlalchemy.exc import SQLAlchemyError

        from ground.store import Store

        try:  # fail here, clearly, rather than inside the server's start-up
            settings.data_dir.mkdir(parents=True, exist_ok=True)
            Store(settings.db_url).close()
        except (SQLAlchemyError, ImportError, OSError) as exc:
            print(f"error: cannot open the flight store {settings.db_url.split('@')[-1]}: {exc}", file=sys.stderr)
            return 2
        uvicorn.run(create_app(settings), host=args.host, port=args.port, log_level="info")
        return 0
    return 2
