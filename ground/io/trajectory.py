"""RTKLIB-format `.pos` → `ground.adjust.types.Trajectory` (ECEF), through `onboard.formats.pos.read_pos`.

llh files carry σ and velocity in local n/e/u: they are rotated to ECEF here (diagonal variances only), so the
adjustment sees one frame whatever wrote the file (ours or RTKLIB's).
"""

from __future__ import annotations

import numpy as np

from ground.adjust.types import Trajectory
from ground.io.errors import FormatError
from onboard.errors import InputError
from onboard.formats.pos import PosTrack, read_pos
from onboard.rtk.geodesy import ecef_to_llh, enu_rotation


def trajectory_from_track(track: PosTrack, source: str = "<pos>") -> Trajectory:
    """Convert a read .pos track into a `Trajectory` (ns since GPS epoch, ECEF m, σ x/y/z, q)."""
    n = len(track.time)
    if n < 2:
        raise FormatError(source, f"the trajectory has {n} epoch(s); at least 2 are needed")
    t_ns = np.array([t.total_ns for t in track.time], dtype=np.int64)
    order = np.argsort(t_ns, kind="stable")
    if np.any(np.diff(t_ns[order]) == 0):
        raise FormatError(source, "duplicated epochs in the trajectory")
    pos = np.asarray(track.pos_ecef_m, dtype=float)
    sd = np.abs(np.asarray(track.sd_m[:, :3], dtype=float))
    vel = None if track.vel_m_s is None else np.asarray(track.vel_m_s, dtype=float)
    if track.llh:
        # columns are (n, e, u) for σ and velocity: rotate to ECEF epoch by epoch
        sd_ecef = np.empty_like(sd)
        vel_ecef = None if vel is None else np.empty_like(vel)
        for i in range(n):
            lat, lon, _ = ecef_to_llh(pos[i])
            r = enu_rotation(lat, lon)  # v_enu = r @ v_ecef
            var_enu = np.array([sd[i, 1], sd[i, 0], sd[i, 2]]) ** 2
            sd_ecef[i] = np.sqrt((r.T**2) @ var_enu)
            if vel is not None and vel_ecef is not None:
                vel_ecef[i] = r.T @ np.array([vel[i, 1], vel[i, 0], vel[i, 2]])
        sd, vel = sd_ecef, vel_ecef
    return Trajectory(
        t_ns=t_ns[order],
        pos_ecef_m=pos[order],
        vel_ecef_m_s=None if vel is None else vel[order],
        sd_m=sd[order],
        q=np.asarray(track.q, dtype=np.int8)[order],
    )


def read_trajectory(path: str) -> Trajectory:
    """Read an RTKLIB .pos file (xyz or llh, week/tow or calendar GPST, with or without velocity)."""
    try:
        track = read_pos(path)
    except InputError as exc:
        raise FormatError(path, str(exc)) from exc
    return trajectory_from_track(track, source=str(path))
