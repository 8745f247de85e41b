"""Flight trajectory (C¹, survey speeds, attitude wobble, lever arm) and the TimePulse → flash chain."""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest

from hil_sim.camera import camera_event, camera_events, pulse_index_range, pulse_time
from hil_sim.flight import Trajectory
from hil_sim.scenario import DEFAULT_NAV_PATH, CameraPlan, FlightPlan, Scenario
from onboard.gnsstime import NS_PER_S
from onboard.rtk.geodesy import ecef_to_enu

START = Scenario().start


def make_traj(**plan: object) -> Trajectory:
    return Trajectory(FlightPlan(**plan), START, 47.4, 8.5, 500.0)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def traj() -> Trajectory:
    return make_traj()


def sample(traj: Trajectory, dt: float = 0.1) -> list[tuple[float, object]]:
    return [(t, traj.state_at_s(t)) for t in np.arange(0.0, traj.duration_s + 30.0, dt)]


def test_static_first_then_climb_to_survey_height_then_landing(traj: Trajectory) -> None:
    plan = traj.plan
    for t in np.arange(0.0, plan.static_s, 1.0):
        st = traj.state_at_s(float(t))
        assert np.allclose(st.pos_enu_m, 0.0) and np.allclose(st.vel_enu_m_s, 0.0) and not st.armed
        assert st.phase == "ground"
    climb = [traj.state_at_s(float(t)) for t in np.arange(plan.static_s + 0.1, plan.static_s + 20, 0.5)]
    assert all(s.armed and s.phase == "climb" for s in climb)
    assert max(s.vel_enu_m_s[2] for s in climb) == pytest.approx(plan.climb_rate_m_s)
    heights = [s.pos_enu_m[2] for _, s in sample(traj, 1.0) if s.phase == "line"]  # type: ignore[attr-defined]
    np.testing.assert_allclose(heights, plan.survey_height_m, atol=1e-9)
    end = traj.state_at_s(traj.duration_s + 10.0)
    assert not end.armed and end.phase == "ground" and end.pos_enu_m[2] == pytest.approx(0.0, abs=1e-9)
    assert np.allclose(end.vel_enu_m_s, 0.0)


def test_survey_lines_fly_at_4_to_5_m_s_with_a_speed_per_line_and_turns_between(traj: Trajectory) -> None:
    plan = traj.plan
    assert len(traj.line_spans_s) == plan.n_lines
    speeds = []
    for i, (a, b, v) in enumerate(traj.line_spans_s):
        vs = [float(np.linalg.norm(traj.state_at_s(float(t)).vel_enu_m_s)) for t in np.linspace(a, b, 20, endpoint=False)]
        assert np.allclose(vs, v) and 4.0 <= v <= 5.0
        assert v == plan.line_speeds_m_s[i % len(plan.line_speeds_m_s)]
        assert (b - a) * v == pytest.approx(plan.line_length_m)
        speeds.append(v)
    assert len(set(speeds)) > 1
    turns = [s for _, s in sample(traj, 0.5) if s.phase == "turn"]  # type: ignore[attr-defined]
    assert turns and all(4.0 <= np.linalg.norm(s.vel_enu_m_s) <= 5.0 for s in turns)
    # Lines are parallel, alternate in direction and sit line_spacing_m apart.
    mids = [traj.state_at_s(0.5 * (a + b)) for a, b, _ in traj.line_spans_s]
    az = math.radians(plan.line_azimuth_deg)
    side = np.array([math.cos(az), -math.sin(az), 0.0])
    offsets = [float(m.pos_enu_m @ side) for m in mids]
    np.testing.assert_allclose(np.diff(offsets), plan.line_spacing_m, atol=1e-6)
    dirs = [m.vel_enu_m_s / np.linalg.norm(m.vel_enu_m_s) for m in mids]
    for d0, d1 in itertools.pairwise(dirs):
        assert d0 @ d1 == pytest.approx(-1.0)


def test_trajectory_is_c1_velocity_is_the_derivative_of_position(traj: Trajectory) -> None:
    h = 1e-4
    times = list(np.arange(0.05, traj.duration_s, 0.37))
    # Segment boundaries too: velocity has no jump there.
    times += [seg.t0_s for seg in traj._segments]
    for t in times:
        p0, p1 = traj.state_at_s(t - h).pos_enu_m, traj.state_at_s(t + h).pos_enu_m
        v = traj.state_at_s(t).vel_enu_m_s
        np.testing.assert_allclose((p1 - p0) / (2 * h), v, atol=2e-3, err_msg=f"t={t}")
        vm, vp = traj.state_at_s(t - h).vel_enu_m_s, traj.state_at_s(t + h).vel_enu_m_s
        assert np.linalg.norm(vp - vm) < 1e-3, f"velocity jump at t={t}"


@pytest.mark.slow
def test_attitude_wobble_stays_within_3_deg_and_is_smooth(traj: Trajectory) -> None:
    rolls, pitches, yaw_dev = [], [], []
    prev = None
    for _, st in sample(traj, 0.1):
        rolls.append(math.degrees(st.roll_rad))  # type: ignore[attr-defined]
        pitches.append(math.degrees(st.pitch_rad))  # type: ignore[attr-defined]
        if st.phase == "line":  # type: ignore[attr-defined]
            track = math.atan2(st.vel_enu_m_s[0], st.vel_enu_m_s[1])  # type: ignore[attr-defined]
            d = (st.yaw_rad - track + math.pi) % (2 * math.pi) - math.pi  # type: ignore[attr-defined]
            yaw_dev.append(math.degrees(d))
        r = st.r_cam_to_enu  # type: ignore[attr-defined]
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(r) == pytest.approx(1.0)
        if prev is not None:
            assert abs(math.degrees(st.roll_rad - prev)) < 0.5  # type: ignore[attr-defined]
        prev = st.roll_rad  # type: ignore[attr-defined]
    for series in (rolls, pitches, yaw_dev):
        assert max(abs(x) for x in series) <= 3.0
        assert max(abs(x) for x in series) > 1.5  # the wobble is really there
    # On the ground before takeoff: level, no wobble.
    st0 = traj.state_at_s(10.0)
    assert st0.roll_rad == 0.0 and st0.pitch_rad == 0.0


def test_camera_looks_down_and_sits_at_the_lever_arm_from_the_antenna(traj: Trajectory) -> None:
    lever = np.asarray(traj.plan.lever_arm_cam_m)
    for t in (10.0, 120.0, 250.0):
        st = traj.state_at_s(t)
        r = st.r_cam_to_enu
        assert r[:, 2] @ np.array([0, 0, -1.0]) > math.cos(math.radians(5))  # optical axis ~ nadir
        # ground.adjust convention: antenna = C + R·O
        np.testing.assert_allclose(st.camera_enu_m + r @ lever, st.pos_enu_m, atol=1e-12)
        enu = ecef_to_enu(st.camera_ecef_m, traj.origin_ecef_m)
        np.testing.assert_allclose(enu, st.camera_enu_m, atol=1e-6)
    st = traj.state_at_s(traj.line_spans_s[0][0] + 5)
    fwd = st.vel_enu_m_s / np.linalg.norm(st.vel_enu_m_s)
    assert st.r_cam_to_enu[:, 1] @ fwd < -0.99  # image "down" points to the tail: top of image forward


def test_static_plan_never_moves() -> None:
    traj = make_traj(fly=False)
    for t in (0.0, 100.0, 5000.0):
        st = traj.state_at_s(t)
        assert np.allclose(st.pos_enu_m, 0.0) and not st.armed


# ----------------------------------------------------------------------------------------- camera


def test_pulses_sit_on_the_gps_grid_at_the_configured_phase_not_on_the_second() -> None:
    plan = CameraPlan(period_s=2.5, phase_offset_s=0.3217)
    t0, t1 = START, START.add_s(100)
    evs = camera_events(plan, t0, t1, valid_from=t0, seed=3)
    assert len(evs) == 40
    for ev in evs:
        assert (ev.pulse_time.total_ns - 321_700_000) % 2_500_000_000 == 0
        assert ev.pulse_time.tow_ns % NS_PER_S != 0
        assert t0 <= ev.pulse_time < t1
    assert np.allclose(np.diff([e.pulse_time.total_ns for e in evs]), 2.5e9)
    assert pulse_time(plan, evs[0].index) == evs[0].pulse_time
    assert len(pulse_index_range(plan, t0, t0)) == 0


def test_flash_lags_by_the_shutter_delay_with_its_jitter() -> None:
    plan = CameraPlan(shutter_delay_mean_s=0.064, shutter_jitter_sigma_s=0.0002)
    evs = camera_events(plan, START, START.add_s(4000), valid_from=START, seed=11)
    delays = np.array([e.delay_s for e in evs])
    n = len(delays)
    assert n == 2000
    assert np.mean(delays) == pytest.approx(0.064, abs=4 * 0.0002 / math.sqrt(n))
    assert np.std(delays) == pytest.approx(0.0002, rel=4 / math.sqrt(2 * n))
    for e in evs[:50]:
        assert e.flash_time is not None and e.flash_time.diff_s(e.pulse_time) == pytest.approx(e.delay_s, abs=1e-9)


def test_pulses_before_valid_time_are_suppressed() -> None:
    plan = CameraPlan()
    valid = START.add_s(30.0)
    evs = camera_events(plan, START, START.add_s(60), valid_from=valid, seed=1)
    assert evs and all(e.pulse_time >= valid for e in evs)
    assert len(evs) == 15


def test_missed_flashes_and_bounces_follow_their_probabilities() -> None:
    plan = CameraPlan(missed_flash_probability=0.1, bounce_probability=0.2, bounce_delay_max_s=0.003)
    evs = camera_events(plan, START, START.add_s(8000), valid_from=START, seed=5)
    n = len(evs)
    missed = [e for e in evs if e.flash_time is None]
    bounced = [e for e in evs if e.bounce_time is not None]
    assert len(missed) / n == pytest.approx(0.1, abs=4 * math.sqrt(0.09 / n))
    assert len(bounced) / (n - len(missed)) == pytest.approx(0.2, abs=4 * math.sqrt(0.16 / n))
    assert all(e.delay_s is None for e in missed)
    for e in bounced:
        assert e.flash_time is not None and 0 < e.bounce_time.diff_s(e.flash_time) <= 0.003  # type: ignore[union-attr]


def test_camera_events_are_reproducible_per_pulse() -> None:
    plan = CameraPlan()
    a = camera_event(plan, 123456, seed=9)
    b = camera_events(plan, pulse_time(plan, 123455), pulse_time(plan, 123458), pulse_time(plan, 0), seed=9)
    assert a in b
    assert camera_event(plan, 123456, seed=10) != a


def test_world_camera_events_give_truth_camera_positions_during_climb_lines_and_descent() -> None:
    from hil_sim.world import World

    world = World(Scenario.default(nav_path=DEFAULT_NAV_PATH))
    evs = world.camera_events(world.start, world.end)
    assert evs[0].pulse_time >= world.start.add_s(world.scenario.camera.valid_after_s)
    phases = set()
    for e in evs:
        assert e.flash_time is not None
        truth = world.truth(e.flash_time)
        phases.add(truth["phase"])
        assert np.linalg.norm(truth["camera_ecef_m"] - truth["antenna_ecef_m"]) == pytest.approx(
            np.linalg.norm(world.scenario.flight.lever_arm_cam_m))
    assert {"climb", "line", "turn", "descent", "ground"} <= phases


def test_plan_dataclasses_are_frozen() -> None:
    plan = CameraPlan()
    with pytest.raises(dataclasses.FrozenInstanceError):
        plan.period_s = 3.0  # type: ignore[misc]
