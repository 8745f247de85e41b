"""The recorder's status snapshot: a dataclass schema, written atomically as JSON for the status web page.

The recorder never serves HTTP: a separate small web process reads this file, so a web fault cannot stop
recording. `write_status` writes a temp file and renames it over the target, so a reader sees either the old
or the new snapshot, never a half-written one.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from onboard.formats.atomic import write_json_atomic

STATUS_SCHEMA = "directgeo-status/1"
DEFAULT_STATUS_PATH = Path("/run/directgeo/status.json")
"""Where the recorder writes its snapshot and the pre-flight page reads it (systemd's RuntimeDirectory)."""
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


def read_status(path: Path) -> dict[str, Any]:
    """The last snapshot as a dict (raises FileNotFoundError / ValueError)."""
    obj = json.loads(Path(path).read_bytes())
    if not isinstance(obj, dict) or obj.get("schema") != STATUS_SCHEMA:
        raise ValueError(f"{path} is not a {STATUS_SCHEMA} snapshot")
    return obj


def read_rtk_status(status_path: Path) -> dict[str, Any] | None:
    """The real-time RTK snapshot beside the status snapshot at `status_path`, None when the daemon runs no RTK
    (no file). Raises ValueError when it is not JSON (half-written, foreign), TypeError when not a JSON object."""
    try:
        obj = json.loads(Path(status_path).with_name(RTK_STATUS_NAME).read_bytes())
    except FileNotFoundError:
        return None
    if not isinstance(obj, dict):
        raise TypeError(f"{RTK_STATUS_NAME} is not a JSON object")
    return obj
