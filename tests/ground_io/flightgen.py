"""A synthetic survey flight written in the real file formats (truth in, truth out) for CLI/API tests.

Truth: antenna trajectory along 3 survey lines at 50 m (1 Hz, with velocities), camera poses in a relative frame
S⁻¹(ENU) with a known similarity, lever arm and shutter delay; files: `SOL.pos` (our writer), `events.csv`,
`poses.csv` (OPK, relative frame), `gcp.csv`.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ground.adjust.types import CameraPose
from ground.io.orientations import write_opk_csv
from ground.io.rotations import r_cam_to_world_from_opk_deg
from onboard.formats.pos import write_pos
from onboard.gnsstime import GpsTime
from onboard.rtk.geodesy import enu_to_ecef, llh_to_ecef
from onboard.rtk.types import Solution

ORIGIN_ECEF = llh_to_ecef(np.radians(48.0), np.radians(-2.0), 80.0)
START = GpsTime.from_week_tow_s(2300, 200_000.0)


@dataclass(frozen=True)
class Truth:
    lever_arm_m: np.ndarray
    delay_s: float
    scale: float
    rotation: np.ndarray
    translation_m: np.ndarray
    n_images: int


def _rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def antenna_enu(t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Three 120 m lines, 30 m apart, 5 m/s with a speed wobble (so delay and lever arm separate), 50 m up."""
    period = 40.0
    line = np.floor(t_s / period)
    u = (t_s % period) / period
    direction = np.where(line % 2 == 0, 1.0, -1.0)
    along = 120.0 * (u + 0.03 * np.sin(2 * np.pi * u * 3))
    e = np.where(direction > 0, along, 120.0 - along)
    n = 30.0 * line + 0.1 * np.sin(t_s * 0.3)
    up = 50.0 + 0.5 * np.sin(t_s * 0.1)
    pos = np.column_stack([e, n, up])
    dalong = 120.0 / period * (1 + 0.03 * 2 * np.pi * 3 * np.cos(2 * np.pi * u * 3))
    vel = np.column_stack([direction * dalong, 0.03 * np.cos(t_s * 0.3), 0.05 * np.cos(t_s * 0.1)])
    heading = np.where(direction > 0, 0.0, np.pi)
    return pos, vel, heading


def write_synthetic_flight(folder: Path, seed: int = 1, n_lines: int = 3, noise_m: float = 0.01,
                           with_gcp: bool = True) -> Truth:
    """Write SOL.pos, events.csv, poses.csv, gcp.csv into `folder`; return the truth."""
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    lever = np.array([0.05, -0.12, -0.08])
    delay = 0.065
    # trajectory, 5 Hz so the Hermite interpolation is exact enough for mm truth
    t = np.arange(0.0, 40.0 * n_lines, 0.2)
    pos_enu, vel_enu, _ = antenna_enu(t)
    pos_ecef = enu_to_ecef(pos_enu, ORIGIN_ECEF)
    rot = enu_to_ecef(vel_enu, ORIGIN_ECEF) - enu_to_ecef(np.zeros(3), ORIGIN_ECEF)
    sols = [
        Solution(time=START.add_s(float(ti)), pos_ecef_m=p, vel_ecef_m_s=v, q=1 if i % 97 else 2, ns=12,
                 cov_pos_m2=np.diag([1e-4, 1e-4, 4e-4]), cov_vel_m2_s2=np.eye(3) * 1e-4, age_s=1.0, ratio=5.0)
        for i, (ti, p, v) in enumerate(zip(t, pos_ecef, rot))
    ]
    write_pos(folder / "SOL.pos", sols, velocity=True)
    # similarity relative → ENU
    scale, r_sim, t_sim = 0.8, _rot_z(0.3), np.array([10.0, -5.0, 2.0])
    # exposures every 2 s, trigger events t_d before exposure
    t_exp = np.arange(3.0, 40.0 * n_lines - 3.0, 2.0) + 0.013
    g_exp, _, heading = antenna_enu(t_exp)
    poses, events = [], []
    for i, (te, g, h) in enumerate(zip(t_exp, g_exp, heading)):
        r_c2enu = _rot_z(-h) @ r_cam_to_world_from_opk_deg(rng.normal(0, 2), rng.normal(0, 2), 0.0)
        c_enu = g - r_c2enu @ lever + rng.normal(0, noise_m, 3)
        c_rel = r_sim.T @ (c_enu - t_sim) / scale
        poses.append(CameraPose(f"IMG_{i:04d}.JPG", c_rel, r_sim.T @ r_c2enu))
        ev = START.add_s(float(te - delay))
        events.append((f"IMG_{i:04d}.JPG", ev.week, ev.tow_ns / 1e9))
    write_opk_csv(folder / "poses.csv", poses)
    with (folder / "events.csv").open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["image", "week", "tow"])
        for name, week, tow in events:
            w.writerow([name, week, f"{tow:.9f}"])
    if with_gcp:
        with (folder / "gcp.csv").open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["name", "role", "x_rel", "y_rel", "z_rel", "X", "Y", "Z"])
            pts = [("G1", "gcp", [20, 10, 0.5]), ("G2", "gcp", [100, 50, 1.0]), ("G3", "gcp", [60, 30, 0.0]),
                   ("C1", "check", [40, 20, 0.2]), ("C2", "check", [90, 5, 0.8])]
            for name, role, enu in pts:
                enu = np.array(enu, float)
                rel = r_sim.T @ (enu - t_sim) / scale
                ecef = enu_to_ecef(enu + rng.normal(0, 0.005, 3), ORIGIN_ECEF)
                w.writerow([name, role, *[f"{v:.6f}" for v in rel], *[f"{v:.4f}" for v in ecef]])
    return Truth(lever, delay, scale, r_sim, t_sim, len(poses))
