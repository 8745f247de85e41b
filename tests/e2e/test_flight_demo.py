"""The README's first command, shortened: a simulated flight through the real daemon, RTK and adjustment."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from hil_sim.mission import RTK_COLD, RTK_SEEDED

PROJECT = Path(__file__).resolve().parents[2]
pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]


def test_short_flight_runs_every_stage(tmp_path: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "hil_sim", "flight", "--flight-s", "150", "--speed", "8", "--out", str(tmp_path)],
        cwd=PROJECT, capture_output=True, text=True, timeout=580, check=False,
    )
    out = proc.stdout + proc.stderr
    (summary_path,) = tmp_path.glob("flight-*/summary.json")
    stages = {s["name"]: s for s in json.loads(summary_path.read_text())}
    assert f"summary: {summary_path}" in out
    for name in ("record rover", "record base", "pair pulses and flashes", "RINEX conversion"):
        assert stages[name]["ok"], (name, stages[name]["summary"], out[-2000:])
    pairing = stages["pair pulses and flashes"]["figures"]
    assert pairing["missing"] == 0 and pairing["max_delay_error_ns"] <= 1000
    # the headline figures are a cold start; the seeded run is a second, labelled stage with its own trajectory
    cold, seeded = stages[RTK_COLD], stages[RTK_SEEDED]
    for rtk in (cold, seeded):
        assert rtk["figures"]["epochs"] > 200 and rtk["figures"]["wrong_fixes"] == 0, rtk["summary"]
        assert Path(rtk["outputs"]["trajectory"]).exists()
    assert cold["outputs"]["trajectory"] != seeded["outputs"]["trajectory"]
    assert f"] {RTK_SEEDED}: " in out  # printed under its label, which says where the seed came from
    assert "final adjustment" in stages
