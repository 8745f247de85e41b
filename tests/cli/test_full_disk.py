"""A full disk while `rtk` and `convert` write: the previous good output survives, the error is one line, exit 1.

Each test mounts a 64 KiB tmpfs (root only: skipped with that reason otherwise), leaves a previous good output
in it, fills the rest, and runs the command again into it (issue 14 case 6: a truncated `clean.obs` beside the
old `clean.nav` under the final names, before).
"""

from __future__ import annotations

import os
import subprocess
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from onboard.__main__ import main
from onboard.gnsstime import GpsTime
from onboard.postpro import rtk_cli
from onboard.rtk.types import Q_FIX, Solution
from tests.conftest import shared_file

GEONET = "gnss/geonet-0759-3040-20050402/"
BASE_3040 = "-3978241.958,3382840.234,3649900.853"
POS = np.array([-3976219.1873, 3382371.6051, 3652511.1423])


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[Path]:
    """A 64 KiB tmpfs mounted at a fresh directory (unmounted afterwards)."""
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root (the full-disk tests run as root in CI)")
    mnt = tmp_path / "disk"
    mnt.mkdir()
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mnt)], check=True)
    try:
        yield mnt
    finally:
        subprocess.run(["umount", str(mnt)], check=True)


def _fill(disk: Path, leave_bytes: int) -> None:
    st = os.statvfs(disk)
    free = st.f_bavail * st.f_frsize
    (disk / "filler").write_bytes(bytes(max(free - leave_bytes, 0)))


def _solutions(n: int) -> list[Solution]:
    cov = np.eye(3) * 1e-4
    return [Solution(GpsTime.from_week_tow_s(1316, 518400.0 + k), POS + [0.001 * k, 0, 0], np.zeros(3), Q_FIX, 8,
                     cov, cov, 0.5, 3.0) for k in range(n)]


def test_rtk_on_a_full_disk_keeps_the_previous_pos(small_disk: Path, monkeypatch: pytest.MonkeyPatch,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    args = ["rtk", "--rover", str(shared_file(GEONET + "07590920.05o.gz")),
            "--base", str(shared_file(GEONET + "30400920.05o.gz")),
            "--nav", str(shared_file(GEONET + "07590920.05n.gz")), f"--base-pos={BASE_3040}"]
    out = small_disk / "rover.pos"
    monkeypatch.setattr(rtk_cli, "postprocess", lambda *a, **k: (_solutions(50), []))
    assert main([*args, "-o", str(out)]) == 0
    previous = out.read_bytes()
    _fill(small_disk, 8192)
    monkeypatch.setattr(rtk_cli, "postprocess", lambda *a, **k: (_solutions(600), []))  # ~90 KB: does not fit
    assert main([*args, "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert err.strip().splitlines()[-1] == (f"directgeo: rtk: error: cannot write {out}: No space left on device "
                                            "(the previous file is unchanged)")
    assert out.read_bytes() == previous
    assert sorted(p.name for p in small_disk.iterdir()) == ["filler", "rover.pos"]  # no temporary file left


def test_convert_on_a_full_disk_keeps_the_previous_pair(small_disk: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = shared_file("ubx/gpsd_ublox-neo-m8t.log")
    assert main(["convert", str(log), "-o", str(small_disk), "--no-progress"]) == 0
    obs, nav = small_disk / "gpsd_ublox-neo-m8t.obs", small_disk / "gpsd_ublox-neo-m8t.nav"
    before = obs.read_bytes(), nav.read_bytes()
    _fill(small_disk, 4096)
    assert main(["convert", str(log), "-o", str(small_disk), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err
    last = err.strip().splitlines()[-1]
    assert last == (f"directgeo: convert: error: cannot write gpsd_ublox-neo-m8t.obs/.nav in {small_disk}: "
                    "No space left on device (the previous files, if any, are unchanged)")
    assert (obs.read_bytes(), nav.read_bytes()) == before
    assert sorted(p.name for p in small_disk.iterdir()) == ["filler", nav.name, obs.name]
