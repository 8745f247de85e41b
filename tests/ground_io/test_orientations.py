"""Orientation importers on the real example files of ../shared/data/orientation (conventions in its README)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ground.adjust.types import CameraPose
from ground.io import crs as crsmod
from ground.io.errors import FormatError
from ground.io.orientations import (
    read_colmap_images,
    read_metashape_cameras,
    read_micmac_folder,
    read_micmac_orientation,
    read_opensfm,
    read_opk_csv,
    read_orientations,
    write_micmac_orientation,
    write_opk_csv,
)
from ground.io.rotations import (
    axis_angle_from_rotation,
    is_rotation,
    opk_deg_from_r_cam_to_world,
    quaternion_wxyz_from_rotation,
    r_cam_to_world_from_opk_deg,
    rotation_from_axis_angle,
    rotation_from_quaternion_wxyz,
)
from onboard.rtk.geodesy import ecef_to_enu
from tests.conftest import shared_file

pytestmark = pytest.mark.shared_data

OPENSFM = "orientation/opensfm/reconstruction_p4rtk_orthority.json"


def _angle_deg(r1: np.ndarray, r2: np.ndarray) -> float:
    """Angle of the rotation r1ᵀ·r2 in degrees."""
    c = (np.trace(r1.T @ r2) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def test_rotation_round_trips() -> None:
    rng = np.random.default_rng(7)
    for _ in range(50):
        v = rng.normal(size=3)
        v *= rng.uniform(0.01, 3.1) / np.linalg.norm(v)
        r = rotation_from_axis_angle(v)
        assert is_rotation(r)
        np.testing.assert_allclose(axis_angle_from_rotation(r), v, atol=1e-9)
        np.testing.assert_allclose(rotation_from_quaternion_wxyz(quaternion_wxyz_from_rotation(r)), r, atol=1e-12)
        o, p, k = rng.uniform(-80, 80, size=3)
        assert np.allclose(opk_deg_from_r_cam_to_world(r_cam_to_world_from_opk_deg(o, p, k)), (o, p, k), atol=1e-9)


def test_nadir_opk_zero_looks_down() -> None:
    """ω=φ=κ=0 in PATB is a nadir camera: the CV optical axis (z) points to −Z of the world."""
    r = r_cam_to_world_from_opk_deg(0.0, 0.0, 0.0)
    np.testing.assert_allclose(r @ [0, 0, 1], [0, 0, -1])
    np.testing.assert_allclose(r @ [1, 0, 0], [1, 0, 0])


def test_opensfm_matches_odm_opk_csv() -> None:
    """Same 4 P4RTK shots: JSON (local UTM-grid frame about reference_lla) vs CSV (UTM 51N, PATB OPK degrees)."""
    rec = read_opensfm(shared_file(OPENSFM))
    csvset = read_opk_csv(shared_file("orientation/csv/odm_xyz_opk.csv"))
    assert len(rec.poses) == 4 and len(csvset.poses) == 4
    ref = rec.extras["reference_lla"]
    origin_utm = crsmod.ecef_to_crs(
        crsmod.lonlat_deg_to_ecef(ref["longitude"], ref["latitude"], ref["altitude"]), "EPSG:32651")[0]
    by_csv = csvset.by_image()
    for pose in rec.poses:
        other = by_csv[pose.image]
        # the CSV is rounded to mm and 0.001°
        np.testing.assert_allclose(pose.centre_rel + origin_utm * [1, 1, 0], other.centre_rel, atol=1.5e-3)
        assert _angle_deg(pose.r_cam_to_rel, other.r_cam_to_rel) < 2e-3


def test_opensfm_gps_enu_needs_grid_convergence() -> None:
    """ODM mixes frames: gps_position (ENU) fits the UTM-grid-aligned centres only after the convergence rotation."""
    rec = read_opensfm(shared_file(OPENSFM))
    ref = rec.extras["reference_lla"]
    origin = crsmod.lonlat_deg_to_ecef(ref["longitude"], ref["latitude"], ref["altitude"])
    r = crsmod.enu_to_grid_rotation(origin, "EPSG:32651")
    gamma_deg = np.degrees(np.arctan2(r[1, 0], r[0, 0]))
    assert gamma_deg == pytest.approx(-0.856, abs=0.002)
    gps, centres = rec.extras["gps_position_enu_m"], rec.by_image()
    d_rot = np.array([r @ gps[k] - centres[k].centre_rel for k in gps])
    d_raw = np.array([gps[k] - centres[k].centre_rel for k in gps])
    rms = lambda d: float(np.sqrt(((d - d.mean(0)) ** 2).sum(1).mean()))
    assert rms(d_rot) == pytest.approx(0.026, abs=0.003)
    assert rms(d_raw) > 0.3


def test_colmap_derived_equals_opensfm() -> None:
    col = read_colmap_images(shared_file("orientation/colmap/images_from_p4rtk_opensfm.txt")).by_image()
    rec = read_opensfm(shared_file(OPENSFM)).by_image()
    assert set(col) == set(rec)
    for k in rec:
        # the derived file prints 12 decimals: centres agree to the README's 1e-10 m (plus print rounding)
        assert np.abs(col[k].centre_rel - rec[k].centre_rel).max() < 1e-9
        np.testing.assert_allclose(col[k].r_cam_to_rel, rec[k].r_cam_to_rel, atol=1e-10)


def test_colmap_doc_example_with_points_lines() -> None:
    s = read_colmap_images(shared_file("orientation/colmap/images_doc_example.txt"))
    assert [p.image for p in s.poses] == ["P1180141.JPG", "P1180142.JPG"]
    assert all(is_rotation(p.r_cam_to_rel) for p in s.poses)


def test_micmac_rel_folder_looks_down() -> None:
    folder = shared_file("orientation/micmac/Ori-Rel")
    s = read_micmac_folder(folder)
    assert [p.image for p in s.poses] == [f"Abbey-IMG_020{i}.jpg" for i in range(4, 8)]
    p0 = s.poses[0]
    np.testing.assert_allclose(p0.centre_rel, [-0.155951755939605613, -2.65330670229561694, 0.170531376088172759])
    optical_axis = p0.r_cam_to_rel @ [0.0, 0.0, 1.0]
    np.testing.assert_allclose(optical_axis, [0.002, 0.022, -0.9997], atol=5e-4)
    assert read_orientations(folder).format == "micmac"


def test_micmac_verif_points_project_in_front(tmp_path: Path) -> None:
    """The file's own <Verif> ground points lie in front of the camera (z_cam > 0) with our reading."""
    import xml.etree.ElementTree as ET

    path = shared_file("orientation/micmac/Ori-Rel/Orientation-Abbey-IMG_0204.jpg.xml")
    pose = read_micmac_orientation(path)
    ters = [np.array([float(v) for v in a.findtext("Ter").split()]) for a in ET.parse(path).iter("Appuis")]
    assert len(ters) == 10
    for ter in ters:
        assert (pose.r_cam_to_rel.T @ (ter - pose.centre_rel))[2] > 0


def test_micmac_angular_coding_refused() -> None:
    with pytest.raises(FormatError, match="CodageAngulaire"):
        read_micmac_orientation(shared_file("orientation/micmac/Ori-Nav-sample/Orientation-IMG_6714.JPG.xml"))


def test_micmac_write_read_round_trip(tmp_path: Path) -> None:
    pose = CameraPose("a b.jpg", np.array([1.5, -2.25, 100.125]), r_cam_to_world_from_opk_deg(3.0, -4.0, 120.0))
    f = tmp_path / "Orientation-a b.jpg.xml"
    write_micmac_orientation(f, pose)
    back = read_micmac_orientation(f)
    assert back.image == "a b.jpg"
    np.testing.assert_allclose(back.centre_rel, pose.centre_rel, atol=0)
    np.testing.assert_allclose(back.r_cam_to_rel, pose.r_cam_to_rel, atol=1e-15)


def test_metashape_excerpt_to_lonlat() -> None:
    """README: chunk transform ∘ camera transform gives lon −120.4179859 lat 39.4119173 h 2420.10 (≈4 cm/1 cm)."""
    s = read_metashape_cameras(shared_file("orientation/metashape/cameras_excerpt_geograypher.xml"))
    assert len(s.poses) == 1
    tr = s.extras["chunk_to_ecef"]
    lon, lat, h = crsmod.ecef_to_lonlat_deg(tr.apply(s.poses[0].centre_rel))
    assert lon == pytest.approx(-120.4179859, abs=2e-7)
    assert lat == pytest.approx(39.4119173, abs=2e-7)
    assert h == pytest.approx(2420.10, abs=0.01)
    ref_lon, ref_lat, ref_h = s.extras["reference"][s.poses[0].image]
    ref_ecef = crsmod.lonlat_deg_to_ecef(ref_lon, ref_lat, ref_h)
    horiz = np.linalg.norm(ecef_to_enu(tr.apply(s.poses[0].centre_rel), ref_ecef)[:2])
    assert 0.02 < horiz < 0.06
    assert abs(h - ref_h) < 0.015
    # camera looks down: optical axis in ECEF points towards the Earth's centre side
    z_ecef = tr.rotation @ s.poses[0].r_cam_to_rel @ [0, 0, 1]
    up = crsmod.lonlat_deg_to_ecef(lon, lat, 1.0) - crsmod.lonlat_deg_to_ecef(lon, lat, 0.0)
    assert float(z_ecef @ up) < -0.99


def test_opk_csv_round_trip_and_prj(tmp_path: Path) -> None:
    src = read_opk_csv(shared_file("orientation/csv/ngi_xyz_opk.csv"))
    assert src.crs is not None and "+proj=tmerc" in src.crs
    out = tmp_path / "opk.csv"
    write_opk_csv(out, src.poses, crs=src.crs)
    back = read_opk_csv(out)
    assert back.crs == src.crs
    for a, b in zip(src.poses, back.poses):
        assert a.image == b.image
        np.testing.assert_allclose(a.centre_rel, b.centre_rel, atol=1e-4)
        assert _angle_deg(a.r_cam_to_rel, b.r_cam_to_rel) < 1e-5


@pytest.mark.parametrize(
    ("content", "match"),
    [
        ("image,X,Y,Z,omega,phi\na,1,2,3,4,5\n", "kappa"),
        ("image,X,Y,Z,omega,phi,kappa\na,1,2,x,4,5,6\n", ":2"),
        ("image,X,Y,Z,omega,phi,kappa\n", "at least one row"),
        ("image,X,Y,Z,omega,phi,kappa\na,1,2,3\n", ":2"),
    ],
)
def test_opk_csv_bad_input_names_file_and_line(tmp_path: Path, content: str, match: str) -> None:
    """Missing column, non-numeric value, no rows, truncated row: FormatError naming the file (and line)."""
    f = tmp_path / "bad.csv"
    f.write_text(content)
    with pytest.raises(FormatError, match=match):
        read_opk_csv(f)


def test_corrupt_files_are_refused(tmp_path: Path) -> None:
    """Truncated JSON/XML and a non-rotation matrix give FormatError, never a half-read pose list."""
    j = tmp_path / "reconstruction.json"
    j.write_text(shared_file(OPENSFM).read_text()[:500])
    with pytest.raises(FormatError, match="JSON"):
        read_opensfm(j)
    x = tmp_path / "Orientation-x.jpg.xml"
    x.write_text(shared_file("orientation/micmac/Ori-Rel/Orientation-Abbey-IMG_0204.jpg.xml").read_text()[:900])
    with pytest.raises(FormatError):
        read_micmac_orientation(x)
    bad = shared_file("orientation/micmac/Ori-Rel/Orientation-Abbey-IMG_0204.jpg.xml").read_text().replace(
        "<L1>0.986054536703784401", "<L1>2.986054536703784401")
    x.write_text(bad)
    with pytest.raises(FormatError, match="not a proper rotation"):
        read_micmac_orientation(x)
    c = tmp_path / "images.txt"
    c.write_text("1 0 0 0 0 1 2 3 1 a.jpg\n\n")
    with pytest.raises(FormatError, match="quaternion"):
        read_colmap_images(c)
    gz = tmp_path / "poses.csv.gz"
    gz.write_text("x")
    with pytest.raises(FormatError, match="unknown orientation format"):
        read_orientations(gz)


def test_opensfm_several_reconstructions_takes_the_largest(tmp_path: Path) -> None:
    """Disconnected blocks have separate frames: the largest reconstruction is used, never a mix."""
    import json

    recs = json.loads(shared_file(OPENSFM).read_text())
    small = {"shots": {k: v for k, v in list(recs[0]["shots"].items())[:1]}, "cameras": recs[0]["cameras"]}
    (tmp_path / "r.json").write_text(json.dumps([small, recs[0]]))
    s = read_opensfm(tmp_path / "r.json")
    assert len(s.poses) == 4


def test_metashape_unaligned_camera_and_chunk_transform(tmp_path: Path) -> None:
    """A camera without a transform (not aligned) is listed, not guessed; a chunk-level transform is used when
    the file has no component (older Metashape/PhotoScan exports)."""
    text = shared_file("orientation/metashape/cameras_excerpt_geograypher.xml").read_text()
    extra = '<camera id="1" sensor_id="0" component_id="0" label="unaligned.JPG"><orientation>1</orientation></camera>'
    text = text.replace("</group>", extra + "</group>")
    start, end = text.index("<components"), text.index("</components>") + len("</components>")
    comp = text[start:end]
    transform = comp[comp.index("<transform>"):comp.index("</transform>") + len("</transform>")]
    chunk_level = text[:start] + transform + text[end:]
    for variant in (text, chunk_level):
        f = tmp_path / "cams.xml"
        f.write_text(variant)
        s = read_metashape_cameras(f)
        assert len(s.poses) == 1
        assert s.extras["unaligned"] == ["unaligned.JPG"]
        lon, lat, _ = crsmod.ecef_to_lonlat_deg(s.extras["chunk_to_ecef"].apply(s.poses[0].centre_rel))
        assert lon == pytest.approx(-120.4179859, abs=2e-7) and lat == pytest.approx(39.4119173, abs=2e-7)
