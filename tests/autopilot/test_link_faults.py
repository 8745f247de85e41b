"""The companion's autopilot link against the hil_sim stand-in, in memory: our heartbeat and stream requests,
a ground station's heartbeat ignored, reboot, heartbeat stop, link loss, MAVLink 1 only, corrections."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from hil_sim.autopilot import AutopilotSimOptions
from onboard.autopilot.corrections import CorrectionsPipe
from onboard.autopilot.feature import STREAMS
from tests.autopilot.harness import Joined
from tests.autopilot.rtcm_frames import rtcm_frame

pytestmark = pytest.mark.timeout(120)
QUICK = AutopilotSimOptions(arm_at_s=4.0, spool_s=1.0, takeoff_s=2.0, survey_s=8.0, landing_s=2.0,
                            disarm_after_s=2.0)


def requested_ids(core_report: dict, after_s: float = -1.0) -> set[int]:
    return {r["message_id"] for r in core_report["interval_requests"] if r["t_s"] > after_s}


@pytest.mark.slow
def test_heartbeat_streams_and_flight(tmp_path: Path) -> None:
    with Joined(tmp_path, QUICK) as j:
        snap = j.run_until(lambda s: s["landed_state"] == "in_air", 20, "in the air")
        assert snap["armed"] is True and snap["mode"] == "AUTO"
        j.run_until(lambda s: s["armed"] is False and s["flown"], 20, "landed and disarmed")
        report = j.core.report()
    assert [e["event"] for e in j.events] == ["armed", "takeoff", "landed", "disarmed"]
    assert all(e["gps_week"] is not None for e in j.events)  # SYSTEM_TIME came before arming
    ours = [h for h in report["heard_heartbeats"]]
    assert ours and all((h["system_id"], h["component_id"], h["type"], h["autopilot"]) == (1, 191, 18, 8)
                        for h in ours)
    assert requested_ids(report) == set(STREAMS.values())
    assert all(r["from"] == "1/191" for r in report["interval_requests"])
    assert report["other_messages"] == {}  # read-only: nothing but heartbeats and interval requests


@pytest.mark.slow
def test_ground_station_heartbeat_does_not_count(tmp_path: Path) -> None:
    """The stand-in forwards a GCS heartbeat (system 255, disarmed) between the autopilot's: armed never flaps."""
    sim = dataclasses.replace(QUICK, arm_at_s=1.0, survey_s=30.0)
    with Joined(tmp_path, sim) as j:
        j.run_until(lambda s: s["landed_state"] == "in_air", 20, "in the air")
        for _ in range(20):
            snap = j.run_until(lambda s: True, 1, "")
            assert snap["armed"] is True
    assert [e["event"] for e in j.events] == ["armed", "takeoff"]
    assert snap["autopilot"]["system_id"] == 1 and snap["packet_loss"] == 0.0


@pytest.mark.slow
def test_reboot_requests_streams_again(tmp_path: Path) -> None:
    sim = dataclasses.replace(QUICK, arm_at_s=100.0, reboot_at_s=(8.0,))
    with Joined(tmp_path, sim) as j:
        j.run_until(lambda s: s["attitude"] is not None, 10, "streams")
        snap = j.run_until(lambda s: s["reboots"] == 1 and s["time_synced"], 30, "reboot seen, streams back")
        report = j.core.report()
    assert snap["interval_requests"] >= 2
    assert requested_ids(report, after_s=8.0) == set(STREAMS.values())
    assert [e["event"] for e in j.events] == ["reboot"]


@pytest.mark.slow
def test_heartbeat_stop_link_down_then_back(tmp_path: Path) -> None:
    sim = dataclasses.replace(QUICK, arm_at_s=100.0, heartbeat_stop=((6.0, 10.0),))
    with Joined(tmp_path, sim) as j:
        j.run_until(lambda s: s["link_up"], 10, "link up")
        snap = j.run_until(lambda s: not s["link_up"], 15, "link down without heartbeats")
        assert snap["heartbeat_age_s"] > 1.5 and snap["attitude"] is not None  # other streams still flow
        j.run_until(lambda s: s["link_up"] and j.sim_time() > 16.0, 15, "link up again")


@pytest.mark.slow
def test_link_loss_and_return(tmp_path: Path) -> None:
    sim = dataclasses.replace(QUICK, arm_at_s=100.0, link_loss=((6.0, 10.0),))
    with Joined(tmp_path, sim) as j:
        j.run_until(lambda s: s["link_up"], 10, "link up")
        lost = j.run_until(lambda s: not s["link_up"], 15, "link lost")
        snap = j.run_until(lambda s: s["link_up"] and j.sim_time() > 16.0, 15, "link back")
        # the streams are asked again at the link's next periodic step after the heartbeat returns, and the
        # stand-in hears the request at its own next step: wait for the stand-in's record, not for our counter
        # (on a loaded machine either may come after the snapshot of "link back")
        j.run_until(lambda s: s["interval_requests"] > lost["interval_requests"]
                    and requested_ids(j.core.report(), after_s=16.0) == set(STREAMS.values()), 10,
                    "streams asked again and heard")
    assert snap["packets_lost"] == 0  # the outage is down time, not packet loss (the numbers wrapped meanwhile)


def test_mavlink1_only_autopilot(tmp_path: Path) -> None:
    """An autopilot on MAVLink 1 ignores v2 frames: we answer in v1, so it hears us and sends what we ask."""
    sim = dataclasses.replace(QUICK, arm_at_s=100.0, mavlink1=True)
    with Joined(tmp_path, sim) as j:
        snap = j.run_until(lambda s: s["attitude"] is not None and s["interval_acks"] >= 8, 15, "v1 streams")
        report = j.core.report()
    assert snap["mavlink_version"] == 1
    assert {h["mavlink_version"] for h in report["heard_heartbeats"]} == {1}
    assert requested_ids(report) == set(STREAMS.values())


@pytest.mark.slow
def test_corrections_reach_the_pipe_whole_or_not_at_all(tmp_path: Path) -> None:
    msgs = tuple(rtcm_frame(n, i) for i, n in enumerate([100, 180, 360, 540, 720, 250, 181, 500] * 4))
    sim = dataclasses.replace(QUICK, arm_at_s=100.0, rtcm_messages=msgs, rtcm_interval_s=0.1,
                              drop_fragment_rate=0.15, reorder_fragments=True, seed=3)
    pipe = CorrectionsPipe()
    with Joined(tmp_path, sim, corrections=pipe) as j:
        j.run_until(lambda s: j.core.report()["rtcm_sent"] == len(msgs), 20, "every message sent")
        j.run_until(lambda s: True, 0.5, "")
        report = j.core.report()
        snap = j.link.snapshot()
    got = []
    while block := pipe.take(1 << 20, 0.01):
        got.append(block)
    intact = [msgs[i] for i in report["rtcm_intact"]]
    assert report["rtcm_broken"], "the seed must drop some fragments"
    # the last message may still be pending (its sequence is dropped only when the next one starts)
    assert b"".join(got) in (b"".join(intact), b"".join(intact[:-1]))
    assert snap["rtcm"]["dropped"] >= len(report["rtcm_broken"]) - 1


@pytest.mark.slow
def test_mission_flight_events_on_the_receivers_timeline(tmp_path: Path) -> None:
    """Driven by the receiver's mission (hil_sim.flight.Trajectory): the lifecycle events' GPS times (through
    SYSTEM_TIME) fall where the trajectory climbs past 2 m and touches down, on the scenario's GPS timeline."""
    from hil_sim.autopilot import MissionFlight
    from hil_sim.scenario import FlightPlan, Scenario
    from onboard.gnsstime import GpsTime

    scenario = Scenario.default(flight=FlightPlan(static_s=6, survey_height_m=6, line_length_m=20, n_lines=2,
                                                  line_spacing_m=6, climb_rate_m_s=3, descent_rate_m_s=3,
                                                  line_speeds_m_s=(5.0,)))
    flight = MissionFlight(scenario)
    with Joined(tmp_path, QUICK, flight=flight) as j:
        j.run_until(lambda s: s["flown"] and s["armed"] is False, 40, "mission flown")
    events = {e["event"]: GpsTime(e["gps_week"], e["gps_tow_ns"]).diff_s(scenario.start) for e in j.events}
    assert list(events) == ["armed", "takeoff", "landed", "disarmed"]
    climb_2m = next(t / 10 for t in range(600) if flight.traj.state_at_s(t / 10).pos_enu_m[2] >= 2.0)
    # EXTENDED_SYS_STATE and HEARTBEAT come at 1 Hz (simulated): an event is seen up to 1 s after it happened
    # (timed on the autopilot's clock: its latest time_boot_ms, ATTITUDE at 4 Hz, so up to 0.25 s early)
    assert -0.3 <= events["armed"] - (flight.traj.takeoff_s - 2.0) < 1.5
    assert -0.3 <= events["takeoff"] - climb_2m < 1.5
    assert -0.3 <= events["landed"] - flight.traj.landing_s < 1.5
    assert -0.3 <= events["disarmed"] - (flight.traj.landing_s + 3.0) < 1.5
