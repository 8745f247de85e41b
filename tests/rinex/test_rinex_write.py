"""The RINEX 3.04 writers on their own: field formats, epoch and event lines, headers, nav round trip."""

from __future__ import annotations

import dataclasses
import io
import math

import numpy as np
import pytest

from onboard.formats.rinex_nav import read_rinex_nav
from onboard.formats.rinex_obs import read_rinex_obs
from onboard.formats.rinex_write import (
    ObsHeaderInfo,
    epoch_line,
    nav_record,
    obs_field,
    regular_interval_s,
    satellite_code,
    write_nav,
    write_obs,
)
from onboard.gnsstime import GpsTime, gpst_from_calendar
from onboard.rtk.types import GNSS_GALILEO, GNSS_GLONASS, GNSS_GPS, GNSS_QZSS, GNSS_SBAS, CameraMark, ObsEpoch
from tests.conftest import shared_file


def _epoch(t: GpsTime, gnss: list[int], sv: list[int]) -> ObsEpoch:
    n = len(sv)
    return ObsEpoch(time=t, gnss_id=np.array(gnss, np.int8), sv_id=np.array(sv, np.int16),
                    pr_m=np.full(n, 2.2e7), cp_cyc=np.full(n, 1.1e8), dop_hz=np.full(n, -12.5),
                    cn0_dbhz=np.full(n, 40.0), lock_ms=np.full(n, 1000.0), lli=np.zeros(n, np.uint8))


def _mark(t: GpsTime | None) -> CameraMark:
    return CameraMark(channel=0, edge="falling", count=1, time=t, acc_est_ns=20, time_base=1, valid=t is not None)


def test_obs_field_formats() -> None:
    assert obs_field(17587846.31567565) == "  17587846.316  "
    assert obs_field(95357975.6041, 1) == "  95357975.6041 "
    assert obs_field(1.0, 0x43) == "         1.0003 "  # only bits 0-2 reach RINEX (RTKLIB's half-cycle-added bit does not)
    # RTKLIB writes exact zeros as blanks but keeps the LLI (a half-cycle flag change on a dropped phase)
    assert obs_field(0.0, 1) == " " * 14 + "1 "
    assert obs_field(math.nan) == " " * 16
    assert obs_field(-2313.14697265625) == "     -2313.147  "
    assert obs_field(1_234_567_890.5) == " 234567890.500  "  # F14.3 cannot hold ≥ 1e9: modulo, as RTKLIB


def test_epoch_and_event_lines_round_to_100_ns() -> None:
    t = gpst_from_calendar(2018, 10, 4, 12, 38, 8_991_000_000)
    assert epoch_line(t, 0, 21) == "> 2018 10 04 12 38 08.9910000  0 21" + " " * 21 + "\n"
    mark = gpst_from_calendar(2018, 10, 4, 12, 39, 5_141_535_570)
    assert epoch_line(mark, 5, 0) == "> 2018 10 04 12 39  5.1415356  5  0\n"
    # 59.99999995 s rounds into the next minute, hour and day
    late = gpst_from_calendar(2018, 10, 4, 23, 59, 59_999_999_950)
    assert epoch_line(late, 0, 1).startswith("> 2018 10 05 00 00 00.0000000  0  1")


def test_satellite_codes() -> None:
    assert satellite_code(GNSS_GPS, 5) == "G05"
    assert satellite_code(GNSS_SBAS, 129) == "S29"
    assert satellite_code(GNSS_QZSS, 1) == "J01"
    assert satellite_code(GNSS_GLONASS, 255) is None and satellite_code(GNSS_SBAS, 5) is None
    assert satellite_code(4, 1) is None  # IMES


def test_regular_interval() -> None:
    t0 = GpsTime(2000, 0)
    times = [t0.add_s(0.2 * k) for k in range(50)]
    assert regular_interval_s(times) == 0.2
    assert regular_interval_s(times[:20] + times[25:]) == 0.2  # one dropped burst: still regular
    assert regular_interval_s([t0.add_s(s) for s in (0, 1, 3, 4.5, 7, 7.2)]) is None


def test_write_obs_marks_header_and_round_trip() -> None:
    t0 = gpst_from_calendar(2020, 1, 1, 0, 0, 999_000_000)
    epochs = [_epoch(t0.add_s(k), [GNSS_GPS, GNSS_GALILEO], [3, 11]) for k in range(4)]
    marks = [_mark(t0.add_s(1.5)), _mark(None), _mark(t0.add_s(0.5)), _mark(t0.add_s(10.0))]
    buf = io.StringIO()
    summary = write_obs(buf, epochs, marks, ObsHeaderInfo(marker_name="TEST", receiver_type="U-BLOX NEO-M8T"))
    text = buf.getvalue()
    assert summary.epochs == 4 and summary.events == 3  # the mark without a valid time is not written
    assert summary.satellites == {"G": {"G03"}, "E": {"E11"}} and summary.interval_s == 1.0
    records = [line[:35] for line in text.split("END OF HEADER", 1)[1].splitlines() if line.startswith(">")]
    assert records == [
        "> 2020 01 01 00 00 00.9990000  0  2",
        "> 2020 01 01 00 00  1.4990000  5  0",
        "> 2020 01 01 00 00 01.9990000  0  2",
        "> 2020 01 01 00 00  2.4990000  5  0",
        "> 2020 01 01 00 00 02.9990000  0  2",
        "> 2020 01 01 00 00 03.9990000  0  2",
        "> 2020 01 01 00 00 10.9990000  5  0",
    ]
    assert "E    4 C1X L1X D1X S1X" in text and "E L1X  0.00000" in text and "G L1C    " in text
    assert "GLONASS" not in text  # no GLONASS lines without GLONASS data


def test_written_obs_reads_back(tmp_path: pytest.TempPathFactory) -> None:
    t0 = gpst_from_calendar(2020, 1, 1, 0, 0, 999_000_000)
    e = _epoch(t0, [GNSS_GPS, GNSS_GPS], [3, 11])
    e.cp_cyc[1] = np.nan
    e.lli[0] = 2
    path = tmp_path / "x.obs"  # type: ignore[operator]
    with open(path, "w") as f:
        write_obs(f, [e], (), ObsHeaderInfo(approx_pos_ecef_m=(1.0, 2.0, 3.0)))
    back = read_rinex_obs(path)
    assert back.header.obs_types == {"G": ["C1C", "L1C", "D1C", "S1C"]}
    (got,) = back.epochs
    assert got.time == t0 and got.sv_id.tolist() == [3, 11]
    assert got.pr_m.tolist() == [2.2e7, 2.2e7] and got.cp_cyc[0] == 1.1e8 and math.isnan(got.cp_cyc[1])
    assert got.lli.tolist() == [2, 0] and got.dop_hz.tolist() == [-12.5, -12.5]


def test_nav_round_trip_of_rtklib_ephemerides() -> None:
    ref = read_rinex_nav(shared_file("gnss/ublox-m8p-galway-2018/rinex/rover-20181004-1237.nav.gz"))
    buf = io.StringIO()
    n = write_nav(buf, ref.ephemerides + ref.ephemerides[:3], leap_s=18)  # repeats are dropped
    assert n == len(ref.ephemerides) == 14
    path_text = buf.getvalue()
    lines = path_text.splitlines()
    assert lines[0] == "     3.04           N: GNSS NAV DATA    G: GPS              RINEX VERSION / TYPE"
    assert all(len(line) <= 80 for line in lines)
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "x.nav"
        p.write_text(path_text)
        back = read_rinex_nav(p)
    assert back.leap_s == 18
    by_key = {(e.prn, e.toe): e for e in back.ephemerides}
    for e in ref.ephemerides:
        b = by_key[(e.prn, e.toe)]
        for f in dataclasses.fields(e):
            va, vb = getattr(e, f.name), getattr(b, f.name)
            if isinstance(va, float):
                assert vb == pytest.approx(va, rel=1e-12, abs=1e-24), f.name
            else:
                assert vb == va, f.name


def test_nav_record_layout() -> None:
    eph = read_rinex_nav(shared_file("gnss/ublox-m8p-galway-2018/rinex/rover-20181004-1237.nav.gz")).ephemerides[0]
    rec = nav_record(eph).splitlines()
    assert len(rec) == 8 and rec[0].startswith(f"G{eph.prn:02d} 2018 10 04 ")
    assert all(line.startswith("    ") for line in rec[1:]) and len(rec[1]) == 4 + 4 * 19
