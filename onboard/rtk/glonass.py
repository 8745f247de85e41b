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
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt

from onboard.gnsstime import GpsTime
from onboard.rtk.consts import J2_GLO, MU_GLO_M3_S2, OMEGA_E_GLO_RAD_S, RE_GLO_M
from onboard.rtk.types import GlonassEphemeris

STEP_S = 60.0
"""Runge–Kutta integration step, s (RTKLIB TSTEP)."""
ERR_EPH_GLO_M = 5.0
"""1-σ error of a GLONASS broadcast orbit and clock, m (RTKLIB ERREPH_GLO; the variance is its square)."""


Seconds = TypeVar("Seconds", float, npt.NDArray[np.float64])
"""A time in s, or an array of them: the clock formulas serve one instant and many alike."""

State = tuple[float, float, float, float, float, float]
"""(x, y, z, vx, vy, vz) in m and m/s. Plain floats: a 6-vector in numpy costs more in call overhead than
the arithmetic (30 RK4 steps for |t − tb| = 30 min)."""


_J2_TERM = 1.5 * J2_GLO * MU_GLO_M3_S2 * RE_GLO_M * RE_GLO_M
"""3/2·J2·μ·ae² (m⁵/s²), evaluated left to right as the expression it replaces."""
_OMG2 = OMEGA_E_GLO_RAD_S * OMEGA_E_GLO_RAD_S
_2OMG = 2.0 * OMEGA_E_GLO_RAD_S


def _acceleration(x0: float, x1: float, x2: float, v0: float, v1: float, v2: float,
                  acc: tuple[float, float, float]) -> tuple[float, float, float]:
    """Acceleration (m/s²) at position (x0, x1, x2) m and velocity (v0, v1, v2) m/s in the rotating PZ-90 frame:
    the second half of the state's derivative (the first is the velocity itself)."""
    r2 = x0 * x0 + x1 * x1 + x2 * x2
    if r2 <= 0.0:
        return (0.0, 0.0, 0.0)
    r3 = r2 * math.sqrt(r2)
    a = _J2_TERM / r2 / r3  # 3/2 J2 μ ae² / r⁵
    b = 5.0 * x2 * x2 / r2
    c = -MU_GLO_M3_S2 / r3 - a * (1.0 - b)
    return ((c + _OMG2) * x0 + _2OMG * v1 + acc[0],
            (c + _OMG2) * x1 - _2OMG * v0 + acc[1],
            (c - 2.0 * a) * x2 + acc[2])


def _rk4_step(x: State, h: float, acc: tuple[float, float, float]) -> State:
    """`x` carried over one Runge–Kutta step of `h` s. The four derivatives k1..k4 are (velocity, acceleration)
    pairs: k1 = (v, a(x)), k2 = (w, b) at x + k1·h/2, k3 = (u, c) at x + k2·h/2, k4 = (t, d) at x + k3·h; the
    components as scalars (tuples of six cost more in packing than the arithmetic)."""
    x0, x1, x2, v0, v1, v2 = x
    h2 = h / 2.0
    a0, a1, a2 = _acceleration(x0, x1, x2, v0, v1, v2, acc)
    w0, w1, w2 = v0 + a0 * h2, v1 + a1 * h2, v2 + a2 * h2
    b0, b1, b2 = _acceleration(x0 + v0 * h2, x1 + v1 * h2, x2 + v2 * h2, w0, w1, w2, acc)
    u0, u1, u2 = v0 + b0 * h2, v1 + b1 * h2, v2 + b2 * h2
    c0, c1, c2 = _acceleration(x0 + w0 * h2, x1 + w1 * h2, x2 + w2 * h2, u0, u1, u2, acc)
    t0, t1, t2 = v0 + c0 * h, v1 + c1 * h, v2 + c2 * h
    d0, d1, d2 = _acceleration(x0 + u0 * h, x1 + u1 * h, x2 + u2 * h, t0, t1, t2, acc)
    wt = h / 6.0
    return (x0 + (v0 + 2.0 * w0 + 2.0 * u0 + t0) * wt,
            x1 + (v1 + 2.0 * w1 + 2.0 * u1 + t1) * wt,
            x2 + (v2 + 2.0 * w2 + 2.0 * u2 + t2) * wt,
            v0 + (a0 + 2.0 * b0 + 2.0 * c0 + d0) * wt,
            v1 + (a1 + 2.0 * b1 + 2.0 * c1 + d1) * wt,
            v2 + (a2 + 2.0 * b2 + 2.0 * c2 + d2) * wt)


def _clock_offset_s(geph: GlonassEphemeris, dt_s: Seconds) -> Seconds:
    """The broadcast clock −τn + γn·dt (s), `dt_s` seconds after tb on the system time scale."""
    return -geph.tau_n_s + geph.gamma_n * dt_s


def _integrate(x: State, dt: float, acc: tuple[float, float, float]) -> State:
    """`x` carried over `dt` s (either sign) in RK4 steps of at most STEP_S, the last one shortened."""
    h = -STEP_S if dt < 0.0 else STEP_S
    while abs(dt) > 1e-9:
        if abs(dt) < STEP_S:
            h = dt
        x = _rk4_step(x, h, acc)
        dt -= h
    return x


def glonass_state(geph: GlonassEphemeris, t: GpsTime) -> npt.NDArray[np.float64]:
    """The integrated state (x, y, z, vx, vy, vz) (PZ-90 ≈ WGS 84 ECEF, m and m/s) at GPS time `t`."""
    return np.array(_integrate((*geph.pos_m, *geph.vel_m_s), t.diff_s(geph.toe), geph.acc_m_s2))


class _Arc:
    """One ephemeris' orbit on the grid tb + k·STEP_S: the RK4 states (x, y, z, vx, vy, vz) integrated from tb in
    whole steps (RTKLIB's own path through those instants) and the acceleration at each, for k in [k0, k0 + K),
    grown on demand."""

    def __init__(self, geph: GlonassEphemeris) -> None:
        self.acc = geph.acc_m_s2
        x = (*geph.pos_m, *geph.vel_m_s)
        self.k0 = 0
        self.states: list[State] = [x]
        self.accels: list[tuple[float, float, float]] = [_acceleration(*x, self.acc)]
        self._arrays: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None = None

    def cover(self, k_lo: int, k_hi: int) -> None:
        """Grow the grid to hold the nodes k_lo..k_hi."""
        while self.k0 > k_lo:
            x = _rk4_step(self.states[0], -STEP_S, self.acc)
            self.states.insert(0, x)
            self.accels.insert(0, _acceleration(*x, self.acc))
            self.k0 -= 1
            self._arrays = None
        while self.k0 + len(self.states) - 1 < k_hi:
            x = _rk4_step(self.states[-1], STEP_S, self.acc)
            self.states.append(x)
            self.accels.append(_acceleration(*x, self.acc))
            self._arrays = None

    def arrays(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """The nodes' states (K, 6) and accelerations (K, 3)."""
        if self._arrays is None:
            self._arrays = (np.array(self.states), np.array(self.accels))
        return self._arrays


def _hermite(s: Any, h: float, x0: Any, a0: Any, x1: Any, a1: Any) -> tuple[list[Any], list[Any], list[Any]]:
    """Quintic Hermite interpolation between two nodes `h` s apart, at the fraction `s` of the step: the
    position, velocity and acceleration matching both nodes' (position, velocity, acceleration), on the
    components x0[i], a0[i] (arrays over the instants)."""
    s2 = s * s
    s3 = s2 * s
    s4 = s3 * s
    s5 = s4 * s
    # the basis of p(s) = p0 + H5·Δp + h·(H1·v0 + H4·v1) + h²·(H2·a0 + H3·a1) and its two derivatives in s
    h1, h2, h3 = s - 6.0 * s3 + 8.0 * s4 - 3.0 * s5, 0.5 * s2 - 1.5 * s3 + 1.5 * s4 - 0.5 * s5, 0.5 * s3 - s4 + 0.5 * s5
    h4, h5 = -4.0 * s3 + 7.0 * s4 - 3.0 * s5, 10.0 * s3 - 15.0 * s4 + 6.0 * s5
    d1, d2, d3 = 1.0 - 18.0 * s2 + 32.0 * s3 - 15.0 * s4, s - 4.5 * s2 + 6.0 * s3 - 2.5 * s4, 1.5 * s2 - 4.0 * s3 + 2.5 * s4
    d4, d5 = -12.0 * s2 + 28.0 * s3 - 15.0 * s4, 30.0 * s2 - 60.0 * s3 + 30.0 * s4
    e1, e2, e3 = -36.0 * s + 96.0 * s2 - 60.0 * s3, 1.0 - 9.0 * s + 18.0 * s2 - 10.0 * s3, 3.0 * s - 12.0 * s2 + 10.0 * s3
    e4, e5 = -24.0 * s + 84.0 * s2 - 60.0 * s3, 60.0 * s - 180.0 * s2 + 120.0 * s3
    hh = h * h
    pos, vel, acc = [], [], []
    for i in range(3):
        dp, v0, v1, g0, g1 = x1[i] - x0[i], x0[i + 3], x1[i + 3], a0[i], a1[i]
        pos.append(x0[i] + h5 * dp + h * (h1 * v0 + h4 * v1) + hh * (h2 * g0 + h3 * g1))
        vel.append((d5 * dp + h * (d1 * v0 + d4 * v1) + hh * (d2 * g0 + d3 * g1)) / h)
        acc.append((e5 * dp + h * (e1 * v0 + e4 * v1) + hh * (e2 * g0 + e3 * g1)) / hh)
    return pos, vel, acc


class GlonassOrbits:
    """GLONASS broadcast orbits at many instants. Each ephemeris is integrated once, from tb in whole RK4 steps
    of STEP_S (RTKLIB's own path through the instants tb + k·STEP_S), and an instant between two such nodes is
    read off the quintic Hermite polynomial through their positions, velocities and accelerations (the force
    model's). It departs from RTKLIB's integration to the instant itself (the last step shortened) by tens of
    micrometres and about a micrometre per second over the ±30 min an ephemeris is used, a millionth of the
    broadcast orbit's 5 m error, for one polynomial per instant instead of up to 60 evaluations of the force
    model. The velocity returned is v + a·dt_s/2: RTKLIB's forward difference over `dt_s` to first order in it
    (the two differ by jerk·dt_s²/6, ~1e-11 m/s at 1 ms). Holds the arcs of at most `size` ephemerides."""

    def __init__(self, size: int = 256) -> None:
        self._arcs: dict[tuple[int, int, int], _Arc] = {}
        self._size = size

    def _arc(self, geph: GlonassEphemeris, dt_lo: float, dt_hi: float) -> _Arc:
        """`geph`'s arc, its grid grown over [dt_lo, dt_hi] s after tb."""
        key = (geph.slot, geph.toe.total_ns, geph.iode)
        arc = self._arcs.get(key)
        if arc is None:
            if len(self._arcs) >= self._size:
                self._arcs.pop(next(iter(self._arcs)))
            arc = self._arcs[key] = _Arc(geph)
        arc.cover(math.floor(dt_lo / STEP_S), math.floor(dt_hi / STEP_S) + 1)
        return arc

    def position_velocity(self, geph: GlonassEphemeris, t: GpsTime, dt_s: float = 1e-3
                          ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], float, float]:
        """As glonass_position_velocity (velocity and drift by a forward difference over `dt_s`)."""
        p, v, c0, drift = self.position_velocity_at(geph, t.diff_s(geph.toe), dt_s)
        return np.array(p), np.array(v), c0, drift

    def position_velocity_at(self, geph: GlonassEphemeris, dt: float, dt_s: float = 1e-3
                             ) -> tuple[tuple[float, float, float], tuple[float, float, float], float, float]:
        """position_velocity at `dt` s after tb (GPS time scale), as plain floats: position (m), velocity
        (m/s), clock bias (s), drift (s/s)."""
        p, v, c0, drift = self.positions_velocities_at(geph, np.array([dt]), dt_s)
        return (float(p[0, 0]), float(p[0, 1]), float(p[0, 2])), (float(v[0, 0]), float(v[0, 1]), float(v[0, 2])), \
            float(c0[0]), float(drift[0])

    def positions_velocities_at(self, geph: GlonassEphemeris, dt: npt.NDArray[np.float64], dt_s: float = 1e-3
                                ) -> tuple[npt.NDArray[np.float64], ...]:
        """position_velocity_at for the instants `dt` (m,) s after tb at once: position (m, 3) m, velocity
        (m, 3) m/s, clock bias (m,) s, drift (m,) s/s."""
        arc = self._arc(geph, float(dt.min()), float(dt.max()))
        states, accels = arc.arrays()
        k = np.floor(dt / STEP_S)
        i = k.astype(np.int64) - arc.k0
        p, v, a = _hermite((dt - STEP_S * k) / STEP_S, STEP_S, states[i].T, accels[i].T, states[i + 1].T,
                           accels[i + 1].T)
        c0, c1 = _clock_offset_s(geph, dt), _clock_offset_s(geph, dt + dt_s)
        h2 = dt_s / 2.0
        vel = [v[j] + a[j] * h2 for j in range(3)]
        return np.stack(p, axis=1), np.stack(vel, axis=1), c0, (c1 - c0) / dt_s


def glonass_clock_s(geph: GlonassEphemeris, t: GpsTime) -> float:
    """Satellite clock bias (s) for `t` read on the satellite clock: −τn + γn·(t_sys − tb) with t_sys = t − bias
    solved by two fixed-point steps (as RTKLIB 2.4.3 geph2clk)."""
    return glonass_clock_at_s(geph, t.diff_s(geph.toe))


def glonass_clock_at_s(geph: GlonassEphemeris, dt0_s: Seconds) -> Seconds:
    """glonass_clock_s for a time `dt0_s` s (or an array of them) after tb read on the satellite clock."""
    dt = dt0_s
    for _ in range(2):
        dt = dt0_s - _clock_offset_s(geph, dt)
    return _clock_offset_s(geph, dt)


def glonass_position(geph: GlonassEphemeris, t: GpsTime) -> tuple[npt.NDArray[np.float64], float]:
    """Satellite position (ECEF m, frame of `t`) and clock bias (s) at GPS time `t` (RTKLIB geph2pos: the
    clock −τn + γn·(t − tb) without iteration; GLONASS broadcasts no relativistic term to add)."""
    x = glonass_state(geph, t)
    dt = t.diff_s(geph.toe)
    return x[:3].copy(), _clock_offset_s(geph, dt)


def glonass_position_velocity(
    geph: GlonassEphemeris, t: GpsTime, dt_s: float = 1e-3
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], float, float]:
    """Position (m), velocity (m/s), clock bias (s) and drift (s/s) at GPS time `t`; velocity and drift by a
    forward difference over `dt_s`, as RTKLIB satpos() and our GPS eph_position_velocity do."""
    p0, c0 = glonass_position(geph, t)
    p1, c1 = glonass_position(geph, t.add_s(dt_s))
    return p0, (p1 - p0) / dt_s, c0, (c1 - c0) / dt_s
