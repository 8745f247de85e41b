"""Pre-flight checks derived from a status snapshot (pure: the caller passes the snapshot and the time)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

OK, WARN, FAIL = "ok", "warn", "fail"


@dataclass(frozen=True)
class PreflightOptions:
    """Thresholds of the pre-flight checks (units in names)."""

    stale_after_s: float = 5.0
    min_satellites: int = 6
    min_cn0_dbhz: float = 35.0
    epoch_stale_after_s: float = 5.0
    disk_margin_bytes: int = 500 * 1024 * 1024


@dataclass(frozen=True)
class Check:
    """One line of the check list: `name`, `level` ok/warn/fail, human `detail`."""

    name: str
    level: str
    detail: str


def preflight_checks(
    status: dict[str, Any] | None, now_wall_ns: int, options: PreflightOptions | None = None
) -> list[Check]:
    """Evaluate a status snapshot (as read from JSON) at wall time `now_wall_ns`; None = no snapshot at all."""
    options = options or PreflightOptions()
    if status is None:
        return [Check("recorder", FAIL, "no status snapshot: is the recorder running?")]
    checks: list[Check] = []
    age_s = (now_wall_ns - int(status.get("updated_wall_ns") or 0)) / 1e9
    state = status.get("state", "?")
    if age_s > options.stale_after_s:
        checks.append(Check("recorder", FAIL, f"status is {age_s:.0f} s old (state was {state}): recorder stalled or stopped"))
    elif state != "recording":
        checks.append(Check("recorder", FAIL, f"state {state}: {status.get('message') or 'not recording'}"))
    else:
        checks.append(Check("recorder", OK, f"recording flight {status.get('flight')}"))

    if not status.get("port_open"):
        checks.append(Check("receiver link", FAIL, f"port {status.get('port_device')} closed: {status.get('port_error') or 'unknown'}"))
    else:
        model = status.get("receiver_model") or "unknown model"
        checks.append(Check("receiver link", OK, f"{model} {status.get('receiver_sw_version') or ''}".strip()))

    cfg = status.get("config_state")
    if cfg == "verified":
        checks.append(Check("configuration", OK, "applied and verified by poll-back"))
    elif cfg == "failed":
        checks.append(Check("configuration", FAIL, status.get("config_error") or "configuration failed"))
    elif cfg == "disabled":
        checks.append(Check("configuration", WARN, "configuration disabled: recording what the receiver sends"))
    else:
        checks.append(Check("configuration", WARN, f"configuration {cfg}"))

    sats = status.get("satellites") or []
    strong = [s for s in sats if s.get("gnss_id") == 0 and float(s.get("cn0_dbhz", 0)) >= options.min_cn0_dbhz]
    level = OK if len(strong) >= options.min_satellites else (WARN if len(strong) >= 5 else FAIL)
    checks.append(Check("satellites", level, f"{len(strong)} GPS satellites ≥ {options.min_cn0_dbhz:.0f} dB-Hz (need {options.min_satellites})"))

    epochs = int(status.get("epochs") or 0)
    checks.append(Check("raw observations", OK if epochs > 0 else FAIL, f"{epochs} epochs recorded, last {status.get('last_epoch_gpst') or 'never'}"))

    free = status.get("disk_free_bytes")
    floor = int(status.get("disk_floor_bytes") or 0)
    if free is None:
        checks.append(Check("disk", WARN, "free space unknown"))
    else:
        need = floor + options.disk_margin_bytes
        checks.append(Check("disk", OK if free >= need else FAIL, f"{free / 1e9:.1f} GB free (floor {floor / 1e6:.0f} MB)"))

    marks = int(status.get("time_marks") or 0)
    checks.append(Check("camera time marks", OK if marks > 0 else WARN,
                        f"{marks} flash marks" + ("" if marks else ": fire one test shot before take-off")))
    return checks


def overall(checks: list[Check]) -> str:
    """The worst level of a check list."""
    levels = {c.level for c in checks}
    return FAIL if FAIL in levels else WARN if WARN in levels else OK


def checks_json(checks: list[Check]) -> list[dict[str, str]]:
    """JSON-able list of checks."""
    return [asdict(c) for c in checks]
