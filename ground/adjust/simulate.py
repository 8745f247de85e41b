"""Synthetic survey blocks for the adjustment's round-trip tests and benchmark (pure: an rng is passed in).

A multicopter flies: hover, climb (photos), survey lines at a different speed per line (or one constant speed),
semicircular turns, descent (photos). The velocity command goes through two cascaded first-order lags, so the
path has continuous velocity and acceleration like a real drone. The camera looks at nadir, image top forward
(camera x right, y down = backwards along track, z forward = down), with a ±wobble on roll/pitch/yaw. The
antenna follows the path; the camera centre is C = A − R_cam→ENU·O. The bundle adjustment's relative frame is a
random similarity of ENU with centre and angle noise; the RTK trajectory has white plus Gauss-Markov noise; ground
points (GCPs / check points) lie on a gently rolling terrain.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import numpy.typing as npt
from scipy.signal import lfilter

from ground.adjust.similarity import Similarity, so3_exp
from ground.adjust.types import CameraPose, ControlPoint, ImageEvent, Trajectory
from onboard.gnsstime import GpsTime
from onboard.rtk.geodesy import ecef_to_llh, enu_rotation, llh_to_ecef

Arr = npt.NDArray[np.float64]
_DT_S = 0.01  # integration step of the flight dynamics


@dataclass(frozen=True)
class BlockOptions:
    """What to simulate (units in names). Defaults: an 8-line block at 50 m, 4–5 m/s, u-blox RTK-like noise."""

    n_lines: int = 8
    line_length_m: float = 150.0
    line_spacing_m: float = 20.0
    altitude_m: float = 50.0
    speed_range_m_s: tuple[float, float] = (4.0, 5.0)
    constant_speed_m_s: float | None = None  # every line at this speed (the unidentifiable along-track case)
    turn_speed_m_s: float = 3.0
    climb_rate_m_s: float = 2.0
    lag_time_constant_s: float = 0.6
    photo_interval_s: float = 0.8
    photos_in_climb_descent: bool = True
    heading_mode: Literal["track", "fixed"] = "track"
    wobble_deg: float = 3.0
    lever_arm_m: tuple[float, float, float] = (0.04, -0.11, -0.09)
    delay_s: float = 0.064
    event_kind: Literal["trigger", "flash"] = "trigger"
    trajectory_rate_hz: float = 5.0
    gnss_white_sigma_m: tuple[float, float, float] = (0.005, 0.005, 0.009)
    gnss_correlated_sigma_m: tuple[float, float, float] = (0.003, 0.003, 0.005)
    gnss_correlation_time_s: float = 30.0
    gnss_bias_m: tuple[float, float, float] = (0.0, 0.0, 0.0)  # constant offset (float ambiguities, datum)
    velocity_sigma_m_s: float = 0.02
    with_velocities: bool = True  # False: the trajectory has no velocities (central differences are used)
    camera_centre_noise_m: float = 0.0058  # per axis: ~1 cm in 3D
    camera_angle_noise_deg: float = 0.01
    n_ground_points: int = 12
    gcp_names: tuple[str, ...] = ()  # which ground points are GCPs (the others are check points)
    ground_sigma_m: float = 0.003  # survey σ of the ground coordinates
    rel_point_noise_m: float = 0.003  # bundle adjustment noise of ground points, ENU m
    origin_llh_deg_m: tuple[float, float, float] = (48.5, -3.5, 80.0)
    gps_week: int = 2400
    start_tow_s: float = 302400.0


@dataclass(frozen=True)
class FlightTruth:
    """A flown path, whatever produced it: antenna truth at the RTK epochs, camera truth at the exposures.

    Times in seconds after `start`; positions/velocities in ENU about `origin_ecef_m`; `r_cam_to_enu` (n,3,3)
    camera (x right, y down, z forward) → ENU; `centres_enu_m` = antenna − R·`lever_arm_m` at each exposure.
    """

    start: GpsTime
    traj_t_s: Arr
    traj_pos_enu_m: Arr
    traj_vel_enu_m_s: Arr
    exposure_s: Arr
    centres_enu_m: Arr
    r_cam_to_enu: Arr
    lever_arm_m: Arr
    origin_ecef_m: Arr
    #: event (trigger pulse or flash mark) times, s after `start`; None: exposure − options.delay_s
    event_s: Arr | None = None


@dataclass(frozen=True)
class SimulatedBlock:
    """Observations (what the adjustment sees) and the truth they came from."""

    poses: tuple[CameraPose, ...]
    events: tuple[ImageEvent, ...]
    trajectory: Trajectory
    control: tuple[ControlPoint, ...]
    origin_ecef_m: Arr
    truth_similarity: Similarity  # relative frame → ENU
    truth_lever_arm_m: Arr
    truth_delay_s: float
    truth_centres_enu_m: Arr  # (n,3) camera centres at exposure
    truth_ground_enu_m: dict[str, Arr] = field(default_factory=dict)


def _lag_path(cmd: Arr, tau_s: float) -> tuple[Arr, Arr]:
    """Velocity command (n,3) through two cascaded first-order lags; returns position and velocity (n,3)."""
    a = _DT_S / (tau_s + _DT_S)
    # v[k] = v[k−1] + a·(u[k] − v[k−1]), twice, starting at rest
    v1 = lfilter([a], [1.0, -(1.0 - a)], cmd, axis=0)
    v2 = lfilter([a], [1.0, -(1.0 - a)], v1, axis=0)
    pos = np.concatenate([np.zeros((1, 3)), np.cumsum((v2[1:] + v2[:-1]) * 0.5 * _DT_S, axis=0)])
    return pos, v2


def _random_rotation(rng: np.random.Generator) -> Arr:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 2] = -q[:, 2]
    return q


def _nadir_camera(heading_rad: float) -> Arr:
    """Camera→ENU for a nadir camera with image top towards `heading` (rad from north, clockwise)."""
    d = np.array([np.sin(heading_rad), np.cos(heading_rad), 0.0])
    z = np.array([0.0, 0.0, -1.0])
    y = -d
    x = np.cross(y, z)
    return np.column_stack([x, y, z])


def simulate_block(options: BlockOptions, rng: np.random.Generator) -> SimulatedBlock:
    """Simulate one flight and its observations (see the module docstring)."""
    o = options
    cmds: list[Arr] = []
    photo_flags: list[npt.NDArray[np.bool_]] = []

    def segment(vel: Arr | list[Arr], photos: bool) -> None:
        arr = np.atleast_2d(np.asarray(vel, dtype=float))
        cmds.append(arr)
        photo_flags.append(np.full(arr.shape[0], photos))

    def hold(vel: tuple[float, float, float], duration_s: float, photos: bool) -> None:
        n = max(round(duration_s / _DT_S), 1)
        segment(np.tile(np.asarray(vel, dtype=float), (n, 1)), photos)

    hold((0, 0, 0), 3.0, False)
    hold((0, 0, o.climb_rate_m_s), o.altitude_m / o.climb_rate_m_s, o.photos_in_climb_descent)
    hold((0, 0, 0), 2.0, False)
    speeds = (
        np.full(o.n_lines, o.constant_speed_m_s)
        if o.constant_speed_m_s is not None
        else rng.permutation(np.linspace(o.speed_range_m_s[0], o.speed_range_m_s[1], o.n_lines))
    )
    for k in range(o.n_lines):
        sign = 1.0 if k % 2 == 0 else -1.0
        hold((0, sign * speeds[k], 0), o.line_length_m / speeds[k], True)
        if k < o.n_lines - 1:
            r = o.line_spacing_m / 2
            dur = np.pi * r / o.turn_speed_m_s
            n = round(dur / _DT_S)
            ang = np.linspace(0, np.pi, n)
            # turn towards +east: the direction sweeps from ±north through east to ∓north
            vel = o.turn_speed_m_s * np.column_stack([np.sin(ang), sign * np.cos(ang), np.zeros(n)])
            segment(vel, False)
    hold((0, 0, 0), 2.0, False)
    hold((0, 0, -o.climb_rate_m_s), (o.altitude_m - 2.0) / o.climb_rate_m_s, o.photos_in_climb_descent)
    hold((0, 0, 0), 3.0, False)
    cmd = np.vstack(cmds)
    photo_ok = np.concatenate(photo_flags)
    pos, vel = _lag_path(cmd, o.lag_time_constant_s)
    t = np.arange(cmd.shape[0]) * _DT_S
    speed_h = np.linalg.norm(vel[:, :2], axis=1)
    heading = np.zeros(t.size)
    if o.heading_mode == "track":
        h = np.arctan2(vel[:, 0], vel[:, 1])
        moving = speed_h > 0.5
        first = int(np.argmax(moving)) if np.any(moving) else 0
        cur = h[first]
        for k in range(t.size):
            if moving[k]:
                cur = h[k]
            heading[k] = cur

    def path_at(tq: Arr) -> tuple[Arr, Arr]:
        """Cubic Hermite on the dense path (exact to far below a millimetre at 100 Hz)."""
        k = np.clip((tq / _DT_S).astype(int), 0, t.size - 2)
        s = (tq - t[k]) / _DT_S
        h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
        d00, d10, d01, d11 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, -6 * s**2 + 6 * s, 3 * s**2 - 2 * s
        p = h00[:, None] * pos[k] + h10[:, None] * _DT_S * vel[k] + h01[:, None] * pos[k + 1]
        p += h11[:, None] * _DT_S * vel[k + 1]
        v = (d00[:, None] * pos[k] + d10[:, None] * _DT_S * vel[k] + d01[:, None] * pos[k + 1]) / _DT_S
        v += d11[:, None] * vel[k + 1]
        return p, v

    freqs = rng.uniform(0.05, 0.25, size=3)
    phases = rng.uniform(0, 2 * np.pi, size=3)

    def attitude(tq: float) -> Arr:
        kk = min(int(tq / _DT_S), t.size - 1)
        ang = np.radians(o.wobble_deg) * np.sin(2 * np.pi * freqs * tq + phases)
        return _nadir_camera(heading[kk]) @ so3_exp(ang)

    # photos: every photo_interval_s while photo_ok, event = exposure − delay
    exposures: list[float] = []
    t_next = 0.0
    for k in range(t.size):
        if photo_ok[k] and t[k] >= t_next and t[k] > 1.0:
            exposures.append(t[k] + rng.uniform(0, 0.009))
            t_next = t[k] + o.photo_interval_s
    t_exp = np.array(exposures)
    lever = np.asarray(o.lever_arm_m, dtype=float)
    ant_exp, _ = path_at(t_exp)
    r_c2e = np.array([attitude(tx) for tx in t_exp])
    centres = ant_exp - r_c2e @ lever

    step = round(1.0 / (o.trajectory_rate_hz * _DT_S))
    lat, lon, height_m = o.origin_llh_deg_m
    truth = FlightTruth(
        start=GpsTime.from_week_tow_s(o.gps_week, o.start_tow_s),
        traj_t_s=np.asarray(t[::step], dtype=np.float64),
        traj_pos_enu_m=pos[::step],
        traj_vel_enu_m_s=vel[::step],
        exposure_s=t_exp,
        centres_enu_m=centres,
        r_cam_to_enu=r_c2e,
        lever_arm_m=lever,
        origin_ecef_m=llh_to_ecef(np.radians(lat), np.radians(lon), height_m),
    )
    return observe_flight(truth, o, rng)


def observe_flight(truth: FlightTruth, options: BlockOptions, rng: np.random.Generator) -> SimulatedBlock:
    """What the adjustment would see of a flight: relative frame, camera noise, events, RTK trajectory, GCPs.

    Uses the observation fields of `options` (delay, event kind, noise, ground points); the flight itself
    (path, attitude, exposures, lever arm) comes from `truth`, e.g. from hil_sim's flight model in the tests.
    """
    o = options
    t_exp = truth.exposure_s
    centres = truth.centres_enu_m
    r_c2e = truth.r_cam_to_enu
    lever = truth.lever_arm_m
    # bundle adjustment relative frame: ENU = T + μ R rel
    sim = Similarity(float(np.exp(rng.uniform(np.log(0.2), np.log(5.0)))), _random_rotation(rng),
                     rng.uniform(-500, 500, size=3))  # fmt: skip
    inv = sim.inverse()
    noisy_c = centres + rng.normal(0, o.camera_centre_noise_m, size=centres.shape)
    rel_c = inv.apply(noisy_c)
    ang_noise = rng.normal(0, np.radians(o.camera_angle_noise_deg), size=(t_exp.size, 3))
    rel_r = np.array([sim.rotation.T @ r @ so3_exp(w) for r, w in zip(r_c2e, ang_noise, strict=True)])

    t0_ns = truth.start.total_ns
    names = [f"IMG_{i:05d}.JPG" for i in range(t_exp.size)]
    poses = tuple(CameraPose(nm, rel_c[i], rel_r[i]) for i, nm in enumerate(names))
    t_event = t_exp - o.delay_s if truth.event_s is None else truth.event_s
    delay_s = o.delay_s if truth.event_s is None else float(np.mean(t_exp - truth.event_s))
    events = tuple(
        ImageEvent(nm, GpsTime.from_total_ns(t0_ns + round(t_event[i] * 1e9)), o.event_kind)
        for i, nm in enumerate(names)
    )

    # RTK-like trajectory at trajectory_rate_hz, ECEF
    tk = truth.traj_t_s
    pk, vk = truth.traj_pos_enu_m, truth.traj_vel_enu_m_s
    a = np.exp(-(tk[1] - tk[0]) / o.gnss_correlation_time_s)
    gm = np.zeros_like(pk)
    gm[0] = rng.normal(0, o.gnss_correlated_sigma_m)
    drive = rng.normal(0, 1, size=pk.shape) * np.asarray(o.gnss_correlated_sigma_m) * np.sqrt(1 - a * a)
    for k in range(1, tk.size):
        gm[k] = a * gm[k - 1] + drive[k]
    noise = (
        gm + rng.normal(0, 1, size=pk.shape) * np.asarray(o.gnss_white_sigma_m) + np.asarray(o.gnss_bias_m)
    )
    origin = truth.origin_ecef_m
    lat, lon, _ = ecef_to_llh(origin)
    rot = enu_rotation(lat, lon)  # ecef → enu
    pos_ecef = origin + (pk + noise) @ rot
    vel_ecef = (vk + rng.normal(0, o.velocity_sigma_m_s, size=vk.shape)) @ rot
    sd_enu = np.sqrt(np.asarray(o.gnss_white_sigma_m) ** 2 + np.asarray(o.gnss_correlated_sigma_m) ** 2)
    sd_ecef = np.sqrt((sd_enu**2) @ (rot**2))
    traj = Trajectory(
        t_ns=(t0_ns + np.round(tk * 1e9)).astype(np.int64),
        pos_ecef_m=pos_ecef,
        vel_ecef_m_s=vel_ecef if o.with_velocities else None,
        sd_m=np.tile(sd_ecef, (tk.size, 1)),
        q=np.ones(tk.size, dtype=np.int8),
    )

    # ground points on a rolling terrain inside the block
    lo, hi = np.percentile(centres[:, :2], [5, 95], axis=0)  # the block's footprint, trimmed
    control = []
    truth_ground: dict[str, Arr] = {}
    n_side = int(np.ceil(np.sqrt(o.n_ground_points)))
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], n_side), np.linspace(lo[1], hi[1], n_side))
    for j in range(o.n_ground_points):
        name = f"P{j:02d}"
        p_true = np.array([gx.ravel()[j], gy.ravel()[j], 2.0 * np.sin(gx.ravel()[j] / 30.0)])
        p_true[:2] += rng.uniform(-3, 3, size=2)
        truth_ground[name] = p_true
        rel = inv.apply(p_true + rng.normal(0, o.rel_point_noise_m, size=3))
        ground = p_true + rng.normal(0, o.ground_sigma_m, size=3)
        sig = np.full(3, np.hypot(o.ground_sigma_m, o.rel_point_noise_m))
        control.append(ControlPoint(name, "gcp" if name in o.gcp_names else "check", rel, ground, sig))
    return SimulatedBlock(
        poses, events, traj, tuple(control), origin, sim, lever, delay_s, centres, truth_ground
    )
