"""RTKLIB .pos writer and reader: columns, header, xyz/llh, week-tow/calendar, velocity, bad input."""

from __future__ import annotations

import io

import numpy as np
import pytest

from onboard.errors import InputError
from onboard.formats.pos import format_solution, read_pos, write_pos
from onboard.gnsstime import GpsTime
from onboard.rtk.types import Q_FIX, Q_FLOAT, Solution

POS = np.array([3774088.9931, -601661.8217, 5089321.3853])


def _sol(k: int, q: int = Q_FIX) -> Solution:
    cov = np.array([[4e-6, 1e-6, -2e-6], [1e-6, 9e-6, 0.0], [-2e-6, 0.0, 1.6e-5]])
    return Solution(GpsTime.from_week_tow_s(2021, 391089.0 + k), POS + [0.001 * k, 0.0, 0.0], np.array([0.1, -0.2, 0.3]),
                    q, 9, cov, cov * 100, 0.99, 5.4)


def test_xyz_tow_line_has_rtklib_columns():
    line = format_solution(_sol(0))
    tok = line.split()
    assert tok[:2] == ["2021", "391089.000"]
    assert [float(t) for t in tok[2:5]] == pytest.approx(list(POS), abs=1e-4)
    assert tok[5:7] == ["1", "9"]
    assert float(tok[7]) == pytest.approx(0.002) and float(tok[8]) == pytest.approx(0.003)
    assert float(tok[10]) == pytest.approx(0.001)   # sdxy = sign·√|cxy|
    assert float(tok[12]) == pytest.approx(-np.sqrt(2e-6), abs=1e-4)  # sdzx negative
    assert float(tok[13]) == pytest.approx(0.99) and float(tok[14]) == pytest.approx(5.4)
    assert len(tok) == 15


def test_round_trip_every_variant(tmp_path):
    sols = [_sol(k, Q_FIX if k % 2 else Q_FLOAT) for k in range(5)]
    for llh in (False, True):
        for velocity in (False, True):
            for calendar in (False, True):
                p = tmp_path / f"t_{llh}_{velocity}_{calendar}.pos"
                n = write_pos(p, sols, ["program : test"], llh=llh, velocity=velocity, calendar=calendar)
                assert n == 5
                text = p.read_text()
                assert text.startswith("% program : test\n%  GPST")
                track = read_pos(p)
                assert track.llh == llh
                assert [t.tow_ns for t in track.time] == [s.time.tow_ns for s in sols]
                np.testing.assert_allclose(track.pos_ecef_m, [s.pos_ecef_m for s in sols], atol=2e-3)
                assert list(track.q) == [s.q for s in sols]
                assert list(track.ns) == [9] * 5
                assert (track.vel_m_s is not None) == velocity
                if velocity and not llh:
                    np.testing.assert_allclose(track.vel_m_s[0], [0.1, -0.2, 0.3])


def test_header_titles_match_rtklib():
    buf = io.StringIO()
    write_pos(buf, [_sol(0)], velocity=True)
    title = buf.getvalue().splitlines()[0]
    for name in ("x-ecef(m)", "y-ecef(m)", "z-ecef(m)", "Q", "ns", "sdx(m)", "sdzx(m)", "age(s)", "ratio",
                 "vx(m/s)", "sdvzx"):
        assert name in title


def test_reader_rejects_files_without_column_titles(tmp_path):
    p = tmp_path / "x.pos"
    p.write_text("2021 391089.000 1 2 3 1 9 0 0 0 0 0 0 0 0\n")
    with pytest.raises(InputError, match="column-title"):
        read_pos(p)


def test_reader_names_the_bad_line(tmp_path):
    p = tmp_path / "x.pos"
    buf = io.StringIO()
    write_pos(buf, [_sol(0), _sol(1)])
    lines = buf.getvalue().splitlines()
    lines[2] = lines[2][:30]
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"x.pos:3"):
        read_pos(p)


def test_reader_of_a_missing_file(tmp_path):
    with pytest.raises(InputError, match="cannot read"):
        read_pos(tmp_path / "nope.pos")
