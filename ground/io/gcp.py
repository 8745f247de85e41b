"""Ground control / check points: our CSV, ODM `gcp_list.txt` and MicMac `DicoAppuisFlottant` XML.

Our CSV `name,role,x_rel,y_rel,z_rel,X,Y,Z[,sigma_m]` carries both the relative-frame coordinates (from the
bundle adjustment) and the ground coordinates (ECEF metres unless a CRS is given). ODM and MicMac files carry
ground coordinates only; `merge_ground_and_relative` ties them to relative coordinates by name.
Ground coordinates become local ENU about the adjustment origin only through `ground.io.crs`.
"""

from __future__ import annotations

import csv
import logging
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from ground.adjust.types import ControlPoint
from ground.io import crs as crsmod
from ground.io.errors import FormatError

log = logging.getLogger(__name__)

Vec = npt.NDArray[np.float64]

#: ODM gcp_list.txt has no check flag: labels starting with one of these are check points
CHECK_PREFIXES = ("chk", "check", "cp_", "cp-")


@dataclass(frozen=True)
class GroundPoint:
    """A point's ground coordinates in `crs` (x = easting/longitude first), σ (m) per axis, role, and rel coords."""

    name: str
    ground: Vec
    crs: str
    role: str = "gcp"
    rel: Vec | None = None
    sigma_m: Vec | None = None


def read_gcp_csv(path: str | Path, crs: str = crsmod.WGS84_ECEF) -> list[GroundPoint]:
    """Read `name,role,x_rel,y_rel,z_rel,X,Y,Z[,sigma_m]` (header required; role gcp or check)."""
    p = Path(path)
    try:
        with p.open(encoding="utf-8", newline="") as fh:
            rows = [r for r in csv.reader(fh) if r and not r[0].lstrip().startswith("#")]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise FormatError(p, f"unreadable GCP CSV: {exc}") from exc
    need = ["name", "role", "x_rel", "y_rel", "z_rel", "x", "y", "z"]
    if not rows or [h.strip().lower() for h in rows[0][:8]] != need:
        raise FormatError(p, "header must be name,role,x_rel,y_rel,z_rel,X,Y,Z[,sigma_m]", line=1)
    has_sigma = len(rows[0]) > 8 and rows[0][8].strip().lower() == "sigma_m"
    out: list[GroundPoint] = []
    names: set[str] = set()
    for n, row in enumerate(rows[1:], start=2):
        if len(row) < 8:
            raise FormatError(p, f"row has {len(row)} field(s), 8 needed (name,role,x_rel,y_rel,z_rel,X,Y,Z)",
                              line=n)
        try:
            name, role = row[0].strip(), row[1].strip().lower()
            vals = np.array([float(v) for v in row[2:8]])
            sigma = np.full(3, float(row[8])) if has_sigma and len(row) > 8 and row[8].strip() else None
        except (IndexError, ValueError) as exc:
            raise FormatError(p, f"bad row {row}: {exc}", line=n) from exc
        if role not in ("gcp", "check"):
            raise FormatError(p, f"role must be gcp or check, got {role!r}", line=n)
        if name in names:
            raise FormatError(p, f"point {name!r} listed twice", line=n)
        if not np.all(np.isfinite(vals)):
            raise FormatError(p, "non-finite coordinate", line=n)
        if sigma is not None and not (np.all(np.isfinite(sigma)) and np.all(sigma > 0)):
            raise FormatError(p, f"sigma_m {row[8].strip()}: must be a finite number > 0 (m)", line=n)
        names.add(name)
        out.append(GroundPoint(name=name, ground=vals[3:], crs=crs, role=role, rel=vals[:3], sigma_m=sigma))
    if not out:
        raise FormatError(p, "no points")
    return out


def read_odm_gcp_list(path: str | Path) -> list[GroundPoint]:
    """Read an ODM `gcp_list.txt` (line 1 SRS; `geo_x geo_y geo_z im_x im_y image [label]`).

    Image measurements are dropped (they belong to the bundle adjustment); points are keyed by label, or by
    their coordinates when unlabeled (`gcp<i>`). Labels with a check prefix (chk, check, cp_) are check points.
    Ground coordinates stay in the file's CRS (US-feet CRSs included: pyproj converts at use).
    """
    p = Path(path)
    try:
        lines = [ln.strip() for ln in p.read_text(encoding="utf-8").splitlines()]
    except (OSError, UnicodeDecodeError) as exc:
        raise FormatError(p, f"unreadable: {exc}") from exc
    lines = [ln for ln in lines if ln and not ln.startswith("#")]
    if not lines:
        raise FormatError(p, "empty gcp_list")
    srs = crsmod.parse_crs(lines[0]).to_string()
    by_key: dict[str, GroundPoint] = {}
    for n, ln in enumerate(lines[1:], start=2):
        parts = ln.split()
        if len(parts) < 6:
            raise FormatError(p, f"expected geo_x geo_y geo_z im_x im_y image [label], got {ln!r}", line=n)
        try:
            xyz = np.array([float(v) for v in parts[:3]])
            float(parts[3]), float(parts[4])
        except ValueError as exc:
            raise FormatError(p, f"non-numeric coordinate: {exc}", line=n) from exc
        label = parts[6] if len(parts) > 6 else None
        key = label or f"{xyz[0]:.6f} {xyz[1]:.6f} {xyz[2]:.6f}"
        if key in by_key:
            if label and not np.allclose(by_key[key].ground, xyz, atol=1e-6):
                raise FormatError(p, f"label {label!r} has two different coordinates", line=n)
            continue
        name = label or f"gcp{len(by_key) + 1}"
        role = "check" if name.lower().startswith(CHECK_PREFIXES) else "gcp"
        by_key[key] = GroundPoint(name=name, ground=xyz, crs=srs, role=role)
    return list(by_key.values())


def read_micmac_gcp(path: str | Path, crs: str) -> list[GroundPoint]:
    """Read a MicMac `DicoAppuisFlottant` XML (`Pt`, `NamePt`, `Incertitude`) with its ground CRS given."""
    p = Path(path)
    try:
        root = ET.parse(p).getroot()
    except (OSError, ET.ParseError) as exc:
        raise FormatError(p, f"not a readable XML file: {exc}") from exc
    if root.tag != "DicoAppuisFlottant":
        raise FormatError(p, f"root element is {root.tag}, expected DicoAppuisFlottant")
    out = []
    for el in root.iter("OneAppuisDAF"):
        name = (el.findtext("NamePt") or "").strip()
        try:
            pt = np.array([float(v) for v in (el.findtext("Pt") or "").split()])
            inc = el.findtext("Incertitude")
            sig = np.array([float(v) for v in inc.split()]) if inc else None
        except ValueError as exc:
            raise FormatError(p, f"point {name!r}: {exc}") from exc
        if not name or pt.size != 3 or (sig is not None and sig.size != 3):
            raise FormatError(p, f"point {name!r}: needs NamePt and 3 coordinates")
        role = "check" if name.lower().startswith(CHECK_PREFIXES) else "gcp"
        out.append(GroundPoint(name=name, ground=pt, crs=crs, role=role, sigma_m=sig))
    if not out:
        raise FormatError(p, "no OneAppuisDAF point")
    return out


def read_relative_csv(path: str | Path) -> dict[str, tuple[Vec, str | None]]:
    """Read `name,x_rel,y_rel,z_rel[,role]`: relative-frame coordinates of points from the bundle adjustment."""
    p = Path(path)
    try:
        rows = [r for r in csv.reader(p.read_text(encoding="utf-8").splitlines()) if r]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise FormatError(p, f"unreadable: {exc}") from exc
    out: dict[str, tuple[Vec, str | None]] = {}
    for n, row in enumerate(rows[1:], start=2):
        try:
            out[row[0].strip()] = (np.array([float(v) for v in row[1:4]]),
                                   row[4].strip().lower() if len(row) > 4 and row[4].strip() else None)
        except (IndexError, ValueError) as exc:
            raise FormatError(p, f"bad row {row}: {exc}", line=n) from exc
    return out


def merge_ground_and_relative(ground: list[GroundPoint], rel: dict[str, tuple[Vec, str | None]]) -> list[GroundPoint]:
    """Attach relative coordinates by name; points present in only one file are dropped and logged."""
    out = []
    for g in ground:
        if g.name not in rel:
            log.warning("ground point %s has no relative coordinates: not used", g.name)
            continue
        r, role = rel[g.name]
        out.append(GroundPoint(g.name, g.ground, g.crs, role or g.role, r, g.sigma_m))
    unknown = set(rel) - {g.name for g in ground}
    if unknown:
        log.warning("relative points without ground coordinates: %s", ", ".join(sorted(unknown)))
    return out


def to_control_points(points: list[GroundPoint], origin_ecef_m: npt.ArrayLike, default_sigma_m: float = 0.01,
                      max_datum_error_m: float = crsmod.MAX_DATUM_ERROR_M) -> list[ControlPoint]:
    """Ground coordinates → ENU about the origin (via pyproj), as `ControlPoint`s for the adjustment."""
    out = []
    for gp in points:
        if gp.rel is None:
            raise ValueError(f"point {gp.name} has no relative-frame coordinates")
        enu = crsmod.crs_to_enu(gp.ground[None, :], gp.crs, origin_ecef_m, max_datum_error_m=max_datum_error_m)[0]
        sigma = gp.sigma_m if gp.sigma_m is not None else np.full(3, default_sigma_m)
        out.append(ControlPoint(name=gp.name, role=gp.role, rel=np.asarray(gp.rel, float), ground_enu_m=enu,
                                sigma_m=np.asarray(sigma, float)))
    return out
