"""The README's first command: the whole product on a simulated flight (ground server, base station, companion
with real-time RTK over GPS_RTCM_DATA and the autopilot link, pre-flight go, upload, ground jobs, report)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from hil_sim.mission import RTK_COLD

PROJECT = Path(__file__).resolve().parents[2]
pytestmark = [pytest.mark.slow, pytest.mark.timeout(900)]

STAGES = ("record rover", "record base", "pre-flight go", "autopilot link", "pair pulses and flashes", "upload",
          "corrections: base → radio → GPS_RTCM_DATA → companion", "real-time RTK (onboard, corrections over MAVLink)",
          RTK_COLD, "final adjustment", "RINEX conversion")


def test_the_demo_flies_uploads_and_processes_every_stage(tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, "-m", "hil_sim", "flight", "--out", str(tmp_path)],
                          cwd=PROJECT, capture_output=True, text=True, timeout=880, check=False)
    out = proc.stdout + proc.stderr
    (summary_path,) = tmp_path.glob("flight-*/summary.json")
    stages = {s["name"]: s for s in json.loads(summary_path.read_text())}
    assert f"summary: {summary_path}" in out
    assert list(stages) == list(STAGES), out[-3000:]
    for name, stage in stages.items():
        assert stage["ok"], (name, stage["summary"], out[-3000:])
    assert proc.returncode == 0
    assert stages["pre-flight go"]["figures"]["go_s"] < stages["pre-flight go"]["figures"]["arm_planned_s"]
    assert stages["upload"]["figures"]["differ"] == []  # every file byte-identical on the server
    # closed by the companion after landing and uploaded by its upload daemon: no command ran the uploader
    assert stages["upload"]["figures"]["automatic"] is True
    assert "flight_over" in stages["autopilot link"]["figures"]["events"]
    realtime, ground = stages["real-time RTK (onboard, corrections over MAVLink)"], stages[RTK_COLD]
    for rtk in (realtime, ground):
        assert rtk["figures"]["epochs"] > 500 and rtk["figures"]["wrong_fixes"] == 0, rtk["summary"]
        assert rtk["figures"]["airborne_fix_ratio"] > 0.9, rtk["summary"]
    assert stages["corrections: base → radio → GPS_RTCM_DATA → companion"]["figures"]["foreign_messages"] == 0
    pairing = stages["pair pulses and flashes"]["figures"]
    assert pairing["missing"] == 0 and pairing["max_delay_error_ns"] <= 1000
    assert abs(pairing["mean_delay_ms"] - pairing["true_mean_delay_ms"]) < 0.001  # ms: within 1 µs
    adjustment = stages["final adjustment"]
    # the ground jobs ran on the drone's own uploaded flight, radio/ corrections included, no processing set
    drone_flight = stages["upload"]["figures"]["server_flight_id"]
    assert "radio/000000.ubx" in stages["upload"]["figures"]["sub_folder_files"]
    assert adjustment["figures"]["flight"] == drone_flight
    assert ground["outputs"]["server_flight"].endswith(f"/flights/{drone_flight}")
    assert adjustment["figures"]["checkpoint_rms_m"]["3d"] <= 0.03
    assert abs(adjustment["figures"]["delay_s"] - adjustment["figures"]["true_delay_s"]) < 0.002
    report = Path(adjustment["outputs"]["report"])
    assert report.stat().st_size > 1000 and "<html" in report.read_text()[:500].lower()
