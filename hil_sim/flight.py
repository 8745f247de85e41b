"""Rover antenna trajectory and camera pose of a survey flight (pure, deterministic, C¹ in position).

The path is a chain of segments in local ENU about the takeoff point: hold on the ground, vertical climb
(trapezoidal vertical speed), acceleration along the first line, straight survey lines at a per-line speed,
half-circle turns whose speed changes linearly from one line's speed to the next, deceleration, hold, vertical
descent and a hold on the ground. Every segment has a linear speed profile, so velocity is continuous
(position C¹) and equals the analytic derivative of position.

Attitude: yaw follows the track (line azimuth on lines, the tangent in turns, held while hovering); roll,
pitch and yaw carry a smooth wobble (two sines each, total amplitude `wobble_amplitude_deg`, ≤ 3°) faded in
after takeoff and out before touchdown. Body axes are x forward, y right, z down (yaw from north, clockwise);
the camera looks down (nadir) with computer-vision axes x right, y down (towards the tail), z forward (= body
down). `lever_arm_cam_m` follows ground.adjust: antenna phase centre minus optical centre in the camera frame,
antenna = C + R_cam→ENU·O, so the camera centre C = antenna − R·O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hil_sim.scenario import FlightPlan
from onboard.gnsstime import GpsTime
from onboard.rtk.geodesy import enu_rotation, llh_to_ecef

Vec = npt.NDArray[np.float64]

# Fixed rotations between frames.
_R_CAM_TO_BODY = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # columns: cam x, y, z in body
_R_NED_TO_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])

# Wobble: (amplitude share, period s, phase rad) per axis; shares sum to 1 so |angle| ≤ amplitude.
_WOBBLE = {
    "roll": ((0.65, 7.3, 0.4), (0.35, 2.9, 1.9)),
    "pitch": ((0.6, 9.1, 2.2), (0.4, 3.7, 0.3)),
    "yaw": ((0.7, 13.7, 1.1), (0.3, 5.3, 2.6)),
}
_FADE_S = 3.0


@dataclass(frozen=True)
class _Segment:
    """Motion with a linearly changing speed along a straight line or a horizontal circular arc.

    Straight: p(τ) = p0 + u·s(τ). Arc: centre, radius, start angle (math angle in the EN plane), turn
    direction ±1. s(τ) = v0·τ + (v1 − v0)·τ²/(2T). `yaw_rad` is the track heading on straight segments
    (None keeps the previous heading).
    """

    t0_s: float
    dur_s: float
    kind: str  # "line" | "arc"
    phase: str
    p0: Vec
    u: Vec
    v0: float
    v1: float
    centre: Vec | None = None
    radius_m: float = 0.0
    angle0_rad: float = 0.0
    turn: float = 1.0
    yaw_rad: float = 0.0

    def at(self, tau: float) -> tuple[Vec, Vec, float]:
        """(position ENU m, velocity ENU m/s, yaw rad) at τ s into the segment (clamped to it)."""
        tau = min(max(tau, 0.0), self.dur_s)
        acc = (self.v1 - self.v0) / self.dur_s if self.dur_s > 0 else 0.0
        s = self.v0 * tau + 0.5 * acc * tau * tau
        v = self.v0 + acc * tau
        if self.kind == "line":
            return self.p0 + self.u * s, self.u * v, self.yaw_rad
        assert self.centre is not None
        ang = self.angle0_rad + self.turn * s / self.radius_m
        radial = np.array([math.cos(ang), math.sin(ang), 0.0])
        tangent = self.turn * np.array([-math.sin(ang), math.cos(ang), 0.0])
        yaw = math.atan2(tangent[0], tangent[1])  # heading from north, clockwise
        return self.centre + self.radius_m * radial, tangent * v, yaw

    def end(self) -> tuple[Vec, Vec, float]:
        return self.at(self.dur_s)


@dataclass(frozen=True)
class FlightState:
    """Truth of the rover at one instant.

    `pos_ecef_m`, `vel_ecef_m_s` antenna phase centre; `pos_enu_m`, `vel_enu_m_s` the same about the takeoff
    point; `roll_rad`, `pitch_rad`, `yaw_rad` body attitude (ZYX from NED); `r_cam_to_enu` camera→ENU rotation;
    `camera_ecef_m` optical centre; `armed` motors armed (False before the climb and after landing);
    `phase` "ground" | "climb" | "line" | "turn" | "transition" | "descent".
    """

    pos_ecef_m: Vec
    vel_ecef_m_s: Vec
    pos_enu_m: Vec
    vel_enu_m_s: Vec
    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    r_cam_to_enu: Vec
    camera_ecef_m: Vec
    camera_enu_m: Vec
    armed: bool
    phase: str
    line_index: int


def _line_segment(t0: float, phase: str, p0: Vec, u: Vec, v0: float, v1: float, dur: float, yaw: float) -> _Segment:
    return _Segment(t0, dur, "line", phase, p0.copy(), u, v0, v1, yaw_rad=yaw)


def _trapezoid(t0: float, phase: str, p0: Vec, u: Vec, dist: float, vmax: float, acc: float,
               yaw: float) -> list[_Segment]:
    """Rest-to-rest straight move over `dist` m: accelerate, cruise, decelerate (triangle when short)."""
    t_acc = vmax / acc
    d_acc = 0.5 * vmax * t_acc
    if 2 * d_acc > dist:
        vmax = math.sqrt(dist * acc)
        t_acc = vmax / acc
        d_acc = dist / 2
    t_cruise = (dist - 2 * d_acc) / vmax
    segs = [_line_segment(t0, phase, p0, u, 0.0, vmax, t_acc, yaw)]
    p = p0 + u * d_acc
    t = t0 + t_acc
    if t_cruise > 0:
        segs.append(_line_segment(t, phase, p, u, vmax, vmax, t_cruise, yaw))
        p = p + u * (dist - 2 * d_acc)
        t += t_cruise
    segs.append(_line_segment(t, phase, p, u, vmax, 0.0, t_acc, yaw))
    return segs


class Trajectory:
    """The rover antenna and camera over a scenario; `state(t)` for any GPS time (held before/after)."""

    def __init__(self, plan: FlightPlan, start: GpsTime, site_lat_deg: float, site_lon_deg: float,
                 site_h_m: float) -> None:
        self.plan = plan
        self.start = start
        self.lat_rad = math.radians(site_lat_deg)
        self.lon_rad = math.radians(site_lon_deg)
        self.origin_ecef_m = llh_to_ecef(self.lat_rad, self.lon_rad, site_h_m)
        self._r_enu_to_ecef = enu_rotation(self.lat_rad, self.lon_rad).T
        self._segments, self.line_spans_s = self._build(plan)
        self.takeoff_s = plan.static_s
        self.landing_s = self._segments[-1].t0_s if plan.fly and plan.land else math.inf
        self.end_of_motion_s = self._segments[-1].t0_s

    # ------------------------------------------------------------------------------------- building
    @staticmethod
    def _build(plan: FlightPlan) -> tuple[list[_Segment], list[tuple[float, float, float]]]:
        zero = np.zeros(3)
        az = math.radians(plan.line_azimuth_deg)
        u_line = np.array([math.sin(az), math.cos(az), 0.0])
        u_side = np.array([math.cos(az), -math.sin(az), 0.0])  # to the right of the first line
        segs: list[_Segment] = [_line_segment(0.0, "ground", zero, u_line, 0.0, 0.0, plan.static_s, az)]
        spans: list[tuple[float, float, float]] = []
        if not plan.fly:
            return segs, spans
        up = np.array([0.0, 0.0, 1.0])
        t = plan.static_s
        segs += _trapezoid(t, "climb", zero, up, plan.survey_height_m, plan.climb_rate_m_s, plan.accel_m_s2, az)
        t = segs[-1].t0_s + segs[-1].dur_s
        p = np.array([0.0, 0.0, plan.survey_height_m])
        # Accelerate along line 0 to its speed; the line proper starts at full speed.
        speeds = [plan.line_speeds_m_s[i % len(plan.line_speeds_m_s)] for i in range(plan.n_lines)]
        v = speeds[0]
        t_acc = v / plan.accel_m_s2
        segs.append(_line_segment(t, "transition", p, u_line, 0.0, v, t_acc, az))
        p = p + u_line * 0.5 * v * t_acc
        t += t_acc
        direction = 1.0
        radius = plan.line_spacing_m / 2.0
        for i in range(plan.n_lines):
            v = speeds[i]
            u = u_line * direction
            yaw = az if direction > 0 else az + math.pi
            dur = plan.line_length_m / v
            segs.append(_line_segment(t, "line", p, u, v, v, dur, yaw))
            spans.append((t, t + dur, v))
            p = p + u * plan.line_length_m
            t += dur
            if i + 1 < plan.n_lines:
                v_next = speeds[i + 1]
                centre = p + u_side * radius
                start_vec = p - centre
                ang0 = math.atan2(start_vec[1], start_vec[0])
                # Turn towards u_side: sign of the rotation from radial to travel direction.
                turn = 1.0 if (start_vec[0] * u[1] - start_vec[1] * u[0]) > 0 else -1.0
                dur_turn = math.pi * radius / (0.5 * (v + v_next))
                segs.append(_Segment(t, dur_turn, "arc", "turn", p.copy(), u, v, v_next, centre=centre,
                                     radius_m=radius, angle0_rad=ang0, turn=turn))
                p = segs[-1].end()[0]
                t += dur_turn
                direction = -direction
        # Decelerate to a hover after the last line.
        v = speeds[-1]
        u = u_line * direction
        yaw = az if direction > 0 else az + math.pi
        t_dec = v / plan.accel_m_s2
        segs.append(_line_segment(t, "transition", p, u, v, 0.0, t_dec, yaw))
        p = p + u * 0.5 * v * t_dec
        t += t_dec
        segs.append(_line_segment(t, "transition", p, u, 0.0, 0.0, 2.0, yaw))
        t += 2.0
        if plan.land:
            segs += _trapezoid(t, "descent", p, -up, plan.survey_height_m, plan.descent_rate_m_s,
                               plan.accel_m_s2, yaw)
            t = segs[-1].t0_s + segs[-1].dur_s
            p = p - up * plan.survey_height_m
            segs.append(_line_segment(t, "ground", p, u, 0.0, 0.0, 0.0, yaw))
        return segs, spans

    # ------------------------------------------------------------------------------------- queries
    def _segment_at(self, tau: float) -> tuple[int, _Segment]:
        idx = 0
        for i, seg in enumerate(self._segments):
            if seg.t0_s <= tau:
                idx = i
            else:
                break
        return idx, self._segments[idx]

    def _yaw_at(self, idx: int, tau: float) -> float:
        seg = self._segments[idx]
        if seg.kind == "arc":
            return seg.at(tau - seg.t0_s)[2]
        return seg.yaw_rad

    def _envelope(self, tau: float) -> float:
        """Wobble fade: 0 on the ground, 1 in flight, smoothstep over _FADE_S at takeoff and touchdown."""
        if not self.plan.fly:
            return 0.0

        def smooth(x: float) -> float:
            x = min(max(x, 0.0), 1.0)
            return x * x * (3.0 - 2.0 * x)

        return smooth((tau - self.takeoff_s) / _FADE_S) * smooth((self.landing_s - tau) / _FADE_S)

    def attitude_rad(self, tau: float, base_yaw_rad: float) -> tuple[float, float, float]:
        """(roll, pitch, yaw) rad at τ s after start, yaw = track heading + wobble."""
        amp = math.radians(self.plan.wobble_amplitude_deg) * self._envelope(tau)
        out = []
        for axis in ("roll", "pitch", "yaw"):
            out.append(amp * sum(w * math.sin(2 * math.pi * tau / per + ph) for w, per, ph in _WOBBLE[axis]))
        return out[0], out[1], base_yaw_rad + out[2]

    @staticmethod
    def r_cam_to_enu(roll: float, pitch: float, yaw: float) -> Vec:
        """Camera (x right, y down, z forward) → ENU rotation for a nadir camera at body attitude (ZYX, NED)."""
        cr, sr, cp, sp, cy, sy = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw), \
            math.sin(yaw)
        rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
        ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
        rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
        return _R_NED_TO_ENU @ rz @ ry @ rx @ _R_CAM_TO_BODY

    def enu_to_ecef(self, enu_m: Vec) -> Vec:
        """ENU point about the takeoff point → ECEF (m)."""
        return self.origin_ecef_m + self._r_enu_to_ecef @ enu_m

    def state_at_s(self, tau: float) -> FlightState:
        """State at τ seconds after the scenario start."""
        idx, seg = self._segment_at(tau)
        pos, vel, _ = seg.at(tau - seg.t0_s)
        if tau > seg.t0_s + seg.dur_s:
            vel = np.zeros(3)  # held after the last segment
        if tau < 0:
            vel = np.zeros(3)
        base_yaw = self._yaw_at(idx, tau)
        roll, pitch, yaw = self.attitude_rad(tau, base_yaw)
        r = self.r_cam_to_enu(roll, pitch, yaw)
        lever = np.asarray(self.plan.lever_arm_cam_m, dtype=float)
        cam_enu = pos - r @ lever
        armed = self.plan.fly and self.takeoff_s <= tau < self.landing_s
        line_index = -1
        for i, (a, b, _v) in enumerate(self.line_spans_s):
            if a <= tau < b:
                line_index = i
        return FlightState(
            pos_ecef_m=self.enu_to_ecef(pos), vel_ecef_m_s=self._r_enu_to_ecef @ vel, pos_enu_m=pos,
            vel_enu_m_s=vel, roll_rad=roll, pitch_rad=pitch, yaw_rad=(yaw + math.pi) % (2 * math.pi) - math.pi,
            r_cam_to_enu=r, camera_ecef_m=self.enu_to_ecef(cam_enu), camera_enu_m=cam_enu, armed=armed,
            phase=seg.phase, line_index=line_index,
        )

    def state(self, t: GpsTime) -> FlightState:
        """State at GPS time `t`."""
        return self.state_at_s(t.diff_s(self.start))

    def position_ecef_m(self, t: GpsTime) -> Vec:
        """Antenna phase centre (ECEF m) at `t` (no attitude work: the hot path of the observables)."""
        tau = t.diff_s(self.start)
        _, seg = self._segment_at(tau)
        return self.enu_to_ecef(seg.at(tau - seg.t0_s)[0])

    @property
    def duration_s(self) -> float:
        """Time from the start to the end of the last motion (landing or final hover), s."""
        return self.end_of_motion_s
