"""The only pyproj user: ENU ↔ ECEF (via onboard.rtk.geodesy) and ECEF ↔ any EPSG CRS, exactly or not at all.

The adjustment runs in a local ENU frame; projection happens only here, at export (and for GCPs given in a
CRS, at import). Transformations are built with `allow_ballpark=False, only_best=True` and run with
`errcheck=True`, so a compound CRS whose geoid grid is not installed (e.g. EPSG:2154+5720 needs RAF20)
raises `CrsError` instead of silently returning ellipsoidal heights.
"""

from __future__ import annotations

import logging
from functools import lru_cache

import numpy as np
import numpy.typing as npt
from pyproj import CRS, Transformer
from pyproj.exceptions import CRSError as _PyprojCRSError
from pyproj.exceptions import ProjError

from ground.io.errors import CrsError
from onboard.rtk.geodesy import ecef_to_enu, ecef_to_llh, enu_to_ecef, llh_to_ecef

log = logging.getLogger(__name__)

Vec = npt.NDArray[np.float64]

WGS84_ECEF = "EPSG:4978"
#: largest accepted error (m) of a datum change inside a transformation; PROJ ships null (0 m shift, "1 m
#: accuracy") transformations such as WGS 84 → RGF93 while the frames differ by ~0.8 m today in Europe
MAX_DATUM_ERROR_M = 0.05


def parse_crs(text: str) -> CRS:
    """A CRS from 'EPSG:n', 'EPSG:h+v', a PROJ string or WKT; ODM's 'WGS84 UTM 16N' form accepted too."""
    t = text.strip()
    parts = t.upper().split()
    if len(parts) == 3 and parts[0] == "WGS84" and parts[1] == "UTM" and parts[2][-1] in "NS":
        zone = int(parts[2][:-1])
        t = f"EPSG:{(32600 if parts[2][-1] == 'N' else 32700) + zone}"
    try:
        return CRS.from_user_input(t)
    except _PyprojCRSError as exc:
        raise CrsError(f"unknown CRS {text!r}: {exc}") from exc


@lru_cache(maxsize=32)
def _transformer(src: str, dst: str) -> Transformer:
    try:
        return Transformer.from_crs(
            parse_crs(src), parse_crs(dst), always_xy=True, allow_ballpark=False, only_best=True
        )
    except ProjError as exc:
        raise CrsError(f"no exact transformation {src} → {dst}: {exc}") from exc


def _datum_name(c: CRS) -> str:
    h = c.sub_crs_list[0] if c.is_compound and c.sub_crs_list else c
    g = h.geodetic_crs
    return g.datum.name if g is not None and g.datum is not None else h.name


def check_datum_change(src: str, dst: str, max_datum_error_m: float = MAX_DATUM_ERROR_M) -> None:
    """Refuse a transformation that changes datum with an unknown or worse-than-tolerance accuracy.

    Same datum (conversions, projections): accepted. Different datums: accepted only when PROJ states an
    accuracy ≤ `max_datum_error_m`; otherwise `CrsError` (e.g. WGS 84 → RGF93/ETRS89 is a null shift of
    stated 1 m accuracy, WGS 84 → ITRF2014 an identity of unknown accuracy).
    """
    d_src, d_dst = _datum_name(parse_crs(src)), _datum_name(parse_crs(dst))
    if d_src == d_dst:
        return
    acc = float(_transformer(src, dst).accuracy)
    if acc < 0 or acc > max_datum_error_m:
        stated = "unknown" if acc < 0 else f"{acc:g} m"
        raise CrsError(
            f"{src} → {dst} changes datum ({d_src} → {d_dst}) with {stated} accuracy (> {max_datum_error_m} m): "
            "PROJ would apply a null or approximate shift. Give the data in one datum, or raise the datum "
            "tolerance (--datum-tolerance-m) if that error is acceptable"
        )


def _run(src: str, dst: str, xyz: Vec, max_datum_error_m: float = MAX_DATUM_ERROR_M) -> Vec:
    pts = np.atleast_2d(np.asarray(xyz, dtype=float))
    if pts.shape[1] != 3:
        raise ValueError(f"points must be (n, 3), got {pts.shape}")
    tr = _transformer(src, dst)
    try:
        x, y, z = tr.transform(pts[:, 0], pts[:, 1], pts[:, 2], errcheck=True)
    except ProjError as exc:
        hint = ""
        dst_crs = parse_crs(dst)
        if dst_crs.is_compound or parse_crs(src).is_compound:
            hint = (" — a vertical datum needs its geoid grid (e.g. RAF20 for NGF-IGN69); install it with "
                    "projsync or export ellipsoidal heights")
        raise CrsError(f"transformation {src} → {dst} failed: {exc}{hint}") from exc
    # after proj_trans, so PROJ has chosen the operation and knows its accuracy
    check_datum_change(src, dst, max_datum_error_m)
    out = np.column_stack([x, y, z]).astype(float)
    if not np.all(np.isfinite(out)):
        raise CrsError(f"transformation {src} → {dst} returned non-finite coordinates")
    return out


def ecef_to_crs(points_ecef_m: npt.ArrayLike, crs: str, source_crs: str = WGS84_ECEF,
                max_datum_error_m: float = MAX_DATUM_ERROR_M) -> Vec:
    """ECEF points (n, 3) in `source_crs` → (n, 3) in `crs` (x = easting/longitude first, heights as the CRS says).

    Geographic CRSs return (lon_deg, lat_deg, h_m). A 2-D CRS keeps the ellipsoidal height as third value.
    A datum change less accurate than `max_datum_error_m` is refused (`check_datum_change`).
    """
    return _run(source_crs, crs, np.asarray(points_ecef_m, dtype=float), max_datum_error_m)


def crs_to_ecef(points: npt.ArrayLike, crs: str, target_crs: str = WGS84_ECEF,
                max_datum_error_m: float = MAX_DATUM_ERROR_M) -> Vec:
    """Points (n, 3) in `crs` (x/longitude first) → ECEF metres of `target_crs`."""
    return _run(crs, target_crs, np.asarray(points, dtype=float), max_datum_error_m)


def enu_to_crs(points_enu_m: npt.ArrayLike, origin_ecef_m: npt.ArrayLike, crs: str,
               source_crs: str = WGS84_ECEF, max_datum_error_m: float = MAX_DATUM_ERROR_M) -> Vec:
    """Local ENU points (n, 3) about `origin_ecef_m` → `crs`."""
    return ecef_to_crs(enu_to_ecef(np.atleast_2d(points_enu_m), origin_ecef_m), crs, source_crs, max_datum_error_m)


def crs_to_enu(points: npt.ArrayLike, crs: str, origin_ecef_m: npt.ArrayLike,
               target_crs: str = WGS84_ECEF, max_datum_error_m: float = MAX_DATUM_ERROR_M) -> Vec:
    """Points (n, 3) in `crs` → local ENU metres about `origin_ecef_m`."""
    return ecef_to_enu(crs_to_ecef(points, crs, target_crs, max_datum_error_m), origin_ecef_m)


def lonlat_deg_to_ecef(lon_deg: float, lat_deg: float, h_m: float) -> Vec:
    """WGS 84 longitude/latitude (degrees) and ellipsoidal height → ECEF metres (no pyproj needed)."""
    return llh_to_ecef(np.radians(lat_deg), np.radians(lon_deg), h_m)


def ecef_to_lonlat_deg(xyz_m: npt.ArrayLike) -> Vec:
    """ECEF metres → [lon_deg, lat_deg, h_m] (WGS 84 ellipsoid)."""
    lat, lon, h = ecef_to_llh(xyz_m)
    return np.array([np.degrees(lon), np.degrees(lat), h])


def enu_to_grid_rotation(origin_ecef_m: npt.ArrayLike, crs: str, source_crs: str = WGS84_ECEF,
                         max_datum_error_m: float = MAX_DATUM_ERROR_M) -> Vec:
    """3×3 rotation turning local ENU vectors into the axes of a projected CRS (grid east, grid north, up).

    Computed from the projection itself (grid directions of 1 m steps east and north at the origin), so it
    holds the meridian convergence with the right sign whatever the projection. Identity for a geographic CRS
    (angles exported there stay relative to true north).
    """
    if not parse_crs(crs).is_projected and not _horizontal_is_projected(crs):
        return np.eye(3)
    origin = np.asarray(origin_ecef_m, dtype=float)
    pts = enu_to_crs(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), origin, crs, source_crs,
                     max_datum_error_m)
    e = pts[1, :2] - pts[0, :2]
    n = pts[2, :2] - pts[0, :2]
    # Angle of true east in grid axes; average with north's for a conformal projection (they agree).
    a = 0.5 * (np.arctan2(e[1], e[0]) + np.arctan2(-n[0], n[1]))
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _horizontal_is_projected(crs: str) -> bool:
    c = parse_crs(crs)
    return bool(c.is_compound and c.sub_crs_list and c.sub_crs_list[0].is_projected)


def is_geographic(crs: str) -> bool:
    """True when the CRS (or its horizontal part) is geographic (longitude/latitude)."""
    c = parse_crs(crs)
    if c.is_compound and c.sub_crs_list:
        c = c.sub_crs_list[0]
    return bool(c.is_geographic)


#: a site this far (degrees) outside a CRS's area of use is refused; nearer, the export is accepted with a
#: warning: half a UTM zone beyond its strip (9° from the central meridian) the scale error is still ≤ 0.5 %
#: at mid-latitudes, a known distortion users choose for a site straddling two zones; half a world away the
#: projection is meaningless
AREA_OF_USE_MARGIN_DEG = 3.0


def check_crs_covers(origin_ecef_m: npt.ArrayLike, crs: str,
                     margin_deg: float = AREA_OF_USE_MARGIN_DEG) -> list[str]:
    """Refuse (CrsError) a CRS whose area of use is more than `margin_deg` away from the site; return a warning
    when the site is just outside it, else nothing. Geographic/geocentric CRSs cover the whole Earth."""
    c = parse_crs(crs)
    area = c.area_of_use
    if area is None:
        return []
    lon, lat = (float(v) for v in ecef_to_lonlat_deg(origin_ecef_m)[:2])
    west, south, east, north = area.west, area.south, area.east, area.north
    lon_in = (west <= lon <= east) if west <= east else (lon >= west or lon <= east)

    def lon_gap(a: float, b: float) -> float:
        return min(abs((a - b + 180.0) % 360.0 - 180.0), 360.0)

    gap_lon = 0.0 if lon_in else min(lon_gap(lon, west), lon_gap(lon, east))
    gap_lat = max(south - lat, lat - north, 0.0)
    if gap_lon == 0.0 and gap_lat == 0.0:
        return []
    zone = int((lon + 180.0) // 6.0) % 60 + 1
    utm = f"EPSG:{(32600 if lat >= 0 else 32700) + zone}"
    where = (f"{abs(lon):.3f}°{'E' if lon >= 0 else 'W'}, {abs(lat):.3f}°{'N' if lat >= 0 else 'S'}")
    text = (f"{crs} ({c.name}) is meant for {west:g}° to {east:g}° longitude, {south:g}° to {north:g}° "
            f"latitude; the site is at {where}, {max(gap_lon, gap_lat):.1f}° outside")
    if gap_lon > margin_deg or gap_lat > margin_deg:
        raise CrsError(f"{text}: its coordinates there are distorted or meaningless; use the CRS of the site "
                       f"(its UTM zone is {zone}, {utm})")
    return [f"{text}: accepted (within {margin_deg:g}°), but the distortion grows outside the zone"]
