"""RTKLIB-format `.pos` → `ground.adjust.types.Trajectory` (ECEF), through `onboard.formats.pos.read_pos`.

llh files carry σ and velocity in local n/e/u: they are rotated to ECEF here (diagonal variances only), so the
adjustment sees one frame whatever wrote the file (ours or RTKLIB's).

Only solution rows become antenna positions: Q 1 (fix) and 2 (float), and 5 (single point, metre-level) only
when asked. Rows of Q 0 (no solution), of another Q, with a position at the Earth's centre (`0,0,0`, what a
writer puts in a row it has no solution for) or with non-finite numbers are left out and counted.
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np
import numpy.typing as npt

from ground.adjust.types import Trajectory
from ground.io.errors import FormatError
from onboard.errors import InputError
from onboard.formats.pos import PosTrack, read_pos
from onboard.rtk.geodesy import ecef_to_llh, enu_rotation

log = logging.getLogger(__name__)

SOLUTION_QUALITIES = (1, 2)
"""RTKLIB Q values read as antenna positions by default: 1 fix, 2 float."""
Q_SINGLE = 5
"""Single-point rows: metre-level, read only when asked (`accept_single`)."""
MIN_GEOCENTRIC_RADIUS_M = 6.0e6
"""A row nearer the Earth's centre than this is no antenna position (e.g. the `0,0,0` of a row without solution)."""


def solution_rows(track: PosTrack, accept_single: bool = False) -> tuple[npt.NDArray[np.bool_], dict[str, int]]:
    """Which rows of `track` are antenna positions, and how many of the others were left out, by reason."""
    q = np.asarray(track.q)
    pos = np.asarray(track.pos_ecef_m, dtype=float).reshape(-1, 3)
    allowed = SOLUTION_QUALITIES + ((Q_SINGLE,) if accept_single else ())
    finite = np.all(np.isfinite(pos), axis=1) & np.all(np.isfinite(np.asarray(track.sd_m, dtype=float)[:, :3]),
                                                       axis=1)
    with np.errstate(invalid="ignore"):
        radius = np.linalg.norm(np.where(np.isfinite(pos), pos, 0.0), axis=1)
    reasons = {
        "no solution (Q=0)": q == 0,
        "single point (Q=5; accept with --accept-single)": (q == Q_SINGLE) & (not accept_single),
        "other Q": ~np.isin(q, (0, Q_SINGLE) + SOLUTION_QUALITIES),
    }
    keep = np.isin(q, allowed)
    counts = {k: int(np.sum(v)) for k, v in reasons.items() if np.any(v)}
    bad_values = keep & ~finite
    off_earth = keep & finite & (radius < MIN_GEOCENTRIC_RADIUS_M)
    if np.any(bad_values):
        counts["non-finite position or σ"] = int(np.sum(bad_values))
    if np.any(off_earth):
        counts["position at the Earth's centre (0,0,0)"] = int(np.sum(off_earth))
    return keep & finite & ~off_earth, counts


def trajectory_from_track(track: PosTrack, source: str = "<pos>", accept_single: bool = False) -> Trajectory:
    """Convert a read .pos track into a `Trajectory` (ns since GPS epoch, ECEF m, σ x/y/z, q) of its solution
    rows only (see the module docstring); raises FormatError when fewer than 2 remain."""
    keep, dropped = solution_rows(track, accept_single)
    if dropped:
        log.warning("%s: %d row(s) left out of the trajectory: %s", source, sum(dropped.values()),
                    ", ".join(f"{n} {why}" for why, n in dropped.items()))
    if not np.all(keep):
        idx = np.flatnonzero(keep)
        track = replace(
            track, time=[track.time[i] for i in idx], pos_ecef_m=track.pos_ecef_m[idx], q=track.q[idx],
            ns=track.ns[idx], sd_m=track.sd_m[idx], age_s=track.age_s[idx], ratio=track.ratio[idx],
            vel_m_s=None if track.vel_m_s is None else track.vel_m_s[idx],
        )
    n = len(track.time)
    if n < 2:
        what = "; left out: " + ", ".join(f"{k} {w}" for w, k in dropped.items()) if dropped else ""
        raise FormatError(source, f"the trajectory has {n} solution epoch(s); at least 2 are needed{what}")
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


def read_trajectory(path: str, accept_single: bool = False) -> Trajectory:
    """Read an RTKLIB .pos file (xyz or llh, week/tow or calendar GPST, with or without velocity): its solution
    rows (Q 1/2, and 5 when `accept_single`)."""
    try:
        track = read_pos(path)
    except InputError as exc:
        raise FormatError(path, str(exc)) from exc
    return trajectory_from_track(track, source=str(path), accept_single=accept_single)
