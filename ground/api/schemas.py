"""Pydantic request/response schemas of the ground API (separate from the ORM models and internal dataclasses)."""

from __future__ import annotations

import datetime as dt
from typing import Any, Literal

from pydantic import BaseModel, Field


class ManifestFile(BaseModel):
    """A file the flight will upload: name (one path component), size in bytes, SHA-256 (hex), optional role."""

    name: str = Field(description="file name, a single path component (no /, .., NUL)")
    size: int = Field(ge=0, description="size in bytes")
    sha256: str = Field(description="SHA-256 of the whole file, 64 hex digits")
    role: str | None = Field(default=None, description="trajectory | events | orientations | gcp | raw | …")


class FlightCreate(BaseModel):
    """Create (or re-open, when identical) a flight from its upload manifest."""

    name: str = Field(min_length=1, max_length=200, description="flight name, e.g. flight-20240501T101500Z")
    files: list[ManifestFile]
    meta: dict[str, Any] = Field(default_factory=dict, description="free metadata (receiver, onboard manifest)")


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


class FlightOut(BaseModel):
    """A flight with its files and jobs."""

    id: str
    name: str
    status: str
    created_at: dt.datetime
    files: list[FileOut]
    jobs: list[JobOut]


class FlightSummary(BaseModel):
    """One line of the flight list."""

    id: str
    name: str
    status: str
    created_at: dt.datetime
    files: int
    bytes_total: int
    bytes_received: int


class JobCreate(BaseModel):
    """Start a job. `adjust` params: trajectory/events/orientations/gcp file names (default: by manifest role)
    and the `python -m ground adjust` options (lever_arm, lever_arm_sigma, delay, delay_sigma, estimate, crs,
    gcp_crs). `rtk` re-processes the trajectory from uploaded rover/base observations and navigation data."""

    kind: Literal["adjust", "rtk"]
    params: dict[str, Any] = Field(default_factory=dict)


class ErrorOut(BaseModel):
    """Error body."""

    detail: str
