"""The API's job kinds: flight files chosen by name or manifest role, parameters checked (`schemas`), then the
pipeline's typed functions. `check_job` runs at submission (its ValueError is the 422); the job functions run
in the job runner's child process and check again (a job re-queued from an older server)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pydantic import ValidationError

from ground.api.schemas import AdjustParams, RtkParams
from ground.api.settings import ApiSettings
from ground.io.events import parse_capture_time
from ground.pipeline import AdjustInputs, RtkInputs, run_adjust, run_rtk
from onboard.errors import InputError

#: roles each kind needs (one of a tuple), and those it uses when present
ADJUST_NEEDS = ("events", "orientations")
RTK_NEEDS = ("rover_obs", "base_obs")


JOURNAL_ROLES = RTK_NEEDS
"""Roles whose files may be the segments of one journal folder (a drone flight: `NNNNNN.ubx` at the top for
the rover, `radio/NNNNNN.ubx` for the corrections it received): the job reads the folder, segments in order."""


def _journal_folder(names: list[str]) -> str | None:
    """The folder (relative, `.` for the flight's top) when `names` are all journal segments of one folder."""
    from onboard.logger.journal import is_segment_name

    folders = {n.rpartition("/")[0] or "." for n in names}
    if names and len(folders) == 1 and all(is_segment_name(n.rpartition("/")[2]) for n in names):
        return folders.pop()
    return None


def _pick(files: dict[str, str | None], name: str | None, role: str) -> str | None:
    """The flight file for `role`: the one named in the params, else the only one with that role; for the
    observation roles also a journal folder (named, or holding every file of that role)."""
    journal = role in JOURNAL_ROLES
    if name is not None:
        if name in files:
            return name
        if journal and any(_journal_folder([n]) == name for n in files):  # a folder holding journal segments
            return name
        raise InputError(f"{role} file {name!r} is not a completely uploaded file (or journal folder) of this flight")
    named = sorted(n for n, r in files.items() if r == role)
    folder = _journal_folder(named) if journal else None
    if folder is not None:
        return folder
    if len(named) > 1:
        raise InputError(f"several files have role {role!r} ({', '.join(named)}): name one in the job params")
    return named[0] if named else None


def _params(kind: str, params: dict[str, Any]) -> AdjustParams | RtkParams:
    model = AdjustParams if kind == "adjust" else RtkParams
    try:
        return model.model_validate(params)
    except ValidationError as exc:
        raise InputError("; ".join(f"{'.'.join(str(x) for x in e['loc']) or 'params'}: {e['msg']}"
                                   for e in exc.errors())) from None


def _adjust_files(p: AdjustParams, files: dict[str, str | None]) -> dict[str, str | None]:
    chosen = {role: _pick(files, getattr(p, role), role) for role in ("trajectory", "events", "orientations", "gcp",
                                                                        "gcp_rel")}
    chosen["capture_times"] = _pick(files, p.capture_times if isinstance(p.capture_times, str) else None,
                                    "capture_times")
    missing = [r for r in ADJUST_NEEDS if chosen[r] is None]
    if missing:
        raise InputError(f"missing uploaded {', '.join(missing)} (set roles in the manifest or name the files)")
    return chosen


def check_job(kind: str, params: dict[str, Any], files: dict[str, str | None]) -> None:
    """At submission: parameters valid and the files the job needs present, else InputError (→ 422)."""
    p = _params(kind, params)
    if isinstance(p, AdjustParams):
        chosen = _adjust_files(p, files)
        if chosen["trajectory"] is None and not any(r in ("rover_obs",) for r in files.values()):
            raise InputError("missing uploaded trajectory (role trajectory) and no rover/base data for an RTK job")
    else:
        missing = [r for r in RTK_NEEDS if _pick(files, getattr(p, r), r) is None]
        if missing:
            raise InputError(f"RTK re-processing needs uploaded {', '.join(missing)} (no base data: nothing to do)")


def adjust_job(settings: ApiSettings, params: dict[str, Any], files: dict[str, str | None], flight_dir: Path,
               out_dir: Path) -> str:
    """API job: the adjustment on a flight's uploaded files."""
    p = _params("adjust", params)
    assert isinstance(p, AdjustParams)
    chosen = _adjust_files(p, files)
    trajectory = flight_dir / chosen["trajectory"] if chosen["trajectory"] else reprocessed_trajectory(out_dir)
    if trajectory is None:
        raise InputError("missing uploaded trajectory (set role trajectory) and no RTK job output for this flight")
    caps: Any = None
    if isinstance(p.capture_times, dict):
        caps = {k: parse_capture_time(v) for k, v in p.capture_times.items()}
    elif chosen["capture_times"]:
        caps = flight_dir / chosen["capture_times"]
    inputs = AdjustInputs(
        trajectory=trajectory, events=flight_dir / str(chosen["events"]),
        orientations=flight_dir / str(chosen["orientations"]),
        gcp=flight_dir / chosen["gcp"] if chosen["gcp"] else None,
        gcp_rel=flight_dir / chosen["gcp_rel"] if chosen["gcp_rel"] else None, capture_times=caps)
    return run_adjust(inputs, p.job_options(), out_dir).summary()


def reprocessed_trajectory(out_dir: Path) -> Path | None:
    """The newest `SOL.pos` written by an RTK job of the same flight (sibling job folders), if any."""
    sols = sorted((q for q in out_dir.parent.glob("*/SOL.pos") if not q.parent.name.startswith(".")),
                  key=lambda q: q.stat().st_mtime)  # ".incoming-…": a worker's outputs being installed
    return sols[-1] if sols else None


def rtk_job(settings: ApiSettings, params: dict[str, Any], files: dict[str, str | None], flight_dir: Path,
            out_dir: Path) -> str:
    """API job: RTK re-processing of the uploaded rover/base observations; writes `SOL.pos` (with velocities)."""
    p = _params("rtk", params)
    assert isinstance(p, RtkParams)
    chosen = {role: _pick(files, getattr(p, role), role) for role in ("rover_obs", "base_obs", "nav")}
    missing = [r for r in RTK_NEEDS if chosen[r] is None]
    if missing:
        raise InputError(f"RTK re-processing needs uploaded {', '.join(missing)} (no base data: nothing to do)")
    inputs = RtkInputs(rover=flight_dir / str(chosen["rover_obs"]), base=flight_dir / str(chosen["base_obs"]),
                       nav=(flight_dir / chosen["nav"],) if chosen["nav"] else ())
    return run_rtk(inputs, p.job_options(), out_dir / "SOL.pos").summary()
