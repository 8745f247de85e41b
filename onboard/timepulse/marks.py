"""Pulse/flash pairing, GPIO tick → GPS time mapping, and the `events.jsonl` record format. Pure.

Inputs are `CameraMark`s: channel 0 = the camera's flash (hot-shoe pulls the line low: **falling** edge,
TIM-TM2 EXTINT0), channel 1 = the trigger pulse where it is measured (TIM-TM2 EXTINT1 or a Pi GPIO mapped to
GPS time). The 2–3 s camera period cannot be aligned to the top of a second, so pulse times are measured,
never assumed: with no trigger measurement every image says so (`pulse_reason`).

Each pairing carries flags:
- ``missed_flash``: the TIM-TM2 rising-edge `count` jumped by more than one (`lost_edges` says how many,
  charged to the next flash). With a measured trigger it means a flash was lost (the previous image has a
  pulse without flash, or the trigger line's count jumped too); otherwise it is reported as ``bounce``;
- ``bounce``: a second flash edge followed within `bounce_window_ns` (dropped, the first edge kept), or
  edges were lost (count jump) while every measured pulse has its flash: the extra edge was a bounce, and
  this flash time may be the bounce's (TIM-TM2 reports only the last falling edge of an epoch);
- ``pulse_without_flash``: a measured pulse with no flash within `max_delay_ns` (and before the next pulse);
- ``flash_without_pulse``: a flash with no measured pulse before it (only when the trigger is measured).

Event log (`events.jsonl`, one JSON object a line, appended and fsynced by `onboard.logger.events.EventLog`).
Every record has ``v`` (format version, 1) and ``kind``:

=============  ===============================================================================================
kind           fields
=============  ===============================================================================================
``mark``       ``source`` ("tim-tm2"/"gpio"), ``channel`` (0 flash, 1 trigger), ``edge`` ("rising"/"falling"),
               ``count`` (TIM-TM2 rising-edge counter; GPIO: edge index), ``week``, ``tow_ns`` (GPS time of
               the edge, ns of week; null when not valid), ``acc_est_ns``, ``time_base`` (0 receiver, 1 GNSS,
               2 UTC), ``valid``; GPIO marks add ``tick_ns`` (host monotonic clock)
``pairing``    ``index`` (image number from 0), ``pulse_week``/``pulse_tow_ns`` (null when not measured),
               ``pulse_source``, ``pulse_reason`` (why there is no pulse time, e.g. "no trigger measurement"),
               ``flash_week``/``flash_tow_ns``/``flash_count``/``flash_acc_est_ns`` (null: no flash),
               ``delay_ns`` (flash − pulse, the measured shutter delay), ``flags`` (list), ``lost_edges``
``timepulse``  what the receiver applied: ``camera_timepulse`` ("TIMEPULSE2"/"TIMEPULSE"), ``period_us``,
               ``length_us``, ``rising``, ``align_to_tow`` (as polled back; null if unknown), ``trigger``
               ("extint1"/"gpio"/"none"), ``trigger_measured``, ``note``
=============  ===============================================================================================
"""

from __future__ import annotations

import dataclasses
import itertools
import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

from onboard.errors import InputError
from onboard.gnsstime import GpsTime
from onboard.rtk.types import CameraMark

EVENT_FORMAT_VERSION = 1
FLASH_CHANNEL = 0
TRIGGER_CHANNEL = 1
COUNT_MODULO = 1 << 16  # TIM-TM2 `count` is U2
NO_TRIGGER_MEASUREMENT = "no trigger measurement"
NO_PULSE_BEFORE_FLASH = "no trigger pulse before this flash"

MISSED_FLASH = "missed_flash"
BOUNCE = "bounce"
PULSE_WITHOUT_FLASH = "pulse_without_flash"
FLASH_WITHOUT_PULSE = "flash_without_pulse"


@dataclass(frozen=True, slots=True)
class PairingOptions:
    """How marks are paired.

    `trigger_measured` False when no trigger line is wired (every image then carries NO_TRIGGER_MEASUREMENT);
    `trigger_edge` the pulse's active edge (the TimePulse polarity); `max_delay_ns` the longest trigger→flash
    delay accepted (must be below the camera period); `bounce_window_ns` edges closer than this to the
    previous one on the same line are contact bounce; `flash_source` when set ("tim-tm2" or "gpio") takes
    flashes from that source only (a GPIO flash input replaces TIM-TM2 EXTINT0 even if both are wired).
    """

    trigger_measured: bool = True
    flash_channel: int = FLASH_CHANNEL
    flash_edge: str = "falling"
    flash_source: str | None = None
    trigger_channel: int = TRIGGER_CHANNEL
    trigger_edge: str = "rising"
    max_delay_ns: int = 1_000_000_000
    bounce_window_ns: int = 20_000_000


@dataclass(frozen=True, slots=True)
class ImagePairing:
    """One image: its measured trigger pulse and its flash, the shutter delay between them, and flags."""

    index: int
    pulse_time: GpsTime | None
    pulse_source: str | None
    pulse_reason: str | None
    flash_time: GpsTime | None
    flash_count: int | None
    flash_acc_est_ns: int | None
    delay_ns: int | None
    flags: tuple[str, ...] = ()
    lost_edges: int = 0

    @property
    def delay_s(self) -> float | None:
        """Flash − pulse in seconds (None when either is missing)."""
        return None if self.delay_ns is None else self.delay_ns / 1e9


def _usable(mark: CameraMark, channel: int, edge: str) -> bool:
    return mark.channel == channel and mark.edge == edge and mark.valid and mark.time is not None


def _debounce(marks: list[CameraMark], window_ns: int) -> tuple[list[CameraMark], set[int]]:
    """Drop edges within `window_ns` of the previous kept edge; returns kept marks and indices (in kept) bounced."""
    kept: list[CameraMark] = []
    bounced: set[int] = set()
    for mark in marks:
        assert mark.time is not None
        if kept and kept[-1].time is not None and mark.time.diff_ns(kept[-1].time) < window_ns:
            bounced.add(len(kept) - 1)
            continue
        kept.append(mark)
    return kept, bounced


def _lost_edges(all_marks: list[CameraMark], flashes: list[CameraMark], options: PairingOptions) -> list[int]:
    """Edges lost before each flash, from the TIM-TM2 rising-edge counter.

    With the flash channel's rising edges (contact opening) available, each reported rising edge carries the
    count including itself, so consecutive rising marks differ by exactly 1 unless edges were lost; the loss
    is charged to the first flash after the earlier rising edge. Without them, consecutive flash (falling)
    reports are compared (less exact: a contact opening in the epoch after its flash shifts one count).
    """
    lost = [0] * len(flashes)
    if options.flash_source not in (None, "tim-tm2"):
        return lost  # only the TIM-TM2 counter reveals lost edges; a GPIO input sees every edge
    rising = sorted((m for m in all_marks if m.source == "tim-tm2" and m.channel == options.flash_channel
                     and m.edge != options.flash_edge and m.valid and m.time is not None),
                    key=lambda m: m.time)  # type: ignore[arg-type, return-value]
    if rising:
        for a, b in itertools.pairwise(rising):
            jump = (b.count - a.count) % COUNT_MODULO - 1
            if jump > 0:
                assert a.time is not None
                after = next((i for i, f in enumerate(flashes) if f.time > a.time), None)  # type: ignore[operator]
                if after is not None:
                    lost[after] += jump
        return lost
    prev_count: int | None = None
    for i, mark in enumerate(flashes):
        if mark.source != "tim-tm2":
            continue
        if prev_count is not None:
            lost[i] = max(0, (mark.count - prev_count) % COUNT_MODULO - 1)
        prev_count = mark.count
    return lost


def pair_marks(marks: Iterable[CameraMark], options: PairingOptions = PairingOptions()) -> list[ImagePairing]:
    """Pair trigger pulses with flashes, in time order; see the module docstring for the flags.

    Marks without a valid time, on other channels or with the other edge are ignored. Each pulse takes the
    first unclaimed flash in [pulse, min(pulse + max_delay_ns, next pulse)).
    """
    all_marks = list(marks)
    flashes = sorted((m for m in all_marks if _usable(m, options.flash_channel, options.flash_edge)
                      and options.flash_source in (None, m.source)),
                     key=lambda m: m.time)  # type: ignore[arg-type, return-value]
    flashes, flash_bounced = _debounce(flashes, options.bounce_window_ns)
    lost = _lost_edges(all_marks, flashes, options)

    def flash_flags(i: int) -> list[str]:
        flags = []
        if lost[i]:
            flags.append(MISSED_FLASH)
        if i in flash_bounced:
            flags.append(BOUNCE)
        return flags

    def from_flash(i: int, pulse: CameraMark | None, reason: str | None, extra: list[str]) -> ImagePairing:
        f = flashes[i]
        assert f.time is not None
        delay = None if pulse is None or pulse.time is None else f.time.diff_ns(pulse.time)
        return ImagePairing(
            index=-1,
            pulse_time=None if pulse is None else pulse.time,
            pulse_source=None if pulse is None else pulse.source,
            pulse_reason=reason,
            flash_time=f.time,
            flash_count=f.count,
            flash_acc_est_ns=f.acc_est_ns,
            delay_ns=delay,
            flags=tuple(flash_flags(i) + extra),
            lost_edges=lost[i],
        )

    out: list[ImagePairing] = []
    if not options.trigger_measured:
        out = [from_flash(i, None, NO_TRIGGER_MEASUREMENT, []) for i in range(len(flashes))]
    else:
        pulses = sorted((m for m in all_marks if _usable(m, options.trigger_channel, options.trigger_edge)),
                        key=lambda m: m.time)  # type: ignore[arg-type, return-value]
        pulses, pulse_bounced = _debounce(pulses, options.bounce_window_ns)
        claimed: set[int] = set()
        fi = 0
        for pi, pulse in enumerate(pulses):
            assert pulse.time is not None
            end_ns = pulse.time.total_ns + options.max_delay_ns
            if pi + 1 < len(pulses):
                nxt = pulses[pi + 1].time
                assert nxt is not None
                end_ns = min(end_ns, nxt.total_ns)
            while fi < len(flashes) and flashes[fi].time.total_ns < pulse.time.total_ns:  # type: ignore[union-attr]
                fi += 1
            extra = [BOUNCE] if pi in pulse_bounced else []
            if fi < len(flashes) and flashes[fi].time.total_ns < end_ns:  # type: ignore[union-attr]
                claimed.add(fi)
                out.append(from_flash(fi, pulse, None, extra))
                fi += 1
            else:
                out.append(ImagePairing(-1, pulse.time, pulse.source, None, None, None, None, None,
                                        tuple(extra + [PULSE_WITHOUT_FLASH])))
        for i in range(len(flashes)):
            if i not in claimed:
                out.append(from_flash(i, None, NO_PULSE_BEFORE_FLASH, [FLASH_WITHOUT_PULSE]))

    def when(p: ImagePairing) -> int:
        t = p.pulse_time if p.pulse_time is not None else p.flash_time
        assert t is not None
        return t.total_ns

    out.sort(key=when)
    if options.trigger_measured:
        out = _lost_edges_to_bounces(out, _lost_pulse_times(all_marks, options))
    return [dataclasses.replace(p, index=i) for i, p in enumerate(out)]


def _lost_pulse_times(all_marks: list[CameraMark], options: PairingOptions) -> list[int]:
    """GPS times (ns) of trigger rising edges reported after a jump of the trigger line's own TIM-TM2 count."""
    rising = sorted((m for m in all_marks if m.source == "tim-tm2" and m.channel == options.trigger_channel
                     and m.edge == "rising" and m.valid and m.time is not None),
                    key=lambda m: m.time)  # type: ignore[arg-type, return-value]
    return [b.time.total_ns for a, b in itertools.pairwise(rising)  # type: ignore[union-attr]
            if (b.count - a.count) % COUNT_MODULO > 1]


def _lost_edges_to_bounces(pairs: list[ImagePairing], lost_pulse_ns: list[int]) -> list[ImagePairing]:
    """Tell a missed flash from a bounce when the trigger is measured.

    A flash-line count jump is a missed flash when the image before it shows a pulse without flash, or when
    the trigger line lost pulses in the same gap (its own count jumped: the whole image's reports were lost,
    e.g. a port outage). Otherwise every pulse has its flash and the extra edge was a bounce; that flash time
    may be the bounce's edge (TIM-TM2 reports the last falling edge of the epoch), which BOUNCE tells.
    """
    fixed: list[ImagePairing] = []
    for i, p in enumerate(pairs):
        if MISSED_FLASH in p.flags and p.pulse_time is not None:
            prev = pairs[i - 1] if i > 0 else None
            prev_ns = _when_ns(prev) if prev is not None else -1
            pulses_lost = any(prev_ns < t <= p.pulse_time.total_ns for t in lost_pulse_ns)
            if not pulses_lost and (prev is None or PULSE_WITHOUT_FLASH not in prev.flags):
                flags = tuple(f for f in p.flags if f != MISSED_FLASH)
                p = dataclasses.replace(p, flags=flags if BOUNCE in flags else (*flags, BOUNCE))
        fixed.append(p)
    return fixed


class PairingRecorder:
    """Incremental pairing for the daemon: feed the marks of each TIM-TM2 report (or GPIO edge) as they come.

    `add(marks)` returns the event records to append now: one `mark` record per mark at once, and a
    `pairing` record for each image once it can no longer change (its pulse/flash is older than the newest
    mark by `settle_ns`: later marks can still bring its flash, a bounce, or the count that reveals a lost
    edge). `flush()` returns the remaining pairings at the end of a flight. Pure: no clock, no I/O.

    Only a window of marks is kept: those newer than the last emitted image minus `settle_ns` (its context:
    the previous pulse window and flash for bounces) plus the last rising flash-line edge before them (the
    counter reference), so the cost per report stays constant over a long flight.
    """

    def __init__(self, options: PairingOptions = PairingOptions(), settle_ns: int | None = None) -> None:
        self.options = options
        floor_ns = options.max_delay_ns + options.bounce_window_ns + 1_000_000_000
        self.settle_ns = max(settle_ns, floor_ns) if settle_ns is not None else floor_ns
        self._marks: list[CameraMark] = []
        self._emitted = 0
        self._latest_ns: int | None = None
        self._last_when_ns: int | None = None

    @property
    def emitted(self) -> int:
        """Pairings already returned."""
        return self._emitted

    @property
    def window(self) -> int:
        """Marks currently held."""
        return len(self._marks)

    def add(self, marks: Iterable[CameraMark], tick_ns: int | None = None) -> list[dict[str, Any]]:
        """Records for these marks and for every image that became final."""
        out: list[dict[str, Any]] = []
        for mark in marks:
            out.append(mark_record(mark, tick_ns))
            if mark.time is None or not mark.valid:
                continue  # recorded, but never part of a pairing
            self._marks.append(mark)
            t = mark.time.total_ns
            self._latest_ns = t if self._latest_ns is None else max(self._latest_ns, t)
        return out + self._pairings(final=False)

    def flush(self) -> list[dict[str, Any]]:
        """The pairing records not yet returned (end of flight)."""
        return self._pairings(final=True)

    def _pairings(self, final: bool) -> list[dict[str, Any]]:
        out = []
        for p in pair_marks(self._marks, self.options):
            when = _when_ns(p)
            if self._last_when_ns is not None and when <= self._last_when_ns:
                continue  # emitted before (kept as context)
            if not final and (self._latest_ns is None or self._latest_ns - when < self.settle_ns):
                break
            out.append(pairing_record(dataclasses.replace(p, index=self._emitted)))
            self._emitted += 1
            self._last_when_ns = when
        if out:
            self._prune()
        return out

    def _prune(self) -> None:
        assert self._last_when_ns is not None
        cut = self._last_when_ns - self.settle_ns
        old = [m for m in self._marks if m.time.total_ns < cut]  # type: ignore[union-attr]
        if not old:
            return
        ref = [m for m in old if m.source == "tim-tm2" and m.channel == self.options.flash_channel
               and m.edge != self.options.flash_edge]
        keep = [max(ref, key=lambda m: m.time.total_ns)] if ref else []  # type: ignore[union-attr]
        self._marks = keep + [m for m in self._marks if m.time.total_ns >= cut]  # type: ignore[union-attr]


def _when_ns(p: ImagePairing) -> int:
    t = p.pulse_time if p.pulse_time is not None else p.flash_time
    assert t is not None
    return t.total_ns


# --- GPIO edge times --------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class TickAnchor:
    """A known correspondence between the host monotonic clock and GPS time (e.g. a PPS edge ↔ its second)."""

    tick_ns: int
    time: GpsTime


def map_tick_to_gps(tick_ns: int, anchors: Sequence[TickAnchor], max_gap_ns: int = 10_000_000_000) -> GpsTime | None:
    """GPS time of a host monotonic `tick_ns`, linear between the two anchors around it (rate from them).

    Outside the anchors' span the nearest two extrapolate; one anchor gives an offset only (rate 1). Returns
    None when the nearest anchor is more than `max_gap_ns` away (PPS lost: better no time than a wrong one).
    Raises ValueError without anchors or with two anchors at the same tick.
    """
    if not anchors:
        raise ValueError("map_tick_to_gps needs at least one anchor")
    ordered = sorted(anchors, key=lambda a: a.tick_ns)
    nearest = min(ordered, key=lambda a: abs(a.tick_ns - tick_ns))
    if abs(nearest.tick_ns - tick_ns) > max_gap_ns:
        return None
    if len(ordered) == 1:
        return nearest.time.add_ns(tick_ns - nearest.tick_ns)
    i = 0
    while i + 2 < len(ordered) and ordered[i + 1].tick_ns <= tick_ns:
        i += 1
    a, b = ordered[i], ordered[i + 1]
    span_tick = b.tick_ns - a.tick_ns
    if span_tick == 0:
        raise ValueError(f"two anchors at the same tick {a.tick_ns}")
    offset = Fraction((tick_ns - a.tick_ns) * b.time.diff_ns(a.time), span_tick)
    return a.time.add_ns(round(offset))


def pps_anchors(pps_ticks_ns: Iterable[int], coarse: TickAnchor, max_offset_ns: int = 400_000_000) -> list[TickAnchor]:
    """Anchors from PPS edges seen on a GPIO: each tick belongs to the whole GPS second nearest its coarse time.

    `coarse` relates the host clock to GPS time roughly (e.g. the host tick at which a navigation epoch's
    bytes arrived, and that epoch's GPS time: tens of ms off). A tick whose coarse time is more than
    `max_offset_ns` from a whole second is not a PPS edge (noise, or a pulse that is not 1 PPS) and is skipped.
    """
    out = []
    for tick in pps_ticks_ns:
        approx = coarse.time.total_ns + (tick - coarse.tick_ns)
        second = round(Fraction(approx, 1_000_000_000)) * 1_000_000_000
        if abs(approx - second) <= max_offset_ns:
            out.append(TickAnchor(tick, GpsTime.from_total_ns(second)))
    return out


def gpio_mark(
    channel: int, rising: bool, tick_ns: int, count: int, anchors: Sequence[TickAnchor], acc_est_ns: int = 1_000
) -> CameraMark:
    """A CameraMark from a GPIO edge (source "gpio"); `valid` False and `time` None when it cannot be mapped.

    `acc_est_ns` the edge timing uncertainty the caller vouches for (chrony/PPS discipline, interrupt latency).
    """
    time = map_tick_to_gps(tick_ns, anchors) if anchors else None
    return CameraMark(channel, "rising" if rising else "falling", count, time, acc_est_ns, 1, time is not None, "gpio")


# --- event records ----------------------------------------------------------------------------------------


def _split(t: GpsTime | None) -> tuple[int | None, int | None]:
    return (None, None) if t is None else (t.week, t.tow_ns)


def mark_record(mark: CameraMark, tick_ns: int | None = None) -> dict[str, Any]:
    """The `mark` event record of a CameraMark (GPIO marks may carry their host tick)."""
    week, tow_ns = _split(mark.time)
    rec: dict[str, Any] = {
        "v": EVENT_FORMAT_VERSION, "kind": "mark", "source": mark.source, "channel": mark.channel,
        "edge": mark.edge, "count": mark.count, "week": week, "tow_ns": tow_ns, "acc_est_ns": mark.acc_est_ns,
        "time_base": mark.time_base, "valid": mark.valid,
    }
    if tick_ns is not None:
        rec["tick_ns"] = tick_ns
    return rec


def pairing_record(p: ImagePairing) -> dict[str, Any]:
    """The `pairing` event record of an ImagePairing."""
    pw, pt = _split(p.pulse_time)
    fw, ft = _split(p.flash_time)
    return {
        "v": EVENT_FORMAT_VERSION, "kind": "pairing", "index": p.index, "pulse_week": pw, "pulse_tow_ns": pt,
        "pulse_source": p.pulse_source, "pulse_reason": p.pulse_reason, "flash_week": fw, "flash_tow_ns": ft,
        "flash_count": p.flash_count, "flash_acc_est_ns": p.flash_acc_est_ns, "delay_ns": p.delay_ns,
        "flags": list(p.flags), "lost_edges": p.lost_edges,
    }


def timepulse_record(
    camera_timepulse: str, period_us: int, length_us: int, rising: bool, align_to_tow: int | None, trigger: str
) -> dict[str, Any]:
    """The `timepulse` record: what the receiver applied to the camera pulse and how pulses are measured."""
    measured = trigger != "none"
    note = ("pulse times measured on " + ("TIM-TM2 channel 1" if trigger == "extint1" else "a GPIO input")
            if measured else f"{NO_TRIGGER_MEASUREMENT}: pulse phase unknown, only flash times are exact")
    return {
        "v": EVENT_FORMAT_VERSION, "kind": "timepulse", "camera_timepulse": camera_timepulse,
        "period_us": period_us, "length_us": length_us, "rising": rising, "align_to_tow": align_to_tow,
        "trigger": trigger, "trigger_measured": measured, "note": note,
    }


def format_line(record: Mapping[str, Any]) -> str:
    """One `events.jsonl` line (compact, keys sorted, newline-terminated) — the same bytes EventLog writes."""
    return json.dumps(record, separators=(",", ":"), sort_keys=True) + "\n"


def _time(rec: Mapping[str, Any], week_key: str, tow_key: str) -> GpsTime | None:
    week, tow = rec.get(week_key), rec.get(tow_key)
    if week is None and tow is None:
        return None
    if not isinstance(week, int) or not isinstance(tow, int):
        raise InputError(f"event record: {week_key}/{tow_key} must be integers, got {week!r}/{tow!r}")
    return GpsTime.from_week_tow_ns(week, tow)


def mark_from_record(rec: Mapping[str, Any]) -> CameraMark:
    """CameraMark from a `mark` record; InputError naming the field when it is malformed."""
    try:
        return CameraMark(
            channel=int(rec["channel"]), edge=str(rec["edge"]), count=int(rec["count"]),
            time=_time(rec, "week", "tow_ns"), acc_est_ns=int(rec["acc_est_ns"]),
            time_base=int(rec["time_base"]), valid=bool(rec["valid"]), source=str(rec["source"]),
        )
    except KeyError as exc:
        raise InputError(f"mark record lacks field {exc}") from exc
    except (TypeError, ValueError) as exc:
        raise InputError(f"mark record malformed: {exc}") from exc


def pairing_from_record(rec: Mapping[str, Any]) -> ImagePairing:
    """ImagePairing from a `pairing` record; InputError naming the field when it is malformed."""
    try:
        return ImagePairing(
            index=int(rec["index"]), pulse_time=_time(rec, "pulse_week", "pulse_tow_ns"),
            pulse_source=rec["pulse_source"], pulse_reason=rec["pulse_reason"],
            flash_time=_time(rec, "flash_week", "flash_tow_ns"), flash_count=rec["flash_count"],
            flash_acc_est_ns=rec["flash_acc_est_ns"], delay_ns=rec["delay_ns"],
            flags=tuple(str(f) for f in rec["flags"]), lost_edges=int(rec["lost_edges"]),
        )
    except KeyError as exc:
        raise InputError(f"pairing record lacks field {exc}") from exc
    except (TypeError, ValueError) as exc:
        raise InputError(f"pairing record malformed: {exc}") from exc


def parse_records(records: Iterable[Mapping[str, Any]]) -> tuple[list[CameraMark], list[ImagePairing], list[dict[str, Any]]]:
    """Split decoded `events.jsonl` objects into marks, pairings and other records (timepulse, future kinds).

    Raises InputError on a record of a newer format version or a malformed mark/pairing.
    """
    marks: list[CameraMark] = []
    pairings: list[ImagePairing] = []
    other: list[dict[str, Any]] = []
    for n, rec in enumerate(records):
        if rec.get("v", EVENT_FORMAT_VERSION) > EVENT_FORMAT_VERSION:
            raise InputError(f"event record {n}: format version {rec.get('v')} is newer than {EVENT_FORMAT_VERSION}")
        kind = rec.get("kind")
        if kind == "mark":
            marks.append(mark_from_record(rec))
        elif kind == "pairing":
            pairings.append(pairing_from_record(rec))
        else:
            other.append(dict(rec))
    return marks, pairings, other
