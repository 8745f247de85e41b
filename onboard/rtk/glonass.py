"""GLONASS satellite position, velocity and clock from the broadcast state vector (GLONASS ICD 5.1 A.3.1.2).

The equations of motion in the rotating PZ-90 frame (central term, J2, centrifugal and Coriolis terms, plus the
broadcast luni-solar acceleration held constant) are integrated from tb with 4th-order Runge–Kutta in steps of
at most 60 s, the last step shortened to land on t: the scheme of RTKLIB ephemeris.c geph2pos()/glorbit()/deq()
(read to check the constants and the step; ICD A.3.1.2 with RTKLIB's correction of the Coriolis terms).
PZ-90.11 is taken as WGS 84 (as RTKLIB does: the two agree to a few centimetres since PZ-90.11, 2014); the
positions are used in the WGS 84 ECEF frame of the other systems without a transformation.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from onboard.gnsstime import GpsTime
from onboard.rtk.consts import J2_GLO, MU_GLO_M3_S2, OMEGA_E_GLO_RAD_S, RE_GLO_M
from onboard.rtk.types import GlonassEphemeris

STEP_S = 60.0
"""Runge–Kutta integration step, s (RTKLIB TSTEP)."""
ERR_EPH_GLO_M = 5.0
"""1-σ error of a GLONASS broadcast orbit and clock, m (RTKLIB ERREPH_GLO; the variance is its square)."""


def _derivative(x: npt.NDArray[np.float64], acc: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """d/dt of the state (x, y, z, vx, vy, vz) in the rotating PZ-90 frame (m, m/s → m/s, m/s²)."""
    r2 = x[0] * x[0] + x[1] * x[1] + x[2] * x[2]
    if r2 <= 0.0:
        return np.zeros(6)
    r3 = r2 * math.sqrt(r2)
    omg2 = OMEGA_E_GLO_RAD_S * OMEGA_E_GLO_RAD_S
    a = 1.5 * J2_GLO * MU_GLO_M3_S2 * RE_GLO_M * RE_GLO_M / r2 / r3  # 3/2 J2 μ ae² / r⁵
    b = 5.0 * x[2] * x[2] / r2
    c = -MU_GLO_M3_S2 / r3 - a * (1.0 - b)
    return np.array([
        x[3], x[4], x[5],
        (c + omg2) * x[0] + 2.0 * OMEGA_E_GLO_RAD_S * x[4] + acc[0],
        (c + omg2) * x[1] - 2.0 * OMEGA_E_GLO_RAD_S * x[3] + acc[1],
        (c - 2.0 * a) * x[2] + acc[2],
    ])


def _rk4_step(x: npt.NDArray[np.float64], h: float, acc: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    k1 = _derivative(x, acc)
    k2 = _derivative(x + k1 * h / 2.0, acc)
    k3 = _derivative(x + k2 * h / 2.0, acc)
    k4 = _derivative(x + k3 * h, acc)
    return x + (k1 + 2.0 * k2 + 2.0 * k3 + k4) * h / 6.0


def glonass_state(geph: GlonassEphemeris, t: GpsTime) -> npt.NDArray[np.float64]:
    """The integrated state (x, y, z, vx, vy, vz) (PZ-90 ≈ WGS 84 ECEF, m and m/s) at GPS time `t`."""
    dt = t.diff_s(geph.toe)
    x = np.array([*geph.pos_m, *geph.vel_m_s], dtype=float)
    acc = np.asarray(geph.acc_m_s2, dtype=float)
    h = -STEP_S if dt < 0.0 else STEP_S
    while abs(dt) > 1e-9:
        if abs(dt) < STEP_S:
            h = dt
        x = _rk4_step(x, h, acc)
        dt -= h
    return x


def glonass_clock_s(geph: GlonassEphemeris, t: GpsTime) -> float:
    """Satellite clock bias (s) for `t` read on the satellite clock: −τn + γn·(t_sys − tb) with t_sys = t − bias
    solved by two fixed-point steps (as RTKLIB 2.4.3 geph2clk)."""
    dt0 = t.diff_s(geph.toe)
    dt = dt0
    for _ in range(2):
        dt = dt0 - (-geph.tau_n_s + geph.gamma_n * dt)
    return -geph.tau_n_s + geph.gamma_n * dt


def glonass_position(geph: GlonassEphemeris, t: GpsTime) -> tuple[npt.NDArray[np.float64], float]:
    """Satellite position (ECEF m, frame of `t`) and clock bias (s) at GPS time `t` (RTKLIB geph2pos: the
    clock −τn + γn·(t − tb) without iteration; GLONASS broadcasts no relativistic term to add)."""
    x = glonass_state(geph, t)
    dt = t.diff_s(geph.toe)
    return x[:3].copy(), -geph.tau_n_s + geph.gamma_n * dt


def glonass_position_velocity(
    geph: GlonassEphemeris, t: GpsTime, dt_s: float = 1e-3
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], float, float]:
    """Position (m), velocity (m/s), clock bias (s) and drift (s/s) at GPS time `t`; velocity and drift by a
    forward difference over `dt_s`, as RTKLIB satpos() and our GPS eph_position_velocity do."""
    p0, c0 = glonass_position(geph, t)
    p1, c1 = glonass_position(geph, t.add_s(dt_s))
    return p0, (p1 - p0) / dt_s, c0, (c1 - c0) / dt_s
