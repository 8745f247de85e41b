"""Exporters of the corrected camera centres and orientations: ODM geo.txt, Pix4D, Metashape, OPK CSV, MicMac.

Input is the adjusted block in local ENU about an ECEF origin; projection to the target CRS happens here (via
`ground.io.crs`, so a missing geoid grid is an error). Rotations are turned from ENU at the origin to the grid
axes at each camera (meridian convergence included) for projected CRSs; for geographic CRSs the angles stay
relative to local ENU (true north). Heights are whatever the CRS says: ellipsoidal for 2-D/3-D geographic and
2-D projected CRSs, orthometric only for a compound CRS whose geoid grid is installed.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from ground.adjust.types import CameraPose
from ground.io import crs as crsmod
from ground.io.orientations import write_micmac_orientation, write_opk_csv
from ground.io.rotations import opk_deg_from_r_cam_to_world
from onboard.formats.atomic import atomic_output
from onboard.rtk.geodesy import ecef_to_llh, enu_rotation, enu_to_ecef

Vec = npt.NDArray[np.float64]


@dataclass(frozen=True)
class ExportedCameras:
    """Cameras in the export CRS: `xyz` (n,3) x/lon first, `r_cam_to_crs` (n,3,3) camera → CRS axes
    (grid E/N/up for projected, local E/N/U for geographic), σ horizontal/vertical (m)."""

    images: tuple[str, ...]
    xyz: Vec
    r_cam_to_crs: Vec
    sigma_h_m: Vec
    sigma_v_m: Vec
    crs: str
    geographic: bool


def cameras_to_crs(images: list[str] | tuple[str, ...], centres_enu_m: npt.ArrayLike, r_cam_to_enu: npt.ArrayLike,
                   origin_ecef_m: npt.ArrayLike, crs: str, sigma_enu_m: npt.ArrayLike | None = None,
                   max_datum_error_m: float = crsmod.MAX_DATUM_ERROR_M) -> ExportedCameras:
    """Project adjusted cameras (ENU about `origin_ecef_m`) into `crs`, rotating attitudes into its axes."""
    c = np.atleast_2d(np.asarray(centres_enu_m, dtype=float))
    r = np.asarray(r_cam_to_enu, dtype=float).reshape(-1, 3, 3)
    origin = np.asarray(origin_ecef_m, dtype=float)
    lat0, lon0, _ = ecef_to_llh(origin)
    r_enu0 = enu_rotation(lat0, lon0)  # ECEF → ENU at the origin
    xyz = crsmod.enu_to_crs(c, origin, crs, max_datum_error_m=max_datum_error_m)
    geographic = crsmod.is_geographic(crs)
    ecef = enu_to_ecef(c, origin)
    out_r = np.empty_like(r)
    for i in range(c.shape[0]):
        lat, lon, _ = ecef_to_llh(ecef[i])
        r_local = enu_rotation(lat, lon) @ r_enu0.T @ r[i]  # camera → ENU at the camera
        grid = np.eye(3) if geographic else crsmod.enu_to_grid_rotation(ecef[i], crs,
                                                                        max_datum_error_m=max_datum_error_m)
        out_r[i] = grid @ r_local
    s = np.full((c.shape[0], 3), np.nan) if sigma_enu_m is None else np.asarray(sigma_enu_m, dtype=float)
    return ExportedCameras(tuple(images), xyz, out_r, np.hypot(s[:, 0], s[:, 1]), s[:, 2], crs, geographic)


def _fmt(v: float, geographic_angle: bool) -> str:
    return f"{v:.9f}" if geographic_angle else f"{v:.4f}"


def write_odm_geo_txt(path: str | Path, cams: ExportedCameras) -> None:
    """ODM `geo.txt`: first line the CRS, then `image x y z yaw pitch roll h_acc v_acc` (x = easting/longitude
    first; accuracies in m, 1σ, horizontal and vertical).

    The angle columns are `nan`: ODM documents yaw/pitch/roll in degrees without their axes or zero, and its
    readers changed (older ones read omega/phi/kappa, newer ones yaw/pitch/roll that replace the EXIF angles;
    a NaN angle is read as "no angles"). The columns must be present because the accuracies are positional
    (columns 8–9); ODM passes them to OpenSfM as the GPS standard deviations of each image.
    """
    g = cams.geographic
    with atomic_output(path, "w") as fh:
        fh.write(cams.crs + "\n")
        fh.writelines(
            f"{name} {_fmt(p[0], g)} {_fmt(p[1], g)} {p[2]:.4f} nan nan nan {sh:.4f} {sv:.4f}\n"
            for name, p, sh, sv in zip(cams.images, cams.xyz, cams.sigma_h_m, cams.sigma_v_m)
        )


def write_pix4d_csv(path: str | Path, cams: ExportedCameras) -> None:
    """Pix4D image geolocation: no header, `image,lat,lon,alt,omega,phi,kappa,acc_h,acc_v` (geographic: lat
    first) or `image,x,y,z,omega,phi,kappa,acc_h,acc_v` (projected); angles in degrees, accuracies in m."""
    with atomic_output(path, "w") as fh:
        w = csv.writer(fh, lineterminator="\n")
        for i, name in enumerate(cams.images):
            x, y, z = cams.xyz[i]
            first, second = (y, x) if cams.geographic else (x, y)
            o, p, k = opk_deg_from_r_cam_to_world(cams.r_cam_to_crs[i])
            w.writerow([name, _fmt(first, cams.geographic), _fmt(second, cams.geographic), f"{z:.4f}",
                        f"{o:.6f}", f"{p:.6f}", f"{k:.6f}", f"{cams.sigma_h_m[i]:.4f}", f"{cams.sigma_v_m[i]:.4f}"])


def write_metashape_txt(path: str | Path, cams: ExportedCameras) -> None:
    """Metashape reference import (columns `nxyzopk` + accuracies `abc`: label, x/lon, y/lat, z, ω, φ, κ)."""
    with atomic_output(path, "w") as fh:
        fh.write(f"# CRS: {cams.crs}\n# columns: nxyzopkabc (Label,X,Y,Z,Omega,Phi,Kappa,X_acc,Y_acc,Z_acc)\n")
        w = csv.writer(fh, lineterminator="\n")
        for i, name in enumerate(cams.images):
            x, y, z = cams.xyz[i]
            o, p, k = opk_deg_from_r_cam_to_world(cams.r_cam_to_crs[i])
            sh = cams.sigma_h_m[i] / np.sqrt(2.0)
            w.writerow([name, _fmt(x, cams.geographic), _fmt(y, cams.geographic), f"{z:.4f}", f"{o:.6f}",
                        f"{p:.6f}", f"{k:.6f}", f"{sh:.4f}", f"{sh:.4f}", f"{cams.sigma_v_m[i]:.4f}"])


def write_all(out_dir: str | Path, cams: ExportedCameras, centres_enu_m: Vec, r_cam_to_enu: Vec) -> dict[str, str]:
    """Write every export into `out_dir`; returns {format: relative path}. MicMac files need a Euclidean frame:
    they are written in the export CRS when it is projected, else in the local ENU frame."""
    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    write_odm_geo_txt(d / "geo.txt", cams)
    write_pix4d_csv(d / "pix4d.csv", cams)
    write_metashape_txt(d / "metashape.txt", cams)
    poses = [CameraPose(n, cams.xyz[i], cams.r_cam_to_crs[i]) for i, n in enumerate(cams.images)]
    write_opk_csv(d / "opk.csv", poses, crs=cams.crs, geographic=cams.geographic)
    ori = d / "Ori-directgeo"
    ori.mkdir(exist_ok=True)
    euclid = poses if not cams.geographic else [
        CameraPose(n, centres_enu_m[i], r_cam_to_enu[i]) for i, n in enumerate(cams.images)]
    for pose in euclid:
        write_micmac_orientation(ori / f"Orientation-{pose.image}.xml", pose)
    return {"odm": "geo.txt", "pix4d": "pix4d.csv", "metashape": "metashape.txt", "opk": "opk.csv",
            "micmac": "Ori-directgeo/",
            "micmac_frame": "local ENU about the origin" if cams.geographic else cams.crs}
