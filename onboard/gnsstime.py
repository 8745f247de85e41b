"""GPS time as integer week + integer nanoseconds of week, and every conversion in one place.

Observation and mark times are never float POSIX seconds: a float loses nanoseconds after ~100 days of
POSIX time, and RTK carrier-phase work needs the epoch to well below a microsecond.
"""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass
from functools import total_ordering

NS_PER_S = 1_000_000_000
SECONDS_PER_WEEK = 604_800
NS_PER_WEEK = SECONDS_PER_WEEK * NS_PER_S

GPS_EPOCH = _dt.datetime(1980, 1, 6, tzinfo=_dt.UTC)

# GPS − UTC leap seconds: (first UTC instant at which the offset applies, offset_s). IERS Bulletin C.
_LEAP_SECONDS: tuple[tuple[_dt.datetime, int], ...] = tuple(
    (_dt.datetime(y, m, 1, tzinfo=_dt.UTC), n)
    for (y, m, n) in (
        (1981, 7, 1), (1982, 7, 2), (1983, 7, 3), (1985, 7, 4), (1988, 1, 5), (1990, 1, 6),
        (1991, 1, 7), (1992, 7, 8), (1993, 7, 9), (1994, 7, 10), (1996, 1, 11), (1997, 7, 12),
        (1999, 1, 13), (2006, 1, 14), (2009, 1, 15), (2012, 7, 16), (2015, 7, 17), (2017, 1, 18),
    )
)


@total_ordering
@dataclass(frozen=True, slots=True)
class GpsTime:
    """An instant in GPS time: `week` (full GPS week number) and `tow_ns` (ns of week, 0 ≤ tow_ns < 1 week).

    Construct through :meth:`from_week_tow_ns` or :meth:`from_week_tow_s` to normalise out-of-range values.
    """

    week: int
    tow_ns: int

    @classmethod
    def from_week_tow_ns(cls, week: int, tow_ns: int) -> GpsTime:
        """Normalise any (week, ns-of-week) pair, e.g. a negative or > 1 week ns count."""
        total = int(week) * NS_PER_WEEK + int(tow_ns)
        w, ns = divmod(total, NS_PER_WEEK)
        return cls(w, ns)

    @classmethod
    def from_week_tow_s(cls, week: int, tow_s: float) -> GpsTime:
        """From a week and float seconds of week (rounded to the nearest ns)."""
        return cls.from_week_tow_ns(week, round(tow_s * NS_PER_S))

    @classmethod
    def from_ms_subms(cls, week: int, tow_ms: int, sub_ms_ns: int) -> GpsTime:
        """From the TIM-TM2 / TIM-TP split: integer ms of week plus a ns fraction of the ms."""
        return cls.from_week_tow_ns(week, int(tow_ms) * 1_000_000 + int(sub_ms_ns))

    @classmethod
    def from_total_ns(cls, total_ns: int) -> GpsTime:
        """From ns since the GPS epoch (1980-01-06 00:00:00 GPST)."""
        return cls.from_week_tow_ns(0, total_ns)

    @classmethod
    def from_utc(cls, utc: _dt.datetime) -> GpsTime:
        """From a timezone-aware UTC datetime (leap seconds applied)."""
        if utc.tzinfo is None:
            raise ValueError("from_utc needs a timezone-aware datetime")
        delta = utc - GPS_EPOCH
        ns = (delta.days * 86_400 + delta.seconds) * NS_PER_S + delta.microseconds * 1_000
        return cls.from_total_ns(ns + leap_seconds_at_utc(utc) * NS_PER_S)

    @property
    def tow_s(self) -> float:
        """Seconds of week as a float (for numerics that need it; loses nothing below ~0.1 ns)."""
        return self.tow_ns / NS_PER_S

    @property
    def total_ns(self) -> int:
        """Nanoseconds since the GPS epoch."""
        return self.week * NS_PER_WEEK + self.tow_ns

    def add_ns(self, ns: int) -> GpsTime:
        """This instant shifted by `ns` nanoseconds."""
        return GpsTime.from_week_tow_ns(self.week, self.tow_ns + int(ns))

    def add_s(self, seconds: float) -> GpsTime:
        """This instant shifted by `seconds` (rounded to the nearest ns)."""
        return self.add_ns(round(seconds * NS_PER_S))

    def diff_ns(self, other: GpsTime) -> int:
        """self − other in integer nanoseconds."""
        return self.total_ns - other.total_ns

    def diff_s(self, other: GpsTime) -> float:
        """self − other in seconds."""
        return self.diff_ns(other) / NS_PER_S

    def to_utc(self) -> _dt.datetime:
        """The UTC datetime of this instant (µs resolution, leap seconds removed)."""
        approx = GPS_EPOCH + _dt.timedelta(microseconds=self.total_ns // 1_000)
        leap = leap_seconds_at_utc(approx - _dt.timedelta(seconds=leap_seconds_at_utc(approx)))
        return approx - _dt.timedelta(seconds=leap)

    def to_gpst_datetime(self) -> _dt.datetime:
        """The calendar date-time of this instant on the GPS time scale (no leap seconds; µs resolution)."""
        return GPS_EPOCH + _dt.timedelta(microseconds=self.total_ns // 1_000)

    def __lt__(self, other: GpsTime) -> bool:
        return (self.week, self.tow_ns) < (other.week, other.tow_ns)

    def __str__(self) -> str:
        return f"{self.week}:{self.tow_ns / NS_PER_S:.9f}"


def leap_seconds_at_utc(utc: _dt.datetime) -> int:
    """GPS − UTC in whole seconds at the UTC instant `utc`."""
    n = 0
    for start, offset in _LEAP_SECONDS:
        if utc >= start:
            n = offset
    return n


def gpst_from_calendar(year: int, month: int, day: int, hour: int, minute: int, second_ns: int) -> GpsTime:
    """GPS time from a calendar date on the GPS time scale (as in RINEX epochs), seconds given in ns."""
    d = _dt.datetime(year, month, day, hour, minute, tzinfo=_dt.UTC) - GPS_EPOCH
    return GpsTime.from_total_ns((d.days * 86_400 + d.seconds) * NS_PER_S + int(second_ns))


def resolve_week(tow_s: float, reference: GpsTime) -> GpsTime:
    """Attach the GPS week to a time of week (RTCM epochs carry none) using a nearby `reference` instant."""
    t = GpsTime.from_week_tow_s(reference.week, tow_s)
    dt = t.diff_s(reference)
    if dt > SECONDS_PER_WEEK / 2:
        t = t.add_ns(-NS_PER_WEEK)
    elif dt < -SECONDS_PER_WEEK / 2:
        t = t.add_ns(NS_PER_WEEK)
    return t


# ------------------------------------------------------------------------------------------------ time systems
# Every instant is kept on the GPS time scale (GpsTime); these convert the other systems' broadcast times to it.

GST_WEEK_OFFSET = 1024
"""GPS week of Galileo System Time week 0 (GST started 1999-08-22 00:00 UTC = GPS week 1024, 13 s ahead of UTC;
GST runs in step with GPST: GST = GPST, only the week count differs)."""
BDT_WEEK_OFFSET = 1356
"""GPS week of BeiDou Time week 0 (BDT started 2006-01-01 00:00:00 UTC, when GPST − UTC was 14 s)."""
BDT_MINUS_GPST_S = -14
"""BDT − GPST, s (BDT has no leap seconds and started 14 s behind GPST)."""
GLONASST_MINUS_UTC_S = 3 * 3600
"""GLONASS time − UTC(SU), s (Moscow time: GLONASS time follows UTC leap seconds)."""


def gpst_from_gst(gst_week: int, gst_tow_ns: int) -> GpsTime:
    """GPS time of a Galileo System Time instant (GST week number as broadcast, 0 at 1999-08-22; ns of week)."""
    return GpsTime.from_week_tow_ns(gst_week + GST_WEEK_OFFSET, gst_tow_ns)


def gst_week_tow_ns(t: GpsTime) -> tuple[int, int]:
    """The GST (week, ns of week) of GPS time `t`."""
    return t.week - GST_WEEK_OFFSET, t.tow_ns


def gpst_from_bdt(bdt_week: int, bdt_tow_ns: int) -> GpsTime:
    """GPS time of a BeiDou Time instant (BDT week, 0 at 2006-01-01; ns of BDT week): GPST = BDT + 14 s."""
    return GpsTime.from_week_tow_ns(bdt_week + BDT_WEEK_OFFSET, bdt_tow_ns - BDT_MINUS_GPST_S * NS_PER_S)


def bdt_week_tow_ns(t: GpsTime) -> tuple[int, int]:
    """The BDT (week, ns of week) of GPS time `t` (BDT = GPST − 14 s)."""
    b = t.add_ns(BDT_MINUS_GPST_S * NS_PER_S)
    return b.week - BDT_WEEK_OFFSET, b.tow_ns


def gpst_from_glonass_datetime(glonass_time: _dt.datetime, leap_s: int) -> GpsTime:
    """GPS time of a GLONASS time calendar instant (UTC(SU) + 3 h; naive or UTC-tagged, read as GLONASS time).

    `leap_s` is GPST − UTC at that instant (s; 18 since 2017): GPST = GLONASS time − 3 h + leap_s. It is a
    parameter because the broadcast GLONASS message and RINEX carry it separately (or not at all).
    """
    g = glonass_time.replace(tzinfo=None) - GPS_EPOCH.replace(tzinfo=None)
    ns = (g.days * 86_400 + g.seconds) * NS_PER_S + g.microseconds * 1_000
    return GpsTime.from_total_ns(ns + (leap_s - GLONASST_MINUS_UTC_S) * NS_PER_S)


def glonass_datetime(t: GpsTime, leap_s: int) -> _dt.datetime:
    """The GLONASS time calendar instant (naive datetime, µs resolution) of GPS time `t`; `leap_s` = GPST − UTC."""
    return t.add_ns((GLONASST_MINUS_UTC_S - leap_s) * NS_PER_S).to_gpst_datetime().replace(tzinfo=None)


def gpst_from_glonass_tod(tod_s: float, reference: GpsTime, leap_s: int) -> GpsTime:
    """GPS time of the GLONASS time of day `tod_s` (s since 00:00 GLONASS time) nearest `reference` (within
    half a day: the broadcast tb/tk carry no date). `leap_s` = GPST − UTC."""
    day_ns = 86_400 * NS_PER_S
    ref_glo = reference.total_ns + (GLONASST_MINUS_UTC_S - leap_s) * NS_PER_S  # GLONASS time, ns since 1980-01-06
    day_start = ref_glo - ref_glo % day_ns
    t = day_start + round(tod_s * NS_PER_S)
    if t - ref_glo > day_ns // 2:
        t -= day_ns
    elif t - ref_glo < -day_ns // 2:
        t += day_ns
    return GpsTime.from_total_ns(t - (GLONASST_MINUS_UTC_S - leap_s) * NS_PER_S)


def gpst_from_glonass_day(n4: int, nt: int, tod_s: float, leap_s: int) -> GpsTime:
    """GPS time of a GLONASS date given as the broadcast four-year interval `n4` (1 = 1996–1999), day `nt`
    within it (1 = 1 January of the leap year) and time of day `tod_s` (GLONASS ICD 5.1 A.3.1.3)."""
    start = _dt.datetime(1996 + 4 * (n4 - 1), 1, 1) + _dt.timedelta(days=nt - 1)
    return gpst_from_glonass_datetime(start, leap_s).add_ns(round(tod_s * NS_PER_S))


def gps_from_glonass_tod(tod_ns: int, reference: GpsTime) -> GpsTime:
    """GPS time of a GLONASS time of day (ns since Moscow midnight, as RTCM MSM DF034) nearest `reference`
    (within 12 h), with the GPS − UTC leap seconds in force at `reference`."""
    leap_s = leap_seconds_at_utc(reference.to_utc())
    day_ns = 86_400 * NS_PER_S
    ref_glo = reference.total_ns + (GLONASST_MINUS_UTC_S - leap_s) * NS_PER_S
    t = ref_glo - ref_glo % day_ns + tod_ns % day_ns
    if t - ref_glo > day_ns // 2:
        t -= day_ns
    elif t - ref_glo < -day_ns // 2:
        t += day_ns
    return GpsTime.from_total_ns(t - (GLONASST_MINUS_UTC_S - leap_s) * NS_PER_S)


def gps_from_bdt_tow_ns(tow_ns: int, reference: GpsTime) -> GpsTime:
    """GPS time of a BeiDou time of week (ns, as RTCM MSM DF427), in the week nearest to `reference`."""
    gps_tow_ns = (tow_ns - BDT_MINUS_GPST_S * NS_PER_S) % NS_PER_WEEK
    return resolve_week(gps_tow_ns / NS_PER_S, reference)
