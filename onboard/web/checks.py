"""Pre-flight checks derived from a status snapshot (pure: the caller passes the snapshot and the time)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from onboard.recorder.status import STALE_AFTER_S

OK, WARN, FAIL = "ok", "warn", "fail"


@dataclass(frozen=True)
class PreflightOptions:
    """Thresholds of the pre-flight checks (units in names)."""

    stale_after_s: float = STALE_AFTER_S
    min_satellites: int = 6
    min_cn0_dbhz: float = 35.0
    epoch_stale_after_s: float = 5.0
    disk_margin_bytes: int = 500 * 1024 * 1024
    rtk_max_age_s: float = 30.0
    """Base corrections older than this (s) cannot be fixed (the RTK engine's max_age_s): the radio link is down."""
    rtk_lag_s: float = 5.0
    """Real-time RTK solutions this far (s) behind the receiver's newest epoch: the engine is stalled or overloaded."""


@dataclass(frozen=True)
class Check:
    """One line of the check list: `name`, `level` ok/warn/fail, human `detail`."""

    name: str
    level: str
    detail: str


def preflight_checks(
    status: dict[str, Any] | None, now_wall_ns: int, options: PreflightOptions | None = None,
    rtk: dict[str, Any] | None = None,
) -> list[Check]:
    """Evaluate a status snapshot (as read from JSON) at wall time `now_wall_ns`; None = no snapshot at all.

    `rtk` is the real-time RTK snapshot (`rtk.json`, `onboard.realtime.service.RtkStatus.to_json`) when the daemon
    runs RTK against a base stream, None otherwise (no RTK line: the trajectory is computed on the ground)."""
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
    if rtk is not None:
        try:
            checks.append(rtk_check(rtk, status, options))
        except (TypeError, ValueError, AttributeError) as exc:  # a foreign or damaged rtk.json
            checks.append(Check("RTK", WARN, f"RTK status malformed: {exc}"))
    return checks


def unreadable_snapshot(why: str) -> list[Check]:
    """The no-go for a snapshot that exists but cannot be used (`why` names the field): the recorder's state
    is unknown, so nothing else is claimed."""
    return [Check("recorder", FAIL, why)]


def _gpst_s(text: Any) -> float | None:
    """Seconds since the GPS epoch of a "week:tow" string (GpsTime.__str__), None if absent or malformed."""
    try:
        week, tow = str(text).split(":")
        return int(week) * 604800.0 + float(tow)
    except (TypeError, ValueError):
        return None


def rtk_check(rtk: dict[str, Any], status: dict[str, Any], options: PreflightOptions) -> Check:
    """The "RTK" line: fixed is ok; float, stale corrections or a stalled engine are warnings, since the flight
    can still be processed on the ground from the journals, but the pilot should know before take-off."""
    if rtk.get("unreadable"):
        return Check("RTK", WARN, f"RTK status unreadable: {rtk['unreadable']}")
    if not rtk.get("running"):
        return Check("RTK", WARN, f"real-time RTK not running ({int(rtk.get('errors') or 0)} errors, "
                                  f"{int(rtk.get('restarts') or 0)} restarts): the ground will post-process")
    if not rtk.get("radio_open"):
        return Check("RTK", WARN, f"base radio closed: {rtk.get('radio_error') or 'unknown'}")
    if not int(rtk.get("base_epochs") or 0):
        return Check("RTK", WARN, f"no base corrections yet ({int(rtk.get('radio_bytes') or 0)} radio bytes): "
                                  "is the base station on?")
    rover_s, rtk_s = _gpst_s(status.get("last_epoch_gpst")), _gpst_s(rtk.get("last_gpst"))
    if rover_s is not None and (rtk_s is None or rover_s - rtk_s > options.rtk_lag_s):
        behind = "no solution yet" if rtk_s is None else f"{rover_s - rtk_s:.0f} s behind the receiver"
        return Check("RTK", WARN, f"RTK engine {behind} ({int(rtk.get('dropped_epochs') or 0)} epochs dropped)")
    age = rtk.get("age_s")
    if age is None or float(age) > options.rtk_max_age_s:
        old = "of unknown age" if age is None else f"{float(age):.0f} s old"
        return Check("RTK", WARN, f"base corrections {old}: radio link down?")
    ns, ratio = int(rtk.get("ns") or 0), float(rtk.get("ratio") or 0.0)
    baseline = rtk.get("baseline_m")
    where = f", baseline {float(baseline) / 1000:.2f} km" if baseline is not None else ""
    if int(rtk.get("q") or 0) == 1:  # RTKLIB's Q: 1 fix, 2 float, 5 single
        ttff = rtk.get("ttff_s")
        first = f", first fix after {float(ttff):.0f} s" if ttff is not None else ""
        return Check("RTK", OK, f"fixed: ratio {ratio:.1f}, {ns} satellites{where}{first}")
    # the engine's own limit, from its snapshot (the daemon's [rtk.engine] may have changed it)
    limit_km = float(rtk.get("max_first_fix_baseline_km") or 0.0)
    if baseline is not None and limit_km > 0.0 and float(baseline) > 1000.0 * limit_km:
        return Check("RTK", WARN, f"float, base {float(baseline) / 1000:.1f} km away: beyond {limit_km:g} km L1 RTK "
                                  "does not fix from a cold start. Set the base closer, or give the surveyed take-off "
                                  "point (rtk.takeoff_position; on the ground: onboard rtk --init-pos)")
    # a cold start waits out the u-blox code multipath (correlated over ~30 s while static): hil_sim's
    # calibrated flights first fix after 9-125 s on the ground; airborne epochs before it are float
    return Check("RTK", WARN, f"not fixed yet (ratio {ratio:.1f}, {ns} satellites{where}): wait for the fix "
                              "before take-off")


def overall(checks: list[Check]) -> str:
    """The worst level of a check list."""
    levels = {c.level for c in checks}
    return FAIL if FAIL in levels else WARN if WARN in levels else OK


def checks_json(checks: list[Check]) -> list[dict[str, str]]:
    """JSON-able list of checks."""
    return [asdict(c) for c in checks]
