"""Orientation importers: OpenSfM/ODM, COLMAP, MicMac, Metashape and OPK CSV → `CameraPose` lists.

Every reader converts to our convention at the boundary (shared/docs/adjustment.md): computer-vision camera
axes (x right, y down, z forward), `centre_rel` in the file's frame and units, `r_cam_to_rel` camera → that
frame. Nothing downstream knows which program wrote the poses.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import shlex
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from ground.adjust.types import CameraPose
from ground.io.errors import FormatError
from ground.io.rotations import (
    is_rotation,
    r_cam_to_world_from_opk_deg,
    rotation_from_axis_angle,
    rotation_from_quaternion_wxyz,
)
from onboard.formats.atomic import atomic_output, write_atomic

log = logging.getLogger(__name__)

Vec = npt.NDArray[np.float64]


@dataclass(frozen=True)
class OrientationSet:
    """Poses read from one file or folder, with what is known of their frame.

    `frame` describes the poses' world frame in words ("relative", "OpenSfM topocentric", "EPSG:32651" …);
    `crs` is set only when the frame is a known CRS (a projected/geographic CRS string for pyproj).
    """

    poses: list[CameraPose]
    format: str
    frame: str
    crs: str | None = None
    extras: dict[str, object] = field(default_factory=dict)

    def by_image(self) -> dict[str, CameraPose]:
        """Poses keyed by image name."""
        return {p.image: p for p in self.poses}


def _floats(text: str | None, n: int, path: Path, what: str) -> Vec:
    if text is None:
        raise FormatError(path, f"missing {what}")
    try:
        values = np.array([float(v) for v in text.split()])
    except ValueError as exc:
        raise FormatError(path, f"{what} is not numeric: {text!r}") from exc
    if values.size != n:
        raise FormatError(path, f"{what} has {values.size} numbers, expected {n}")
    return values


def _check_rotation(r: Vec, path: Path, image: str) -> Vec:
    if not np.all(np.isfinite(r)) or not is_rotation(r, tol=1e-5):
        raise FormatError(path, f"rotation of {image} is not a proper rotation matrix")
    return r


# ---------------------------------------------------------------- OpenSfM / ODM reconstruction.json


def read_opensfm(path: str | Path) -> OrientationSet:
    """Read an OpenSfM/ODM `reconstruction.json` (x_cam = R·X + t, centre = −Rᵀt, R from axis-angle).

    With several reconstructions (disconnected blocks) the largest is used, since each has its own frame.
    `extras`: `reference_lla` (dict lat/lon/alt in degrees/m, or None) and `gps_position_enu_m`
    (image → topocentric ENU of the reference; in ODM files the poses may be UTM-grid aligned instead).
    """
    p = Path(path)
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise FormatError(p, f"not a readable JSON file: {exc}") from exc
    if not isinstance(data, list) or not data or not all(isinstance(r, dict) for r in data):
        raise FormatError(p, "expected a JSON list of reconstructions")
    recs = sorted(data, key=lambda r: len(r.get("shots", {})), reverse=True)
    if len(recs) > 1:
        log.warning("%s holds %d reconstructions; using the largest (%d shots)", p, len(recs),
                    len(recs[0].get("shots", {})))
    rec = recs[0]
    shots = rec.get("shots")
    if not isinstance(shots, dict) or not shots:
        raise FormatError(p, "reconstruction has no shots")
    poses: list[CameraPose] = []
    gps: dict[str, Vec] = {}
    for name, shot in shots.items():
        try:
            rotvec = np.asarray(shot["rotation"], dtype=float).reshape(3)
            t = np.asarray(shot["translation"], dtype=float).reshape(3)
        except (KeyError, TypeError, ValueError) as exc:
            raise FormatError(p, f"shot {name!r}: rotation/translation missing or malformed") from exc
        r_world_to_cam = rotation_from_axis_angle(rotvec)
        poses.append(CameraPose(image=name, centre_rel=-r_world_to_cam.T @ t, r_cam_to_rel=r_world_to_cam.T))
        if "gps_position" in shot:
            gps[name] = np.asarray(shot["gps_position"], dtype=float).reshape(3)
    ref = rec.get("reference_lla")
    return OrientationSet(
        poses=poses,
        format="opensfm",
        frame="OpenSfM/ODM local frame about reference_lla (ODM: UTM-grid aligned)",
        extras={"reference_lla": ref, "gps_position_enu_m": gps},
    )


# ---------------------------------------------------------------- COLMAP images.txt


def read_colmap_images(path: str | Path) -> OrientationSet:
    """Read a COLMAP text model `images.txt` (`IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME` + POINTS2D line).

    Quaternion is Hamilton (w, x, y, z), world → camera; centre = −Rᵀt.
    """
    p = Path(path)
    try:
        lines = p.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise FormatError(p, f"unreadable: {exc}") from exc
    poses: list[CameraPose] = []
    i = 0
    while i < len(lines):
        line = lines[i].strip()
        i += 1
        if not line or line.startswith("#"):
            continue
        parts = line.split()
        if len(parts) < 10:
            raise FormatError(p, f"image line has {len(parts)} fields, expected 10", line=i)
        try:
            q = np.array([float(v) for v in parts[1:5]])
            t = np.array([float(v) for v in parts[5:8]])
        except ValueError as exc:
            raise FormatError(p, "non-numeric pose", line=i) from exc
        if not np.isfinite(q).all() or np.linalg.norm(q) < 1e-9:
            raise FormatError(p, "invalid quaternion", line=i)
        name = " ".join(parts[9:])  # COLMAP names may contain spaces only at the end
        r_world_to_cam = rotation_from_quaternion_wxyz(q)
        poses.append(CameraPose(image=name, centre_rel=-r_world_to_cam.T @ t, r_cam_to_rel=r_world_to_cam.T))
        i += 1  # the POINTS2D line that always follows (possibly empty)
    if not poses:
        raise FormatError(p, "no image lines")
    return OrientationSet(poses=poses, format="colmap", frame="COLMAP model frame")


# ---------------------------------------------------------------- MicMac Orientation-*.xml

MICMAC_PREFIX = "Orientation-"


def read_micmac_orientation(path: str | Path) -> CameraPose:
    """Read one MicMac `Orientation-<image>.xml` (P_world = M·P_cam + Centre, M rows L1..L3).

    Only the matrix coding (`CodageMatr`) is accepted: angular codings (`CodageAngulaire`) depend on the
    `KnownConv` in subtle ways, so they are refused with an error rather than guessed.
    """
    p = Path(path)
    try:
        root = ET.parse(p).getroot()
    except (OSError, ET.ParseError) as exc:
        raise FormatError(p, f"not a readable XML file: {exc}") from exc
    oc = root if root.tag == "OrientationConique" else root.find(".//OrientationConique")
    if oc is None:
        raise FormatError(p, "no OrientationConique element")
    ext = oc.find("Externe")
    if ext is None:
        raise FormatError(p, "no Externe element")
    centre = _floats(ext.findtext("Centre"), 3, p, "Centre")
    rot = ext.find("ParamRotation")
    if rot is None:
        raise FormatError(p, "no ParamRotation element")
    matr = rot.find("CodageMatr")
    if matr is None:
        if rot.find("CodageAngulaire") is not None:
            raise FormatError(p, "CodageAngulaire (angles) is not supported; export the orientation with "
                                 "CodageMatr (rotation matrix), e.g. Apero's default output")
        raise FormatError(p, "no CodageMatr element")
    m = np.vstack([_floats(matr.findtext(k), 3, p, k) for k in ("L1", "L2", "L3")])
    name = p.name
    image = name[len(MICMAC_PREFIX):-4] if name.startswith(MICMAC_PREFIX) and name.endswith(".xml") else p.stem
    return CameraPose(image=image, centre_rel=centre, r_cam_to_rel=_check_rotation(m, p, image))


def read_micmac_folder(folder: str | Path) -> OrientationSet:
    """Read every `Orientation-*.xml` of a MicMac `Ori-*` folder (sorted by image name)."""
    d = Path(folder)
    files = sorted(d.glob(f"{MICMAC_PREFIX}*.xml"))
    if not files:
        raise FormatError(d, "no Orientation-*.xml files in this folder")
    poses = [read_micmac_orientation(f) for f in files]
    return OrientationSet(poses=poses, format="micmac", frame=f"MicMac {d.name} frame")


#: largest uncompressed member of a MicMac .zip (bytes): an orientation XML is a few kB
MAX_MICMAC_MEMBER_BYTES = 1 << 20


def read_micmac_zip(path: str | Path) -> OrientationSet:
    """Read the `Orientation-*.xml` of a MicMac `Ori-*` folder sent as one .zip (a flight file is one file, not a
    folder). Members are matched by their base name, wherever they sit in the archive; nothing is extracted to
    disk, and a member over `MAX_MICMAC_MEMBER_BYTES` or two with the same name are refused."""
    import tempfile
    import zipfile

    p = Path(path)
    try:
        with zipfile.ZipFile(p) as zf, tempfile.TemporaryDirectory(prefix="micmac-") as tmp:
            seen: set[str] = set()
            for info in zf.infolist():
                name = info.filename.rsplit("/", 1)[-1]
                if info.is_dir() or not (name.startswith(MICMAC_PREFIX) and name.endswith(".xml")):
                    continue
                if name in seen:
                    raise FormatError(p, f"{name} appears twice in the archive")
                if info.file_size > MAX_MICMAC_MEMBER_BYTES:
                    raise FormatError(p, f"{name}: {info.file_size} bytes, too large for an orientation file")
                seen.add(name)
                (Path(tmp) / name).write_bytes(zf.read(info))
            if not seen:
                raise FormatError(p, "no Orientation-*.xml in this archive (zip the MicMac Ori-* folder)")
            try:
                got = read_micmac_folder(tmp)
            except FormatError as exc:  # name the member, not the temporary copy
                raise FormatError(p, f"{Path(exc.path).name}: {exc.detail}", line=exc.line) from None
    except (zipfile.BadZipFile, OSError) as exc:
        raise FormatError(p, f"not a readable zip archive: {exc}") from exc
    return OrientationSet(poses=got.poses, format="micmac", frame=f"MicMac frame ({p.name})")


def write_micmac_orientation(path: str | Path, pose: CameraPose) -> None:
    """Write a MicMac `Orientation-<image>.xml` holding the pose's Centre and CodageMatr (camera → world)."""
    oc = ET.Element("OrientationConique")
    ET.SubElement(oc, "TypeProj").text = "eProjStenope"
    ext = ET.SubElement(oc, "Externe")
    ET.SubElement(ext, "KnownConv").text = "eConvApero_DistM2C"
    ET.SubElement(ext, "Centre").text = " ".join(repr(float(v)) for v in pose.centre_rel)
    matr = ET.SubElement(ET.SubElement(ext, "ParamRotation"), "CodageMatr")
    for k, row in zip(("L1", "L2", "L3"), np.asarray(pose.r_cam_to_rel, dtype=float)):
        ET.SubElement(matr, k).text = " ".join(repr(float(v)) for v in row)
    ET.SubElement(ET.SubElement(oc, "ConvOri"), "KnownConv").text = "eConvApero_DistM2C"
    ET.indent(oc, space="     ")
    write_atomic(path, '<?xml version="1.0" ?>\n' + ET.tostring(oc, encoding="unicode") + "\n")


# ---------------------------------------------------------------- Metashape camera XML


@dataclass(frozen=True)
class ChunkTransform:
    """Metashape chunk → ECEF similarity: X_ecef = scale·R·x_chunk + t (metres)."""

    rotation: Vec
    translation_m: Vec
    scale: float

    def apply(self, x_chunk: npt.ArrayLike) -> Vec:
        """Chunk coordinates (…, 3) → ECEF metres."""
        return self.scale * np.asarray(x_chunk, dtype=float) @ self.rotation.T + self.translation_m


def read_metashape_cameras(path: str | Path) -> OrientationSet:
    """Read a Metashape "Export Cameras" XML: 4×4 camera → chunk transforms (CV camera axes).

    Cameras without a transform (not aligned) are skipped and listed in `extras["unaligned"]`.
    `extras["chunk_to_ecef"]` is the component (or chunk) `ChunkTransform` when the file has one, and
    `extras["reference"]` maps image label → (lon_deg, lat_deg, alt_m) from `<reference>` when present.
    """
    p = Path(path)
    try:
        root = ET.parse(p).getroot()
    except (OSError, ET.ParseError) as exc:
        raise FormatError(p, f"not a readable XML file: {exc}") from exc
    chunk = root.find("chunk") if root.tag == "document" else root
    if chunk is None or chunk.find("cameras") is None:
        raise FormatError(p, "no chunk/cameras element: not a Metashape cameras export")
    components: dict[str, ChunkTransform] = {}
    for comp in chunk.iter("component"):
        tr = comp.find("transform")
        if tr is not None:
            components[comp.get("id", "0")] = _chunk_transform(tr, p)
    chunk_tr = chunk.find("transform")
    default = _chunk_transform(chunk_tr, p) if chunk_tr is not None else None
    poses: list[CameraPose] = []
    unaligned: list[str] = []
    reference: dict[str, tuple[float, float, float]] = {}
    used: ChunkTransform | None = default
    for cam in chunk.find("cameras").iter("camera"):  # type: ignore[union-attr]
        label = cam.get("label", cam.get("id", "?"))
        ref = cam.find("reference")
        if ref is not None and all(ref.get(k) is not None for k in ("x", "y", "z")):
            reference[label] = (float(ref.get("x")), float(ref.get("y")), float(ref.get("z")))  # type: ignore[arg-type]
        text = cam.findtext("transform")
        if text is None:
            unaligned.append(label)
            continue
        m = _floats(text, 16, p, f"transform of camera {label}").reshape(4, 4)
        r = m[:3, :3]
        poses.append(CameraPose(image=label, centre_rel=m[:3, 3].copy(), r_cam_to_rel=_check_rotation(r, p, label)))
        comp_id = cam.get("component_id")
        if comp_id is not None and comp_id in components:
            used = components[comp_id]
    if not poses:
        raise FormatError(p, "no aligned camera (no camera has a transform)")
    if unaligned:
        log.warning("%s: %d cameras are not aligned and were skipped", p, len(unaligned))
    if used is None and len(components) == 1:
        used = next(iter(components.values()))
    return OrientationSet(
        poses=poses,
        format="metashape",
        frame="Metashape chunk frame",
        extras={"chunk_to_ecef": used, "unaligned": unaligned, "reference": reference},
    )


def _chunk_transform(el: ET.Element, p: Path) -> ChunkTransform:
    r = _floats(el.findtext("rotation"), 9, p, "chunk rotation").reshape(3, 3)
    t = _floats(el.findtext("translation"), 3, p, "chunk translation")
    s = float(_floats(el.findtext("scale") or "1", 1, p, "chunk scale")[0])
    return ChunkTransform(rotation=_check_rotation(r, p, "chunk"), translation_m=t, scale=s)


# ---------------------------------------------------------------- OPK CSV

_OPK_COLUMNS: dict[str, tuple[str, ...]] = {
    "image": ("image", "filename", "name", "label", "photo"),
    "x": ("x", "easting", "east"),
    "y": ("y", "northing", "north"),
    "z": ("z", "altitude", "height", "h"),
    "omega": ("omega", "o", "w"),
    "phi": ("phi", "p"),
    "kappa": ("kappa", "k"),
}


def _split_rows(text: str) -> list[list[str]]:
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if lines and "," in lines[0]:
        return [row for row in csv.reader(io.StringIO("\n".join(lines)))]
    return [shlex.split(ln) for ln in lines]  # space-delimited, quotes as in ODM/orthority files


def read_opk_csv(path: str | Path) -> OrientationSet:
    """Read an OPK CSV: `image,X,Y,Z,omega,phi,kappa` (degrees, PATB/photogrammetric axes) with a header.

    Comma- or whitespace-delimited, quoted or not; extra columns ignored; a `.prj` sidecar (PROJ string or
    WKT) sets `crs`. Rotations are converted to CV axes: R = Rx(ω)Ry(φ)Rz(κ)·diag(1, −1, −1).
    """
    p = Path(path)
    try:
        rows = _split_rows(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, csv.Error, ValueError) as exc:
        raise FormatError(p, f"unreadable CSV: {exc}") from exc
    if len(rows) < 2:
        raise FormatError(p, "needs a header line and at least one row")
    header = [h.strip().lower() for h in rows[0]]
    col: dict[str, int] = {}
    for key, aliases in _OPK_COLUMNS.items():
        for a in aliases:
            if a in header:
                col[key] = header.index(a)
                break
        else:
            raise FormatError(p, f"header has no {key!r} column (got {rows[0]})", line=1)
    poses: list[CameraPose] = []
    for n, row in enumerate(rows[1:], start=2):
        try:
            vals = {k: float(row[i]) for k, i in col.items() if k != "image"}
            image = row[col["image"]].strip()
        except (IndexError, ValueError) as exc:
            raise FormatError(p, f"bad row {row}: {exc}", line=n) from exc
        if not image:
            raise FormatError(p, "empty image name", line=n)
        r = r_cam_to_world_from_opk_deg(vals["omega"], vals["phi"], vals["kappa"])
        poses.append(CameraPose(image=image, centre_rel=np.array([vals["x"], vals["y"], vals["z"]]), r_cam_to_rel=r))
    prj = p.with_suffix(".prj")
    crs = prj.read_text(encoding="utf-8").strip() if prj.is_file() else None
    return OrientationSet(poses=poses, format="opk-csv", frame=crs or "OPK CSV frame", crs=crs)


def write_opk_csv(path: str | Path, poses: list[CameraPose], crs: str | None = None,
                  geographic: bool | None = None) -> None:
    """Write an OPK CSV (`image,X,Y,Z,omega,phi,kappa`, degrees, PATB axes) and a `.prj` when `crs` is given,
    both atomically.

    X,Y are written with 9 decimals when they are degrees (a geographic CRS: 1e-9° ≈ 0.1 mm; the 4 decimals
    of metres would be 1e-4° ≈ 11 m of latitude), with 4 (0.1 mm) when they are metres. `geographic` defaults
    to what `crs` says (metres without a CRS).
    """
    from ground.io.crs import is_geographic
    from ground.io.rotations import opk_deg_from_r_cam_to_world

    p = Path(path)
    degrees = geographic if geographic is not None else (crs is not None and is_geographic(crs))
    xy = ".9f" if degrees else ".4f"
    with atomic_output(p, "w") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["image", "X", "Y", "Z", "omega", "phi", "kappa"])
        for pose in poses:
            o, ph, k = opk_deg_from_r_cam_to_world(pose.r_cam_to_rel)
            c = pose.centre_rel
            w.writerow([pose.image, f"{c[0]:{xy}}", f"{c[1]:{xy}}", f"{c[2]:.4f}", f"{o:.6f}", f"{ph:.6f}",
                        f"{k:.6f}"])
    if crs is not None:
        write_atomic(p.with_suffix(".prj"), crs + "\n")


# ---------------------------------------------------------------- dispatch


def read_orientations(path: str | Path) -> OrientationSet:
    """Read poses from a file or folder, choosing the reader from its shape.

    Folder → MicMac `Ori-*` (`.zip` → the same folder zipped); `.json` → OpenSfM; `.txt` → COLMAP `images.txt`;
    `.xml` → Metashape cameras (or a single MicMac orientation); `.csv` → OPK CSV.
    """
    p = Path(path)
    if p.is_dir():
        return read_micmac_folder(p)
    if not p.is_file():
        raise FormatError(p, "no such file or folder")
    suffix = p.suffix.lower()
    if suffix == ".json":
        return read_opensfm(p)
    if suffix == ".txt":
        return read_colmap_images(p)
    if suffix == ".csv":
        return read_opk_csv(p)
    if suffix == ".zip":
        return read_micmac_zip(p)
    if suffix == ".xml":
        if p.name.startswith(MICMAC_PREFIX):
            pose = read_micmac_orientation(p)
            return OrientationSet(poses=[pose], format="micmac", frame="MicMac frame")
        return read_metashape_cameras(p)
    raise FormatError(p, f"unknown orientation format {suffix!r} (expected a folder, .json, .txt, .xml, .csv, .zip)")
