"""Image events: the onboard `events.jsonl` and the CSV `image,week,tow`, and matching events to image files.

Matching (pure functions, no clocks): by order when the counts agree, else by EXIF capture time — the camera
clock's offset from GPS time is unknown (local time zone, drift), so it is estimated as the densest
difference between capture times and event times, then each photo takes the nearest unused event within a
tolerance. Photos left without an event are "missing marks", events left without a photo are "extra
marks"; a jump of the receiver's mark `count` by more than one says marks were lost there.
"""

from __future__ import annotations

import csv
import datetime as dt
import json
import logging
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ground.adjust.types import ImageEvent
from ground.io.errors import FormatError
from onboard.errors import InputError
from onboard.gnsstime import NS_PER_S, GpsTime

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class AutopilotAttitude:
    """The autopilot's body attitude at an exposure (deg: roll, pitch ±180, yaw 0–360 from north), from the
    onboard camera cross-check (`camera_check` records): a prior for geotag exports before a bundle adjustment
    (flight controller body frame: the camera's boresight and any gimbal are not in it)."""

    roll_deg: float
    pitch_deg: float
    yaw_deg: float


@dataclass(frozen=True)
class CameraCheck:
    """One `camera_check` record (`onboard.autopilot.camera`): `result` "matched", "shot_without_flash"
    (the autopilot triggered, no flash mark) or "flash_without_shot"; the autopilot's event (`shot_source`,
    `shot_index`, `shot_time`), the flash mark (`flash_time`, `flash_count`), `delay_s` flash − shot,
    `exposure_time` (flash, else shot) and the autopilot's `attitude` there (None when not known)."""

    result: str
    exposure_time: GpsTime
    shot_source: str | None = None
    shot_index: int | None = None
    shot_time: GpsTime | None = None
    flash_time: GpsTime | None = None
    flash_count: int | None = None
    delay_s: float | None = None
    attitude: AutopilotAttitude | None = None


@dataclass(frozen=True)
class Mark:
    """One event time from the receiver, before it is tied to an image.

    `count` is the receiver's mark counter (TIM-TM2 `count`) when known, `kind` "flash" or "trigger";
    `autopilot_attitude` the autopilot's attitude at this exposure when the onboard camera cross-check logged
    one (a prior: the exporters do not use it).
    """

    time: GpsTime
    kind: str = "flash"
    count: int | None = None
    measured_delay_s: float | None = None
    autopilot_attitude: AutopilotAttitude | None = None


# ------------------------------------------------------------------------------------------------ readers


def read_events_csv(path: str | Path, default_kind: str = "trigger") -> list[ImageEvent]:
    """Read `image,week,tow` (GPS week, seconds of week of the trigger pulse or flash mark; header required).

    An optional `kind` column ("flash"/"trigger") overrides `default_kind`.
    """
    p = Path(path)
    try:
        with p.open(encoding="utf-8", newline="") as fh:
            rows = [r for r in csv.reader(fh) if r and not r[0].lstrip().startswith("#")]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise FormatError(p, f"unreadable events CSV: {exc}") from exc
    if not rows:
        raise FormatError(p, "empty events CSV")
    header = [h.strip().lower() for h in rows[0]]
    for need in ("image", "week", "tow"):
        if need not in header:
            raise FormatError(p, f"header needs image,week,tow (got {rows[0]})", line=1)
    ci, cw, ct = header.index("image"), header.index("week"), header.index("tow")
    ck = header.index("kind") if "kind" in header else None
    events: list[ImageEvent] = []
    seen: set[str] = set()
    for n, row in enumerate(rows[1:], start=2):
        try:
            image = row[ci].strip()
            week = int(row[cw])
            tow_s = float(row[ct])
        except (IndexError, ValueError) as exc:
            raise FormatError(p, f"bad row {row}: {exc}", line=n) from exc
        if not 0.0 <= tow_s < 604_800.0 or week < 0:
            raise FormatError(p, f"week/tow out of range: {week} {tow_s}", line=n)
        if image in seen:
            raise FormatError(p, f"image {image!r} listed twice", line=n)
        seen.add(image)
        kind = row[ck].strip() if ck is not None and ck < len(row) and row[ck].strip() else default_kind
        if kind not in ("flash", "trigger"):
            raise FormatError(p, f"kind must be flash or trigger, got {kind!r}", line=n)
        events.append(ImageEvent(image=image, time=GpsTime.from_week_tow_s(week, tow_s), kind=kind))
    return events


CAMERA_CHECK_RESULTS = ("matched", "shot_without_flash", "flash_without_shot")


def _check_time(rec: dict[str, Any], prefix: str, n: int) -> GpsTime | None:
    week, tow = rec.get(f"{prefix}_week"), rec.get(f"{prefix}_tow_ns")
    if week is None and tow is None:
        return None
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in (week, tow)):
        raise InputError(f"camera_check record {n}: {prefix}_week/{prefix}_tow_ns must be whole numbers, "
                         f"got {week!r}, {tow!r}")
    assert isinstance(week, int) and isinstance(tow, int)
    return GpsTime.from_week_tow_ns(week, tow)


def _optional(rec: dict[str, Any], key: str, kinds: tuple[type, ...], n: int) -> Any:
    value = rec.get(key)
    if value is not None and (isinstance(value, bool) or not isinstance(value, kinds)):
        raise InputError(f"camera_check record {n}: {key} must be {' or '.join(k.__name__ for k in kinds)}, "
                         f"got {value!r}")
    return value


def camera_checks_from_records(records: list[dict[str, Any]]) -> list[CameraCheck]:
    """The `camera_check` records of decoded events.jsonl records, in exposure-time order (other kinds are
    skipped). Raises `InputError` on a malformed or newer-format one."""
    out: list[CameraCheck] = []
    for n, rec in enumerate(records):
        if rec.get("kind") != "camera_check":
            continue
        if rec.get("v") != 1:
            raise InputError(f"camera_check record {n}: format version {rec.get('v')!r} (this reader knows 1)")
        result = rec.get("result")
        if result not in CAMERA_CHECK_RESULTS:
            raise InputError(f"camera_check record {n}: result must be one of {CAMERA_CHECK_RESULTS}, "
                             f"got {result!r}")
        exposure = _check_time(rec, "exposure", n)
        if exposure is None:
            raise InputError(f"camera_check record {n}: no exposure time")
        angles = [_optional(rec, k, (int, float), n) for k in ("roll_deg", "pitch_deg", "yaw_deg")]
        attitude = None if None in angles else AutopilotAttitude(*(float(a) for a in angles))
        delay_ns = _optional(rec, "delay_ns", (int,), n)
        out.append(CameraCheck(
            result=str(result), exposure_time=exposure, shot_source=_optional(rec, "shot_source", (str,), n),
            shot_index=_optional(rec, "shot_index", (int,), n), shot_time=_check_time(rec, "shot", n),
            flash_time=_check_time(rec, "flash", n), flash_count=_optional(rec, "flash_count", (int,), n),
            delay_s=None if delay_ns is None else delay_ns / NS_PER_S, attitude=attitude))
    return sorted(out, key=lambda c: c.exposure_time.total_ns)


ATTITUDE_MATCH_NS = 1_000_000
"""A camera_check's exposure and a mark are the same flash when their GPS times agree to 1 ms (both are the
same TIM-TM2 edge; the tolerance only absorbs a record written with a coarser time)."""


def _with_attitude(marks: list[Mark], checks: list[CameraCheck]) -> list[Mark]:
    by_time = sorted((c.exposure_time.total_ns, c.attitude) for c in checks if c.attitude is not None)
    if not by_time:
        return marks
    times = [t for t, _ in by_time]
    out = []
    for m in marks:
        i = int(np.searchsorted(times, m.time.total_ns))
        near = [j for j in (i - 1, i) if 0 <= j < len(times) and abs(times[j] - m.time.total_ns) <= ATTITUDE_MATCH_NS]
        if near:
            j = min(near, key=lambda j: abs(times[j] - m.time.total_ns))
            m = replace(m, autopilot_attitude=by_time[j][1])
        out.append(m)
    return out


def marks_from_records(records: list[dict[str, Any]]) -> list[Mark]:
    """Image marks from decoded events.jsonl records (format of `onboard.timepulse.marks`).

    One mark per `pairing` record: its flash time (kind "flash", with the measured pulse→flash delay) or, with
    no flash, its measured pulse time (kind "trigger"). A log without pairing records falls back to its valid
    flash-channel `mark` records. A `camera_check` record at a mark's time gives it `autopilot_attitude`.
    Raises `InputError` on malformed or newer-format records.
    """
    from onboard.timepulse.marks import FLASH_CHANNEL, parse_records

    marks, pairings, _ = parse_records(records)
    checks = camera_checks_from_records(records)
    out: list[Mark] = []
    for p in pairings:
        if p.flash_time is not None:
            out.append(Mark(p.flash_time, "flash", p.flash_count, p.delay_s))
        elif p.pulse_time is not None:
            out.append(Mark(p.pulse_time, "trigger", None, None))
    if not pairings:
        out = [Mark(m.time, "flash", m.count) for m in marks
               if m.channel == FLASH_CHANNEL and m.valid and m.time is not None]
    return _with_attitude(sorted(out, key=lambda m: m.time), checks)


def read_marks_jsonl(path: str | Path) -> list[Mark]:
    """Image marks from an onboard `events.jsonl` (torn/corrupt lines skipped and logged), in time order."""
    from onboard.logger.events import read_events  # the onboard reader: one parser of that file

    p = Path(path)
    if not p.is_file():
        raise FormatError(p, "no such events file")
    got = read_events(p)
    if got.skipped_lines:
        log.warning("%s: %d torn or corrupt lines skipped", p, got.skipped_lines)
    try:
        marks = marks_from_records(got.records)
    except InputError as exc:
        raise FormatError(p, str(exc)) from exc
    if not marks:
        raise FormatError(p, f"no image mark among {len(got.records)} records")
    return marks


def read_capture_times(path: str | Path) -> dict[str, dt.datetime]:
    """Capture times from a sidecar: CSV `image,capture_time` or JSON {image: time}.

    Times are EXIF-style `YYYY:MM:DD HH:MM:SS[.fff]` or ISO 8601; they are camera clock readings (naive;
    treated as UTC — the offset to GPS time is estimated by the matcher anyway).
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise FormatError(p, f"unreadable: {exc}") from exc
    if p.suffix.lower() == ".json":
        try:
            raw = json.loads(text)
        except json.JSONDecodeError as exc:
            raise FormatError(p, f"bad JSON: {exc}") from exc
        items = list(raw.items()) if isinstance(raw, dict) else []
    else:
        rows = list(csv.reader(text.splitlines()))
        items = [(r[0], r[1]) for r in rows[1:] if len(r) >= 2]
    out: dict[str, dt.datetime] = {}
    for name, value in items:
        t = parse_capture_time(str(value))
        if t is None:
            raise FormatError(p, f"capture time of {name!r} unreadable: {value!r}")
        out[str(name)] = t
    return out


def parse_capture_time(text: str) -> dt.datetime | None:
    """EXIF `YYYY:MM:DD HH:MM:SS[.fff]` or ISO 8601 → naive-UTC datetime, None when unreadable."""
    s = text.strip()
    if len(s) >= 19 and s[4] == ":" and s[7] == ":":
        s = s[:4] + "-" + s[5:7] + "-" + s[8:]
    try:
        t = dt.datetime.fromisoformat(s)  # Python ≥ 3.11 accepts a trailing Z
    except ValueError:
        return None
    if t.tzinfo is not None:
        t = t.astimezone(dt.UTC).replace(tzinfo=None)
    return t


def exif_capture_time(image_path: str | Path) -> dt.datetime | None:
    """DateTimeOriginal (+ SubSecTimeOriginal) of a JPEG through Pillow; None when absent or unreadable."""
    try:
        from PIL import Image, UnidentifiedImageError
    except ImportError:  # Pillow is optional: sidecar capture times work without it
        return None
    try:
        with Image.open(image_path) as im:
            exif = im.getexif().get_ifd(0x8769)  # Exif IFD
    except (OSError, UnidentifiedImageError):
        return None
    value = exif.get(0x9003)  # DateTimeOriginal
    if not value:
        return None
    sub = str(exif.get(0x9291, "")).strip()  # SubSecTimeOriginal
    return parse_capture_time(f"{value}.{sub}" if sub.isdigit() else str(value))


# ------------------------------------------------------------------------------------------------ matching


@dataclass(frozen=True)
class MatchReport:
    """The outcome of tying marks to images.

    `events` one `ImageEvent` per matched image, `missing_marks` photos with no mark, `extra_marks` marks with
    no photo (their times), `count_jumps` (previous count, next count) where the receiver lost marks,
    `clock_offset_s` camera clock − GPS time (None when matched by order), `method` "order" or "capture_time".
    """

    events: list[ImageEvent]
    missing_marks: list[str] = field(default_factory=list)
    extra_marks: list[GpsTime] = field(default_factory=list)
    count_jumps: list[tuple[int, int]] = field(default_factory=list)
    clock_offset_s: float | None = None
    method: str = "order"

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary."""
        return {
            "matched": len(self.events),
            "missing_marks": list(self.missing_marks),
            "extra_marks": [str(t) for t in self.extra_marks],
            "count_jumps": [list(j) for j in self.count_jumps],
            "clock_offset_s": self.clock_offset_s,
            "method": self.method,
        }


def count_jumps(marks: list[Mark]) -> list[tuple[int, int]]:
    """(previous, next) counter pairs where the receiver's mark counter skipped values (16-bit wrap aware)."""
    jumps = []
    prev: int | None = None
    for m in marks:
        if m.count is not None and prev is not None and (m.count - prev) % 65536 > 1:
            jumps.append((prev, m.count))
        if m.count is not None:
            prev = m.count
    return jumps


def _event(image: str, m: Mark) -> ImageEvent:
    return ImageEvent(image=image, time=m.time, kind=m.kind, measured_delay_s=m.measured_delay_s)


def match_marks_to_images(
    marks: list[Mark],
    images: list[str],
    capture_times: dict[str, dt.datetime] | None = None,
    tolerance_s: float = 1.5,
) -> MatchReport:
    """Tie receiver marks to image files.

    Without capture times, by order: the sorted image names and the time-ordered marks must be equally many
    and the counter must not jump (else there is no way to know which photo lost its mark: refused). With
    capture times (EXIF or sidecar, 1 s resolution typically) the camera-clock offset is the centre of the
    densest `tolerance_s` window of all capture − mark differences; each photo then takes the nearest unused
    mark within `tolerance_s` of its corrected time.
    """
    ms = sorted(marks, key=lambda m: m.time)
    jumps = count_jumps(ms)
    if not capture_times:
        names = sorted(images)
        if len(names) != len(ms) or jumps:
            detail = f"{len(names)} photos, {len(ms)} marks" + (f", counter jumps {jumps}" if jumps else "")
            raise ValueError(f"cannot match by order ({detail}); give capture times (EXIF or a sidecar)")
        return MatchReport(events=[_event(n, m) for n, m in zip(names, ms)], count_jumps=jumps, method="order")

    named = [n for n in images if n in capture_times]
    no_time = [n for n in images if n not in capture_times]
    if not named or not ms:
        return MatchReport(events=[], missing_marks=sorted(images), extra_marks=[m.time for m in ms],
                           count_jumps=jumps, method="capture_time")
    t0 = ms[0].time
    mark_s = np.array([m.time.diff_s(t0) for m in ms])
    epoch = min(capture_times[n] for n in named)
    cap_s = np.array([(capture_times[n] - epoch).total_seconds() for n in named])
    diffs = np.sort((cap_s[:, None] - mark_s[None, :]).ravel())
    # densest window of width 2·tolerance: two pointers over the sorted differences
    j = 0
    best, best_i, best_j = 0, 0, 0
    for i in range(diffs.size):
        while diffs[i] - diffs[j] > 2 * tolerance_s:
            j += 1
        if i - j + 1 > best:
            best, best_i, best_j = i - j + 1, i, j
    offset = float(np.median(diffs[best_j:best_i + 1]))
    order = np.argsort(cap_s, kind="stable")
    used = np.zeros(len(ms), dtype=bool)
    events: list[ImageEvent] = []
    missing: list[str] = list(no_time)
    for k in order:
        target = cap_s[k] - offset
        cand = np.flatnonzero(~used & (np.abs(mark_s - target) <= tolerance_s))
        if cand.size == 0:
            missing.append(named[k])
            continue
        best_mark = int(cand[np.argmin(np.abs(mark_s[cand] - target))])
        used[best_mark] = True
        events.append(_event(named[k], ms[best_mark]))
    offset_gps_s = (epoch - dt.datetime(1980, 1, 6)).total_seconds() - t0.total_ns / NS_PER_S + offset
    return MatchReport(
        events=sorted(events, key=lambda e: e.time),
        missing_marks=sorted(missing),
        extra_marks=[ms[i].time for i in np.flatnonzero(~used)],
        count_jumps=jumps,
        clock_offset_s=offset_gps_s,
        method="capture_time",
    )
