"""A MicMac `Ori-*` folder sent as one .zip (how the web form and the API carry it: a flight file is one file):
read exactly as the folder, refusals in words naming the archive's member."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pytest

from ground.adjust.types import CameraPose
from ground.io.errors import FormatError
from ground.io.orientations import read_micmac_folder, read_orientations, write_micmac_orientation
from ground.io.rotations import r_cam_to_world_from_opk_deg


def micmac_zip(poses: list[CameraPose], folder: Path, archive: Path) -> Path:
    """Write the poses as a MicMac Ori folder and zip it (members under `Ori-Test/`, as `zip -r` makes)."""
    folder.mkdir(parents=True)
    for p in poses:
        write_micmac_orientation(folder / f"Orientation-{p.image}.xml", p)
    with zipfile.ZipFile(archive, "w") as zf:
        for f in sorted(folder.iterdir()):
            zf.write(f, f"Ori-Test/{f.name}")
        zf.writestr("Ori-Test/AutoCal_Foc-24000_Cam-X.xml", "<ExportAPERO/>")  # other files: ignored
    return archive


def _poses() -> list[CameraPose]:
    return [CameraPose(f"IMG_{i:04d}.JPG", np.array([1.0 * i, -2.0, 100.0 + i]),
                       r_cam_to_world_from_opk_deg(1.0 * i, -2.0, 30.0 * i)) for i in range(5)]


def test_zip_reads_as_the_folder(tmp_path: Path) -> None:
    z = micmac_zip(_poses(), tmp_path / "Ori-Test", tmp_path / "ori.zip")
    got, ref = read_orientations(z), read_micmac_folder(tmp_path / "Ori-Test")
    assert got.format == "micmac" and [p.image for p in got.poses] == [p.image for p in ref.poses]
    for a, b in zip(got.poses, ref.poses):
        np.testing.assert_array_equal(a.centre_rel, b.centre_rel)
        np.testing.assert_array_equal(a.r_cam_to_rel, b.r_cam_to_rel)


def test_zip_refusals_in_words(tmp_path: Path) -> None:
    bad = tmp_path / "bad.zip"
    bad.write_bytes(b"not a zip at all")
    with pytest.raises(FormatError, match="not a readable zip archive"):
        read_orientations(bad)
    empty = tmp_path / "empty.zip"
    with zipfile.ZipFile(empty, "w") as zf:
        zf.writestr("readme.txt", "no orientations")
    with pytest.raises(FormatError, match="no Orientation-"):
        read_orientations(empty)
    twice = tmp_path / "twice.zip"
    with zipfile.ZipFile(twice, "w") as zf:
        zf.writestr("a/Orientation-X.JPG.xml", "<x/>")
        zf.writestr("b/Orientation-X.JPG.xml", "<x/>")
    with pytest.raises(FormatError, match="appears twice"):
        read_orientations(twice)
    broken = tmp_path / "broken.zip"
    with zipfile.ZipFile(broken, "w") as zf:
        zf.writestr("Ori-X/Orientation-IMG_1.JPG.xml", "<OrientationConique><Externe/></OrientationConique>")
    with pytest.raises(FormatError) as exc:
        read_orientations(broken)
    text = str(exc.value)
    assert text.startswith(str(broken)) and text.endswith("broken.zip: Orientation-IMG_1.JPG.xml: missing Centre")
    assert "/tmp/micmac-" not in text
