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


GLONASS_UTC_OFFSET_S = 3 * 3600
"""GLONASS system time = UTC(SU) + 3 h (Moscow time; UTC(SU) taken as UTC)."""
BDT_GPST_OFFSET_S = 14
"""GPS time − BeiDou time (BDT started 2006-01-01 00:00:00 UTC, when GPS − UTC was 14 s)."""


def gps_from_glonass_tod(tod_ns: int, reference: GpsTime) -> GpsTime:
    """GPS time of a GLONASS time of day (ns since Moscow midnight, as RTCM MSM DF034) on the day nearest to
    `reference` (any GPS time within 12 h of it). GLONASS follows UTC, leap seconds included: the result adds
    the GPS − UTC offset in force at that UTC instant."""
    ref_utc = reference.to_utc()
    utc_tod_ns = (tod_ns - GLONASS_UTC_OFFSET_S * NS_PER_S) % (86_400 * NS_PER_S)
    midnight = ref_utc.replace(hour=0, minute=0, second=0, microsecond=0)
    t_utc_ns = utc_tod_ns
    ref_tod_ns = (ref_utc - midnight) // _dt.timedelta(microseconds=1) * 1_000
    if t_utc_ns - ref_tod_ns > 43_200 * NS_PER_S:
        t_utc_ns -= 86_400 * NS_PER_S
    elif t_utc_ns - ref_tod_ns < -43_200 * NS_PER_S:
        t_utc_ns += 86_400 * NS_PER_S
    day = midnight + _dt.timedelta(microseconds=t_utc_ns // 1_000)
    whole = GpsTime.from_utc(day)
    return whole.add_ns(t_utc_ns % 1_000)


def gps_from_bdt_tow_ns(tow_ns: int, reference: GpsTime) -> GpsTime:
    """GPS time of a BeiDou time of week (ns, as RTCM MSM DF427), in the week nearest to `reference`."""
    gps_tow_ns = (tow_ns + BDT_GPST_OFFSET_S * NS_PER_S) % NS_PER_WEEK
    return resolve_week(gps_tow_ns / NS_PER_S, reference)
