"""Velocity-aided (cubic Hermite) trajectory interpolation: exactness, refusal of extrapolation and gaps, σ."""

from __future__ import annotations

import numpy as np
import pytest

from ground.adjust.interpolate import interpolate_antenna, trajectory_velocities_ecef
from ground.adjust.types import Trajectory
from onboard.rtk.geodesy import enu_rotation, llh_to_ecef

LAT, LON = np.radians(48.1), np.radians(-1.7)
ORIGIN = llh_to_ecef(LAT, LON, 60.0)
ROT = enu_rotation(LAT, LON)  # ECEF → ENU
T0_NS = 1_400_000_000 * 10**9


def _cubic(t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A cubic ENU motion (m, m/s): accelerating along east, climbing, curving north."""
    p = np.column_stack([4.0 * t_s + 0.05 * t_s**2 + 0.002 * t_s**3, 0.3 * t_s**2 - 0.01 * t_s**3, 2 * t_s])
    v = np.column_stack([4.0 + 0.1 * t_s + 0.006 * t_s**2, 0.6 * t_s - 0.03 * t_s**2, np.full_like(t_s, 2.0)])
    return p, v


def _trajectory(
    t_s: np.ndarray, with_velocity: bool = True, sd_enu: tuple = (0.01, 0.01, 0.02)
) -> Trajectory:
    p, v = _cubic(t_s)
    sd = np.sqrt((np.asarray(sd_enu) ** 2) @ (ROT**2))
    return Trajectory(
        t_ns=(T0_NS + np.round(t_s * 1e9)).astype(np.int64),
        pos_ecef_m=ORIGIN + p @ ROT,
        vel_ecef_m_s=(v @ ROT) if with_velocity else None,
        sd_m=np.tile(sd, (t_s.size, 1)),
        q=np.ones(t_s.size, dtype=np.int8),
    )


def test_hermite_is_exact_for_cubic_motion_where_linear_is_not() -> None:
    t = np.arange(0, 20.0, 1.0)  # a 1 Hz RTK solution
    traj = _trajectory(t)
    te = np.array([0.37, 5.5, 12.91, 18.999])
    out = interpolate_antenna(traj, T0_NS + np.round(te * 1e9).astype(np.int64), ORIGIN)
    p_true, v_true = _cubic(te)
    assert out.valid.all()
    assert np.allclose(out.pos_enu_m, p_true, atol=1e-6)  # ECEF round trip rounding only
    assert np.allclose(out.vel_enu_m_s, v_true, atol=1e-6)
    # linear interpolation of the same samples errs by centimetres
    p_s, _ = _cubic(t)
    lin = np.column_stack([np.interp(te, t, p_s[:, k]) for k in range(3)])
    assert np.max(np.abs(lin - p_true)) > 0.01
    # the acceleration is the cubic's second derivative
    acc_true = np.column_stack([0.1 + 0.012 * te, 0.6 - 0.06 * te, np.zeros_like(te)])
    assert np.allclose(out.acc_enu_m_s2, acc_true, atol=1e-5)


def test_velocities_by_central_differences_when_the_file_has_none() -> None:
    t = np.sort(np.concatenate([np.arange(0, 20.0, 0.2), [7.05]]))  # non-uniform spacing
    traj = _trajectory(t, with_velocity=False)
    v = trajectory_velocities_ecef(traj, max_gap_s=1.0) @ ROT.T
    _, v_true = _cubic(t)
    # three-point derivative is exact for quadratics; the cubic term leaves O(h²·jerk) ≈ mm/s
    assert np.allclose(v[1:-1], v_true[1:-1], atol=2e-3)
    out = interpolate_antenna(traj, np.array([T0_NS + 3_333_000_000]), ORIGIN)
    assert np.allclose(out.pos_enu_m[0], _cubic(np.array([3.333]))[0][0], atol=1e-4)


def test_extrapolation_and_gaps_are_flagged_not_guessed() -> None:
    t = np.concatenate([np.arange(0, 10.0, 1.0), np.arange(15.0, 20.0, 1.0)])  # a 6 s gap
    traj = _trajectory(t)
    te = np.array([-0.5, 3.2, 12.0, 19.0, 19.5])
    out = interpolate_antenna(traj, T0_NS + np.round(te * 1e9).astype(np.int64), ORIGIN, max_gap_s=1.5)
    assert list(out.valid) == [False, True, False, True, False]
    assert "extrapolation" in out.reason[0] and "extrapolation" in out.reason[4]
    assert "gap" in out.reason[2]
    assert np.isnan(out.pos_enu_m[0]).all() and out.quality[2] == 0
    assert out.reason[1] == "" and out.reason[3] == ""  # the last epoch itself is inside


def test_sigma_is_rotated_to_enu_and_quality_is_the_worst_neighbour() -> None:
    t = np.arange(0, 5.0, 1.0)
    traj = _trajectory(t, sd_enu=(0.01, 0.02, 0.03))
    q = traj.q.copy()
    q[2] = 2
    traj = Trajectory(traj.t_ns, traj.pos_ecef_m, traj.vel_ecef_m_s, traj.sd_m, q)
    out = interpolate_antenna(traj, np.array([T0_NS + 500_000_000, T0_NS + 1_500_000_000]), ORIGIN)
    # diag(R·diag(σ_ecef²)·Rᵀ) is not the original diag exactly (the ECEF σ lost the cross terms) but close
    assert np.all(out.sigma_enu_m > 0.005) and np.all(out.sigma_enu_m < 0.04)
    assert list(out.quality) == [1, 2]


def test_unusable_trajectories_raise() -> None:
    t = np.arange(0, 5.0, 1.0)
    traj = _trajectory(t)
    unsorted = Trajectory(traj.t_ns[[0, 2, 1, 3, 4]], traj.pos_ecef_m, traj.vel_ecef_m_s, traj.sd_m, traj.q)
    with pytest.raises(ValueError, match="strictly increasing at epoch 2"):
        interpolate_antenna(unsorted, np.array([T0_NS]), ORIGIN)
    single = Trajectory(traj.t_ns[:1], traj.pos_ecef_m[:1], None, traj.sd_m[:1], traj.q[:1])
    with pytest.raises(ValueError, match="≥ 2 epochs"):
        interpolate_antenna(single, np.array([T0_NS]), ORIGIN)


def test_gps_time_events_are_accepted() -> None:
    from onboard.gnsstime import GpsTime

    traj = _trajectory(np.arange(0, 10.0, 1.0))
    times = [GpsTime.from_total_ns(T0_NS + 2_500_000_000), GpsTime.from_total_ns(T0_NS + 7_250_000_000)]
    by_time = interpolate_antenna(traj, times, ORIGIN)
    by_ns = interpolate_antenna(traj, np.array([t.total_ns for t in times]), ORIGIN)
    assert np.array_equal(by_time.pos_enu_m, by_ns.pos_enu_m) and by_time.valid.all()
