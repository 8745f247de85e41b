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


def _feature_without_link(tmp_path: Path) -> tuple[Any, list[dict[str, Any]]]:
    """An AutopilotFeature opened on a flight whose link never opens (no autopilot on the wire), its
    events.jsonl a list and the recorder's loop run inline; the camera check is fed directly."""
    from onboard.autopilot.feature import AutopilotFeature, AutopilotOptions
    from onboard.errors import LinkLost
    from onboard.hw.fake import ManualClock
    from onboard.logger.journal import JournalOptions
    from onboard.recorder.feature import FlightContext

    def no_link() -> Any:
        raise LinkLost("no autopilot")

    events: list[dict[str, Any]] = []
    clock = ManualClock()
    feature = AutopilotFeature(AutopilotOptions(reopen_s=0.05), no_link, clock)
    feature.on_flight_opened(FlightContext(tmp_path, clock, JournalOptions(), tmp_path / "status.json",
                                           post=lambda fn, *a: fn(*a), request_stop=lambda *a: None,
                                           append_event=events.append))
    return feature, events


def _shot_and_flash(feature: Any, at: GpsTime, flash: bool = True) -> None:
    from onboard.autopilot.camera import CameraShot
    from onboard.receiver.decode import TimeMarks

    assert feature.link is not None
    with feature.link._lock:
        feature.link.camera.add_shot(CameraShot("CAMERA_FEEDBACK", 1, at))
    if flash:
        mark = CameraMark(0, "falling", 1, at.add_s(SHUTTER_DELAY_S), 20, 1, True)
        feature.on_decoded(TimeMarks(0, 1, (mark,), 0))


def test_the_last_camera_checks_are_written_when_the_recording_stops(tmp_path: Path) -> None:
    """A shot and its flash within the last `decide_after_ns` before a stop, and a shot whose flash never came:
    both decided and in the flight's event log when it closes (the log is still open at on_flight_closing)."""
    feature, events = _feature_without_link(tmp_path)
    t = GpsTime(2300, 100 * 10**9)
    _shot_and_flash(feature, t)
    _shot_and_flash(feature, t.add_s(2.0), flash=False)
    assert [e for e in events if e.get("kind") == "camera_check"] == []  # undecided: a partner may still come
    feature.on_flight_closing("test stop")
    checks = [e for e in events if e.get("kind") == "camera_check"]
    assert [c["result"] for c in checks] == ["matched", "shot_without_flash"]
    assert checks[0]["delay_ns"] == round(SHUTTER_DELAY_S * 1e9)
    feature.on_flight_closed("test stop")
    assert feature.link is not None and feature.link._thread is not None and not feature.link._thread.is_alive()


def test_a_rollover_keeps_undecided_checks_for_the_next_flight(tmp_path: Path) -> None:
    """At a roll-over recording goes on: a shot whose flash mark may still come is not decided (it would be a
    false "no flash" here and a false "no shot" in the next flight); it is decided when its flash arrives."""
    from onboard.recorder.feature import rollover_reason

    feature, events = _feature_without_link(tmp_path)
    t = GpsTime(2300, 100 * 10**9)
    _shot_and_flash(feature, t, flash=False)
    feature.on_flight_closing(rollover_reason("test"))
    assert [e for e in events if e.get("kind") == "camera_check"] == []
    from onboard.receiver.decode import TimeMarks

    feature.on_decoded(TimeMarks(0, 1, (CameraMark(0, "falling", 1, t.add_s(SHUTTER_DELAY_S), 20, 1, True),), 0))
    _shot_and_flash(feature, t.add_s(4.0))  # time moves on past the first shot's decision horizon
    checks = [e for e in events if e.get("kind") == "camera_check"]
    assert [c["result"] for c in checks] == ["matched"] and checks[0]["shot_tow_ns"] == t.tow_ns
    feature.on_flight_closing("test stop")
    feature.on_flight_closed("test stop")
