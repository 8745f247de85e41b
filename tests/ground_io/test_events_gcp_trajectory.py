"""Events (CSV, events.jsonl, matching), GCP readers (ours, ODM, MicMac) and the .pos → Trajectory boundary."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np
import pytest

from ground.io import crs as crsmod
from ground.io.errors import CrsError, FormatError
from ground.io.events import (
    Mark,
    match_marks_to_images,
    parse_capture_time,
    read_capture_times,
    read_events_csv,
    read_marks_jsonl,
)
from ground.io.gcp import (
    merge_ground_and_relative,
    read_gcp_csv,
    read_micmac_gcp,
    read_odm_gcp_list,
    to_control_points,
)
from ground.io.trajectory import read_trajectory
from onboard.gnsstime import GpsTime
from onboard.rtk.geodesy import ecef_to_enu
from tests.conftest import shared_file
from tests.ground_io.flightgen import ORIGIN_ECEF, write_synthetic_flight

T0 = GpsTime.from_week_tow_s(2300, 100_000.0)


def test_events_csv_reads_week_tow_to_the_ns(tmp_path: Path) -> None:
    f = tmp_path / "ev.csv"
    f.write_text("image,week,tow,kind\na.jpg,2300,100000.123456789,flash\nb.jpg,2300,100002.5,\n")
    ev = read_events_csv(f)
    assert ev[0].time == GpsTime(2300, 100_000_123_456_789) and ev[0].kind == "flash"
    assert ev[1].kind == "trigger"


@pytest.mark.parametrize(
    ("content", "match"),
    [
        ("image,week\na,1\n", "image,week,tow"),
        ("image,week,tow\na,2300,700000\n", ":2"),
        ("image,week,tow\na,2300,1\na,2300,2\n", "twice"),
        ("image,week,tow\na,2300,abc\n", ":2"),
    ],
)
def test_events_csv_bad_rows(tmp_path: Path, content: str, match: str) -> None:
    """Missing column, tow beyond a week, duplicated image, non-numeric tow: FormatError with file:line."""
    f = tmp_path / "ev.csv"
    f.write_text(content)
    with pytest.raises(FormatError, match=match):
        read_events_csv(f)


def test_events_jsonl_pairings_torn_line_and_other_records(tmp_path: Path) -> None:
    """Records written by onboard.timepulse.marks: one mark per pairing (flash time, measured delay; pulse time
    when the flash is missing); timepulse records ignored; a torn last line (power cut) skipped."""
    from onboard.rtk.types import CameraMark
    from onboard.timepulse.marks import (
        ImagePairing,
        format_line,
        mark_record,
        pairing_record,
        timepulse_record,
    )

    t = [T0.add_s(2.0 * i) for i in range(3)]
    lines = [format_line(timepulse_record("TIMEPULSE2", 2_000_000, 1000, True, None, "extint1"))]
    lines += [format_line(pairing_record(ImagePairing(i, t[i], "tim-tm2", None, t[i].add_s(0.064), 10 + i, 20,
                                                      64_000_000))) for i in range(2)]
    lines.append(format_line(pairing_record(ImagePairing(2, t[2], "tim-tm2", None, None, None, None, None,
                                                         ("pulse_without_flash",)))))
    f = tmp_path / "events.jsonl"
    f.write_text("".join(lines) + '{"v":1,"kind":"pairing","ind')
    marks = read_marks_jsonl(f)
    assert [m.kind for m in marks] == ["flash", "flash", "trigger"]
    assert marks[1].time == t[1].add_s(0.064) and marks[1].measured_delay_s == pytest.approx(0.064)
    assert marks[2].time == t[2] and marks[0].count == 10
    # an older log with marks only: the valid flash-channel edges are the events
    mk = CameraMark(channel=0, edge="falling", count=5, time=t[0], acc_est_ns=20, time_base=1, valid=True,
                    source="tim-tm2")
    f.write_text(format_line(mark_record(mk)))
    assert [m.time for m in read_marks_jsonl(f)] == [t[0]]
    f.write_text(format_line(timepulse_record("TIMEPULSE2", 2_000_000, 1000, True, None, "none")))
    with pytest.raises(FormatError, match="no image mark"):
        read_marks_jsonl(f)
    f.write_text('{"v":1,"kind":"mark","channel":0}\n')
    with pytest.raises(FormatError, match="lacks field"):
        read_marks_jsonl(f)


def _marks(n: int, drop: tuple[int, ...] = ()) -> list[Mark]:
    return [Mark(T0.add_s(2.0 * i), count=i) for i in range(n) if i not in drop]


def test_match_by_order_and_refusal_on_count_jump() -> None:
    rep = match_marks_to_images(_marks(4), ["c.jpg", "a.jpg", "b.jpg", "d.jpg"])
    assert [e.image for e in rep.events] == ["a.jpg", "b.jpg", "c.jpg", "d.jpg"]
    with pytest.raises(ValueError, match="counter jumps"):
        match_marks_to_images(_marks(5, drop=(2,)), ["a", "b", "c", "d"])


def test_match_by_capture_time_flags_missing_and_extra() -> None:
    """Camera clock 2 h + 17.4 s off GPS (time zone + drift), 1 s EXIF resolution; one mark lost, one photo missing."""
    marks = _marks(10, drop=(4,))
    utc0 = T0.to_gpst_datetime().replace(tzinfo=None) + dt.timedelta(hours=2, seconds=17.4)
    caps = {f"IMG_{i}.JPG": (utc0 + dt.timedelta(seconds=2.0 * i)).replace(microsecond=0) for i in range(10) if i != 7}
    rep = match_marks_to_images(marks, sorted(caps) + ["IMG_X.JPG"], caps)
    assert rep.method == "capture_time"
    assert {e.image: e.time for e in rep.events}["IMG_5.JPG"] == T0.add_s(10.0)
    assert len(rep.events) == 8
    assert rep.missing_marks == ["IMG_4.JPG", "IMG_X.JPG"]
    assert rep.extra_marks == [T0.add_s(14.0)]
    assert rep.count_jumps == [(3, 5)]
    assert rep.clock_offset_s == pytest.approx(7217.4 - 0.0, abs=1.0)


def test_capture_times_sidecar(tmp_path: Path) -> None:
    f = tmp_path / "caps.csv"
    f.write_text("image,capture_time\na.jpg,2024:05:01 10:00:01.25\nb.jpg,2024-05-01T08:00:03Z\n")
    caps = read_capture_times(f)
    assert caps["a.jpg"] == dt.datetime(2024, 5, 1, 10, 0, 1, 250000)
    assert caps["b.jpg"] == dt.datetime(2024, 5, 1, 8, 0, 3)
    assert parse_capture_time("garbage") is None
    f.write_text("image,capture_time\na.jpg,yesterday\n")
    with pytest.raises(FormatError, match="unreadable"):
        read_capture_times(f)


def test_gcp_csv_to_enu(tmp_path: Path) -> None:
    write_synthetic_flight(tmp_path, n_lines=1)
    pts = read_gcp_csv(tmp_path / "gcp.csv")
    assert [p.role for p in pts] == ["gcp", "gcp", "gcp", "check", "check"]
    cps = to_control_points(pts, ORIGIN_ECEF)
    np.testing.assert_allclose(cps[0].ground_enu_m, [20, 10, 0.5], atol=0.03)
    bad = tmp_path / "bad.csv"
    bad.write_text("name,role,x_rel,y_rel,z_rel,X,Y,Z\nA,control,1,2,3,4,5,6\n")
    with pytest.raises(FormatError, match="role"):
        read_gcp_csv(bad)


def test_odm_gcp_lists_real_files() -> None:
    utm = read_odm_gcp_list(shared_file("orientation/odm/gcp_list_utm16n.txt"))
    assert len(utm) == 1 and utm[0].crs == "EPSG:32616"
    labelled = read_odm_gcp_list(shared_file("orientation/odm/gcp_list_with_label.txt"))
    assert [p.name for p in labelled] == ["gcp1"]
    feet = read_odm_gcp_list(shared_file("orientation/odm/gcp_list_epsg2251_feet.txt"))
    lonlat = read_odm_gcp_list(shared_file("orientation/odm/gcp_list_proj4_lonlat.txt"))
    assert len(lonlat) == 2
    # the feet CRS is honoured by pyproj: the point lands in Michigan (lon ≈ −85 to −86°, lat ≈ 44–46°)
    with pytest.raises(CrsError, match="NAD83|North American"):  # NAD83 → WGS 84 is a 4 m shift: refused
        crsmod.crs_to_ecef(feet[0].ground[None, :], feet[0].crs)
    ecef = crsmod.crs_to_ecef(feet[0].ground[None, :], feet[0].crs, max_datum_error_m=5.0)[0]
    lon, lat, _ = crsmod.ecef_to_lonlat_deg(ecef)
    assert -90 < lon < -82 and 40 < lat < 48
    # lon/lat PROJ-string file: ground stays lon, lat, h
    e = crsmod.crs_to_ecef(lonlat[0].ground[None, :], lonlat[0].crs)[0]
    assert crsmod.ecef_to_lonlat_deg(e)[0] == pytest.approx(-85.61322729531112, abs=1e-9)


def test_micmac_gcp_real_file_merge_with_relative(tmp_path: Path) -> None:
    pts = read_micmac_gcp(shared_file("orientation/micmac/gcp/MesurePointGround.xml"), crs="EPSG:4978")
    assert pts[0].name == "P_1_A"
    np.testing.assert_allclose(pts[0].sigma_m, [1, 1, 1])
    rel = {"P_1_A": (np.array([1.0, 2.0, 3.0]), "check")}
    merged = merge_ground_and_relative(pts, rel)
    assert len(merged) == 1 and merged[0].role == "check"


def test_missing_geoid_grid_is_an_error() -> None:
    """EPSG:2154+5720 (Lambert-93 + NGF-IGN69) needs the RAF20 grid, not installed: error, never ellipsoidal."""
    p = crsmod.lonlat_deg_to_ecef(-2.0, 48.0, 80.0)
    for tolerance_m in (0.05, 2.0):  # the grid is checked first, whatever the datum tolerance
        with pytest.raises(CrsError, match="geoid grid"):
            crsmod.ecef_to_crs(p, "EPSG:2154+5720", max_datum_error_m=tolerance_m)


@pytest.mark.slow
def test_datum_mixing_is_refused() -> None:
    """WGS 84 → ETRS89/RGF93 (null shift, 1 m) and → ITRF2014 (identity, unknown accuracy) are refused by
    default; the same datum (UTM on WGS 84) is a plain conversion; a stated tolerance lets a 1 m shift through."""
    p = crsmod.lonlat_deg_to_ecef(-2.0, 48.0, 80.0)
    for crs in ("EPSG:4936", "EPSG:7789", "EPSG:2154", "EPSG:25830"):
        with pytest.raises(CrsError, match="changes datum"):
            crsmod.ecef_to_crs(p, crs)
    crsmod.check_datum_change("EPSG:4978", "EPSG:32630")
    e = crsmod.ecef_to_crs(p, "EPSG:25830", max_datum_error_m=1.0)
    assert e.shape == (1, 3)


def test_ecef_to_utm_and_back_mm(tmp_path: Path) -> None:
    p = crsmod.lonlat_deg_to_ecef(120.95, 24.68, 186.0)
    utm = crsmod.ecef_to_crs(p, "EPSG:32651")
    np.testing.assert_allclose(crsmod.crs_to_ecef(utm, "EPSG:32651")[0], p, atol=1e-6)
    assert utm[0, 2] == pytest.approx(186.0, abs=1e-6)  # 2-D projected CRS keeps the ellipsoidal height
    with pytest.raises(CrsError, match="unknown CRS"):
        crsmod.ecef_to_crs(p, "EPSG:999999")


def test_trajectory_xyz_and_llh_agree(tmp_path: Path) -> None:
    """Our .pos in xyz and in llh (σ and velocity in n/e/u) give the same Trajectory."""
    from onboard.formats.pos import read_pos, write_pos
    from onboard.rtk.types import Solution

    write_synthetic_flight(tmp_path, n_lines=1)
    xyz = read_trajectory(str(tmp_path / "SOL.pos"))
    track = read_pos(tmp_path / "SOL.pos")
    sols = [Solution(time=t, pos_ecef_m=p, vel_ecef_m_s=v, q=int(q), ns=12, cov_pos_m2=np.diag([1e-4, 1e-4, 4e-4]),
                     cov_vel_m2_s2=np.eye(3) * 1e-4) for t, p, v, q in zip(track.time, track.pos_ecef_m,
                                                                             track.vel_m_s, track.q)]
    write_pos(tmp_path / "llh.pos", sols, llh=True, velocity=True, calendar=True)
    llh = read_trajectory(str(tmp_path / "llh.pos"))
    np.testing.assert_array_equal(llh.t_ns, xyz.t_ns)
    np.testing.assert_allclose(ecef_to_enu(llh.pos_ecef_m, ORIGIN_ECEF), ecef_to_enu(xyz.pos_ecef_m, ORIGIN_ECEF),
                               atol=2e-3)
    np.testing.assert_allclose(llh.vel_ecef_m_s, xyz.vel_ecef_m_s, atol=2e-3)
    write_pos(tmp_path / "novel.pos", sols)  # no velocity columns: the adjustment differences positions
    novel = read_trajectory(str(tmp_path / "novel.pos"))
    assert novel.vel_ecef_m_s is None and len(novel.t_ns) == len(xyz.t_ns)
    (tmp_path / "one.pos").write_text("\n".join((tmp_path / "SOL.pos").read_text().splitlines()[:2]) + "\n")
    with pytest.raises(FormatError, match="at least 2"):
        read_trajectory(str(tmp_path / "one.pos"))
    (tmp_path / "bad.pos").write_text("hello\n")
    with pytest.raises(FormatError):
        read_trajectory(str(tmp_path / "bad.pos"))


@pytest.mark.parametrize(("posf", "timef", "outvel"), [(1, 0, 1), (1, 1, 0), (0, 0, 1), (0, 1, 1)])
def test_trajectory_written_by_rtklib_itself(tmp_path: Path, posf: int, timef: int, outvel: int) -> None:
    """.pos files formatted by RTKLIB's own writer (outsolheads/outsols through pyrtklib, CRLF line ends) in
    xyz (posf 1) or llh (posf 0), GPST week/tow (timef 0) or calendar (timef 1), with or without velocities,
    read back to the trajectory they were written from."""
    rtk = pytest.importorskip("pyrtklib", reason="pyrtklib (RTKLIB bindings) not installed")
    write_synthetic_flight(tmp_path, n_lines=1)
    ours = read_trajectory(str(tmp_path / "SOL.pos"))
    opt = rtk.solopt_default
    opt.posf, opt.timef, opt.outvel, opt.times, opt.outhead, opt.timeu = posf, timef, outvel, 0, 1, 3
    buf = getattr(rtk, "Arr1Dunsigned char")(4096)
    ref = rtk.Arr1Ddouble(6)
    out = bytearray(bytes(buf[i] for i in range(rtk.outsolheads(buf, opt))))
    for k in range(len(ours.t_ns)):
        sol = rtk.sol_t()
        week, tow_ns = divmod(int(ours.t_ns[k]), 604_800 * 10**9)
        sol.time = rtk.gpst2time(week, tow_ns / 1e9)
        rr, qr = sol.rr, sol.qr
        vel = ours.vel_ecef_m_s[k] if ours.vel_ecef_m_s is not None else np.zeros(3)
        for i, v in enumerate([*ours.pos_ecef_m[k], *vel]):
            rr[i] = float(v)
        for i in range(3):
            qr[i] = float(ours.sd_m[k, i] ** 2)
        sol.stat, sol.ns, sol.ratio, sol.age = int(ours.q[k]), 12, 5.0, 1.0
        out += bytes(buf[i] for i in range(rtk.outsols(buf, sol, ref, opt)))
    assert b"\r\n" in out
    (tmp_path / "rtklib.pos").write_bytes(bytes(out))
    got = read_trajectory(str(tmp_path / "rtklib.pos"))
    np.testing.assert_array_equal(got.t_ns, ours.t_ns)
    np.testing.assert_array_equal(got.q, ours.q)
    np.testing.assert_allclose(ecef_to_enu(got.pos_ecef_m, ORIGIN_ECEF), ecef_to_enu(ours.pos_ecef_m, ORIGIN_ECEF),
                               atol=1e-3)
    if outvel:
        assert got.vel_ecef_m_s is not None
        np.testing.assert_allclose(got.vel_ecef_m_s, ours.vel_ecef_m_s, atol=1e-4)
    else:
        assert got.vel_ecef_m_s is None
    np.testing.assert_allclose(np.linalg.norm(got.sd_m, axis=1), np.linalg.norm(ours.sd_m, axis=1), rtol=0.01)
