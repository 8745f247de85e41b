"""The satellite-system vocabulary (gnssId ↔ RINEX letter ↔ satellite id) and the time systems' offsets."""

from __future__ import annotations

import datetime as dt

import pytest

from onboard.gnsstime import (
    GpsTime,
    bdt_week_tow_ns,
    glonass_datetime,
    gpst_from_bdt,
    gpst_from_glonass_datetime,
    gpst_from_glonass_day,
    gpst_from_glonass_tod,
    gpst_from_gst,
    gst_week_tow_ns,
)
from onboard.rtk.consts import l1_wavelength_m
from onboard.rtk.gnss import (
    SYSTEMS,
    SatIdError,
    glonass_l1_freq_hz,
    is_beidou_geo,
    parse_sat_id,
    sat_id,
)
from onboard.rtk.types import GNSS_BEIDOU, GNSS_GALILEO, GNSS_GLONASS, GNSS_GPS, GNSS_QZSS, GNSS_SBAS

S = 1_000_000_000


def test_ublox_gnss_ids_and_rinex_letters() -> None:
    assert {s.gnss_id: s.letter for s in SYSTEMS.values()} == {0: "G", 1: "S", 2: "E", 3: "C", 5: "J", 6: "R"}


@pytest.mark.parametrize(("gnss", "sv", "text"), [
    (GNSS_GPS, 5, "G05"), (GNSS_GLONASS, 7, "R07"), (GNSS_GALILEO, 11, "E11"), (GNSS_BEIDOU, 59, "C59"),
    (GNSS_QZSS, 1, "J01"), (GNSS_SBAS, 120, "S20"), (GNSS_SBAS, 158, "S58"),
])
def test_sat_id_round_trip(gnss: int, sv: int, text: str) -> None:
    assert sat_id(gnss, sv) == text
    assert parse_sat_id(text) == (gnss, sv)


def test_sat_id_rejects_what_no_system_defines() -> None:
    for bad in ("X01", "G33", "R25", "", "E", "Gxx", "S19"):
        with pytest.raises(SatIdError):
            parse_sat_id(bad)
    with pytest.raises(SatIdError):
        sat_id(4, 1)  # IMES
    with pytest.raises(SatIdError):
        sat_id(GNSS_GLONASS, 255)  # u-blox's "slot unknown"
    assert parse_sat_id(" 5") == (GNSS_GPS, 5)  # RINEX 2 writes GPS without a letter


def test_glonass_frequencies_and_wavelengths() -> None:
    assert glonass_l1_freq_hz(0) == 1_602_000_000.0
    assert glonass_l1_freq_hz(-7) == 1_598_062_500.0 and glonass_l1_freq_hz(6) == 1_605_375_000.0
    with pytest.raises(SatIdError):
        glonass_l1_freq_hz(7)
    assert l1_wavelength_m(GNSS_GLONASS, 1) == pytest.approx(299_792_458.0 / 1_602_562_500.0)
    assert l1_wavelength_m(GNSS_GALILEO) == l1_wavelength_m(GNSS_GPS) == l1_wavelength_m(GNSS_QZSS)
    assert l1_wavelength_m(GNSS_BEIDOU) == pytest.approx(0.192039486)
    assert l1_wavelength_m(GNSS_GLONASS) is None  # no channel: its phase cannot be turned into cycles
    assert l1_wavelength_m(GNSS_GLONASS, 7) is None


def test_beidou_geo_prns() -> None:
    assert [p for p in range(1, 64) if is_beidou_geo(p)] == [1, 2, 3, 4, 5, 59, 60, 61, 62, 63]


def test_gst_is_gpst_with_week_1024_as_zero() -> None:
    t = GpsTime(2176, 263_400 * S)
    assert gst_week_tow_ns(t) == (1152, 263_400 * S)
    assert gpst_from_gst(1152, 263_400 * S) == t


def test_bdt_is_14_s_behind_gpst() -> None:
    # BDT week 0 began 2006-01-01 00:00:00 UTC, when GPST was 14 s ahead of UTC
    assert gpst_from_bdt(0, 0) == GpsTime.from_utc(dt.datetime(2006, 1, 1, tzinfo=dt.UTC))
    t = GpsTime(2176, 5 * S)
    week, tow = bdt_week_tow_ns(t)
    assert (week, tow) == (2176 - 1356 - 1, 604_800 * S - 9 * S)  # 14 s back crosses the BDT week start
    assert gpst_from_bdt(week, tow) == t


def test_glonass_time_is_utc_plus_3_h() -> None:
    leap = 18
    utc = dt.datetime(2021, 9, 22, 1, 30, tzinfo=dt.UTC)
    t = GpsTime.from_utc(utc)
    glo = dt.datetime(2021, 9, 22, 4, 30)
    assert gpst_from_glonass_datetime(glo, leap) == t
    assert glonass_datetime(t, leap) == glo
    # time of day 04:30 GLONASS nearest a reference half a day away either side
    assert gpst_from_glonass_tod(4.5 * 3600, t.add_s(40_000), leap) == t
    assert gpst_from_glonass_tod(4.5 * 3600, t.add_s(-40_000), leap) == t
    # just after midnight GLONASS time (21:00 UTC the day before) seen from 23:59 GLONASS time
    ref = gpst_from_glonass_datetime(dt.datetime(2021, 9, 21, 23, 59), leap)
    assert gpst_from_glonass_tod(60.0, ref, leap) == gpst_from_glonass_datetime(dt.datetime(2021, 9, 22, 0, 1), leap)
    # N4 = 7 is 2020–2023; day 631 of it is 2021-09-22 (2020 has 366 days)
    assert gpst_from_glonass_day(7, 631, 4.5 * 3600, leap) == t
