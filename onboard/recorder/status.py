"""The recorder's status snapshot: a dataclass schema, written atomically as JSON for the status web page.

The recorder never serves HTTP: a separate small web process reads this file, so a web fault cannot stop
recording. `write_status` writes a temp file and renames it over the target, so a reader sees either the old
or the new snapshot, never a half-written one.
"""

from __future__ import annotations

import dataclasses
import json
import math
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from onboard.formats.atomic import write_json_atomic

STATUS_SCHEMA = "directgeo-status/1"
DEFAULT_STATUS_PATH = Path("/run/directgeo/status.json")
"""Where the recorder writes its snapshot and the pre-flight page reads it (systemd's RuntimeDirectory)."""
STALE_AFTER_S = 5.0
"""A snapshot older than this (s) means the recorder stalled or stopped (the pre-flight page's verdict); the
recorder's `status.interval_s` is therefore at most half of it."""
RTK_STATUS_NAME = "rtk.json"
"""The real-time RTK snapshot (`onboard.realtime.service.RtkStatus`), written beside the recorder's status snapshot."""
STATES = ("starting", "recording", "port_lost", "disk_full", "stopped", "error")
CONFIG_STATES = ("disabled", "pending", "detecting", "configuring", "verified", "failed")


@dataclass
class SatelliteStatus:
    """One tracked satellite of the last epoch: `gnss_id` u-blox GNSS id, `sv_id`, `cn0_dbhz` C/N0."""

    gnss_id: int
    sv_id: int
    cn0_dbhz: float


@dataclass
class StatusSnapshot:
    """What the recorder is doing (JSON schema `directgeo-status/1`).

    `state` one of STATES; `message` why (e.g. the port error, "disk full"); `receiver_*` from MON-VER;
    `config_state` one of CONFIG_STATES with `config_error` naming the failing message and field;
    counters since start; `last_epoch_gpst` "week:tow_s" text of the last raw epoch; `satellites` of that
    epoch; `time_marks` TIM-TM2 edges seen; `aid_eph_polls` backup AID-EPH polls sent; `disk_free_bytes` of
    the data directory.
    """

    schema: str = STATUS_SCHEMA
    pid: int = 0
    updated_wall_ns: int = 0
    started_wall_ns: int = 0
    state: str = "starting"
    message: str | None = None
    flight: str | None = None
    flight_dir: str | None = None
    segment: str | None = None
    port_device: str = ""
    port_open: bool = False
    port_error: str | None = None
    port_reconnects: int = 0
    receiver_model: str | None = None
    receiver_sw_version: str | None = None
    receiver_hw_version: str | None = None
    receiver_extensions: list[str] = field(default_factory=list)
    config_state: str = "pending"
    config_error: str | None = None
    config_report: dict[str, Any] | None = None
    bytes_recorded: int = 0
    frames: int = 0
    skipped_bytes: int = 0
    decode_failures: int = 0
    epochs: int = 0
    last_epoch_gpst: str | None = None
    last_epoch_week: int | None = None
    last_epoch_tow_s: float | None = None
    satellites: list[SatelliteStatus] = field(default_factory=list)
    time_marks: int = 0
    last_mark_gpst: str | None = None
    aid_eph_polls: int = 0
    events: int = 0
    journal_syncs: int = 0
    disk_free_bytes: int | None = None
    disk_floor_bytes: int = 0
    feature_errors: dict[str, int] = field(default_factory=dict)
    """Exceptions in each recorder feature's hooks (`onboard.recorder.feature`), by feature name."""

    def to_json(self) -> dict[str, Any]:
        """JSON-able dict."""
        return dataclasses.asdict(self)


def write_status(path: Path, snapshot: StatusSnapshot | dict[str, Any]) -> None:
    """Write a snapshot (the recorder's, or a feature's JSON dict such as `rtk.json`) atomically: temp file in the
    same directory + rename. Not fsync'd: a snapshot lives in /run (tmpfs) and is rewritten every second."""
    obj = snapshot.to_json() if isinstance(snapshot, StatusSnapshot) else snapshot
    write_json_atomic(path, obj, fsync=False)


class SnapshotError(ValueError):
    """A snapshot that cannot be used: not JSON, not ours, or `field` holding a value of the wrong kind (`why`)."""

    def __init__(self, field: str, why: str) -> None:
        self.field = field
        self.why = why
        super().__init__(f"{field}: {why}" if field else why)


def _reject_constant(name: str) -> float:
    raise ValueError(f"{name} is not a number JSON allows")


def _loads(data: bytes) -> Any:
    """JSON as strict as the web answer must be: NaN/Infinity and absurd nesting are refused (ValueError)."""
    try:
        return json.loads(data, parse_constant=_reject_constant)
    except RecursionError:
        raise ValueError("nested too deeply") from None
    except UnicodeDecodeError as exc:
        raise ValueError(f"not UTF-8 (byte {exc.start})") from None


def _why_not(value: Any, hint: Any) -> str | None:
    """Why `value` (from JSON) is not of type `hint` (a StatusSnapshot field's), None when it is."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        reasons = [_why_not(value, a) for a in args]
        if None in reasons:
            return None
        named = [r for r in reasons if r is not None and not r.startswith("must be null")]
        return named[0] if named else reasons[0]
    if hint is type(None):
        return None if value is None else f"must be null, got {value!r}"
    if hint is bool:
        return None if isinstance(value, bool) else f"must be true or false, got {value!r}"
    if hint is int:
        ok = isinstance(value, int) and not isinstance(value, bool)
        return None if ok else f"must be a whole number, got {value!r}"
    if hint is float:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        return None if ok else f"must be a number, got {value!r}"
    if hint is str:
        return None if isinstance(value, str) else f"must be text, got {value!r}"
    if origin is list:
        if not isinstance(value, list):
            return f"must be a list, got {value!r}"
        for i, item in enumerate(value):
            why = _why_not(item, args[0])
            if why is not None:
                return f"item {i}: {why}"
        return None
    if origin is dict or hint is dict:
        return None if isinstance(value, dict) else f"must be an object, got {value!r}"
    if dataclasses.is_dataclass(hint):
        if not isinstance(value, dict):
            return f"must be an object, got {value!r}"
        hints = typing.get_type_hints(hint)
        for f in dataclasses.fields(hint):
            if f.name not in value:
                return f"{f.name}: missing"
            why = _why_not(value[f.name], hints[f.name])
            if why is not None:
                return f"{f.name}: {why}"
        return None
    return None  # Any


def check_snapshot(obj: Any) -> dict[str, Any]:
    """`obj` (parsed JSON) as a snapshot whose every known field has its StatusSnapshot type; fields may be
    missing (the page then says "unknown") and unknown ones (a feature's) pass. Raises SnapshotError."""
    if not isinstance(obj, dict):
        raise SnapshotError("", f"not a {STATUS_SCHEMA} snapshot (a JSON {type(obj).__name__})")
    if obj.get("schema") != STATUS_SCHEMA:
        raise SnapshotError("schema", f"must be {STATUS_SCHEMA!r}, got {obj.get('schema')!r}")
    hints = typing.get_type_hints(StatusSnapshot)
    for f in dataclasses.fields(StatusSnapshot):
        if f.name in obj:
            why = _why_not(obj[f.name], hints[f.name])
            if why is not None:
                raise SnapshotError(f.name, why)
    return obj


def read_status(path: Path) -> dict[str, Any]:
    """The last snapshot as a dict, every known field of its type (FileNotFoundError when absent, OSError when
    unreadable, SnapshotError (a ValueError) when not JSON, not ours or a field is of the wrong kind)."""
    data = Path(path).read_bytes()
    try:
        obj = _loads(data)
    except ValueError as exc:
        raise SnapshotError("", f"not valid JSON: {exc}") from None
    return check_snapshot(obj)


def read_feature_status(status_path: Path, name: str) -> dict[str, Any] | None:
    """A feature's snapshot `name` (rtk.json, autopilot.json, upload.json) beside the status snapshot at
    `status_path`, None when the feature is not running (no file). Raises ValueError when it is not strict JSON
    (half-written, foreign), TypeError when not a JSON object, OSError when unreadable."""
    try:
        obj = _loads(Path(status_path).with_name(name).read_bytes())
    except FileNotFoundError:
        return None
    if not isinstance(obj, dict):
        raise TypeError(f"{name} is not a JSON object")
    return obj


def read_rtk_status(status_path: Path) -> dict[str, Any] | None:
    """The real-time RTK snapshot beside the status snapshot (`read_feature_status` of rtk.json)."""
    return read_feature_status(status_path, RTK_STATUS_NAME)
