"""FastAPI app of the pre-flight check page: `create_app(status_path)`; reads the snapshot on each request."""

from __future__ import annotations

import logging
import os
import time
from importlib import resources
from pathlib import Path
from typing import Any

from fastapi import FastAPI
from fastapi.responses import HTMLResponse

from onboard.recorder.status import DEFAULT_STATUS_PATH, read_feature_status, read_rtk_status, read_status
from onboard.web.checks import (
    AUTOPILOT,
    UPLOAD,
    PreflightOptions,
    blocks,
    checks_json,
    headline,
    overall,
    preflight_checks,
    unreadable_snapshot,
)

log = logging.getLogger(__name__)


def _load(status_path: Path) -> tuple[dict[str, Any] | None, str | None, bool]:
    """(snapshot, error, unreadable): unreadable when the file exists but cannot be used."""
    try:
        return read_status(status_path), None, False
    except FileNotFoundError:
        return None, f"{status_path} does not exist", False
    except (ValueError, OSError) as exc:  # half-written by a foreign tool, unreadable, wrong schema or types
        return None, f"status snapshot unreadable: {exc}", True


def _load_beside(status_path: Path, name: str) -> dict[str, Any] | None:
    """A feature's JSON snapshot beside status.json: None when absent (the feature is not configured),
    {"unreadable": why} when it is not a JSON object (torn, foreign, unreadable)."""
    try:
        obj = read_feature_status(status_path, name)
    except (ValueError, OSError) as exc:
        return {"unreadable": f"{name}: {exc}"}
    except TypeError:
        return {"unreadable": f"{name} is not a JSON object of ours"}
    if obj is not None and "unreadable" in obj:
        return {"unreadable": f"{name} is not a JSON object of ours"}
    return obj


def create_app(status_path: Path | None = None, options: PreflightOptions | None = None,
               base_stream: str | None = None) -> FastAPI:
    """The status web app for the snapshot at `status_path` (default: `$ONBOARD_STATUS_PATH`, else the
    recorder's default /run/directgeo/status.json), so `uvicorn --factory onboard.web.app:create_app` works.
    `base_stream` is the recorder's `rtk.base_stream` (default `$ONBOARD_RTK_BASE_STREAM`, the recorder's own
    variable), shown without credentials as the base-correction source."""
    if status_path is None:
        status_path = Path(os.environ.get("ONBOARD_STATUS_PATH", str(DEFAULT_STATUS_PATH)))
    if base_stream is None:
        base_stream = os.environ.get("ONBOARD_RTK_BASE_STREAM")
    options = options or PreflightOptions()
    app = FastAPI(title="directgeo pre-flight check", version="1")
    page = resources.files("onboard.web").joinpath("preflight.html").read_text(encoding="utf-8")

    @app.get("/", response_class=HTMLResponse)
    def index() -> str:
        """The pre-flight check page (refreshes itself from /api/preflight)."""
        return page

    @app.get("/api/preflight")
    def preflight() -> dict[str, Any]:
        """Checks derived from the current snapshot, their overall level, and the snapshot itself."""
        status, error, unreadable = _load(status_path)
        rtk = None
        if status is not None:
            try:
                rtk = read_rtk_status(status_path)
            except (ValueError, TypeError, OSError) as exc:  # torn or foreign rtk.json: say so, keep the rest
                rtk = {"unreadable": str(exc)}
        autopilot = _load_beside(status_path, AUTOPILOT) if status is not None else None
        upload = _load_beside(status_path, UPLOAD) if status is not None else None
        if unreadable:
            checks = unreadable_snapshot(str(error))
        else:
            checks = preflight_checks(status, time.time_ns(), options, rtk, autopilot, upload, base_stream)
        return {"overall": overall(checks), "headline": headline(checks), "checks": checks_json(checks),
                "blocks": blocks(status, rtk, autopilot, upload, base_stream), "status": status, "rtk": rtk,
                "autopilot": autopilot, "upload": upload, "error": error}

    @app.get("/api/status")
    def status() -> dict[str, Any]:
        """The raw status snapshot (404-like empty object with an error when absent)."""
        snap, error, _ = _load(status_path)
        return snap if snap is not None else {"error": error}

    return app
