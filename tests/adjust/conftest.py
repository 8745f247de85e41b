"""Fixtures of the adjustment tests: simulated blocks (seeded) and their problems."""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
import pytest

from ground.adjust.model import AdjustmentProblem
from ground.adjust.simulate import BlockOptions, SimulatedBlock, simulate_block
from ground.adjust.solve import build_problem

# a quiet block: noise far below the tolerances, so a round trip isolates the model and the signs
QUIET = {
    "gnss_white_sigma_m": (0.001, 0.001, 0.001),
    "gnss_correlated_sigma_m": (0.0, 0.0, 0.0),
    "velocity_sigma_m_s": 0.001,
    "camera_centre_noise_m": 0.001,
    "camera_angle_noise_deg": 0.001,
    "ground_sigma_m": 0.001,
    "rel_point_noise_m": 0.001,
    "n_lines": 6,
    "line_length_m": 100.0,
    "photo_interval_s": 1.0,
}


@pytest.fixture(autouse=True)
def _quiet_adjust_logs(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.ERROR, logger="ground.adjust.solve")


def make_block(seed: int = 0, **overrides: object) -> SimulatedBlock:
    """A simulated block with BlockOptions overrides."""
    return simulate_block(BlockOptions(**overrides), np.random.default_rng(seed))  # type: ignore[arg-type]


def problem_of(block: SimulatedBlock, with_gcps: bool = True) -> AdjustmentProblem:
    """The adjustment problem of a block (all control points, or check points only)."""
    control = block.control if with_gcps else tuple(c for c in block.control if c.role == "check")
    return build_problem(block.poses, block.events, block.trajectory, control, block.origin_ecef_m)


@pytest.fixture
def block_factory() -> Callable[..., SimulatedBlock]:
    return make_block


@pytest.fixture
def problem_factory() -> Callable[..., AdjustmentProblem]:
    return problem_of


@pytest.fixture(scope="module")
def quiet_block() -> SimulatedBlock:
    """Quiet block, one GCP (P05), trigger events with a 64 ms delay."""
    return make_block(3, gcp_names=("P05",), **QUIET)


@pytest.fixture
def quiet() -> dict[str, object]:
    """BlockOptions overrides for a quiet block."""
    return dict(QUIET)


def make_hil_block(
    seed: int,
    event_kind: str = "trigger",
    line_speeds_m_s: tuple[float, ...] | None = None,
    photo_phases: tuple[str, ...] = ("line", "climb", "descent"),
    **overrides: object,
) -> SimulatedBlock:
    """A block flown by hil_sim's flight model (C¹ path, accelerations, turns, wobble) and camera chain
    (TimePulse every second → shutter 64 ms ± 0.2 ms → flash), observed by ground.adjust.simulate.observe_flight.

    Photos are those exposed on the survey lines, in the climb and in the descent. `event_kind` "trigger" uses
    the pulse times as events (t_d ≈ 64 ms); "flash" uses the flash marks (t_d = 0).
    """
    from ground.adjust.simulate import FlightTruth, observe_flight
    from hil_sim.camera import camera_event, pulse_index_range
    from hil_sim.flight import Trajectory as HilFlight
    from hil_sim.scenario import CameraPlan, FlightPlan
    from onboard.gnsstime import GpsTime

    rng = np.random.default_rng(seed)
    speeds = line_speeds_m_s or tuple(rng.permutation(np.linspace(4.0, 5.0, 6)))
    plan = FlightPlan(
        static_s=5.0, survey_height_m=50.0, line_length_m=200.0, line_spacing_m=25.0, n_lines=6,
        line_azimuth_deg=float(rng.uniform(0, 360)), line_speeds_m_s=speeds, lever_arm_cam_m=(0.04, -0.11, -0.09),
    )  # fmt: skip
    camera = CameraPlan(period_s=1.0, valid_after_s=0.0)
    start = GpsTime.from_week_tow_s(2400, 302400.0)
    flight = HilFlight(plan, start, 48.5, -3.5, 80.0)
    t_traj = np.arange(plan.static_s - 2.0, flight.duration_s, 0.2)
    states = [flight.state_at_s(float(t)) for t in t_traj]
    exposures, pulses, centres, rots = [], [], [], []
    end = start.add_s(flight.duration_s - 1.0)
    for k in pulse_index_range(camera, start.add_s(plan.static_s + 1.0), end):
        ev = camera_event(camera, k, seed)
        if ev.flash_time is None:
            continue
        tau = ev.flash_time.diff_s(start)
        st = flight.state_at_s(tau)
        if st.phase not in photo_phases or st.pos_enu_m[2] < 10.0:
            continue
        exposures.append(tau)
        pulses.append(ev.pulse_time.diff_s(start))
        centres.append(st.camera_enu_m)
        rots.append(st.r_cam_to_enu)
    exp = np.array(exposures)
    truth = FlightTruth(
        start=start,
        traj_t_s=t_traj,
        traj_pos_enu_m=np.array([s.pos_enu_m for s in states]),
        traj_vel_enu_m_s=np.array([s.vel_enu_m_s for s in states]),
        exposure_s=exp,
        centres_enu_m=np.array(centres),
        r_cam_to_enu=np.array(rots),
        lever_arm_m=np.array(plan.lever_arm_cam_m),
        origin_ecef_m=flight.origin_ecef_m,
        event_s=np.array(pulses) if event_kind == "trigger" else exp.copy(),
    )
    return observe_flight(truth, BlockOptions(event_kind=event_kind, **overrides), rng)  # type: ignore[arg-type]


@pytest.fixture
def hil_block_factory() -> Callable[..., SimulatedBlock]:
    return make_hil_block
