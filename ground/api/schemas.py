"""Pydantic request/response schemas of the ground API (separate from the ORM models and internal dataclasses)."""

from __future__ import annotations

import datetime as dt
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from ground.io.crs import MAX_DATUM_ERROR_M, WGS84_ECEF
from ground.io.events import parse_capture_time
from ground.pipeline import AdjustJobOptions, RtkJobOptions, parameter_specs
from onboard import validate
from onboard.errors import InputError


class ManifestFile(BaseModel):
    """A file the flight will upload: name (a relative path of the flight folder), size in bytes, SHA-256 (hex),
    optional role."""

    name: str = Field(description="file name relative to the flight folder, e.g. events.jsonl or radio/000000.ubx "
                                  "(components of letters, digits, . _ + -; no .., leading dot, \\, NUL)")
    size: int = Field(ge=0, description="size in bytes")
    sha256: str = Field(description="SHA-256 of the whole file, 64 hex digits")
    role: str | None = Field(default=None, description="trajectory | events | orientations | gcp | rover_obs | "
                             "base_obs | nav | raw | …")


class FlightCreate(BaseModel):
    """Create (or re-open, when identical) a flight from its upload manifest."""

    name: str = Field(min_length=1, max_length=200, description="flight name, e.g. flight-20240501T101500Z")
    files: list[ManifestFile]
    meta: dict[str, Any] = Field(default_factory=dict, description="free metadata (receiver, onboard manifest)")


class FilesAdd(BaseModel):
    """File entries to add to an existing flight (then uploaded by PUT like the manifest's)."""

    files: list[ManifestFile]


class FileOut(BaseModel):
    """Upload state of one file."""

    name: str
    role: str | None
    size: int
    sha256: str
    received: int
    status: Literal["pending", "partial", "complete"]


class JobOut(BaseModel):
    """A processing job and its status."""

    id: str
    kind: str
    status: Literal["queued", "running", "done", "failed"]
    params: dict[str, Any]
    message: str
    created_at: dt.datetime
    started_at: dt.datetime | None
    finished_at: dt.datetime | None


class OutputFileOut(BaseModel):
    """One output file of a job: path relative to the job's folder, size (bytes), SHA-256 (hex)."""

    name: str
    size: int
    sha256: str


class JobInputFile(BaseModel):
    """A file a worker fetches for a job: a flight file (`job_id` None, from `/files/{name}/content`) or an
    output of an earlier job of the flight (`/jobs/{job_id}/outputs/{name}`), with its size and SHA-256."""

    name: str
    role: str | None = None
    size: int
    sha256: str
    job_id: str | None = None


class JobSpec(BaseModel):
    """What a worker needs to run a job: kind, parameters, time limit (s) and the files to fetch."""

    job_id: str
    flight_id: str
    kind: str
    params: dict[str, Any]
    time_limit_s: float
    files: list[JobInputFile]
    earlier_outputs: list[JobInputFile]


class JobFinish(BaseModel):
    """A worker's final word on a job: done or failed, with the job's message."""

    model_config = ConfigDict(extra="forbid")

    status: Literal["done", "failed"]
    message: str = Field(max_length=100_000)


class FlightOut(BaseModel):
    """A flight with its files and jobs."""

    id: str
    name: str
    status: str
    created_at: dt.datetime
    created_by: str | None = Field(default=None, description="name of the token that created the flight (a "
                                   "drone's name for its uploads; None: the bootstrap token)")
    files: list[FileOut]
    jobs: list[JobOut]


class FlightSummary(BaseModel):
    """One line of the flight list."""

    id: str
    name: str
    status: str
    created_at: dt.datetime
    created_by: str | None = Field(default=None, description="name of the token that created the flight")
    files: int
    bytes_total: int
    bytes_received: int


class JobCreate(BaseModel):
    """Start a job: `kind` and its `params` (see `AdjustParams`, `RtkParams`; checked at submission, 422)."""

    kind: Literal["adjust", "rtk"]
    params: dict[str, Any] = Field(default_factory=dict)


class AdjustParams(BaseModel):
    """Parameters of an `adjust` job: file names of the flight (default: the file with that manifest role) and
    the options of `python -m ground adjust`. Values are checked as on the command line (finite, with units)."""

    model_config = ConfigDict(extra="forbid")

    trajectory: str | None = Field(default=None, description="RTKLIB .pos (default: role trajectory, else the "
                                   "flight's last RTK job output)")
    events: str | None = Field(default=None, description="events.jsonl or CSV image,week,tow (role events)")
    orientations: str | None = Field(default=None, description="bundle adjustment file (role orientations)")
    gcp: str | None = Field(default=None, description="GCP file (role gcp)")
    gcp_rel: str | None = Field(default=None, description="relative GCP CSV for ODM/MicMac GCP files (role gcp_rel)")
    capture_times: str | dict[str, str] | None = Field(
        default=None, description="to match events.jsonl to the images: a file of the flight (CSV/JSON, role "
        "capture_times) or {image: camera clock time, EXIF 'YYYY:MM:DD HH:MM:SS' or ISO 8601}")
    lever_arm: tuple[float, float, float] | None = Field(default=None, description="dx,dy,dz (m), camera frame")
    lever_arm_sigma: float | None = Field(default=None, description="σ (m) making lever_arm a prior")
    delay: float | None = Field(default=None, description="shutter delay t_d (s)")
    delay_sigma: float | None = Field(default=None, description="σ (s) making delay a prior")
    estimate: list[Literal["lever-arm", "delay"]] = Field(default_factory=list)
    crs: str = Field(default="EPSG:4979", description="CRS of the exports")
    gcp_crs: str = Field(default=WGS84_ECEF, description="CRS of the GCP ground coordinates")
    relative_control: bool = False
    events_kind: Literal["trigger", "flash"] = "trigger"
    datum_tolerance_m: float = MAX_DATUM_ERROR_M
    accept_single: bool = False
    accept_blunder: bool = False

    @model_validator(mode="after")
    def _check(self) -> AdjustParams:
        options = self.job_options()  # ValueError in onboard.validate's words → 422
        try:
            parameter_specs(options)
        except InputError as exc:  # a value/σ/estimate rule
            raise ValueError(str(exc)) from None
        if isinstance(self.capture_times, dict):
            for image, text in self.capture_times.items():
                if parse_capture_time(text) is None:
                    raise ValueError(f"capture_times[{image!r}] {text!r}: must be 'YYYY:MM:DD HH:MM:SS' or ISO 8601")
        return self

    def job_options(self) -> AdjustJobOptions:
        """The pipeline's options of these parameters."""
        return AdjustJobOptions(
            lever_arm_m=self.lever_arm, lever_arm_sigma_m=self.lever_arm_sigma, delay_s=self.delay,
            delay_sigma_s=self.delay_sigma, estimate=tuple(self.estimate), crs=self.crs, gcp_crs=self.gcp_crs,
            relative_control=self.relative_control, events_kind=self.events_kind,
            datum_tolerance_m=self.datum_tolerance_m, accept_single=self.accept_single,
            accept_blunder=self.accept_blunder)


class RtkParams(BaseModel):
    """Parameters of an `rtk` job: file names (default: by role rover_obs, base_obs, nav) and options."""

    model_config = ConfigDict(extra="forbid")

    rover_obs: str | None = Field(default=None, description="rover observations: a file of the flight, or a "
                                  "folder of its journal segments ('.' = the drone's own journal; default: role "
                                  "rover_obs)")
    base_obs: str | None = Field(default=None, description="base observations: a file or a journal folder, e.g. "
                                 "'radio' = the corrections the drone received (default: role base_obs)")
    nav: str | None = Field(default=None, description="RINEX navigation (role nav; default: the ephemerides in "
                            "the rover and base data)")
    base_pos: str | tuple[float, float, float] | None = Field(
        default=None, description="base antenna phase centre, ECEF m: 'X,Y,Z' or [X, Y, Z] (default: the base "
        "file's header)")
    direction: Literal["forward", "backward", "combined"] = Field(
        default="combined", description="processing direction: combined (default: forward and backward, the "
        "backward pass carrying the forward's fixes back), forward (as the drone computed it) or backward")
    elmask_deg: float = Field(default=15.0, description="elevation mask (°, 0–90)")
    static_start: bool = Field(default=False, description="the rover stands still from its first epoch until "
                               "take-off (a drone recording from power-on on the ground): held static until its "
                               "Doppler speed says it moves")
    systems: str = Field(default="auto", description="constellations, RINEX letters: G GPS, R GLONASS, E Galileo, "
                         "C BeiDou, J QZSS (e.g. 'G' for a LEA-6T, 'GREJ' for an M8T; leave R out unless the base "
                         "receiver is of the rover's type), or 'auto' (default): every one both receivers observed")

    @model_validator(mode="after")
    def _check(self) -> RtkParams:
        self.job_options()
        return self

    def job_options(self) -> RtkJobOptions:
        """The pipeline's options of these parameters."""
        pos = None if self.base_pos is None else validate.ecef_position_m(self.base_pos, name="base_pos")
        return RtkJobOptions(base_pos_ecef_m=pos, direction=self.direction, elmask_deg=self.elmask_deg,
                             static_start=self.static_start, systems=self.systems)


class ErrorOut(BaseModel):
    """Error body."""

    detail: str
