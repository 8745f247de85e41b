"""`onboard rtk` with the M8P base's real RTCM3 stream as base (the lossy radio-like link), end to end."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from onboard.formats.pos import read_pos
from tests.conftest import shared_file

PROJECT = Path(__file__).resolve().parents[2]
M8P = "gnss/ublox-m8p-galway-2018"
ROVER_REF_ECEF_M = np.array([3774088.9931, -601661.8217, 5089321.3853])  # mean of the M8P's own RTK fixes


@pytest.mark.slow
def test_rtcm3_stream_as_base(tmp_path: Path) -> None:
    rover = shared_file(f"{M8P}/raw/rover-20181004-1237.ubx.gz")
    base = shared_file(f"{M8P}/rtcm3/base-20181004-1236.rtcm3.gz")
    nav = shared_file(f"{M8P}/rinex/rover-20181004-1237.nav.gz")
    out = tmp_path / "m8p.pos"
    proc = subprocess.run(
        [sys.executable, "-m", "onboard", "rtk", "--rover", str(rover), "--base", str(base), "--nav", str(nav),
         "--no-progress", "-o", str(out)],
        cwd=PROJECT, capture_output=True, text=True, timeout=600, check=False,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    track = read_pos(out)
    fixed = track.q == 1
    assert len(track.q) > 1000 and fixed.mean() > 0.85, proc.stdout
    # base position taken from the stream's RTCM 1005: fixed epochs sit on the receiver's own RTK mean
    err = np.linalg.norm(track.pos_ecef_m[fixed] - ROVER_REF_ECEF_M, axis=1)
    assert np.all(err < 0.10)


def test_rtcm_stream_without_rover_time_is_refused(tmp_path: Path) -> None:
    base = shared_file(f"{M8P}/rtcm3/base-20181004-1236.rtcm3.gz")
    empty = tmp_path / "empty.ubx"
    empty.write_bytes(b"")
    proc = subprocess.run(
        [sys.executable, "-m", "onboard", "rtk", "--rover", str(empty), "--base", str(base), "-o",
         str(tmp_path / "x.pos")], cwd=PROJECT, capture_output=True, text=True, timeout=120, check=False,
    )
    assert proc.returncode == 2 and "error" in proc.stderr and "Traceback" not in proc.stderr
