"""The camera cross-check in the autopilot link: the hil_sim stand-in's CAMERA_FEEDBACK (boot µs, mapped to GPS
time by SYSTEM_TIME) beside flash marks handed in as the recorder hands TIM-TM2 marks; camera_check records
with the stand-in's attitude at each exposure, and the counts in the link's snapshot (autopilot.json)."""

from __future__ import annotations

import datetime as dt
import math
import time
from pathlib import Path
from typing import Any

import pytest

from hil_sim.autopilot import AutopilotSimOptions
from onboard.gnsstime import GpsTime
from onboard.rtk.types import CameraMark
from tests.autopilot.harness import Joined

pytestmark = pytest.mark.timeout(120)
SHUTTER_DELAY_S = 0.08


@pytest.mark.slow
def test_feedback_and_flashes_cross_checked_with_attitude(tmp_path: Path) -> None:
    sim = AutopilotSimOptions(arm_at_s=2.0, spool_s=1.0, takeoff_s=2.0, survey_s=14.0, camera_period_s=2.0)
    flashes: dict[int, float] = {}  # img_idx → sim time of its flash
    checks: list[dict[str, Any]] = []
    j = Joined(tmp_path, sim, speed=4.0)
    j.link.camera_sink = checks.append  # the recorder's events.jsonl (AutopilotFeature passes its appender)
    with j:
        utc0 = j.core.utc_start
        deadline = time.monotonic() + 40
        seen = 0
        while time.monotonic() < deadline and seen < 6:
            last = j.link.snapshot()["last_camera_feedback"]
            if last is not None and last["img_idx"] not in flashes:
                seen += 1
                t_flash = last["time_usec"] / 1e6 + SHUTTER_DELAY_S
                flashes[last["img_idx"]] = t_flash
                if seen % 3 != 0:  # every third image loses its flash (a hot-shoe cable fault)
                    gpst = GpsTime.from_utc(utc0 + dt.timedelta(seconds=t_flash))
                    j.link.on_flash_marks([CameraMark(0, "falling", seen, gpst, 20, 1, True)])
            time.sleep(0.02)
        assert seen == 6, f"only {seen} CAMERA_FEEDBACK"
        time.sleep(0.8)  # > decide_after at 4×: the last ones are decided before the end
        snap = j.link.snapshot()
    assert all(c["kind"] == "camera_check" for c in checks)
    assert not any(e.get("kind") == "camera_check" for e in j.events)  # lifecycle events stay apart
    matched = [c for c in checks if c["result"] == "matched"]
    lost = [c for c in checks if c["result"] == "shot_without_flash"]
    assert len(matched) >= 4 and len(lost) >= 2, checks
    assert {c["shot_index"] for c in lost} >= {idx for k, idx in enumerate(flashes, 1) if k % 3 == 0}
    for c in matched:
        assert c["shot_source"] == "CAMERA_FEEDBACK"
        assert abs(c["delay_ns"] - SHUTTER_DELAY_S * 1e9) < 2e6  # ms-resolution boot time mapping
        t = flashes[c["shot_index"]]
        if any(j.core.flight.phase(t + dt_s)[1] != 2 for dt_s in (-0.3, 0.3)):
            continue  # the stand-in's roll jumps to 0 off the survey lines: no interpolation holds there
        pose = j.core.flight.pose(t)
        assert c["roll_deg"] == pytest.approx(math.degrees(pose.roll_rad), abs=0.5)
        assert c["pitch_deg"] == pytest.approx(math.degrees(pose.pitch_rad), abs=0.5)
        dyaw = (c["yaw_deg"] - math.degrees(pose.yaw_rad) + 180) % 360 - 180
        assert abs(dyaw) < 1.0
    cc = snap["camera_check"]
    assert cc["shots"] >= 6 and cc["matched"] >= 4 and cc["shots_without_flash"] >= 1
    assert cc["last_delay_ms"] == pytest.approx(80.0, abs=2.0)
