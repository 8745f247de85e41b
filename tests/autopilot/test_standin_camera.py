"""The stand-in's CAMERA_FEEDBACK in a combined run: one per trigger of the simulated receiver's camera (fed as
`hil_sim.receiver.ReceiverCore.on_camera_pulse` feeds it), stamped as ArduPilot stamps a trigger (UTC µs from
its GPS at the trigger, img_idx counting up, attitude at the trigger), sent a little later; none for a trigger
during a reboot."""

from __future__ import annotations

import math
from typing import Any

from hil_sim.autopilot import AutopilotCore, AutopilotSimOptions, MissionFlight
from hil_sim.camera import camera_events
from hil_sim.scenario import CameraPlan, Scenario
from onboard.autopilot.camera import camera_time_gpst


def _ask_for_camera_feedback(core: AutopilotCore, t: float) -> None:
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    core.receive(mav.command_long_encode(1, 1, 511, 0, 180, 1e6, 0, 0, 0, 0, 0).pack(mav), t)


def _feedback(frames: list[bytes]) -> list[Any]:
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    parser = mavlink.MAVLink(None)
    return [m for f in frames for m in parser.parse_buffer(f) or [] if m.get_type() == "CAMERA_FEEDBACK"]


def _fly(core: AutopilotCore, scenario: Scenario, until_s: float, from_s: float = 0.0) -> list[Any]:
    """Step the core every 10 ms of simulated time, handing it the camera's triggers as the receiver would."""
    plan = scenario.camera
    events = camera_events(plan, scenario.start.add_s(from_s), scenario.start.add_s(until_s),
                           scenario.start.add_s(plan.valid_after_s), scenario.seed)
    got: list[Any] = []
    t = from_s
    for n in range(round((until_s - from_s) * 100) + 50):
        t = from_s + n / 100
        while events and events[0].pulse_time.diff_s(scenario.start) <= t:
            core.camera_trigger(events.pop(0))
        got += _feedback(core.step(t))
    return got


def test_one_feedback_per_receiver_trigger_at_its_utc_with_attitude() -> None:
    scenario = Scenario.default(camera=CameraPlan(period_s=2.0, valid_after_s=20.0, missed_flash_probability=0.3))
    mission = MissionFlight(scenario)
    core = AutopilotCore(AutopilotSimOptions(gcs_heartbeat=False, camera_from_receiver=True), mission)
    _ask_for_camera_feedback(core, 0.0)
    start_s, end_s = mission.traj.takeoff_s, mission.traj.takeoff_s + 60.0
    got = _fly(core, scenario, end_s, from_s=start_s)
    plan = scenario.camera
    truth = camera_events(plan, scenario.start.add_s(start_s), scenario.start.add_s(end_s),
                          scenario.start.add_s(plan.valid_after_s), scenario.seed)
    assert len(truth) == 30 and len(got) == len(truth)  # missed flashes too: the autopilot triggered them
    assert sum(ev.flash_time is None for ev in truth) >= 3
    assert [m.img_idx for m in got] == list(range(1, len(truth) + 1))
    report = core.report()["camera"]
    assert report["triggers"] == report["feedback_sent"] == len(truth)
    assert report["without_flash"] == sum(ev.flash_time is None for ev in truth)
    for msg, ev in zip(got, truth, strict=True):
        assert msg.time_usec > 10**15  # UNIX-epoch µs, as ArduPilot stamps an image from its GPS
        stamped = camera_time_gpst(msg.time_usec, lambda ms: None)
        assert stamped is not None and abs(stamped.diff_s(ev.pulse_time)) < 0.006  # ms-accurate GPS time
        pose = mission.pose(ev.pulse_time.diff_s(scenario.start))
        assert math.isclose(msg.roll, math.degrees(pose.roll_rad), abs_tol=1e-3)
        assert math.isclose(msg.yaw, math.degrees(pose.yaw_rad), abs_tol=1e-3)
        assert abs(msg.lat / 1e7 - pose.lat_deg) < 2e-7


def test_a_trigger_during_a_reboot_is_not_reported_and_the_index_restarts() -> None:
    scenario = Scenario.default(camera=CameraPlan(period_s=2.0, valid_after_s=20.0))
    reboot_s = 31.0
    core = AutopilotCore(AutopilotSimOptions(gcs_heartbeat=False, camera_from_receiver=True,
                                             reboot_at_s=(reboot_s,), reboot_silence_s=2.5),
                         MissionFlight(scenario))
    _ask_for_camera_feedback(core, 0.0)
    before = _fly(core, scenario, reboot_s - 0.01)
    _ask_for_camera_feedback(core, reboot_s + 3.0)  # the companion asks again after the reboot
    after = _fly(core, scenario, 40.0, from_s=reboot_s)
    assert [m.img_idx for m in before] == list(range(1, len(before) + 1)) and len(before) == 6
    assert core.report()["camera"]["unseen_in_reboot"] == 1  # the pulse in the 2.5 s of silence
    assert after[0].img_idx == 1
    # still UTC from the autopilot's GPS after the reboot (not µs since the new boot)
    assert all(m.time_usec > 10**15 for m in before + after)
