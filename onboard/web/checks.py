"""Pre-flight checks derived from the recorder's snapshots (pure: the caller passes the snapshots and the time).

Inputs, all beside status.json: the recorder's `status.json` (checked by `check_snapshot`), the real-time RTK
`rtk.json`, the autopilot link's `autopilot.json` (`onboard.autopilot.feature.LinkStatus`) and the uploader's
`upload.json` (keys `queued`, `uploading`, `done`, `last_result`, `last_error`, `last_success_wall_ns`,
`bytes_sent`). Every value of the last two is read through `field()`: a value of the wrong kind is a named
no-go (`FieldError`), never an exception out of the page. The check list is in priority order: the go/no-go
line (`headline`) names the first failing check, else the first warning.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any
from urllib.parse import urlsplit

from onboard.recorder.status import STALE_AFTER_S
from onboard.rtk.gnss import SYSTEMS, SYSTEMS_BY_LETTER
from onboard.rtk.types import GNSS_SBAS

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
    base_timeout_s: float = 10.0
    """With real-time RTK configured, base corrections absent or older than this (s) are a no-go, naming how long
    ago they stopped and their source (the recorder's `rtk.preflight_base_timeout_s`, published in rtk.json,
    takes precedence): a cm direct-georeferencing flight should not take off without its base."""
    rtk_lag_s: float = 5.0
    """Real-time RTK solutions this far (s) behind the receiver's newest epoch: the engine is stalled or overloaded."""
    min_disk_minutes: float = 30.0
    """Recording time left (min, at the measured recording rate) below which the disk is a no-go: a survey
    flight of one battery is 20–30 min."""
    rate_after_s: float = 10.0
    """The recording rate is measured once the recorder has run this long (s)."""
    max_packet_loss: float = 0.05
    """MAVLink packet loss above this ratio is a warning (a marginal TELEM2 wiring or baud rate)."""
    min_battery_pct: float = 30.0
    """Battery below this (%) before take-off is a warning."""


class FieldError(ValueError):
    """A snapshot value of the wrong kind: `where` file, `key` (dotted path), `why`."""

    def __init__(self, where: str, key: str, why: str) -> None:
        self.where, self.key, self.why = where, key, why
        super().__init__(f"{where}: {key} {why}")


_KINDS: dict[str, tuple[str, Any]] = {
    "number": ("a number", lambda v: isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)),
    "integer": ("a whole number", lambda v: isinstance(v, int) and not isinstance(v, bool)),
    "bool": ("true or false", lambda v: isinstance(v, bool)),
    "text": ("text", lambda v: isinstance(v, str)),
    "object": ("an object", lambda v: isinstance(v, dict)),
    "list": ("a list", lambda v: isinstance(v, list)),
}


def field(obj: dict[str, Any], key: str, kinds: str, where: str, optional: bool = True) -> Any:
    """`obj[key]` (dotted `key` for nested objects) if it is one of `kinds` ("number|text", see _KINDS); None
    when absent or null and `optional`. Raises FieldError naming the file and the key."""
    value: Any = obj
    for part in key.split("."):
        if not isinstance(value, dict):
            raise FieldError(where, key, f"is inside {value!r}, not an object")
        value = value.get(part)
        if value is None:
            break
    if value is None:
        if optional:
            return None
        raise FieldError(where, key, "is missing")
    names = kinds.split("|")
    if not any(_KINDS[k][1](value) for k in names):
        raise FieldError(where, key, f"must be {' or '.join(_KINDS[k][0] for k in names)}, got {value!r}")
    return value


@dataclass(frozen=True)
class Check:
    """One line of the check list: `name`, `level` ok/warn/fail, human `detail`."""

    name: str
    level: str
    detail: str


def preflight_checks(
    status: dict[str, Any] | None, now_wall_ns: int, options: PreflightOptions | None = None,
    rtk: dict[str, Any] | None = None, autopilot: dict[str, Any] | None = None,
    upload: dict[str, Any] | None = None, base_stream: str | None = None,
) -> list[Check]:
    """Evaluate a status snapshot (as read from JSON) at wall time `now_wall_ns`; None = no snapshot at all.

    `rtk` is the real-time RTK snapshot (`rtk.json`, `onboard.realtime.service.RtkStatus.to_json`) when the daemon
    runs RTK against a base stream, None otherwise (no RTK line: the trajectory is computed on the ground).
    `autopilot` is `autopilot.json` (None: no autopilot link configured, no autopilot lines), `upload` is
    `upload.json` (None: no automatic upload configured), `base_stream` the recorder's `rtk.base_stream` (to name
    the correction source). A dict with only "unreadable" stands for a file that exists but is not JSON."""
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

    checks += autopilot_link_checks(autopilot, options)

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

    checks.append(satellites_check(status.get("satellites") or [], rtk, options))

    epochs = int(status.get("epochs") or 0)
    checks.append(Check("raw observations", OK if epochs > 0 else FAIL, f"{epochs} epochs recorded, last {status.get('last_epoch_gpst') or 'never'}"))

    checks.append(disk_check(status, rtk, autopilot, options))

    marks = int(status.get("time_marks") or 0)
    checks.append(Check("camera time marks", OK if marks > 0 else WARN,
                        f"{marks} flash marks" + ("" if marks else ": fire one test shot before take-off")))
    if rtk is None and base_stream:
        checks.append(Check("base corrections", FAIL, f"real-time RTK configured ({describe_base_stream(base_stream, autopilot)}) "
                                                      "but not reporting: no rtk.json"))
    if rtk is not None:
        try:
            checks.append(base_corrections_check(rtk, autopilot, base_stream, options))
            checks.append(rtk_check(rtk, status, options))
        except (TypeError, ValueError, AttributeError) as exc:  # a foreign or damaged rtk.json
            checks.append(Check("RTK", WARN, f"RTK status malformed: {exc}"))
    checks += autopilot_state_checks(autopilot, options)
    checks.append(upload_check(upload))
    return checks


def _engine_gnss_ids(sats: list[dict[str, Any]], rtk: dict[str, Any] | None) -> list[int]:
    """u-blox gnssIds of the constellations the RTK engine differences, in the receiver's order: those of
    rtk.json's `systems` (RINEX letters) once the engine has decided them, else every constellation tracked in
    `sats` that the engine can use (not SBAS)."""
    letters = rtk.get("systems") if isinstance(rtk, dict) else None
    if isinstance(letters, str) and letters and all(c in SYSTEMS_BY_LETTER for c in letters.upper()):
        return [SYSTEMS_BY_LETTER[c].gnss_id for c in dict.fromkeys(letters.upper())]
    tracked = dict.fromkeys(int(s.get("gnss_id", -1)) for s in sats)
    return [g for g in tracked if g in SYSTEMS and g != GNSS_SBAS]


def satellites_check(sats: list[dict[str, Any]], rtk: dict[str, Any] | None, options: PreflightOptions) -> Check:
    """The "satellites" line: satellites at C/N0 ≥ min_cn0_dbhz of the constellations the engine uses, per
    constellation. The engine double-differences within each constellation (one reference satellite each), so a
    constellation adds its satellites less one: min_satellites of one constellation are as good as
    min_satellites + 1 split over two (a warning one double difference short, a no-go below)."""
    ids = _engine_gnss_ids(sats, rtk)
    counts = {g: 0 for g in ids}
    for s in sats:
        g = int(s.get("gnss_id", -1))
        if g in counts and float(s.get("cn0_dbhz", 0)) >= options.min_cn0_dbhz:
            counts[g] += 1
    double_differences = sum(max(n - 1, 0) for n in counts.values())
    need = options.min_satellites - 1
    level = OK if double_differences >= need else (WARN if double_differences >= need - 1 else FAIL)
    cn0 = f"≥ {options.min_cn0_dbhz:.0f} dB-Hz"
    if len(counts) <= 1:
        name = SYSTEMS[ids[0]].name if ids else "GPS"
        return Check("satellites", level,
                     f"{sum(counts.values())} {name} satellites {cn0} (need {options.min_satellites})")
    per = ", ".join(f"{SYSTEMS[g].name} {n}" for g, n in counts.items())
    return Check("satellites", level,
                 f"{sum(counts.values())} satellites {cn0}: {per} (need {options.min_satellites} of one "
                 "constellation, one more for each further one)")


def _guarded(name: str, build: Any) -> list[Check]:
    """`build()`'s checks, or one named no-go when a value has the wrong kind (FieldError)."""
    try:
        result = build()
    except FieldError as exc:
        return [Check(name, FAIL, f"{exc}: cannot tell whether it is safe")]
    return result if isinstance(result, list) else [result]


AUTOPILOT = "autopilot.json"
UPLOAD = "upload.json"
GPS_FIX_NAMES = {0: "no GPS", 1: "no fix", 2: "2D fix", 3: "3D fix", 4: "DGPS", 5: "RTK float", 6: "RTK fixed",
                 7: "static", 8: "PPP"}


def autopilot_link_checks(ap: dict[str, Any] | None, options: PreflightOptions) -> list[Check]:
    """"autopilot link" (heartbeat, loss) and "autopilot pre-arm" (SYS_STATUS pre-arm health): no-go when the
    link is down or the autopilot's own pre-arm checks fail. None (no autopilot.json): no lines."""
    if ap is None:
        return []
    if "unreadable" in ap:
        return [Check("autopilot link", FAIL, f"autopilot status unreadable: {ap['unreadable']}")]

    def link() -> list[Check]:
        name = field(ap, "link", "text", AUTOPILOT) or "the autopilot link"
        age = field(ap, "heartbeat_age_s", "number", AUTOPILOT)
        if not field(ap, "link_open", "bool", AUTOPILOT):
            err = field(ap, "link_error", "text", AUTOPILOT) or "not open yet"
            return [Check("autopilot link", FAIL, f"{name} closed: {err}")]
        if age is None:
            return [Check("autopilot link", FAIL, f"no heartbeat from the autopilot yet on {name}")]
        if not field(ap, "link_up", "bool", AUTOPILOT):
            return [Check("autopilot link", FAIL, f"autopilot link lost: last heartbeat {age:.0f} s ago on {name}")]
        loss = float(field(ap, "packet_loss", "number", AUTOPILOT) or 0.0)
        armed = field(ap, "armed", "bool", AUTOPILOT)
        mode = field(ap, "mode", "text", AUTOPILOT) or "mode unknown"
        landed = (field(ap, "landed_state", "text", AUTOPILOT) or "undefined").replace("_", " ")
        state = f"{'ARMED' if armed else 'disarmed' if armed is False else 'armed?'}, {mode}, {landed}"
        detail = f"heartbeat {age:.1f} s ago, {100 * loss:.1f} % packets lost; {state}"
        return [Check("autopilot link", WARN if loss > options.max_packet_loss else OK, detail)]

    def prearm() -> Check:
        ok = field(ap, "prearm_ok", "bool", AUTOPILOT)
        if ok is None:
            return Check("autopilot pre-arm", WARN, "pre-arm health not reported yet (SYS_STATUS)")
        if not ok:
            return Check("autopilot pre-arm", FAIL, "the autopilot's pre-arm checks fail: see the ground station")
        return Check("autopilot pre-arm", OK, "pre-arm checks pass")

    checks = _guarded("autopilot link", link)
    if checks[0].level == OK or checks[0].level == WARN:
        checks += _guarded("autopilot pre-arm", prearm)
    return checks


def autopilot_state_checks(ap: dict[str, Any] | None, options: PreflightOptions) -> list[Check]:
    """"autopilot GPS", "battery" and "camera cross-check" from autopilot.json (warnings, never no-gos: the
    autopilot refuses to arm on its own GPS and battery failsafes)."""
    if ap is None or "unreadable" in ap:
        return []

    def gps() -> Check:
        fix = field(ap, "gps.fix_type", "integer", AUTOPILOT)
        if fix is None:
            return Check("autopilot GPS", WARN, "no GPS_RAW_INT from the autopilot yet")
        sats = field(ap, "gps.satellites", "integer", AUTOPILOT)
        h_acc = field(ap, "gps.h_acc_m", "number", AUTOPILOT)
        acc = f", ±{h_acc:.2f} m horizontal" if h_acc else ""
        detail = f"{GPS_FIX_NAMES.get(fix, f'fix type {fix}')}, {sats if sats is not None else '?'} satellites{acc}"
        return Check("autopilot GPS", OK if fix >= 3 else WARN, detail)

    def battery() -> Check:
        volts = field(ap, "battery.voltage_v", "number", AUTOPILOT)
        pct = field(ap, "battery.remaining_pct", "number", AUTOPILOT)
        if volts is None and pct is None:
            return Check("battery", WARN, "battery not reported yet (SYS_STATUS)")
        text = ", ".join(t for t in (None if volts is None else f"{volts:.2f} V",
                                     None if pct is None else f"{pct:.0f} %") if t)
        low = pct is not None and pct < options.min_battery_pct
        return Check("battery", WARN if low else OK, text + (" : charge it before take-off" if low else ""))

    def camera() -> list[Check]:
        if field(ap, "camera_check", "object", AUTOPILOT) is None:
            return []
        shots = int(field(ap, "camera_check.shots", "integer", AUTOPILOT) or 0)
        flashes = int(field(ap, "camera_check.flashes", "integer", AUTOPILOT) or 0)
        matched = int(field(ap, "camera_check.matched", "integer", AUTOPILOT) or 0)
        no_flash = int(field(ap, "camera_check.shots_without_flash", "integer", AUTOPILOT) or 0)
        no_shot = int(field(ap, "camera_check.flashes_without_shot", "integer", AUTOPILOT) or 0)
        delay = field(ap, "camera_check.last_delay_ms", "number", AUTOPILOT)
        if shots == 0:
            return [Check("camera cross-check", OK, f"no autopilot camera trigger yet ({flashes} flash marks)")]
        last = f", last trigger → flash delay {delay:.0f} ms" if delay is not None else ""
        if no_flash or no_shot:
            return [Check("camera cross-check", WARN, f"{no_flash} autopilot images without a flash mark, {no_shot} "
                                                      f"flash marks without an autopilot trigger ({matched} agree{last}):"
                                                      " check the hot-shoe cable")]
        return [Check("camera cross-check", OK, f"{matched} triggers and flash marks agree{last}")]

    return _guarded("autopilot GPS", gps) + _guarded("battery", battery) + _guarded("camera cross-check", camera)


def describe_base_stream(spec: str | None, ap: dict[str, Any] | None) -> str:
    """The base-correction source in words, without credentials (an NTRIP URL carries a password): from the
    recorder's `rtk.base_stream` when known, else "MAVLink" when the autopilot link reassembles RTCM."""
    spec = (spec or "").strip()
    if spec == "mavlink":
        return "MAVLink GPS_RTCM_DATA (ground station inject)"
    if spec.startswith("serial:"):
        return f"radio {spec.removeprefix('serial:')}"
    if spec.startswith(("tcp://", "ntrip://")):
        try:
            url = urlsplit(spec)
            where = f"{url.hostname}:{url.port}" if url.port else str(url.hostname)
        except ValueError:
            where = "?"
        return f"TCP {where}" if spec.startswith("tcp") else f"NTRIP {where}{urlsplit(spec).path}"
    rtcm = ap.get("rtcm") if isinstance(ap, dict) else None
    if isinstance(rtcm, dict) and isinstance(rtcm.get("messages"), int) and rtcm["messages"] > 0:
        return "MAVLink GPS_RTCM_DATA"
    return "the base stream"


def base_corrections_check(rtk: dict[str, Any], ap: dict[str, Any] | None, base_stream: str | None,
                           options: PreflightOptions) -> Check:
    """"base corrections": their source and the age of the newest base epoch (rtk.json `age_s`, rover epoch −
    base epoch, s). rtk.json exists only when real-time RTK is configured (`rtk.base_stream`): then no
    corrections, or corrections older than the timeout (rtk.json `preflight_base_timeout_s`, else
    `options.base_timeout_s`), are a no-go."""
    source = describe_base_stream(base_stream, ap)
    timeout = rtk.get("preflight_base_timeout_s")
    timeout_s = options.base_timeout_s if timeout is None else float(timeout)
    if rtk.get("unreadable") or not rtk.get("running"):
        return Check("base corrections", FAIL, f"{source}: real-time RTK not running")
    if not rtk.get("radio_open"):
        return Check("base corrections", FAIL, f"{source} closed: {rtk.get('radio_error') or 'unknown'}")
    if not int(rtk.get("base_epochs") or 0):
        return Check("base corrections", FAIL, f"none yet from {source}: is the base station on?")
    position = rtk.get("base_position_check")
    if isinstance(position, str) and position.startswith("rejected"):
        return Check("base corrections", FAIL, f"base position {position} ({source})")
    age = rtk.get("age_s")
    if age is None:
        return Check("base corrections", FAIL, f"base corrections of unknown age (source {source})")
    if float(age) > timeout_s:
        return Check("base corrections", FAIL, f"base corrections stopped {float(age):.0f} s ago (source {source}; "
                                               f"no-go after {timeout_s:g} s)")
    return Check("base corrections", OK, f"{source}, {float(age):.1f} s old")


def disk_check(status: dict[str, Any], rtk: dict[str, Any] | None, ap: dict[str, Any] | None,
               options: PreflightOptions) -> Check:
    """"disk": free space above the recorder's floor, and minutes of recording left at the measured rate
    (receiver bytes + base radio journal + autopilot tlog since the recorder started)."""
    free = status.get("disk_free_bytes")
    floor = int(status.get("disk_floor_bytes") or 0)
    if free is None:
        return Check("disk", WARN, "free space unknown")
    text = f"{free / 1e9:.1f} GB free (floor {floor / 1e6:.0f} MB)"
    if free < floor + options.disk_margin_bytes:
        return Check("disk", FAIL, text)
    elapsed_s = (int(status.get("updated_wall_ns") or 0) - int(status.get("started_wall_ns") or 0)) / 1e9
    written = int(status.get("bytes_recorded") or 0)
    for extra, key in ((rtk, "radio_bytes"), (ap, "tlog_bytes")):
        value = extra.get(key) if isinstance(extra, dict) else None
        if isinstance(value, int) and not isinstance(value, bool) and value > 0:
            written += value
    minutes = minutes_left(free - floor, written, elapsed_s, options.rate_after_s)
    if minutes is None:
        return Check("disk", OK, text + ", recording rate not measured yet")
    left = f"{text}, ≈ {minutes:.0f} min of recording left" if minutes < 10**5 else f"{text}, > 10⁵ min left"
    return Check("disk", FAIL if minutes < options.min_disk_minutes else OK, left)


def minutes_left(usable_bytes: int, written_bytes: int, elapsed_s: float, min_elapsed_s: float) -> float | None:
    """Minutes of recording `usable_bytes` hold at the rate `written_bytes / elapsed_s` (None before
    `min_elapsed_s` or before anything was written)."""
    if elapsed_s < min_elapsed_s or written_bytes <= 0:
        return None
    return max(usable_bytes, 0) / (written_bytes / elapsed_s) / 60.0


def _count(obj: dict[str, Any], key: str) -> int:
    """An upload counter: a number of flights, or the list of them."""
    value = field(obj, key, "integer|list", UPLOAD)
    return 0 if value is None else len(value) if isinstance(value, list) else int(value)


def upload_check(upload: dict[str, Any] | None) -> Check:
    """"upload": flights waiting, the one uploading, the last result (upload.json; absent: none configured)."""
    if upload is None:
        return Check("upload", OK, "no automatic upload configured")
    if "unreadable" in upload:
        return Check("upload", FAIL, f"upload status unreadable: {upload['unreadable']}")

    def build() -> Check:
        queued, done = _count(upload, "queued"), _count(upload, "done")
        uploading = field(upload, "uploading", "text|integer|bool|list|object", UPLOAD)
        result = field(upload, "last_result", "text", UPLOAD)
        error = field(upload, "last_error", "text", UPLOAD)
        field(upload, "last_success_wall_ns", "integer", UPLOAD)
        sent = field(upload, "bytes_sent", "integer", UPLOAD)
        now = "" if uploading in (None, False, [], {}, 0) else (
            f", uploading {uploading}" if isinstance(uploading, str) else ", uploading")
        text = f"{queued} flights waiting{now}, {done} uploaded"
        text += f", {sent / 1e6:.1f} MB sent" if sent else ""
        if error:
            return Check("upload", WARN, f"{text}; last attempt failed: {error}")
        return Check("upload", OK, text + (f"; last: {result}" if result else ""))

    return _guarded("upload", build)[0]


def headline(checks: list[Check]) -> dict[str, str]:
    """The go/no-go line: `level` (the worst), `verdict` text, `fault` "<check>: <detail>" of the first
    failing check (else the first warning; empty when all are ok)."""
    level = overall(checks)
    first = next((c for c in checks if c.level == level), None) if level != OK else None
    verdict = {OK: "READY TO FLY", WARN: "CHECK WARNINGS", FAIL: "DO NOT FLY"}[level]
    return {"level": level, "verdict": verdict, "fault": "" if first is None else f"{first.name}: {first.detail}"}


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


def _fmt(value: Any, unit: str = "", digits: int = 1) -> str:
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.{digits}f}{unit}"
    return f"{value}{unit}"


def _rows(where: str, obj: dict[str, Any], spec: list[tuple[str, str, str, str, int]]) -> list[list[str]]:
    """[label, text] rows of `obj` (label, key, kinds, unit, digits); a wrong-kind value shows its error."""
    rows = []
    for label, key, kinds, unit, digits in spec:
        try:
            rows.append([label, _fmt(field(obj, key, kinds, where), unit, digits)])
        except FieldError as exc:
            rows.append([label, f"unreadable: {exc.why}"])
    return rows


RTK_Q_NAMES = {1: "fixed", 2: "float", 5: "single", 0: "no solution"}


def _rtk_state(rtk: dict[str, Any] | None) -> str:
    """Our real-time RTK quality in words, beside the autopilot's GPS."""
    if rtk is None:
        return "not running (post-processed on the ground)"
    q = rtk.get("q")
    if "unreadable" in rtk or not isinstance(q, int) or isinstance(q, bool):
        return "unreadable"
    ratio = rtk.get("ratio")
    extra = f", ratio {ratio:.1f}" if isinstance(ratio, (int, float)) and not isinstance(ratio, bool) and q == 1 else ""
    return RTK_Q_NAMES.get(q, f"Q {q}") + extra


def blocks(status: dict[str, Any] | None, rtk: dict[str, Any] | None, ap: dict[str, Any] | None,
           upload: dict[str, Any] | None, base_stream: str | None) -> dict[str, list[list[str]]]:
    """The page's value blocks ("autopilot", "base corrections", "camera", "upload"): [label, text] rows,
    each value read through `field()` (a wrong-kind value reads "unreadable: ...")."""
    out: dict[str, list[list[str]]] = {}
    if ap is not None:
        if "unreadable" in ap:
            out["autopilot"] = [["status", f"unreadable: {ap['unreadable']}"]]
        else:
            out["autopilot"] = _rows(AUTOPILOT, ap, [
                ("link", "link", "text", "", 0), ("link open", "link_open", "bool", "", 0),
                ("link up (heartbeat)", "link_up", "bool", "", 0),
                ("heartbeat age", "heartbeat_age_s", "number", " s", 1),
                ("packets lost", "packets_lost", "integer", "", 0), ("armed", "armed", "bool", "", 0),
                ("mode", "mode", "text", "", 0), ("landed state", "landed_state", "text", "", 0),
                ("pre-arm healthy", "prearm_ok", "bool", "", 0),
                ("battery", "battery.voltage_v", "number", " V", 2),
                ("battery left", "battery.remaining_pct", "number", " %", 0),
                ("autopilot GPS fix type", "gps.fix_type", "integer", "", 0),
                ("autopilot GPS satellites", "gps.satellites", "integer", "", 0),
                ("autopilot GPS accuracy", "gps.h_acc_m", "number", " m", 2),
            ])
            for row in out["autopilot"]:
                if row[0] == "autopilot GPS fix type" and row[1].isdigit():
                    row[1] = f"{row[1]} ({GPS_FIX_NAMES.get(int(row[1]), '?')})"
            out["autopilot"].append(["our real-time RTK", _rtk_state(rtk)])
            out["camera"] = _rows(AUTOPILOT, ap, [
                ("autopilot triggers", "camera_check.shots", "integer", "", 0),
                ("flashes (TIM-TM2 falling edges)", "camera_check.flashes", "integer", "", 0),
                ("agree", "camera_check.matched", "integer", "", 0),
                ("trigger without flash", "camera_check.shots_without_flash", "integer", "", 0),
                ("flash without trigger", "camera_check.flashes_without_shot", "integer", "", 0),
                ("last trigger → flash delay", "camera_check.last_delay_ms", "number", " ms", 1),
                ("pairing tolerance", "camera_check.tolerance_ms", "number", " ms", 0),
            ])
    if rtk is not None and "unreadable" not in rtk:
        rows = [["source", describe_base_stream(base_stream, ap)]]
        rows += _rows("rtk.json", rtk, [
            ("age of corrections", "age_s", "number", " s", 1), ("base epochs", "base_epochs", "integer", "", 0),
            ("bytes received", "radio_bytes", "integer", "", 0), ("baseline", "baseline_m", "number", " m", 0),
        ])
        out["base corrections"] = rows
    if upload is None:
        out["upload"] = [["upload", "no automatic upload configured"]]
    elif "unreadable" in upload:
        out["upload"] = [["upload", f"unreadable: {upload['unreadable']}"]]
    else:
        out["upload"] = _rows(UPLOAD, upload, [
            ("uploading", "uploading", "text|integer|bool|list|object", "", 0),
            ("last result", "last_result", "text", "", 0), ("last error", "last_error", "text", "", 0),
            ("bytes sent", "bytes_sent", "integer", "", 0),
        ])
        for label, key in (("flights waiting", "queued"), ("flights uploaded", "done")):
            try:
                out["upload"].insert(0, [label, str(_count(upload, key))])
            except FieldError as exc:
                out["upload"].insert(0, [label, f"unreadable: {exc.why}"])
    return out
