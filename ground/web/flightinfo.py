"""What the web pages show of a flight, derived from what the store and the flight's files hold.

Nothing here is stored: the store has the manifest (names, sizes, SHA-256, roles, `meta`), the upload state of
each file and the jobs; the rest is read from the completely uploaded files and the jobs' outputs, cached by the
file's SHA-256 (a complete file never changes). How each column is derived:

- **state**: `uploading` while a file is incomplete; `processing` while a job is queued or running; otherwise
  the newest job's end (`done` / `failed`); `uploaded` when every file is in and no job ever ran.
- **drone**: the name of the token that created the flight (a drone's own token), else the manifest's
  `meta.drone` (or `meta.drone_id`), else the receiver named in an uploaded onboard `manifest.json` (role
  manifest), else unknown.
- **date**, **duration**: first and last epoch of the trajectory (below), in UTC; without one, the date is the
  `YYYYMMDDTHHMMSSZ` stamp of the flight name (onboard names flights so), else the day the server created it.
- **fix ratio**: epochs with Q = 1 (fix) among the epochs with a solution in the trajectory: the post-processed
  one (`SOL.pos` of the newest finished RTK job) when there is one, else the uploaded real-time one (role
  trajectory).
- **images**: image marks of the uploaded events file (role events: onboard `events.jsonl` or an
  image,week,tow CSV).
"""

from __future__ import annotations

import datetime as dt
import functools
import json
import logging
import re
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ground.store import Flight, FlightFile, Job
from onboard.errors import InputError
from onboard.gnsstime import GpsTime

log = logging.getLogger(__name__)

STATES = ("uploading", "uploaded", "processing", "done", "failed")
_NAME_STAMP = re.compile(r"(\d{8}T\d{6})Z")


def flight_state(file_statuses: list[str], job_statuses: list[str]) -> str:
    """The flight's state from its files' upload states and its jobs' states (oldest job first)."""
    if any(s != "complete" for s in file_statuses):
        return "uploading"
    if any(s in ("queued", "running") for s in job_statuses):
        return "processing"
    if job_statuses:
        return "done" if job_statuses[-1] == "done" else "failed"
    return "uploaded"


@dataclass(frozen=True)
class TrackStats:
    """Epoch counts by RTKLIB quality of a .pos file and its time span (UTC)."""

    epochs: int
    fix: int
    float_: int
    single: int
    other: int
    start_utc: dt.datetime
    end_utc: dt.datetime

    @property
    def fix_ratio(self) -> float:
        """Fix epochs / epochs with a solution (0–1)."""
        return self.fix / self.epochs if self.epochs else 0.0

    @property
    def duration_s(self) -> float:
        """Last minus first epoch (s)."""
        return (self.end_utc - self.start_utc).total_seconds()


@functools.lru_cache(maxsize=512)
def _track_stats(path: str, sha256: str) -> TrackStats:
    from ground.io.trajectory import read_trajectory

    traj = read_trajectory(path, accept_single=True)
    q = np.asarray(traj.q)
    return TrackStats(int(q.size), int(np.sum(q == 1)), int(np.sum(q == 2)), int(np.sum(q == 5)),
                      int(np.sum(~np.isin(q, (1, 2, 5)))), GpsTime.from_total_ns(int(traj.t_ns[0])).to_utc(),
                      GpsTime.from_total_ns(int(traj.t_ns[-1])).to_utc())


def track_stats(path: Path, sha256: str) -> TrackStats | str:
    """The stats of a trajectory file, or why it cannot be read (in words, without the server's paths)."""
    try:
        return _track_stats(str(path), sha256)
    except (InputError, OSError, ValueError, IndexError) as exc:
        return f"{path.name}: {getattr(exc, 'detail', exc)}"


@functools.lru_cache(maxsize=512)
def _image_count(path: str, sha256: str) -> int:
    from ground.io.events import read_events_csv, read_marks_jsonl

    p = Path(path)
    return len(read_marks_jsonl(p)) if p.suffix.lower() == ".jsonl" else len(read_events_csv(p))


def image_count(path: Path, sha256: str) -> int | None:
    """Image marks in an events file; None when it cannot be read (the flight page says why)."""
    try:
        return _image_count(str(path), sha256)
    except (InputError, OSError, ValueError):
        return None


@dataclass(frozen=True)
class EventSummary:
    """An onboard events.jsonl in short: record counts by type/event, the non-mark records (flight, autopilot),
    and the lines skipped as torn or corrupt."""

    counts: list[tuple[str, int]]
    notable: list[dict[str, Any]]
    skipped_lines: int


#: record types of events.jsonl listed one by one on the flight page (the marks are only counted)
NOTABLE_TYPES = ("flight", "autopilot", "camera_check")


@functools.lru_cache(maxsize=128)
def _events(path: str, sha256: str) -> EventSummary:
    from onboard.logger.events import read_events

    got = read_events(Path(path))
    counts = Counter(" / ".join(str(r[k]) for k in ("type", "event") if k in r) or "(untyped)" for r in got.records)
    notable = [r for r in got.records if r.get("type") in NOTABLE_TYPES][:200]
    return EventSummary(sorted(counts.items()), notable, got.skipped_lines)


def event_summary(path: Path, sha256: str) -> EventSummary | None:
    """The summary of an onboard events.jsonl (None for another events format)."""
    if path.suffix.lower() != ".jsonl":
        return None
    return _events(str(path), sha256)


@functools.lru_cache(maxsize=64)
def _trajectory_plot(path: str, key: str) -> str:
    from ground.io.trajectory import read_trajectory
    from ground.report import figure_data_uri, trajectory_figure

    traj = read_trajectory(path, accept_single=True)
    return figure_data_uri(trajectory_figure(traj, np.asarray(traj.pos_ecef_m[0], dtype=float), None))


def trajectory_plot(path: Path, key: str) -> str | None:
    """The report's trajectory figure (E/N about the first epoch, coloured by fix status) as a PNG data URI;
    None when the file cannot be read (`track_stats` says why)."""
    try:
        return _trajectory_plot(str(path), key)
    except (InputError, OSError, ValueError, IndexError):
        return None


def _aware(t: dt.datetime) -> dt.datetime:
    return t if t.tzinfo is not None else t.replace(tzinfo=dt.UTC)


@dataclass(frozen=True)
class FlightRow:
    """One line of the flights list (see the module docstring for how each value is derived)."""

    id: str
    name: str
    drone: str | None
    date: dt.date
    date_source: str
    duration_s: float | None
    images: int | None
    fix_ratio: float | None
    fix_source: str | None
    state: str
    files: int
    bytes_total: int
    bytes_received: int
    created_at: dt.datetime


def _drone(flight: Flight, files_dir: Path) -> str | None:
    if flight.creator is not None:  # the token that created the flight (None: the bootstrap token)
        return flight.creator.name
    meta = (flight.manifest or {}).get("meta") or {}
    for key in ("drone", "drone_id"):
        if isinstance(meta.get(key), str) and meta[key].strip():
            return str(meta[key]).strip()
    for f in flight.files:
        if f.role == "manifest" and f.status == "complete":
            try:
                receiver = json.loads((files_dir / f.name).read_text(encoding="utf-8")).get("receiver") or {}
            except (OSError, ValueError, AttributeError):
                continue
            if isinstance(receiver, dict):
                ident = receiver.get("unique_id") or receiver.get("serial") or receiver.get("name")
                if ident:
                    return f"receiver {ident}"
    return None


def trajectories(flight: Flight, files_dir: Path, outputs_dir: Path) -> list[tuple[str, str, Path, str]]:
    """The flight's trajectories as (label, source, path, cache key): the uploaded real-time ones (role
    trajectory), then the post-processed `SOL.pos` of the newest finished RTK job."""
    out = [("real-time (uploaded)", f.name, files_dir / f.name, f.sha256) for f in flight.files
           if f.role == "trajectory" and f.status == "complete"]
    done = [j for j in flight.jobs if j.kind == "rtk" and j.status == "done"]
    if done:
        sol = outputs_dir / done[-1].id / "SOL.pos"
        if sol.is_file():
            st = sol.stat()
            out.append(("post-processed (RTK job)", f"RTK job {done[-1].id[:8]}", sol,
                        f"{done[-1].id}:{st.st_size}:{st.st_mtime_ns}"))
    return out


def flight_row(flight: Flight, files_dir: Path, outputs_dir: Path) -> FlightRow:
    """The list line of a flight whose files, jobs and creator are loaded."""
    files: list[FlightFile] = list(flight.files)
    jobs: list[Job] = list(flight.jobs)
    stats: TrackStats | None = None
    fix_source = None
    for label, _, path, key in reversed(trajectories(flight, files_dir, outputs_dir)):
        got = track_stats(path, key)
        if isinstance(got, TrackStats):
            stats, fix_source = got, label
            break
    images = None
    for f in files:
        if f.role == "events" and f.status == "complete":
            images = image_count(files_dir / f.name, f.sha256)
            break
    created = _aware(flight.created_at)
    if stats is not None:
        date, date_source = stats.start_utc.date(), "first trajectory epoch"
    elif (m := _NAME_STAMP.search(flight.name)) is not None:
        date, date_source = dt.datetime.strptime(m.group(1), "%Y%m%dT%H%M%S").date(), "flight name"
    else:
        date, date_source = created.date(), "arrival at the server"
    return FlightRow(
        id=flight.id, name=flight.name, drone=_drone(flight, files_dir), date=date, date_source=date_source,
        duration_s=stats.duration_s if stats else None, images=images,
        fix_ratio=stats.fix_ratio if stats else None, fix_source=fix_source,
        state=flight_state([f.status for f in files], [j.status for j in jobs]), files=len(files),
        bytes_total=sum(f.size for f in files), bytes_received=sum(f.received for f in files), created_at=created)


@dataclass(frozen=True)
class FlightFilter:
    """Filters of the flights list (None: any)."""

    state: str | None = None
    drone: str | None = None
    date_from: dt.date | None = None
    date_to: dt.date | None = None

    def keeps(self, row: FlightRow) -> bool:
        """Whether a row passes every filter (drone: case-insensitive substring; dates inclusive)."""
        if self.state and row.state != self.state:
            return False
        if self.drone and (row.drone is None or self.drone.lower() not in row.drone.lower()):
            return False
        if self.date_from and row.date < self.date_from:
            return False
        return not (self.date_to and row.date > self.date_to)
