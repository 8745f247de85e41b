"""ECEF ↔ geodetic (WGS 84) and local ENU frames. Angles in radians unless a name says _deg."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from onboard.rtk.consts import WGS84_A_M, WGS84_E2

Vec = npt.NDArray[np.float64]


def llh_to_ecef(lat_rad: float, lon_rad: float, h_m: float) -> Vec:
    """Geodetic latitude, longitude (rad) and ellipsoidal height (m) → ECEF position (m), shape (3,)."""
    sl, cl = np.sin(lat_rad), np.cos(lat_rad)
    n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * sl * sl)
    return np.array(
        [(n + h_m) * cl * np.cos(lon_rad), (n + h_m) * cl * np.sin(lon_rad), (n * (1.0 - WGS84_E2) + h_m) * sl]
    )


def ecef_to_llh(xyz_m: npt.ArrayLike) -> Vec:
    """ECEF position (m) → array [lat_rad, lon_rad, h_m] (iterative, converges to < 1e-4 mm)."""
    # plain floats and math: this runs several times per epoch in the RTK engine
    x, y, z = np.asarray(xyz_m, dtype=float).tolist()
    r2 = x * x + y * y
    zk, v = 0.0, WGS84_A_M
    znew = z
    for _ in range(20):
        zk = znew
        rho2 = r2 + zk * zk
        sinp = zk / math.sqrt(rho2) if rho2 > 0 else 0.0
        v = WGS84_A_M / math.sqrt(1.0 - WGS84_E2 * sinp * sinp)
        znew = z + v * WGS84_E2 * sinp
        if abs(znew - zk) < 1e-4:
            break
    if r2 > 1e-12:
        lat = math.atan(znew / math.sqrt(r2))
        lon = math.atan2(y, x)
    else:
        lat = math.pi / 2 if z > 0 else -math.pi / 2
        lon = 0.0
    h = math.sqrt(r2 + znew * znew) - v
    return np.array([lat, lon, h])


def enu_rotation(lat_rad: float, lon_rad: float) -> Vec:
    """3×3 matrix turning an ECEF vector into local East, North, Up at (lat, lon): v_enu = R @ v_ecef."""
    # math's sin/cos: libm's, which numpy's float64 sin/cos call (equal on every one of 3e6 test angles, see
    # tests/rtk/test_fast_paths.py), without a numpy scalar per call (the engine asks twice per epoch)
    sl, cl = math.sin(lat_rad), math.cos(lat_rad)
    so, co = math.sin(lon_rad), math.cos(lon_rad)
    return np.array([[-so, co, 0.0], [-sl * co, -sl * so, cl], [cl * co, cl * so, sl]])


def ecef_to_enu(xyz_m: npt.ArrayLike, origin_ecef_m: npt.ArrayLike) -> Vec:
    """ECEF point(s) (…, 3) → local ENU (m) about `origin_ecef_m`."""
    origin = np.asarray(origin_ecef_m, dtype=float)
    lat, lon, _ = ecef_to_llh(origin)
    return (np.asarray(xyz_m, dtype=float) - origin) @ enu_rotation(lat, lon).T


def enu_to_ecef(enu_m: npt.ArrayLike, origin_ecef_m: npt.ArrayLike) -> Vec:
    """Local ENU point(s) (…, 3) about `origin_ecef_m` → ECEF (m)."""
    origin = np.asarray(origin_ecef_m, dtype=float)
    lat, lon, _ = ecef_to_llh(origin)
    return np.asarray(enu_m, dtype=float) @ enu_rotation(lat, lon) + origin


def azimuth_elevation(receiver_ecef_m: npt.ArrayLike, sat_ecef_m: npt.ArrayLike) -> tuple[Vec, Vec]:
    """Azimuth and elevation (rad) of satellites (n, 3) seen from a receiver (3,), both ECEF metres."""
    rcv = np.asarray(receiver_ecef_m, dtype=float)
    lat, lon, _ = ecef_to_llh(rcv)
    los = np.atleast_2d(np.asarray(sat_ecef_m, dtype=float)) - rcv
    enu = los @ enu_rotation(lat, lon).T
    horiz = np.hypot(enu[:, 0], enu[:, 1])
    return np.arctan2(enu[:, 0], enu[:, 1]) % (2 * np.pi), np.arctan2(enu[:, 2], horiz)


def parse_xyz_m(text: str) -> tuple[float, float, float]:
    """Three comma-separated numbers "X,Y,Z" (ECEF m: a take-off point, a base position); ValueError naming
    `text` otherwise. The one parser behind the settings key and the command lines' positions (text in, no I/O)."""
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        raise ValueError(f"expected X,Y,Z in ECEF metres, got {text!r}") from None
    if len(vals) != 3:
        raise ValueError(f"expected X,Y,Z in ECEF metres, got {text!r}")
    return (vals[0], vals[1], vals[2])
