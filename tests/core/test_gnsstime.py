"""GPS time arithmetic and conversions."""

from __future__ import annotations

import datetime as dt

from hypothesis import given
from hypothesis import strategies as st

from onboard.gnsstime import NS_PER_WEEK, GpsTime, gpst_from_calendar, resolve_week


def test_normalisation_across_week_boundary() -> None:
    t = GpsTime.from_week_tow_ns(1590, NS_PER_WEEK + 5)
    assert (t.week, t.tow_ns) == (1591, 5)
    assert GpsTime.from_week_tow_ns(1590, -1) == GpsTime(1589, NS_PER_WEEK - 1)


def test_tim_tm2_ms_plus_subms_keeps_nanoseconds() -> None:
    t = GpsTime.from_ms_subms(2021, 396_000_123, 456_789)
    assert t.tow_ns == 396_000_123_456_789


def test_utc_round_trip_with_leap_seconds() -> None:
    utc = dt.datetime(2018, 10, 4, 12, 37, 0, tzinfo=dt.UTC)
    t = GpsTime.from_utc(utc)
    assert t.week == 2021
    # 2018: GPS − UTC = 18 s
    assert t == gpst_from_calendar(2018, 10, 4, 12, 37, 18 * 10**9)
    assert t.to_utc() == utc


def test_resolve_week_near_rollover() -> None:
    ref = GpsTime.from_week_tow_s(2000, 604_790.0)
    assert resolve_week(5.0, ref) == GpsTime.from_week_tow_s(2001, 5.0)
    ref2 = GpsTime.from_week_tow_s(2001, 3.0)
    assert resolve_week(604_799.0, ref2) == GpsTime.from_week_tow_s(2000, 604_799.0)


@given(st.integers(0, 3000), st.integers(0, NS_PER_WEEK - 1), st.integers(-10**15, 10**15))
def test_add_and_diff_are_exact(week: int, tow_ns: int, delta_ns: int) -> None:
    t = GpsTime(week, tow_ns)
    assert t.add_ns(delta_ns).diff_ns(t) == delta_ns
    assert (t.add_ns(delta_ns) > t) == (delta_ns > 0)
