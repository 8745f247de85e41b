"""Post-processing runs over paired rover/base epoch streams: forward, backward, combined.

Follows RTKLIB postpos.c: base epochs are paired causally with rover epochs (latest base epoch at or before
the rover epoch, within a small tolerance for the …999 ms / …992 ms receiver tags); the combined solution
smooths forward and backward filters and validates fixes across both (RTKLIB combres/valcomb). Pure.
"""

from __future__ import annotations

import bisect
import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from onboard.gnsstime import GpsTime
from onboard.rtk.options import RtkOptions
from onboard.rtk.rtkpos import NavData, rtk_init, rtk_pos
from onboard.rtk.types import LLI_SLIP, Q_FIX, Q_FLOAT, Q_NONE, ObsEpoch, Solution

log = logging.getLogger(__name__)

Arr = npt.NDArray[np.float64]
DIRECTIONS = ("forward", "backward", "combined")
COMBINE_FIX_AGREEMENT_M = 0.05
"""Forward and backward fixes further apart than this (3D, m) are not reported as fixed."""
COMBINE_FLOAT_VOUCH_M = 0.5
"""A fix in one direction is kept where the other is float only if that float's 3D σ is below this (m)."""


def pair_epochs(rover: Sequence[ObsEpoch], base: Sequence[ObsEpoch], tolerance_s: float = 0.025,
                max_age_s: float = 30.0) -> list[ObsEpoch | None]:
    """For each rover epoch, the latest base epoch with t_base ≤ t_rover + tolerance (None when none or
    older than `max_age_s`). Base epochs without GPS observations are skipped (a lossy RTCM link can deliver
    GLONASS-only epochs)."""
    usable = [b for b in base if len(b.gps_only()) > 0]
    usable.sort(key=lambda b: b.time)
    keys = [b.time.total_ns for b in usable]
    tol_ns = round(tolerance_s * 1e9)
    out: list[ObsEpoch | None] = []
    for r in rover:
        i = bisect.bisect_right(keys, r.time.total_ns + tol_ns) - 1
        if i < 0:
            out.append(None)
            continue
        b = usable[i]
        out.append(b if r.time.diff_s(b.time) <= max_age_s else None)
    return out


@dataclass
class RunStats:
    """Counts of one run: epochs, solutions per Q, cycle slips detected."""

    epochs: int = 0
    fixed: int = 0
    float_: int = 0
    single: int = 0
    slips: int = 0


def reverse_slip_flags(epochs: Sequence[ObsEpoch]) -> list[ObsEpoch]:
    """Epochs for a backward pass: each observation gets the loss-of-lock bit of the satellite's next phase
    observation in time.

    LLI bit 0 says "lost lock since the previous phase observation"; processed in reverse, the slip lies
    between this epoch and the one processed next (RTKLIB postpos does the same for its backward solution).
    Gaps count: a flag on the epoch after a phase gap belongs to the epoch before the gap."""
    by_time = sorted(epochs, key=lambda e: e.time)
    pending: dict[tuple[int, int], int] = {}  # flag of the later phase observation, per satellite
    out: list[ObsEpoch] = [by_time[0]] * len(by_time) if by_time else []
    for k in range(len(by_time) - 1, -1, -1):
        ep = by_time[k]
        lli = ep.lli & ~np.uint8(LLI_SLIP)
        for j, (g, sv) in enumerate(zip(ep.gnss_id, ep.sv_id)):
            key = (int(g), int(sv))
            if not np.isfinite(ep.cp_cyc[j]):
                continue
            lli[j] |= pending.get(key, 0)
            pending[key] = int(ep.lli[j]) & LLI_SLIP
        out[k] = replace(ep, lli=lli.astype(np.uint8))
    return out


def run_filter(rover: Sequence[ObsEpoch], paired_base: Sequence[ObsEpoch | None], nav: NavData,
               base_pos_ecef_m: Arr | None, options: RtkOptions, backward: bool = False,
               init_pos_ecef_m: Arr | None = None, progress: Callable[[int], None] | None = None
               ) -> tuple[list[Solution], RunStats]:
    """One filter pass over all rover epochs (in time order, or reversed when `backward`).

    Returns the solutions in time order (index-aligned with `rover`) and run statistics.
    """
    st = rtk_init(options, None if backward else init_pos_ecef_m)
    order = range(len(rover) - 1, -1, -1) if backward else range(len(rover))
    if backward:
        rover = reverse_slip_flags(rover)
        base_rev = {id(b): r for b, r in zip(
            sorted({id(b): b for b in paired_base if b is not None}.values(), key=lambda e: e.time),
            reverse_slip_flags(sorted({id(b): b for b in paired_base if b is not None}.values(),
                                      key=lambda e: e.time)))}
        paired_base = [None if b is None else base_rev[id(b)] for b in paired_base]
    sols: list[Solution | None] = [None] * len(rover)
    stats = RunStats(epochs=len(rover))
    for i in order:
        sol = rtk_pos(st, rover[i], paired_base[i], nav, base_pos_ecef_m)
        sols[i] = sol
        stats.fixed += sol.q == Q_FIX
        stats.float_ += sol.q == Q_FLOAT
        stats.single += sol.q not in (Q_FIX, Q_FLOAT)
        if progress is not None:
            progress(1)
    stats.slips = st.slips
    return [s for s in sols if s is not None], stats


def _smooth(a: Solution, b: Solution) -> tuple[Arr, Arr]:
    """Two-filter smoother (RTKLIB smoother()): inverse-covariance weighted mean of two estimates."""
    try:
        ia = np.linalg.inv(a.cov_pos_m2)
        ib = np.linalg.inv(b.cov_pos_m2)
        cov = np.linalg.inv(ia + ib)
        return cov @ (ia @ a.pos_ecef_m + ib @ b.pos_ecef_m), cov
    except np.linalg.LinAlgError:
        return 0.5 * (a.pos_ecef_m + b.pos_ecef_m), 0.5 * (a.cov_pos_m2 + b.cov_pos_m2)


def _consistent(fixed: Solution, other: Solution) -> bool:
    """Is a fixed position inside the 99.9 % ellipsoid of the other direction's float covariance?"""
    d = fixed.pos_ecef_m - other.pos_ecef_m
    try:
        return float(d @ np.linalg.solve(other.cov_pos_m2 + fixed.cov_pos_m2, d)) <= 16.27
    except np.linalg.LinAlgError:
        return False


def combine(fwd: Solution, bwd: Solution) -> Solution:
    """Combine one epoch's forward and backward solutions (RTKLIB combres with fix validation)."""
    if fwd.q == Q_NONE:
        return bwd
    if bwd.q == Q_NONE:
        return fwd
    if fwd.q == Q_FIX and bwd.q == Q_FIX:
        pos, cov = _smooth(fwd, bwd)
        agree = np.linalg.norm(fwd.pos_ecef_m - bwd.pos_ecef_m) <= COMBINE_FIX_AGREEMENT_M
        q = Q_FIX if agree else Q_FLOAT
        ratio = min(fwd.ratio, bwd.ratio)
        if not agree:
            ff = fwd.__class__
            return ff(fwd.time, pos, fwd.vel_ecef_m_s, Q_FLOAT, max(fwd.ns, bwd.ns), cov + np.eye(3) * 0.01,
                      fwd.cov_vel_m2_s2, fwd.age_s, ratio)
        return Solution(fwd.time, pos, fwd.vel_ecef_m_s, q, max(fwd.ns, bwd.ns), cov, fwd.cov_vel_m2_s2,
                        fwd.age_s, ratio)
    if fwd.q == Q_FIX or bwd.q == Q_FIX:
        fixed, other = (fwd, bwd) if fwd.q == Q_FIX else (bwd, fwd)
        if other.q != Q_FLOAT:
            return fixed
        # the other direction's float must be converged enough to vouch for the fix, and agree with it
        if float(np.sqrt(np.trace(other.cov_pos_m2))) <= COMBINE_FLOAT_VOUCH_M and _consistent(fixed, other):
            return fixed
        pos, cov = _smooth(fwd, bwd)
        return Solution(fwd.time, pos, fwd.vel_ecef_m_s, Q_FLOAT, max(fwd.ns, bwd.ns), cov, fwd.cov_vel_m2_s2,
                        fwd.age_s, fixed.ratio)
    if fwd.q == bwd.q:
        pos, cov = _smooth(fwd, bwd)
        return Solution(fwd.time, pos, fwd.vel_ecef_m_s, fwd.q, max(fwd.ns, bwd.ns), cov, fwd.cov_vel_m2_s2,
                        fwd.age_s, max(fwd.ratio, bwd.ratio))
    return fwd if fwd.q < bwd.q else bwd


def postprocess(rover: Sequence[ObsEpoch], base: Sequence[ObsEpoch], nav: NavData, base_pos_ecef_m: Arr | None,
                options: RtkOptions, direction: str = "forward", init_pos_ecef_m: Arr | None = None,
                progress: Callable[[int], None] | None = None) -> tuple[list[Solution], list[RunStats]]:
    """Pair, then run forward, backward or both and combine. Rover epochs are processed in time order."""
    if direction not in DIRECTIONS:
        raise ValueError(f"direction must be one of {DIRECTIONS}, not {direction!r}")
    rov = sorted(rover, key=lambda e: e.time)
    paired = pair_epochs(rov, base, options.pair_tolerance_s, options.max_age_s)
    if direction == "forward":
        sols, st = run_filter(rov, paired, nav, base_pos_ecef_m, options, False, init_pos_ecef_m, progress)
        return sols, [st]
    if direction == "backward":
        sols, st = run_filter(rov, paired, nav, base_pos_ecef_m, options, True, init_pos_ecef_m, progress)
        return sols, [st]
    f, sf = run_filter(rov, paired, nav, base_pos_ecef_m, options, False, init_pos_ecef_m, progress)
    b, sb = run_filter(rov, paired, nav, base_pos_ecef_m, options, True, init_pos_ecef_m, progress)
    return [combine(x, y) for x, y in zip(f, b, strict=True)], [sf, sb]


def first_time(epochs: Sequence[ObsEpoch]) -> GpsTime | None:
    """Time of the first epoch, None for an empty stream."""
    return min((e.time for e in epochs), default=None)
