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
GROUND = SYSTEMD_DIR / "directgeo-ground.service"
WORKER = SYSTEMD_DIR / "directgeo-worker@.service"


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


def test_ground_unit_serves_with_its_queue_and_a_credential_token() -> None:
    from ground.cli import EXIT_USAGE as GROUND_EXIT_USAGE

    svc = unit(GROUND)["Service"]
    assert "python -m ground serve" in svc["ExecStart"] and "--queue ${DIRECTGEO_QUEUE}" in svc["ExecStart"]
    assert svc["Environment"] == "DIRECTGEO_QUEUE=inprocess"  # one machine needs no configuration file
    assert svc["EnvironmentFile"].startswith("-")  # optional: the fleet's DATABASE_URL and queue
    assert "--token-file %d/ground.token" in svc["ExecStart"] and svc["LoadCredential"].startswith("ground.token:")
    assert "--data-dir /var/lib/directgeo-ground" in svc["ExecStart"] and svc["StateDirectory"] == "directgeo-ground"
    assert svc["User"] == "directgeo-ground" and svc["ProtectSystem"] == "strict" and svc["NoNewPrivileges"] == "yes"
    assert svc["Restart"] == "on-failure" and svc["RestartPreventExitStatus"].split() == [str(GROUND_EXIT_USAGE)]
    assert svc["KillMode"] == "mixed"  # SIGTERM to the server only: in-process jobs are waited for


def test_worker_template_is_stateless_and_lets_its_job_finish() -> None:
    from ground.cli import EXIT_USAGE as GROUND_EXIT_USAGE

    u = unit(WORKER)
    svc = u["Service"]
    assert "python -m ground worker" in svc["ExecStart"] and "--api ${DIRECTGEO_API}" in svc["ExecStart"]
    assert "--cache-dir /var/cache/directgeo-worker/%i" in svc["ExecStart"]
    assert svc["CacheDirectory"] == "directgeo-worker/%i" and svc["DynamicUser"] == "yes"
    assert "--token-file %d/worker.token" in svc["ExecStart"] and svc["LoadCredential"].startswith("worker.token:")
    assert svc["EnvironmentFile"] == "/etc/directgeo/worker.env"  # DATABASE_URL and DIRECTGEO_API are required
    # the running job is not signalled: SIGTERM reaches the worker alone, which finishes the job first
    assert svc["KillMode"] == "mixed"
    assert svc["Restart"] == "on-failure" and svc["RestartPreventExitStatus"].split() == [str(GROUND_EXIT_USAGE)]
    assert "directgeo-ground.service" in u["Unit"]["After"]
    for key in ("Requires", "BindsTo", "PartOf", "Requisite"):  # the API may live on another machine
        assert "directgeo-ground" not in u["Unit"].get(key, ""), key


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze is not installed here")
@pytest.mark.parametrize("path", [RECORDER, WEB, UPLOAD, GROUND, WORKER], ids=lambda p: p.name)
def test_systemd_analyze_verify(tmp_path: Path, path: Path) -> None:
    """Verify a copy whose interpreter path points at this virtualenv (verify checks ExecStart exists)."""
    text = path.read_text().replace("/opt/directgeo/.venv/bin/python", sys.executable)
    copy = tmp_path / path.name.replace("@.", "@1.")  # a template is verified as one of its instances
    copy.write_text(text)
    proc = subprocess.run(["systemd-analyze", "verify", "--man=no", str(copy)], capture_output=True, text=True,
                          timeout=60, check=False)
    # Complaints about *our* unit fail the test; noise about unrelated host units does not.
    ours = [line for line in (proc.stdout + proc.stderr).splitlines() if path.name in line]
    assert proc.returncode == 0 and not ours, proc.stdout + proc.stderr
