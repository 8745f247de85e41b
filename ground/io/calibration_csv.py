"""Reader of the lever-arm ground-calibration CSV (input of `ground.adjust.calibration.calibrate_lever_arm`).

Format (UTF-8, comma-separated, metres; lines starting with '#' and blank lines are ignored)::

    target,group,x,y,z
    C1,camera_frame,0.031,-0.012,0.004     # camera target in the calibrated camera frame (x right, y down, z fwd)
    C1,camera_acq,12.410,3.221,0.871        # the same target in this acquisition's frame
    B1,box_frame,0.020,0.015,0.000          # receiver-box target in the box frame
    B1,box_acq,12.502,3.108,0.902           # the same target in this acquisition's frame
    phase_centre,box_frame,0.000,0.000,0.012  # antenna phase centre in the box frame (exactly one such row)

Groups: camera_frame, camera_acq, box_frame, box_acq (a `phase_centre` group is accepted for the phase-centre row
too). One file holds one acquisition; compare two acquisitions with two files. Every error names the file and
line; nothing is guessed.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from ground.adjust.calibration import CalibrationInput
from ground.io.errors import FormatError

GROUPS = ("camera_frame", "camera_acq", "box_frame", "box_acq")
PHASE_CENTRE = "phase_centre"
HEADER = ("target", "group", "x", "y", "z")


def read_calibration_csv(path: str | Path) -> CalibrationInput:
    """Read one acquisition's calibration targets; raises FormatError (file:line: detail) on any bad row."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise FormatError(p, f"not UTF-8 text ({exc.reason})") from exc
    groups: dict[str, dict[str, np.ndarray]] = {g: {} for g in GROUPS}
    phase: np.ndarray | None = None
    header_seen = False
    rows = [
        (i + 1, line)
        for i, line in enumerate(text.splitlines())
        if line.strip() and not line.lstrip().startswith("#")
    ]
    for lineno, row in ((n, next(csv.reader([line]))) for n, line in rows):
        cells = [c.strip() for c in row]
        if not header_seen:
            if tuple(c.lower() for c in cells[:5]) != HEADER:
                raise FormatError(
                    p, f"first row must be the header {','.join(HEADER)}; got {','.join(cells)}", lineno
                )
            header_seen = True
            continue
        if len(cells) < 5:
            raise FormatError(p, f"expected 5 fields target,group,x,y,z; got {len(cells)}", lineno)
        target, group = cells[0], cells[1].lower()
        if not target:
            raise FormatError(p, "empty target name", lineno)
        try:
            xyz = np.array([float(c) for c in cells[2:5]])
        except ValueError as exc:
            raise FormatError(p, f"coordinates must be numbers in metres ({exc})", lineno) from exc
        if not all(math.isfinite(v) for v in xyz):
            raise FormatError(p, "coordinates must be finite", lineno)
        if target == PHASE_CENTRE or group == PHASE_CENTRE:
            if group not in ("box_frame", PHASE_CENTRE):
                raise FormatError(
                    p, f"the phase centre must be given in the box frame, not '{group}'", lineno
                )
            if phase is not None:
                raise FormatError(p, "more than one phase_centre row", lineno)
            phase = xyz
            continue
        if group not in groups:
            raise FormatError(p, f"unknown group '{cells[1]}' (expected one of {', '.join(GROUPS)})", lineno)
        if target in groups[group]:
            raise FormatError(p, f"target '{target}' appears twice in group {group}", lineno)
        groups[group][target] = xyz
    if not header_seen:
        raise FormatError(p, "empty file: no header and no target")
    if phase is None:
        raise FormatError(p, "no phase_centre row (the antenna phase centre in the box frame)")
    for g in GROUPS:
        if not groups[g]:
            raise FormatError(p, f"no target in group {g}")
    return CalibrationInput(
        camera_frame=groups["camera_frame"],
        camera_acq=groups["camera_acq"],
        box_acq=groups["box_acq"],
        box_frame=groups["box_frame"],
        phase_centre_box_m=phase,
    )
