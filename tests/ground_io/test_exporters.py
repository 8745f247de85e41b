"""Exporters: ENU poses projected to a CRS with grid-convergence-corrected attitudes, checked on the real ODM
example (OpenSfM poses vs the OPK CSV of the same shots), plus the per-format layouts."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ground.io import crs as crsmod
from ground.io.exporters import cameras_to_crs, write_all
from ground.io.orientations import read_opensfm, read_opk_csv
from ground.io.rotations import opk_deg_from_r_cam_to_world
from tests.conftest import shared_file


def _enu_block() -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """The ODM shots turned into true ENU about reference_lla (undo the grid alignment) and the CSV's OPK."""
    rec = read_opensfm(shared_file("orientation/opensfm/reconstruction_p4rtk_orthority.json"))
    ref = rec.extras["reference_lla"]
    origin = crsmod.lonlat_deg_to_ecef(ref["longitude"], ref["latitude"], ref["altitude"])
    grid_from_enu = crsmod.enu_to_grid_rotation(origin, "EPSG:32651")
    names = [p.image for p in rec.poses]
    centres = np.array([grid_from_enu.T @ p.centre_rel for p in rec.poses])
    rots = np.array([grid_from_enu.T @ p.r_cam_to_rel for p in rec.poses])
    csv = {p.image: p for p in read_opk_csv(shared_file("orientation/csv/odm_xyz_opk.csv")).poses}
    opk = {n: np.array(opk_deg_from_r_cam_to_world(csv[n].r_cam_to_rel)) for n in names}
    return names, centres, rots, origin, opk


def test_projected_export_reproduces_odm_opk(tmp_path: Path) -> None:
    """ENU → UTM 51N: κ includes the −0.856° convergence; ω φ κ equal the ODM CSV to 0.01°, centres to 0.2 m
    (ODM's local frame is a shifted UTM grid, so its distances carry the UTM scale error, ≈ 0.1 m here)."""
    names, centres, rots, origin, opk = _enu_block()
    cams = cameras_to_crs(names, centres, rots, origin, "EPSG:32651", np.full((4, 3), 0.02))
    csv = {p.image: p for p in read_opk_csv(shared_file("orientation/csv/odm_xyz_opk.csv")).poses}
    for i, n in enumerate(names):
        got = np.array(opk_deg_from_r_cam_to_world(cams.r_cam_to_crs[i]))
        np.testing.assert_allclose(got, opk[n], atol=0.01)
        np.testing.assert_allclose(cams.xyz[i], csv[n].centre_rel, atol=0.2)
    # without the convergence the kappas would be off by ~0.86°: the test can fail
    raw = np.array(opk_deg_from_r_cam_to_world(rots[0]))
    assert abs(raw[2] - opk[names[0]][2]) > 0.5
    out = write_all(tmp_path, cams, centres, rots)
    assert set(out) >= {"odm", "pix4d", "metashape", "opk", "micmac"}
    back = read_opk_csv(tmp_path / "opk.csv")
    assert back.crs == "EPSG:32651" and [p.image for p in back.poses] == names


def test_geographic_export_layouts(tmp_path: Path) -> None:
    """EPSG:4326: Pix4D puts latitude first, ODM geo.txt longitude first; angles stay ENU; heights ellipsoidal."""
    names, centres, rots, origin, _ = _enu_block()
    cams = cameras_to_crs(names, centres, rots, origin, "EPSG:4326")
    write_all(tmp_path, cams, centres, rots)
    pix = (tmp_path / "pix4d.csv").read_text().splitlines()[0].split(",")
    geo = (tmp_path / "geo.txt").read_text().splitlines()
    assert geo[0] == "EPSG:4326"
    lon, lat = float(geo[1].split()[1]), float(geo[1].split()[2])
    assert 120.9 < lon < 121.0 and 24.6 < lat < 24.7
    assert float(pix[1]) == pytest.approx(lat) and float(pix[2]) == pytest.approx(lon)
    h_expected = crsmod.ecef_to_lonlat_deg(crsmod.enu_to_ecef(centres[0], origin))[2]
    assert float(geo[1].split()[3]) == pytest.approx(h_expected, abs=1e-3)
    # angles are turned to the local ENU at each camera: ≈ 200 m / 6371 km = 3e-5 rad from the origin ENU
    np.testing.assert_allclose(cams.r_cam_to_crs[0], rots[0], atol=5e-5)
    assert not np.allclose(cams.r_cam_to_crs[0], rots[0], atol=1e-6)


def test_odm_geo_txt_carries_each_image_accuracy_and_no_guessed_angles(tmp_path: Path) -> None:
    """geo.txt rows read the way ODM's documentation lays them out (`image x y z yaw pitch roll h_acc v_acc`):
    the accuracies are the per-image σ in columns 8–9 (positional, so the angle columns must exist) and the
    angles are NaN, which ODM's reader takes as "no angles" (their axes and zero are not documented)."""
    import math

    names, centres, rots, origin, _ = _enu_block()
    sigma = np.column_stack([np.linspace(0.006, 0.012, len(names))] * 2 + [np.linspace(0.009, 0.02, len(names))])
    cams = cameras_to_crs(names, centres, rots, origin, "EPSG:32651", sigma)
    write_all(tmp_path, cams, centres, rots)
    rows = [line.split() for line in (tmp_path / "geo.txt").read_text().splitlines()[1:]]
    assert [r[0] for r in rows] == names and all(len(r) == 9 for r in rows)
    for r, sh, sv in zip(rows, cams.sigma_h_m, cams.sigma_v_m):
        assert all(math.isnan(float(v)) for v in r[4:7])
        assert float(r[7]) == pytest.approx(sh, abs=1e-4) and float(r[8]) == pytest.approx(sv, abs=1e-4)
    assert float(rows[-1][8]) > float(rows[0][8]) > 0.0
