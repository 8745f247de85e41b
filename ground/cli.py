"""`python -m ground adjust|calibrate|serve|token`: the command line of the ground app (a thin shell over
`ground.pipeline`, the calibration core and the API).

Every value is checked by a type function (`onboard.validate`), errors read `directgeo: ground <command>:
error: <message>`; exit codes: 0 done, 1 failure (disk full, a bug: logged, traceback with -v), 2 bad input or
usage, 3 refused by a data rule (the data cannot support an answer). No traceback reaches a user.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

from ground.adjust.model import AdjustmentRefused
from ground.io import crs as crsmod
from ground.pipeline import (
    MAX_DELAY_S,
    MAX_SIGMA_M,
    AdjustInputs,
    AdjustJobOptions,
    result_number,
    run_adjust,
)
from onboard import validate
from onboard.errors import ConfigFileError, InputError
from onboard.formats.atomic import write_atomic

log = logging.getLogger(__name__)

PROG = "python -m ground"
ERROR_PREFIX = "directgeo"
#: options whose value may start with "-" (a negative X or dx): "--opt -1,2,3" is joined into "--opt=-1,2,3"
#: before argparse, which would otherwise take "-1,2,3" for an unknown option
NEGATIVE_VALUE_OPTIONS = ("--lever-arm", "--delay")

EXIT_OK, EXIT_FAILURE, EXIT_USAGE, EXIT_REFUSED = 0, 1, 2, 3


class _Parser(argparse.ArgumentParser):
    """argparse with the product's error line (`directgeo: ground <command>: error: ...`, exit 2)."""

    def error(self, message: str) -> NoReturn:
        self.print_usage(sys.stderr)
        _error(self.prog.replace(PROG, "ground").strip(), message)
        raise SystemExit(EXIT_USAGE)


def _error(command: str, message: str) -> None:
    print(f"{ERROR_PREFIX}: {command}: error: {message}", file=sys.stderr)


def _estimate_list(text: str) -> tuple[str, ...]:
    """`--estimate` value: a comma list of lever-arm, delay (or empty)."""
    from ground.pipeline import ESTIMABLE

    items = tuple(e.strip() for e in text.split(",") if e.strip())
    for e in items:
        if e not in ESTIMABLE:
            raise argparse.ArgumentTypeError(f"{e!r}: must be {', '.join(ESTIMABLE)} or lever-arm,delay")
    return items


def _crs_text(text: str) -> str:
    """A CRS as EPSG:n / EPSG:h+v / PROJ / WKT: refused now when unknown."""
    try:
        crsmod.parse_crs(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def _join_negative_values(argv: Sequence[str]) -> list[str]:
    out: list[str] = []
    it = iter(range(len(argv)))
    for i in it:
        a = argv[i]
        if a in NEGATIVE_VALUE_OPTIONS and i + 1 < len(argv) and argv[i + 1].startswith("-") \
                and len(argv[i + 1]) > 1 and (argv[i + 1][1].isdigit() or argv[i + 1][1] in ".in"):
            out.append(f"{a}={argv[i + 1]}")
            next(it, None)
        else:
            out.append(a)
    return out


def build_parser() -> argparse.ArgumentParser:
    """The `python -m ground` argument parser."""
    p = _Parser(prog=PROG, description="directgeo ground app: camera positions in your CRS from an RTK trajectory, "
                "camera events and a bundle adjustment (adjust), the lever arm from a ground acquisition "
                "(calibrate), and the flight store / processing server (serve). Run a command with --help for "
                "its options, units and an example.",
                epilog="example: python -m ground adjust --trajectory SOL.pos --events events.csv "
                "--orientations poses.csv --gcp gcp.csv -o out/")
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging (and the traceback of an internal error)")
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
               "--lever-arm 0.04,-0.11,-0.09 --lever-arm-sigma 0.005 \\\n    --estimate delay --crs EPSG:32632 "
               "-o out/\n\nwrites out/results.json, out/report.html and out/exports/ (geo.txt, Pix4D, Metashape, "
               "OPK CSV, MicMac).\nexit codes: 0 done, 1 failure (e.g. disk full: the previous outputs are kept), 2 bad input, "
               "3 refused (the data cannot support an answer; the message says what to add)")
    a.add_argument("--trajectory", required=True, type=Path, metavar="FILE", help="antenna trajectory: RTKLIB .pos (xyz or llh, GPST week/tow or calendar, "
                   "velocity columns optional)")
    a.add_argument("--events", required=True, type=Path, metavar="FILE", help="camera events: the onboard events.jsonl, or a CSV "
                   "image,week,tow (GPS week, seconds of week)")
    a.add_argument("--events-kind", choices=("trigger", "flash"), default="trigger",
                   help="what the CSV times are: trigger pulses (t_d ≈ shutter lag) or flash marks "
                   "(t_d ≈ 0) (default: %(default)s)")
    a.add_argument("--capture-times", type=Path, metavar="FILE", help="CSV image,capture_time or JSON {image: time} (camera clock, "
                   "EXIF 'YYYY:MM:DD HH:MM:SS' or ISO 8601) to match events.jsonl to the images")
    a.add_argument("--images", type=Path, metavar="DIR", help="folder of the photos: EXIF capture times to match events.jsonl")
    a.add_argument("--orientations", required=True, type=Path, metavar="FILE|DIR",
                   help="bundle adjustment: OpenSfM/ODM reconstruction.json, COLMAP images.txt, MicMac "
                   "Ori-* folder, Metashape camera .xml or OPK .csv (image,X,Y,Z,omega,phi,kappa; degrees)")
    a.add_argument("--gcp", type=Path, metavar="FILE", help="GCP CSV name,role,x_rel,y_rel,z_rel,X,Y,Z, ODM gcp_list.txt or "
                   "MicMac XML (then --gcp-rel)")
    a.add_argument("--gcp-rel", type=Path, metavar="FILE", help="CSV name,x_rel,y_rel,z_rel[,role] for ODM/MicMac GCP files")
    a.add_argument("--gcp-crs", default=crsmod.WGS84_ECEF, type=_crs_text, metavar="CRS", help="CRS of the GCP ground coordinates, EPSG:n or EPSG:h+v "
                   "(default: %(default)s, ECEF metres)")
    a.add_argument("--lever-arm", type=validate.arg_type(validate.lever_arm_m), metavar="DX,DY,DZ", help="lever arm dx,dy,dz (m, each within ±5 m): antenna phase "
                   "centre − optical centre in the camera frame (x right, y down, z forward), e.g. from `calibrate`; "
                   "negative values as they are: --lever-arm -0.04,0.11,0.09")
    a.add_argument("--lever-arm-sigma", metavar="M",
                   type=validate.arg_type(validate.positive, unit=" m", maximum=MAX_SIGMA_M), help="σ (m, each axis, > 0) making --lever-arm a prior, e.g. 0.005")
    a.add_argument("--delay", metavar="S",
                   type=validate.arg_type(validate.number, unit=" s", minimum=-MAX_DELAY_S, maximum=MAX_DELAY_S), help="shutter delay t_d (s): event time → exposure, e.g. 0.064")
    a.add_argument("--delay-sigma", metavar="S",
                   type=validate.arg_type(validate.positive, unit=" s", maximum=MAX_DELAY_S), help="σ (s, > 0) making --delay a prior, e.g. 0.002")
    a.add_argument("--estimate", default=(), type=_estimate_list, metavar="LIST", help="leave these free: lever-arm, delay or "
                   "lever-arm,delay")
    a.add_argument("--relative-control", action="store_true", help="differenced aerial control between consecutive "
                   "images (float RTK or a GNSS bias; needs ≥ 1 GCP)")
    a.add_argument("--crs", default="EPSG:4979", type=_crs_text, metavar="CRS", help="CRS of the exports, EPSG:n or EPSG:h+v with "
                   "a geoid (its grid must be installed) (default: %(default)s, WGS 84 lat/lon/ellipsoidal h)")
    a.add_argument("--datum-tolerance-m", metavar="M",
                   type=validate.arg_type(validate.positive, unit=" m", maximum=1000.0),
                   default=crsmod.MAX_DATUM_ERROR_M,
                   help="largest accepted error of a datum change (PROJ null shifts such as WGS 84 → RGF93 state "
                   "1 m and are refused by default) (default: %(default)s m)")
    a.add_argument("--accept-single", action="store_true", help="also use single-point trajectory rows (Q=5, "
                   "metre-level); by default only fix (1) and float (2) rows are antenna positions")
    a.add_argument("--accept-blunder", action="store_true", help="write the exports even when σ̂₀ shows a blunder "
                   "(residuals > 10× their σ); by default such a result is refused (exit 3)")
    a.add_argument("-o", "--out", required=True, type=Path, metavar="DIR",
                   help="output folder (created; results.json, report.html, exports/ replaced atomically)")
    k = sub.add_parser(
        "calibrate", help="lever arm from a ground (pseudo-materialization) acquisition",
        description="Lever arm O (antenna phase centre − optical centre, camera frame) with σ from targets on "
                    "the camera and on the receiver box measured in one photogrammetric acquisition of the "
                    "drone (Daakir 2016); prints the --lever-arm/--lever-arm-sigma options for `adjust`. "
                    "Exit codes: 0 done (stable), 1 the second acquisition differs beyond 3σ, 2 bad input. "
                    "Example: python -m ground calibrate targets.csv --compare after_landing.csv -o lever.json")
    k.add_argument("targets", type=Path, help="CSV target,group,x,y,z (m); group is camera_frame (camera "
                   "target in the calibrated camera frame), camera_acq / box_acq (the same targets in this "
                   "acquisition), box_frame (box targets, and one row named phase_centre)")
    k.add_argument("--compare", type=Path, metavar="FILE", help="a second acquisition (e.g. after landing) to check stability")
    k.add_argument("-o", "--out", type=Path, metavar="FILE", help="write the JSON result to this file (atomically)")
    s = sub.add_parser(
        "serve", help="run the ground API (FastAPI + uvicorn)",
        description="Flight store and processing server: resumable checksummed uploads, RTK re-processing and "
                    "adjustment jobs, reports. Every route but /health needs 'Authorization: Bearer TOKEN' of a role it "
                    "lets through (the bootstrap token of --token-file/$DIRECTGEO_TOKEN is an admin; others: "
                    "`token create`); OpenAPI "
                    "at /docs and /openapi.json; the web interface for engineers at /ui (sign in with an engineer "
                    "token). Example: DIRECTGEO_TOKEN=... python -m ground serve --port 8600 "
                    "--data-dir /srv/directgeo")
    _store_options(s)
    s.add_argument("--host", default="127.0.0.1", help="address to listen on, e.g. 0.0.0.0 for every interface (default: %(default)s)")
    s.add_argument("--port", type=validate.arg_type(validate.tcp_port), default=8600, help="TCP port, 1–65535 (default: %(default)s)")
    s.add_argument("--token-file", type=Path, metavar="FILE", help="file holding the bootstrap admin token (else "
                   "$DIRECTGEO_TOKEN); other tokens: `token create`")
    s.add_argument("--max-chunk-mib", type=validate.arg_type(validate.positive, unit=" MiB", maximum=1024.0),
                   default=16.0, help="largest upload chunk (default: %(default)s MiB)")
    s.add_argument("--max-file-gib", type=validate.arg_type(validate.positive, unit=" GiB", maximum=1024.0),
                   default=8.0, help="largest uploaded file (default: %(default)s GiB)")
    s.add_argument("--queue", choices=("inprocess", "postgres"), default="inprocess",
                   help="where jobs run: inprocess (child processes of this server; SQLite is enough) or postgres "
                   "(a procrastinate queue in the PostgreSQL database, run by 'python -m ground worker' "
                   "processes) (default: %(default)s)")
    s.add_argument("--job-timeout-s", type=validate.arg_type(validate.positive, unit=" s"), default=4 * 3600.0,
                   help="a job running longer is stopped and failed (default: %(default)s s)")
    w = sub.add_parser(
        "worker", help="run processing jobs from the PostgreSQL queue (stateless; run one per core/machine)",
        description="A processing worker: takes jobs from the procrastinate queue in PostgreSQL, fetches each "
                    "flight's files through the API (local cache, SHA-256 checked), runs the job in a child "
                    "process with the server's time limit and posts outputs and status through the API. A "
                    "worker killed mid-job has its job retried by another after --stalled-after-s. Stop with "
                    "SIGTERM (the running job is finished first). Example: python -m ground worker --api "
                    "http://ground:8600 --token-file /etc/directgeo/worker.token --database-url "
                    "postgresql://directgeo@db/directgeo")
    w.add_argument("--api", required=True, metavar="URL", help="base URL of the ground API, e.g. http://ground:8600")
    w.add_argument("--token-file", type=Path, metavar="FILE", help="file holding the worker's API token "
                   "(else $DIRECTGEO_TOKEN)")
    w.add_argument("--database-url", metavar="URL", help="the queue's PostgreSQL database, libpq or SQLAlchemy "
                   "URL (else $DATABASE_URL)")
    w.add_argument("--cache-dir", type=Path, metavar="DIR", default=Path("ground-worker-cache"),
                   help="local copies of flight files and per-job scratch folders (default: %(default)s)")
    w.add_argument("--heartbeat-s", type=validate.arg_type(validate.positive, unit=" s", maximum=3600.0),
                   default=10.0, help="heartbeat period, also how often stalled jobs are looked for "
                   "(default: %(default)s s)")
    w.add_argument("--stalled-after-s", type=validate.arg_type(validate.positive, unit=" s", maximum=86400.0),
                   default=30.0, help="a worker silent this long is taken for dead and its job is run again "
                   "(> 2 heartbeats) (default: %(default)s s)")
    w.add_argument("--name", default="", help="worker name in the queue (default: host-pid)")
    t = sub.add_parser(
        "token", help="create, revoke and list the API tokens (roles drone, engineer, worker, admin)",
        description="API tokens with roles, in the flight store `serve` uses (same --data-dir / --database-url / "
                    "$DATABASE_URL). Only each token's SHA-256 is stored: `create` prints the token once. Roles: "
                    "drone (create flights, upload their files), engineer (read and process everything), worker "
                    "(processing machines), admin (everything and the tokens). Example: python -m ground token "
                    "create --role drone --name drone-07 --data-dir /srv/directgeo > /etc/directgeo/token")
    tsub = t.add_subparsers(dest="token_command", required=True)
    tc = tsub.add_parser("create", help="create a token: prints it (and only it) on stdout, once",
                         description="Create a token; stdout is the token alone (capture it: it is not stored "
                                     "and cannot be shown again), its id and name go to stderr.")
    tc.add_argument("--role", required=True, choices=_role_names(), help="what the token may do")
    tc.add_argument("--name", metavar="NAME", help="unique name, e.g. the drone's (default: <role>-<8 hex digits>)")
    _store_options(tc)
    tr = tsub.add_parser("revoke", help="revoke a token by id or name (refused from then on)",
                         description="Revoke a token; exit 0 when revoked, 2 when no active token has that id or name.")
    tr.add_argument("token", metavar="ID|NAME", help="the token's id or name (see `token list`)")
    _store_options(tr)
    tl = tsub.add_parser("list", help="list the tokens (no secrets: id, name, role, created, last used, revoked)")
    tl.add_argument("--json", action="store_true", help="one JSON array instead of a table")
    _store_options(tl)
    return p


def _role_names() -> list[str]:
    from ground.api.roles import Role  # not ground.api.auth: no FastAPI import for the parser

    return [r.value for r in Role]


def _store_options(p: argparse.ArgumentParser) -> None:
    """--data-dir and --database-url: where `serve` and `token` find the flight store."""
    p.add_argument("--data-dir", type=Path, metavar="DIR", default=Path("ground-data"),
                   help="raw flight files and the default SQLite store (default: %(default)s)")
    p.add_argument("--database-url", metavar="URL",
                   help="SQLAlchemy URL (else $DATABASE_URL, else SQLite in the data dir)")


def _open_store(data_dir: Path, db_url: str) -> Any:
    """The flight store, or a clear `ConfigFileError` (unreachable server, missing driver, unwritable dir)."""
    from sqlalchemy.exc import SQLAlchemyError

    from ground.store import Store

    try:
        data_dir.mkdir(parents=True, exist_ok=True)
        return Store(db_url)
    except (SQLAlchemyError, ImportError, OSError) as exc:
        raise ConfigFileError(f"cannot open the flight store {db_url.split('@')[-1]}: {exc}") from exc


def _calibrate(args: argparse.Namespace) -> int:
    """`calibrate`: G's pseudo-materialization core on one (or two) target files; prints the adjust options."""
    from ground.adjust.calibration import CalibrationError, calibrate_lever_arm, compare_calibrations
    from ground.io.calibration_csv import read_calibration_csv

    try:
        first = calibrate_lever_arm(read_calibration_csv(args.targets))
        second = calibrate_lever_arm(read_calibration_csv(args.compare)) if args.compare else None
    except (InputError, CalibrationError) as exc:
        _error("ground calibrate", str(exc))
        return EXIT_USAGE
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
        if args.out.is_dir():
            _error("ground calibrate", f"-o {args.out}: is a folder, give a file name")
            return EXIT_USAGE
        write_atomic(args.out, json.dumps(out, indent=2, allow_nan=False) + "\n")
    return 0 if second is None or out["comparison"]["stable"] else 1


def _adjust(args: argparse.Namespace) -> int:
    """`adjust`: the pipeline's adjustment on the command line's files and options; prints a summary."""
    inputs = AdjustInputs(trajectory=args.trajectory, events=args.events, orientations=args.orientations,
                          gcp=args.gcp, gcp_rel=args.gcp_rel, capture_times=args.capture_times,
                          images_dir=args.images)
    try:
        options = AdjustJobOptions(
            lever_arm_m=args.lever_arm, lever_arm_sigma_m=args.lever_arm_sigma, delay_s=args.delay,
            delay_sigma_s=args.delay_sigma, estimate=args.estimate, crs=args.crs, gcp_crs=args.gcp_crs,
            relative_control=args.relative_control, events_kind=args.events_kind,
            datum_tolerance_m=args.datum_tolerance_m, accept_single=args.accept_single,
            accept_blunder=args.accept_blunder,
        )
    except ValueError as exc:  # a value refused by the options' checks (onboard.validate's words)
        raise InputError(str(exc)) from exc
    res = run_adjust(inputs, options, args.out).results
    lv, lvs = res["lever_arm_m"], res["lever_arm_sigma_m"]
    print(f"{res['n_images']} images, sigma0 {result_number(res['sigma0'], 1, '.3f')}")
    print("lever arm (m): " + ", ".join(f"{result_number(v, 1, '+.4f')} ± {result_number(s, 1, '.4f')}"
                                        for v, s in zip(lv, lvs)))
    print(f"delay: {result_number(res['delay_s'], 1e3, '+.2f')} ± "
          f"{result_number(res['delay_sigma_s'], 1e3, '.2f')} ms")
    for w in res["warnings"]:
        print(f"warning: {w}")
    print(f"wrote {args.out / 'results.json'}, {args.out / 'report.html'}, {args.out / 'exports'}")
    return EXIT_OK


def _serve(args: argparse.Namespace) -> int:
    """`serve`: settings checked, the store opened once (a clear error here, not in the server), then uvicorn."""
    import uvicorn

    from ground.api.app import create_app
    from ground.api.settings import ApiSettings, load_token

    settings = ApiSettings(
        data_dir=args.data_dir, token=load_token(args.token_file),
        database_url=args.database_url or os.environ.get("DATABASE_URL"),
        max_chunk_bytes=int(args.max_chunk_mib * 1024**2), max_file_bytes=int(args.max_file_gib * 1024**3),
        job_queue=args.queue, job_timeout_s=args.job_timeout_s,
    )
    _open_store(settings.data_dir, settings.db_url).close()  # fail here, clearly, not inside the server's start-up
    uvicorn.run(create_app(settings), host=args.host, port=args.port, log_level="info")
    return EXIT_OK


def _worker(args: argparse.Namespace) -> int:
    """`worker`: options checked, the queue reached once (a clear error here), then procrastinate's worker."""
    import psycopg

    from ground.api.queue import libpq_dsn
    from ground.api.settings import load_token
    from ground.api.worker import WorkerOptions, serve

    url = args.database_url or os.environ.get("DATABASE_URL")
    if not url:
        raise ConfigFileError("no queue database: pass --database-url or set $DATABASE_URL (PostgreSQL)")
    try:
        dsn = libpq_dsn(url)
        options = WorkerOptions(api_url=args.api, token=load_token(args.token_file), dsn=dsn,
                                cache_dir=args.cache_dir, heartbeat_s=args.heartbeat_s,
                                stalled_after_s=args.stalled_after_s, name=args.name)
    except ValueError as exc:
        raise ConfigFileError(str(exc)) from None
    try:
        psycopg.connect(dsn, connect_timeout=10).close()
    except psycopg.Error as exc:
        raise ConfigFileError(f"cannot reach the queue database {dsn.split('@')[-1]}: {exc}") from exc
    serve(options)
    return EXIT_OK


def _token(args: argparse.Namespace) -> int:
    """`token create|revoke|list` on the store of --data-dir / --database-url / $DATABASE_URL."""
    from ground.api.auth import Role, create_token, default_token_name, list_tokens, revoke_token
    from ground.api.settings import database_url

    store = _open_store(args.data_dir, database_url(args.data_dir, args.database_url
                                                    or os.environ.get("DATABASE_URL")))
    try:
        if args.token_command == "create":
            role = Role(args.role)
            name = args.name or default_token_name(role)
            token_id, clear = create_token(store, role, name)
            print(clear)  # stdout: the token alone, for `> token-file` or $(…)
            print(f"created {role.value} token {name!r} (id {token_id}); it is shown only this once",
                  file=sys.stderr)
            return EXIT_OK
        if args.token_command == "revoke":
            if not revoke_token(store, args.token):
                raise InputError(f"no active token with id or name {args.token!r} (see `token list`)")
            print(f"revoked {args.token}", file=sys.stderr)
            return EXIT_OK
        rows = list_tokens(store)
        if args.json:
            print(json.dumps([{"id": t.id, "name": t.name, "role": t.role.value,
                               **{k: (None if getattr(t, k) is None else getattr(t, k).isoformat())
                                  for k in ("created_at", "last_used_at", "revoked_at")}} for t in rows], indent=2))
            return EXIT_OK
        print(f"{'id':32}  {'name':24} {'role':8}  {'created (UTC)':16}  {'last used':16}  revoked")
        for t in rows:
            when = [x.strftime("%Y-%m-%d %H:%M") if x is not None else "-" for x in
                    (t.created_at, t.last_used_at, t.revoked_at)]
            print(f"{t.id:32}  {t.name:24} {t.role.value:8}  {when[0]:16}  {when[1]:16}  {when[2]}")
        return EXIT_OK
    finally:
        store.close()


COMMANDS = {"adjust": _adjust, "calibrate": _calibrate, "serve": _serve, "token": _token, "worker": _worker}


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit code (0 ok, 1 failure, 2 bad input/usage, 3 refused)."""
    raw = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(_join_negative_values(raw))
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="%(levelname)s %(name)s: %(message)s")
    command = f"ground {args.command}"
    try:
        return COMMANDS[args.command](args)
    except AdjustmentRefused as exc:
        _error(command, f"refused: {exc}")
        return EXIT_REFUSED
    except (InputError, ConfigFileError) as exc:
        _error(command, str(exc))
        return EXIT_USAGE
    except OSError as exc:
        _error(command, f"{exc.strerror or exc}{f': {exc.filename}' if exc.filename else ''} (nothing half-written "
                        "was left under a final name)")
        return EXIT_FAILURE
    except Exception as exc:  # a bug: logged with its traceback (shown with -v), one line here
        log.debug("internal error", exc_info=True)
        _error(command, f"internal error ({type(exc).__name__}: {exc}); run with -v for the traceback")
        return EXIT_FAILURE
