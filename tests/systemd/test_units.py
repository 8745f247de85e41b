"""The systemd units are source code: required directives present, and `systemd-analyze verify` clean."""

from __future__ import annotations

import configparser
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from onboard.recorder.cli import EXIT_USAGE
from onboard.recorder.daemon import EXIT_DISK_FULL

SYSTEMD_DIR = Path(__file__).resolve().parents[2] / "systemd"
RECORDER = SYSTEMD_DIR / "directgeo-recorder.service"
WEB = SYSTEMD_DIR / "directgeo-web.service"
UPLOAD = SYSTEMD_DIR / "directgeo-upload.service"


def unit(path: Path) -> configparser.RawConfigParser:
    parser = configparser.RawConfigParser(strict=False, interpolation=None)
    parser.optionxform = str  # type: ignore[assignment,method-assign]
    parser.read(path)
    return parser


def test_recorder_unit_directives() -> None:
    u = unit(RECORDER)
    svc = u["Service"]
    assert svc["Type"] == "notify"
    assert svc["WatchdogSec"].endswith("s") and int(svc["WatchdogSec"][:-1]) >= 10
    assert svc["Restart"] == "on-failure"
    # a bad configuration (2) fails the same way again; below the disk floor (3) a restart cannot record;
    # a runtime failure (1) is restarted
    assert set(svc["RestartPreventExitStatus"].split()) == {str(EXIT_USAGE), str(EXIT_DISK_FULL)} == {"2", "3"}
    assert svc["User"] == "directgeo" and svc["User"] != "root"
    assert set(svc["SupplementaryGroups"].split()) == {"dialout", "gpio"}
    for key, value in {"ProtectSystem": "strict", "NoNewPrivileges": "yes", "PrivateTmp": "yes",
                       "ProtectHome": "yes", "RuntimeDirectory": "directgeo"}.items():
        assert svc[key] == value, key
    assert "/var/lib/directgeo" in svc["ReadWritePaths"] and "/run/directgeo" in svc["ReadWritePaths"]
    assert "python -m onboard run" in svc["ExecStart"]


def test_web_unit_after_not_requires_recorder() -> None:
    u = unit(WEB)
    assert "directgeo-recorder.service" in u["Unit"]["After"]
    for key in ("Requires", "BindsTo", "PartOf", "Requisite"):
        assert "directgeo-recorder" not in u["Unit"].get(key, ""), key
    assert u["Service"]["User"] not in ("root", "directgeo")  # the web user cannot touch the serial port
    assert "dialout" not in u["Service"].get("SupplementaryGroups", "")
    assert u["Service"]["Restart"] == "on-failure"
    assert u["Service"]["RestartPreventExitStatus"].split() == ["2"]  # usage/configuration: do not loop


def test_upload_unit_low_priority_after_not_requires_recorder() -> None:
    u = unit(UPLOAD)
    svc = u["Service"]
    assert "python -m onboard upload-daemon" in svc["ExecStart"]
    assert "directgeo-recorder.service" in u["Unit"]["After"] and "network-online.target" in u["Unit"]["After"]
    for key in ("Requires", "BindsTo", "PartOf", "Requisite"):
        assert "directgeo-recorder" not in u["Unit"].get(key, ""), key
    assert int(svc["Nice"]) >= 10 and svc["IOSchedulingClass"] == "idle"
    assert svc["Restart"] == "on-failure" and svc["RestartPreventExitStatus"].split() == [str(EXIT_USAGE)]
    assert svc["User"] == "directgeo"  # the recorder's user: it reads (and may delete) the flights
    assert "/var/lib/directgeo" in svc["ReadWritePaths"] and "/run/directgeo" in svc["ReadWritePaths"]
    assert svc["ProtectSystem"] == "strict" and svc["NoNewPrivileges"] == "yes"
    assert "PrivateNetwork" not in svc  # it talks to the ground app


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze is not installed here")
@pytest.mark.parametrize("path", [RECORDER, WEB, UPLOAD], ids=lambda p: p.name)
def test_systemd_analyze_verify(tmp_path: Path, path: Path) -> None:
    """Verify a copy whose interpreter path points at this virtualenv (verify checks ExecStart exists)."""
    text = path.read_text().replace("/opt/directgeo/.venv/bin/python", sys.executable)
    copy = tmp_path / path.name
    copy.write_text(text)
    proc = subprocess.run(["systemd-analyze", "verify", "--man=no", str(copy)], capture_output=True, text=True,
                          timeout=60, check=False)
    # Complaints about *our* unit fail the test; noise about unrelated host units does not.
    ours = [line for line in (proc.stdout + proc.stderr).splitlines() if path.name in line]
    assert proc.returncode == 0 and not ours, proc.stdout + proc.stderr
