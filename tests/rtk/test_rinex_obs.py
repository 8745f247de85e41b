"""RINEX 2.10/2.11/3.04 observation reader on the real files in ../shared/data/gnss."""

from __future__ import annotations

import gzip

import numpy as np
import pytest

from onboard.errors import InputError
from onboard.formats.rinex_obs import read_rinex_obs
from onboard.gnsstime import gpst_from_calendar
from onboard.rtk.types import GNSS_GLONASS, GNSS_GPS, LLI_HALF_CYCLE, LLI_SLIP
from tests.conftest import shared_file


def test_v304_ublox_rover_header_and_first_epoch():
    f = read_rinex_obs(shared_file("gnss/ublox-m8p-galway-2018/rinex/rover-20181004-1237.obs.gz"))
    h = f.header
    assert h.version == pytest.approx(3.04)
    assert h.obs_types["G"] == ["C1C", "L1C", "D1C", "S1C"]
    np.testing.assert_allclose(h.approx_pos_ecef_m, [3774090.1817, -601658.4023, 5089319.5498])
    assert len(f.epochs) == 1205  # event records (flag 5, TIM-TM2) are not epochs
    e = f.epochs[0]
    assert e.time == gpst_from_calendar(2018, 10, 4, 12, 38, 8_991_000_000)
    g = e.gps_only()
    i = int(np.flatnonzero(g.sv_id == 3)[0])
    assert g.pr_m[i] == pytest.approx(17587846.316)
    assert g.cp_cyc[i] == pytest.approx(92424756.781)
    assert g.dop_hz[i] == pytest.approx(206.561)
    assert g.cn0_dbhz[i] == pytest.approx(51.0)
    j = int(np.flatnonzero(g.sv_id == 22)[0])
    assert g.lli[j] == LLI_SLIP  # "95357975.6041": LLI digit 1
    assert np.any(e.gnss_id == GNSS_GLONASS) and np.any(e.gnss_id == GNSS_GPS)
    assert np.any((g.lli & LLI_HALF_CYCLE) != 0)


def test_v304_rtcm_base_has_no_doppler_and_header_position():
    f = read_rinex_obs(shared_file("gnss/ublox-m8p-galway-2018/rinex/base-20181004-1236.rtcm.obs.gz"))
    np.testing.assert_allclose(f.header.antenna_position_ecef_m(), [3774089.2120, -601661.6157, 5089321.2474])
    g = f.epochs[0].gps_only()
    assert len(g) == 10 and np.all(np.isnan(g.dop_hz)) and np.all(np.isfinite(g.cp_cyc))


def test_v210_geonet_reads_120_epochs_with_l1_c1():
    f = read_rinex_obs(shared_file("gnss/geonet-0759-3040-20050402/07590920.05o.gz"))
    assert f.header.obs_types["G"] == ["L1", "C1", "L2", "P2"]
    assert f.header.interval_s == 30.0
    assert len(f.epochs) == 120
    e = f.epochs[0]
    assert list(e.sv_id) == [3, 7, 8, 11, 19, 20, 24, 28]
    assert e.cp_cyc[0] == pytest.approx(55923622.160)
    assert e.pr_m[0] == pytest.approx(24767686.375)
    assert e.time.diff_s(f.epochs[1].time) == -30.0


def test_v211_cors_with_more_than_twelve_satellites_uses_continuation_lines():
    f = read_rinex_obs(shared_file("gnss/ublox-m8p-galway-2018/cors-glw1/glw1277m.18o.gz"))
    assert len(f.epochs) == 720
    big = max(f.epochs, key=len)
    assert len(big) > 12  # the satellite list continued on a second line
    assert np.all(np.isfinite(big.gps_only().pr_m))
    assert np.all(np.abs(big.gps_only().pr_m - 2.2e7) < 4e6)  # every value landed in the right column


def test_v304_septentrio_picks_l1c_among_many_signals():
    f = read_rinex_obs(shared_file("gnss/geonet-3034-sept-20210922/SEPT265G.21O.gz"))
    g = f.epochs[0].gps_only()
    assert len(f.epochs) == 360 and len(g) == 7
    # L1 C/A: carrier/code ratio is the L1 frequency/c
    ratio = g.cp_cyc / g.pr_m
    np.testing.assert_allclose(ratio, 1575.42e6 / 299792458.0, rtol=2e-5)


def test_not_rinex_is_a_clear_error(tmp_path):
    p = tmp_path / "x.obs"
    p.write_text("hello\n")
    with pytest.raises(InputError, match="not a RINEX file"):
        read_rinex_obs(p)


def test_navigation_file_is_refused_as_observations():
    with pytest.raises(InputError, match="not an observation file"):
        read_rinex_obs(shared_file("gnss/broadcast-nav-20100701/brdc1820.10n"))


def test_corrupt_gzip_is_a_clear_error(tmp_path):
    raw = shared_file("gnss/geonet-0759-3040-20050402/07590920.05o.gz").read_bytes()
    p = tmp_path / "cut.obs.gz"
    p.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(InputError, match="gzip"):
        read_rinex_obs(p)


def test_truncated_last_epoch_is_dropped_and_the_rest_kept(tmp_path):
    text = gzip.decompress(shared_file("gnss/geonet-0759-3040-20050402/07590920.05o.gz").read_bytes()).decode()
    lines = text.splitlines()
    p = tmp_path / "trunc.05o"
    p.write_text("\n".join(lines[:-3]) + "\n")
    f = read_rinex_obs(p)
    assert len(f.epochs) == 119


def test_garbage_in_an_observation_field_names_the_satellite(tmp_path):
    text = gzip.decompress(shared_file("gnss/geonet-0759-3040-20050402/07590920.05o.gz").read_bytes()).decode()
    lines = text.splitlines()
    k = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln)
    lines[k + 2] = "  5592XYZ2.160" + lines[k + 2][14:]
    p = tmp_path / "bad.05o"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match="G 3"):
        read_rinex_obs(p)


def test_missing_end_of_header(tmp_path):
    p = tmp_path / "h.obs"
    p.write_text("     3.04           OBSERVATION DATA    M                   RINEX VERSION / TYPE\n")
    with pytest.raises(InputError, match="END OF HEADER"):
        read_rinex_obs(p)


@pytest.mark.parametrize("name", ["gnss/ublox-m8p-galway-2018/rinex/rover-20181004-1237.obs.gz",  # RINEX 3.04
                                  "gnss/ublox-m8p-galway-2018/cors-glw1/glw1277m.18o.gz"])  # RINEX 2.11
def test_systems_filter_keeps_exactly_the_gps_satellites(name):
    full = read_rinex_obs(shared_file(name))
    gps = read_rinex_obs(shared_file(name), systems="G")
    assert len(gps.epochs) == len(full.epochs)
    assert any(np.any(e.gnss_id == GNSS_GLONASS) for e in full.epochs)
    for a, b in zip(full.epochs, gps.epochs, strict=True):
        ga = a.gps_only()
        assert b.time == a.time and np.all(b.gnss_id == GNSS_GPS)
        for f in ("sv_id", "pr_m", "cp_cyc", "dop_hz", "cn0_dbhz", "lli"):
            np.testing.assert_array_equal(getattr(b, f), getattr(ga, f))
