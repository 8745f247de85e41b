"""The ground jobs as functions of typed inputs: RTK re-processing and the final adjustment.

Both the command line (`python -m ground adjust`) and the API's job runner call these with dataclasses (no
argv, no redirected stdout): inputs (paths), an options object (values already checked), an output directory
→ a result object. Every file is written atomically (`onboard.formats.atomic`): a failure leaves the previous
good output. Errors: `InputError` (bad files or values), `AdjustmentRefused` / `RefusedByData` (the data
cannot support an answer), `CrsError` (a transformation that cannot be done exactly).
"""

from __future__ import annotations

import datetime as dt
import json
import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ground.adjust.model import AdjustmentOptions, AdjustmentRefused, DelaySpec, LeverArmSpec
from ground.adjust.types import ImageEvent
from ground.io import crs as crsmod
from onboard import validate
from onboard.errors import InputError
from onboard.formats.atomic import atomic_output, write_atomic

if TYPE_CHECKING:
    from ground.io.gcp import GroundPoint

log = logging.getLogger(__name__)

ESTIMABLE = ("lever-arm", "delay")
"""Parameters `--estimate` may leave free."""
MAX_DELAY_S = 5.0
"""Largest |shutter delay| accepted (s): cameras expose within tens of ms of their trigger; 5 s is no delay."""
MAX_SIGMA_M = 10.0
"""Largest prior σ of the lever arm (m): a drone is smaller."""
RTK_DIRECTIONS = ("forward", "backward", "combined")
RTK_SYSTEMS_AUTO = "auto"
"""RtkJobOptions.systems: every constellation both receivers observed (onboard.postpro.inputs.observed_systems)."""


class RefusedByData(AdjustmentRefused):
    """The inputs are well-formed but cannot give an answer (e.g. an RTK run without a single solution)."""


def _ensure_out_dir(out_dir: Path) -> None:
    """Create the output folder, refusing a path that is a file (InputError, not a traceback)."""
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(f"output folder {out_dir}: is a file, not a folder")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"output folder {out_dir}: cannot be created ({exc.strerror or exc})") from exc


# ------------------------------------------------------------------------------------------------ adjustment


@dataclass(frozen=True)
class AdjustInputs:
    """The files of one adjustment. `capture_times`: a CSV/JSON sidecar, or {image: camera clock time (naive
    UTC)} given directly (the API), to match an events.jsonl to the images."""

    trajectory: Path
    events: Path
    orientations: Path
    gcp: Path | None = None
    gcp_rel: Path | None = None
    capture_times: Path | Mapping[str, dt.datetime] | None = None
    images_dir: Path | None = None


@dataclass(frozen=True)
class AdjustJobOptions:
    """Parameter choices of one adjustment, checked on construction (ValueError in `onboard.validate` words).

    Lever arm and delay: a value alone is fixed, a value with σ is a prior, `estimate` without a value leaves
    the parameter free. Lever arm dx,dy,dz in m (camera frame: x right, y down, z forward), delay in s.
    """

    lever_arm_m: tuple[float, float, float] | None = None
    lever_arm_sigma_m: float | None = None
    delay_s: float | None = None
    delay_sigma_s: float | None = None
    estimate: tuple[str, ...] = ()
    crs: str = "EPSG:4979"
    gcp_crs: str = crsmod.WGS84_ECEF
    relative_control: bool = False
    events_kind: str = "trigger"
    datum_tolerance_m: float = crsmod.MAX_DATUM_ERROR_M
    accept_single: bool = False
    #: accept a result flagged `blunder_suspected` (σ̂₀ above the limit) instead of refusing it
    accept_blunder: bool = False

    def __post_init__(self) -> None:
        if self.lever_arm_m is not None:
            object.__setattr__(self, "lever_arm_m", validate.lever_arm_m(self.lever_arm_m, name="lever arm"))
        if self.lever_arm_sigma_m is not None:
            validate.positive(self.lever_arm_sigma_m, name="lever arm σ", unit=" m", maximum=MAX_SIGMA_M)
        if self.delay_s is not None:
            validate.number(self.delay_s, name="delay", unit=" s", minimum=-MAX_DELAY_S, maximum=MAX_DELAY_S)
        if self.delay_sigma_s is not None:
            validate.positive(self.delay_sigma_s, name="delay σ", unit=" s", maximum=MAX_DELAY_S)
        validate.positive(self.datum_tolerance_m, name="datum tolerance", unit=" m", maximum=1000.0)
        for e in self.estimate:
            if e not in ESTIMABLE:
                raise ValueError(f"estimate {e!r}: must be one of {', '.join(ESTIMABLE)}")
        if self.events_kind not in ("trigger", "flash"):
            raise ValueError(f"events kind {self.events_kind!r}: must be trigger or flash")
        for name in ("crs", "gcp_crs"):
            text = getattr(self, name)
            if not isinstance(text, str) or not text.strip() or "\x00" in text:
                raise ValueError(f"{name} {text!r}: must be a CRS such as EPSG:4979 or EPSG:32632")


def parameter_specs(options: AdjustJobOptions) -> tuple[LeverArmSpec, DelaySpec]:
    """Lever-arm and delay specs from the rules (value → fixed, value + σ → prior, estimate → free)."""
    if options.lever_arm_m is None:
        if options.lever_arm_sigma_m is not None:
            raise InputError("--lever-arm-sigma needs --lever-arm")
        lever = LeverArmSpec(mode="free")
        if "lever-arm" not in options.estimate:
            log.info("no --lever-arm given: the lever arm is estimated freely")
    elif options.lever_arm_sigma_m is not None:
        lever = LeverArmSpec(mode="prior", value_m=options.lever_arm_m, sigma_m=(options.lever_arm_sigma_m,) * 3)
    elif "lever-arm" in options.estimate:
        raise InputError("--estimate lever-arm with a --lever-arm value needs --lever-arm-sigma (a prior) "
                         "or drop the value to leave it free")
    else:
        lever = LeverArmSpec(mode="fixed", value_m=options.lever_arm_m)
    if options.delay_s is None:
        if options.delay_sigma_s is not None:
            raise InputError("--delay-sigma needs --delay")
        delay = DelaySpec(mode="free")
    elif options.delay_sigma_s is not None:
        delay = DelaySpec(mode="prior", value_s=options.delay_s, sigma_s=options.delay_sigma_s)
    elif "delay" in options.estimate:
        raise InputError("--estimate delay with a --delay value needs --delay-sigma (a prior) or drop the value")
    else:
        delay = DelaySpec(mode="fixed", value_s=options.delay_s)
    return lever, delay


@dataclass(frozen=True)
class AdjustOutcome:
    """What an adjustment run produced: the results (as written to results.json) and where."""

    results: dict[str, Any]
    out_dir: Path

    def summary(self) -> str:
        """One line for a job's message."""
        res = self.results
        lever_txt = ", ".join(result_number(v, 1, ".4f") for v in res["lever_arm_m"])
        return (f"adjusted {res['n_images']} images: lever arm ({lever_txt}) m, "
                f"delay {result_number(res['delay_s'], 1e3, '.1f')} ms, "
                f"sigma0 {result_number(res['sigma0'], 1, '.2f')}")


def result_number(value: float | None, scale: float = 1.0, fmt: str = ".3f") -> str:
    """A result number for printing; None (σ of an undeterminable parameter in to_dict) prints as such."""
    return "undetermined" if value is None else format(value * scale, fmt)


def _read_events(inputs: AdjustInputs, options: AdjustJobOptions,
                 images: list[str]) -> tuple[list[ImageEvent], dict[str, Any]]:
    from ground.io.events import (
        exif_capture_time,
        match_marks_to_images,
        read_capture_times,
        read_events_csv,
        read_marks_jsonl,
    )

    if inputs.events.suffix.lower() == ".jsonl":
        marks = read_marks_jsonl(inputs.events)
        caps: Mapping[str, dt.datetime] | None
        if isinstance(inputs.capture_times, Path):
            caps = read_capture_times(inputs.capture_times)
        else:
            caps = inputs.capture_times
        if caps is None and inputs.images_dir is not None:
            found = {n: exif_capture_time(inputs.images_dir / n) for n in images}
            caps = {n: t for n, t in found.items() if t is not None}
            log.info("EXIF capture times read for %d of %d images in %s", len(caps), len(images), inputs.images_dir)
        try:
            rep = match_marks_to_images(marks, images, dict(caps) if caps is not None else None)
        except ValueError as exc:
            raise InputError(str(exc)) from exc
        return rep.events, rep.to_dict()
    events = read_events_csv(inputs.events, default_kind=options.events_kind)
    return events, {"method": "csv image names", "matched": len(events)}


def read_control(gcp: Path, gcp_rel: Path | None, gcp_crs: str) -> list[GroundPoint]:
    """The GCP/check points of a GCP file, its reader chosen by suffix: `.csv` name,x,y,z[,σ,role] with relative
    coordinates in `gcp_crs`; `.xml` MicMac and other suffixes ODM `gcp_list.txt`, which hold ground coordinates
    only and need `gcp_rel` (a relative CSV name,x_rel,y_rel,z_rel). `InputError` in the importers' words."""
    from ground.io.gcp import (
        merge_ground_and_relative,
        read_gcp_csv,
        read_micmac_gcp,
        read_odm_gcp_list,
        read_relative_csv,
    )

    suffix = gcp.suffix.lower()
    if suffix == ".csv":
        return read_gcp_csv(gcp, crs=gcp_crs)
    ground = read_micmac_gcp(gcp, gcp_crs) if suffix == ".xml" else read_odm_gcp_list(gcp)
    if gcp_rel is None:
        raise InputError(f"{gcp} has ground coordinates only: give --gcp-rel name,x_rel,y_rel,z_rel")
    return merge_ground_and_relative(ground, read_relative_csv(gcp_rel))


def run_adjust(inputs: AdjustInputs, options: AdjustJobOptions, out_dir: Path) -> AdjustOutcome:
    """Read everything, adjust, write results.json, the exports and report.html into `out_dir` (atomically).

    Raises `InputError` (bad files/arguments), `AdjustmentRefused` (not solvable as posed, or a result whose
    σ̂₀ shows a blunder unless `options.accept_blunder`) or `CrsError`. Nothing is written when it raises.
    """
    from ground.adjust.solve import adjust, build_problem
    from ground.io.exporters import cameras_to_crs, write_all
    from ground.io.gcp import to_control_points
    from ground.io.orientations import read_orientations
    from ground.io.trajectory import read_trajectory
    from ground.report import write_report

    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(f"output folder {out_dir}: is a file, not a folder")
    lever, delay = parameter_specs(options)
    crsmod.parse_crs(options.crs)  # fail before the work on an unknown CRS
    traj = read_trajectory(str(inputs.trajectory), accept_single=options.accept_single)
    oset = read_orientations(inputs.orientations)
    events, matching = _read_events(inputs, options, [p.image for p in oset.poses])
    origin = np.asarray(traj.pos_ecef_m[0], dtype=float)
    tol = options.datum_tolerance_m
    crsmod.ecef_to_crs(origin, options.crs, max_datum_error_m=tol)  # missing geoid grid / datum mix: fail now
    crs_notes = crsmod.check_crs_covers(origin, options.crs)
    control = []
    if inputs.gcp is not None:
        control = to_control_points(read_control(inputs.gcp, inputs.gcp_rel, options.gcp_crs), origin,
                                    max_datum_error_m=tol)
    problem = build_problem(oset.poses, events, traj, control, origin_ecef_m=origin)
    adj_options = AdjustmentOptions(lever_arm=lever, delay=delay, relative_control=options.relative_control)
    result = adjust(problem, adj_options)
    if result.blunder_suspected and not options.accept_blunder:
        raise AdjustmentRefused(
            f"σ̂₀ = {result.sigma0:.3g}: the residuals are {result.sigma0:.3g}× the stated σ, a blunder remains "
            f"(a GCP, the base position, or inputs of different flights); no exports written"
            + (f"; GCPs excluded: {', '.join(g.name for g in result.excluded_gcps)}" if result.excluded_gcps else ""))

    _ensure_out_dir(out_dir)
    centres_enu = result.corrected_positions_enu_m(problem.centre_rel)
    r_enu = np.einsum("ij,njk->nik", result.rotation, problem.r_cam_to_rel)
    sigma = result.camera_sigma_enu_m  # the accuracy the adjustment reached, never the prior's
    cams = cameras_to_crs(problem.images, centres_enu, r_enu, origin, options.crs, sigma, max_datum_error_m=tol)
    exports = write_all(out_dir / "exports", cams, centres_enu, r_enu)
    results = result.to_dict()
    results["warnings"] = list(crs_notes) + results["warnings"]
    results["inputs"] = {
        "trajectory": str(inputs.trajectory), "events": str(inputs.events), "orientations": str(inputs.orientations),
        "orientation_format": oset.format, "gcp": str(inputs.gcp) if inputs.gcp else None,
        "gcp_crs": options.gcp_crs,
        "lever_arm": {"mode": lever.mode, "value_m": list(lever.value_m), "sigma_m": list(lever.sigma_m)},
        "delay": {"mode": delay.mode, "value_s": delay.value_s, "sigma_s": delay.sigma_s},
        "origin_ecef_m": [float(v) for v in origin], "export_crs": options.crs,
    }
    results["matching"] = matching
    results["skipped"] = [{"image": n, "reason": r} for n, r in problem.skipped]
    results["exports"] = {k: f"exports/{v}" if k != "micmac_frame" else v for k, v in exports.items()}
    results["cameras"] = [
        {"image": n, "x": float(p[0]), "y": float(p[1]), "z": float(p[2]),
         "sigma_h_m": float(sh), "sigma_v_m": float(sv)}
        for n, p, sh, sv in zip(cams.images, cams.xyz, cams.sigma_h_m, cams.sigma_v_m)
    ]
    write_atomic(out_dir / "results.json", json.dumps(results, indent=2, allow_nan=False) + "\n")
    write_report(out_dir / "report.html", results, problem=problem, trajectory=traj, origin_ecef_m=origin)
    return AdjustOutcome(results, out_dir)


# ------------------------------------------------------------------------------------------------ RTK


@dataclass(frozen=True)
class RtkInputs:
    """Rover and base observations (RINEX obs, UBX log or journal folder, e.g. a drone flight's own folder; the
    base also an RTCM3 stream or a corrections journal such as the flight's radio/) and RINEX navigation files
    (none: the ephemerides found in the rover and base data)."""

    rover: Path
    base: Path
    nav: tuple[Path, ...] = ()


@dataclass(frozen=True)
class RtkJobOptions:
    """Options of an RTK re-processing run, checked on construction (ValueError in `onboard.validate` words).

    `base_pos_ecef_m` the base antenna phase centre (ECEF m; None: the base file's header), `direction`
    forward/backward/combined (default combined: the backward pass carries the forward's fixes back over the
    epochs the forward spent confirming, as post-processing can and the drone cannot), `elmask_deg` the
    elevation mask (°), `velocity` write velocity columns,
    `static_start` the rover stands still from its first epoch until take-off (the engine's static start:
    no process noise until its Doppler speed exceeds the take-off speed; `onboard rtk --static-start`),
    `systems` the constellations as RINEX letters (`onboard rtk --systems`: "G" the LEA-6T's GPS, "GREJ" the
    M8T's; GLONASS is fixed on the assumption of one receiver type at both ends), or "auto": every one both
    receivers observed, as the drone's own real-time engine uses its receiver's.
    """

    base_pos_ecef_m: tuple[float, float, float] | None = None
    direction: str = "combined"
    elmask_deg: float = 15.0
    velocity: bool = True
    static_start: bool = False
    systems: str = RTK_SYSTEMS_AUTO

    def __post_init__(self) -> None:
        if self.systems != RTK_SYSTEMS_AUTO:
            object.__setattr__(self, "systems", validate.gnss_systems(self.systems))
        if self.base_pos_ecef_m is not None:
            object.__setattr__(self, "base_pos_ecef_m",
                               validate.ecef_position_m(self.base_pos_ecef_m, name="base position"))
        if self.direction not in RTK_DIRECTIONS:
            raise ValueError(f"direction {self.direction!r}: must be one of {', '.join(RTK_DIRECTIONS)}")
        validate.elevation_mask_deg(self.elmask_deg, name="elevation mask")


@dataclass(frozen=True)
class RtkOutcome:
    """What an RTK run wrote: the .pos path and the count of epochs by quality."""

    output: Path
    n_epochs: int
    n_fix: int
    n_float: int
    n_single: int
    n_none: int
    header: tuple[str, ...] = field(default=())
    systems: str = "G"
    """The constellations the engine used (RINEX letters)."""
    n_disputed: int = 0
    """Combined runs: epochs one pass fixed that the combination reports float, the two passes disagreeing on the
    integers there (RunStats.disputed, summed over the passes)."""

    def summary(self) -> str:
        """One line for a job's message."""
        n = max(self.n_epochs, 1)
        disputed = (f"; {self.n_disputed} fixes written as float: the forward and backward passes disagree there"
                    if self.n_disputed else "")
        return (f"{self.n_epochs} epochs: fix {self.n_fix} ({100 * self.n_fix / n:.1f} %), float {self.n_float}, "
                f"single {self.n_single}, no solution {self.n_none} (not written); systems {self.systems}"
                f"{disputed}; written {self.output.name}")


def run_rtk(inputs: RtkInputs, options: RtkJobOptions, output: Path) -> RtkOutcome:
    """Post-process rover + base with the onboard engine and write an RTKLIB .pos of its solution rows.

    Rows without a solution (Q=0) or with a non-finite position are not written. Raises `InputError` (unusable
    files), `RefusedByData` (no epoch has a solution). The .pos is written atomically.
    """
    from dataclasses import replace

    from onboard.errors import DataRefused
    from onboard.formats.pos import is_position, write_pos
    from onboard.postpro.inputs import load_rtk_inputs, observed_systems
    from onboard.rtk.options import RtkOptions
    from onboard.rtk.postpro import postprocess
    from onboard.rtk.types import Q_FIX, Q_FLOAT, Q_SINGLE

    try:
        run = load_rtk_inputs(inputs.rover, inputs.base, list(inputs.nav), options.base_pos_ecef_m,
                              base_pos_hint="base_pos X,Y,Z", nav_hint="a RINEX navigation file (role nav)",
                              systems=validate.GNSS_SYSTEM_LETTERS if options.systems == RTK_SYSTEMS_AUTO
                              else options.systems)
    except DataRefused as exc:
        raise RefusedByData(str(exc)) from None
    rov_gps, bas_gps, nav, base_pos_arr = run.rover, run.base, run.nav, run.base_pos_ecef_m
    # the engine leaves the constellations it is not given alone: the data read with all of them serve any choice
    systems = observed_systems(run) if options.systems == RTK_SYSTEMS_AUTO else options.systems
    rtk_options = replace(RtkOptions(), systems=systems, elmask_deg=options.elmask_deg,
                          ar_elmask_deg=max(options.elmask_deg, 15.0), static_start=options.static_start)
    sols, stats = postprocess(rov_gps, bas_gps, nav, base_pos_arr, rtk_options, options.direction)
    good = [s for s in sols if is_position(s)]
    q = np.array([s.q for s in sols], dtype=int)
    if not good:
        raise RefusedByData(f"no epoch of {len(sols)} has a position solution (wrong navigation day, base "
                            "position or base data?): no .pos written")
    bx, by, bz = (float(v) for v in base_pos_arr)
    chosen = f"{systems} (auto: both receivers')" if options.systems == RTK_SYSTEMS_AUTO else systems
    header = (f"program   : directgeo ground rtk job (L1, systems {chosen})", f"inp file  : {inputs.rover.name}",
              f"inp file  : {inputs.base.name}", *(f"inp file  : {n.name}" for n in inputs.nav),
              f"pos mode  : kinematic{' (static start)' if options.static_start else ''}",
              f"solution  : {options.direction}",
              f"elev mask : {options.elmask_deg:.1f} deg", f"ref pos   : {bx:14.4f} {by:14.4f} {bz:14.4f}", "",
              "(x/y/z-ecef=WGS84,Q=1:fix,2:float,5:single,sdx/sdy/sdz=std(m))", "")
    with atomic_output(output, "w") as fh:
        write_pos(fh, good, header, velocity=options.velocity)
    return RtkOutcome(output, len(sols), int(np.sum(q == Q_FIX)), int(np.sum(q == Q_FLOAT)),
                      int(np.sum(q == Q_SINGLE)), len(sols) - len(good), header, systems,
                      sum(s.disputed for s in stats))
