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
from onboard.rtk.rtkpos import NavData, epoch_receivers, epoch_spp, rtk_init, rtk_pos
from onboard.rtk.slots import slot_layout
from onboard.rtk.types import LLI_SLIP, Q_FIX, Q_FLOAT, Q_NONE, BasePositionRejected, ObsEpoch, Solution

log = logging.getLogger(__name__)

Arr = npt.NDArray[np.float64]
DIRECTIONS = ("forward", "backward", "combined")
COMBINE_FIX_AGREEMENT_M = 0.05
"""Forward and backward fixes further apart than this (3D, m) are not reported as fixed. A float whose 3D σ
is below it (a state just released from a hold) takes part in the test as a fix would."""


BASE_CHECK_EPOCHS = 60
"""Base epochs (spread over the data) whose single-point solutions test the given base position: their median
is good to about a metre, and 60 single points cost a few milliseconds."""


def _finite_position(name: str, pos_ecef_m: Arr | None) -> Arr | None:
    """`pos_ecef_m` as a (3,) float array; ValueError when it is not three finite ECEF coordinates (m)."""
    if pos_ecef_m is None:
        return None
    pos = np.asarray(pos_ecef_m, float)
    if pos.shape != (3,) or not np.all(np.isfinite(pos)):
        raise ValueError(f"{name} {pos_ecef_m!r}: must be three finite ECEF coordinates in metres")
    return pos


def base_spp_offset_m(base: Sequence[ObsEpoch], nav: NavData, base_pos_ecef_m: Arr, options: RtkOptions
                      ) -> tuple[float, int] | None:
    """(3D distance in m between `base_pos_ecef_m` and the median single-point position of up to
    BASE_CHECK_EPOCHS base epochs spread over the data, on the constellations of `options`, how many epochs
    solved); None when none solves (no ephemerides for them: nothing contradicts the position)."""
    gps = sorted((b for b in base if len(b.gps_only()) > 0), key=lambda e: e.time)
    if not gps:
        return None
    sample = gps[:: max(1, len(gps) // BASE_CHECK_EPOCHS)][:BASE_CHECK_EPOCHS]
    # the engine's constellations: a base tracking few GPS satellites beside the others is judged on all it
    # tracks (hil_sim's 5-satellite GPS+GLONASS sky, 3-4 of them GPS: on GPS alone 3 of 60 epochs solved, GDOP
    # 37, median 55 m off: refused; on both 48 solved, median 8.9 m)
    layout = slot_layout(options.systems)
    spps = epoch_spp(sample, epoch_receivers(sample, nav.store, None, layout, getattr(nav, "broadcast", None)),
                     nav, options)
    pos = np.array([s.pos_ecef_m for s in spps if s.ok])
    if pos.size == 0:
        return None
    return float(np.linalg.norm(np.median(pos, axis=0) - base_pos_ecef_m)), int(pos.shape[0])


def check_base_position(base: Sequence[ObsEpoch], nav: NavData, base_pos_ecef_m: Arr, options: RtkOptions
                        ) -> None:
    """Refuse (BasePositionRejected) a base position the base's own single-point solution contradicts by more
    than options.max_base_spp_offset_m (see base_spp_offset_m; 0 disables the test)."""
    if options.max_base_spp_offset_m <= 0.0:
        return
    found = base_spp_offset_m(base, nav, base_pos_ecef_m, options)
    if found is None:
        log.warning("base position not checked: no single-point solution of the base")
        return
    offset_m, n = found
    if offset_m > options.max_base_spp_offset_m:
        raise BasePositionRejected(offset_m, options.max_base_spp_offset_m, n)
    log.debug("base position %.1f m from the base's single-point position (%d epochs)", offset_m, n)


def pair_epochs(rover: Sequence[ObsEpoch], base: Sequence[ObsEpoch], tolerance_s: float = 0.025,
                max_age_s: float = 30.0, systems: frozenset[int] | None = None) -> list[ObsEpoch | None]:
    """For each rover epoch, the latest base epoch with t_base ≤ t_rover + tolerance (None when none or
    older than `max_age_s`). Base epochs without GPS observations are skipped (a lossy RTCM link can deliver
    GLONASS-only epochs); with `systems` (u-blox gnssIds of the engine's constellations), so are the epochs
    that lack one of them which the base sends elsewhere in `base` (a half epoch: the engine evaluates a base
    epoch at its one time, so the whole epoch before it is carried forward instead; see
    onboard.receiver.base_epochs.pairing_base_epoch)."""
    usable = [b for b in base if len(b.gps_only()) > 0]
    if systems is not None:
        sent = frozenset().union(*(b.systems() for b in base)) & systems
        usable = [b for b in usable if sent <= b.systems()]
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
    float_restarts: int = 0
    """Float ambiguities restarted for fitting no integer set while determined (RtkOptions.stuck_float_s)."""
    rejected_updates: int = 0
    """Epochs without a measurement update because every outlier pass found an outlier (RtkState.rejected_updates)."""
    disputed: int = 0
    """Combined runs: this pass's fixed epochs that the combination reports float, the other pass disagreeing
    with the fix or refuting the integers it rests on, or the fix not borne out (combine_passes)."""


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
               init_pos_ecef_m: Arr | None = None, progress: Callable[[int], None] | None = None,
               anchors: Sequence[Solution | None] | None = None) -> tuple[list[Solution], RunStats]:
    """One filter pass over all rover epochs (in time order, or reversed when `backward`).

    Returns the solutions in time order (index-aligned with `rover`) and run statistics. The known take-off
    point and the static start describe the first epoch in time: a backward pass starts at the last one, so it
    gets neither. `anchors` (index-aligned with `rover`, None where there is none): another pass's fixes that pin
    this one (handover_anchors), their covariance widened by options.handover_sigma_m.
    """
    st = rtk_init(replace(options, static_start=False), None) if backward else rtk_init(options, init_pos_ecef_m)
    order = range(len(rover) - 1, -1, -1) if backward else range(len(rover))
    if backward:
        rover = reverse_slip_flags(rover)
        base_rev = {id(b): r for b, r in zip(
            sorted({id(b): b for b in paired_base if b is not None}.values(), key=lambda e: e.time),
            reverse_slip_flags(sorted({id(b): b for b in paired_base if b is not None}.values(),
                                      key=lambda e: e.time)))}
        paired_base = [None if b is None else base_rev[id(b)] for b in paired_base]
    # slot arrays and satellite positions/clocks of every epoch in one batch (and the base's modelled ranges
    # from its known position): they depend on the data alone, not on the filter
    layout = slot_layout(st.options.systems)
    broadcast = getattr(nav, "broadcast", None)
    rcv_r = epoch_receivers(list(rover), nav.store, None, layout, broadcast)
    spps = epoch_spp(list(rover), rcv_r, nav, st.options)
    bases = list({id(b): b for b in paired_base if b is not None}.values())
    rcv_b = dict(zip((id(b) for b in bases), epoch_receivers(bases, nav.store, base_pos_ecef_m, layout, broadcast)))
    sols: list[Solution | None] = [None] * len(rover)
    stats = RunStats(epochs=len(rover))
    for i in order:
        b = paired_base[i]
        anchor = None
        if anchors is not None and (a := anchors[i]) is not None:
            anchor = (a.pos_ecef_m, a.cov_pos_m2 + np.eye(3) * options.handover_sigma_m**2)
        sol = rtk_pos(st, rover[i], b, nav, base_pos_ecef_m, (rcv_r[i], None if b is None else rcv_b[id(b)]),
                      spps[i], anchor)
        sols[i] = sol
        stats.fixed += sol.q == Q_FIX
        stats.float_ += sol.q == Q_FLOAT
        stats.single += sol.q not in (Q_FIX, Q_FLOAT)
        if progress is not None:
            progress(1)
    stats.slips = st.slips
    stats.float_restarts = st.float_restarts
    stats.rejected_updates = st.rejected_updates
    return [s for s in sols if s is not None], stats


def handover_anchors(sols: Sequence[Solution], min_run_s: float) -> list[Solution | None]:
    """The forward pass's fixes (time order) that pin the backward pass, index-aligned (None elsewhere): the
    first epoch of each run of consecutive fixes lasting `min_run_s` (s) or more. The backward pass meets it
    after crossing the run on its own, so where it fixes the run by itself the two passes stay independent
    checks of each other (combine); pinned there, it carries the fix on into the epochs before, where the
    forward pass had none (RtkOptions.combined_handover)."""
    runs = fix_runs(sols)
    spans = _hypothesis_spans_s(sols, [None if r < 0 else ("run", r) for r in runs])
    return [sol if r >= 0 and (i == 0 or runs[i - 1] != r) and spans[("run", r)] >= min_run_s else None
            for i, (sol, r) in enumerate(zip(sols, runs, strict=True))]


def _smooth(a: Solution, b: Solution) -> tuple[Arr, Arr]:
    """Two-filter smoother (RTKLIB smoother()): inverse-covariance weighted mean of two estimates."""
    try:
        ia = np.linalg.inv(a.cov_pos_m2)
        ib = np.linalg.inv(b.cov_pos_m2)
        cov = np.linalg.inv(ia + ib)
        return cov @ (ia @ a.pos_ecef_m + ib @ b.pos_ecef_m), cov
    except np.linalg.LinAlgError:
        return 0.5 * (a.pos_ecef_m + b.pos_ecef_m), 0.5 * (a.cov_pos_m2 + b.cov_pos_m2)


def _precise(sol: Solution) -> bool:
    """Is a solution's 3D σ within the fix agreement distance (a fix, or a float pinned by a recent hold)?"""
    return float(np.sqrt(max(np.trace(sol.cov_pos_m2), 0.0))) <= COMBINE_FIX_AGREEMENT_M


def _combined(fwd: Solution, bwd: Solution, q: int, pos: Arr, cov: Arr, ratio: float) -> Solution:
    """The epoch's combined solution: position/covariance (ECEF m, m²) and quality given, the rest from fwd."""
    return Solution(fwd.time, pos, fwd.vel_ecef_m_s, q, max(fwd.ns, bwd.ns), cov, fwd.cov_vel_m2_s2, fwd.age_s,
                    ratio)


def combine(fwd: Solution, bwd: Solution) -> Solution:
    """Combine one epoch's forward and backward solutions (RTKLIB combres with valcomb).

    Both fixed: the smoothed position, fixed only if the two fixes agree within COMBINE_FIX_AGREEMENT_M (two
    different integer sets: neither is trusted). One fixed, the other float: the fix, as RTKLIB, unless the
    float is itself precise to that distance and disagrees. A float cannot vouch for or veto a fix by its
    covariance: floats built on time-correlated code are metres off with decimetre σ (the right forward fixes
    of hil_sim and M8P sit at a median Mahalanobis distance of 80-90 from the backward float), so the
    guard against wrong fixes is each pass's own validation. Otherwise the smoothed position at the lower
    quality, or the better-quality solution."""
    if fwd.q == Q_NONE:
        return bwd
    if bwd.q == Q_NONE:
        return fwd
    dist = float(np.linalg.norm(fwd.pos_ecef_m - bwd.pos_ecef_m))
    if fwd.q == Q_FIX and bwd.q == Q_FIX:
        pos, cov = _smooth(fwd, bwd)
        ratio = min(fwd.ratio, bwd.ratio)
        if dist <= COMBINE_FIX_AGREEMENT_M:
            return _combined(fwd, bwd, Q_FIX, pos, cov, ratio)
        return _combined(fwd, bwd, Q_FLOAT, pos, cov + np.eye(3) * dist**2 / 4.0, ratio)
    if Q_FIX in (fwd.q, bwd.q):
        fixed, other = (fwd, bwd) if fwd.q == Q_FIX else (bwd, fwd)
        if other.q == Q_FLOAT and _precise(other) and dist > COMBINE_FIX_AGREEMENT_M:
            pos, cov = _smooth(fwd, bwd)
            return _combined(fwd, bwd, Q_FLOAT, pos, cov + np.eye(3) * dist**2 / 4.0, fixed.ratio)
        return fixed
    if fwd.q == bwd.q:
        pos, cov = _smooth(fwd, bwd)
        return _combined(fwd, bwd, fwd.q, pos, cov, max(fwd.ratio, bwd.ratio))
    return fwd if fwd.q < bwd.q else bwd


_Key = tuple[str, int]
"""An integer hypothesis of one pass (fix_hypotheses): ("lineage", Solution.fix_id) or ("run", its index)."""


def fix_runs(sols: Sequence[Solution]) -> list[int]:
    """Per epoch, the index of the run of consecutive fixes it belongs to (-1 where not fixed)."""
    out = [-1] * len(sols)
    run = -1
    for i, sol in enumerate(sols):
        if sol.q == Q_FIX:
            if i == 0 or sols[i - 1].q != Q_FIX:
                run += 1
            out[i] = run
    return out


def fix_hypotheses(sols: Sequence[Solution]) -> list[_Key | None]:
    """Per epoch, which integer hypothesis of its pass a fix rests on (None where not fixed): the engine's
    lineage (Solution.fix_id: one set of integers across the pass's breaks), else its run of consecutive fixes."""
    runs = fix_runs(sols)
    return [None if r < 0 else ("lineage", s.fix_id) if s.fix_id >= 0 else ("run", r) for s, r in zip(sols, runs)]


def _hypothesis_spans_s(sols: Sequence[Solution], keys: Sequence[_Key | None]) -> dict[_Key, float]:
    """Each hypothesis's span (s): from its first to its last fixed epoch in the pass."""
    first: dict[_Key, GpsTime] = {}
    last: dict[_Key, GpsTime] = {}
    for sol, k in zip(sols, keys):
        if k is not None:
            first.setdefault(k, sol.time)
            last[k] = sol.time
    return {k: abs(last[k].diff_s(first[k])) for k in first}


def contested_hypotheses(fwd: Sequence[Solution], bwd: Sequence[Solution], distance_m: float, min_span_s: float
                         ) -> tuple[set[_Key], set[_Key]]:
    """The integer hypotheses (fix_hypotheses) of each pass that a hypothesis of the other pass contradicts:
    (forward's, backward's). Two hypotheses contradict each other when their fixes lie more than `distance_m`
    apart at most of the epochs both are fixed (two integer sets: a constant offset through a slowly changing
    geometry; one set's fixes straying at a few epochs is those epochs' matter, which combine() settles). A
    hypothesis held over less than `min_span_s` (s), not borne out by the epochs after it, refutes nothing."""
    hf, hb = fix_hypotheses(fwd), fix_hypotheses(bwd)
    return _contested(fwd, bwd, hf, hb, _hypothesis_spans_s(fwd, hf), _hypothesis_spans_s(bwd, hb), distance_m,
                      min_span_s)


def _contested(fwd: Sequence[Solution], bwd: Sequence[Solution], hf: Sequence[_Key | None],
               hb: Sequence[_Key | None], span_f: dict[_Key, float], span_b: dict[_Key, float], distance_m: float,
               min_span_s: float) -> tuple[set[_Key], set[_Key]]:
    """contested_hypotheses on the passes' hypotheses and spans already found."""
    meets: dict[tuple[_Key, _Key], list[int]] = {}
    for f, b, kf, kb in zip(fwd, bwd, hf, hb, strict=True):
        if kf is not None and kb is not None:
            count = meets.setdefault((kf, kb), [0, 0])
            count[0] += 1
            count[1] += float(np.linalg.norm(f.pos_ecef_m - b.pos_ecef_m)) > distance_m
    bad_f: set[_Key] = set()
    bad_b: set[_Key] = set()
    for (kf, kb), (n_both, n_apart) in meets.items():
        if 2 * n_apart > n_both:
            if span_b[kb] >= min_span_s:
                bad_f.add(kf)
            if span_f[kf] >= min_span_s:
                bad_b.add(kb)
    return bad_f, bad_b


def combine_passes(fwd: Sequence[Solution], bwd: Sequence[Solution], contest_distance_m: float = 0.10,
                   contest_min_span_s: float = 5.0, anchors: Sequence[Solution | None] | None = None
                   ) -> list[Solution]:
    """Combine two passes epoch by epoch (combine); with `contest_distance_m` > 0, a fix resting on an integer
    hypothesis that the other pass contradicts (contested_hypotheses), or held over less than
    `contest_min_span_s` (s), or next to an epoch where the passes dispute it (beside_disputes), is reported
    float where the other pass has no fix to agree with it.

    One held set of integers (a lineage of the engine, else a run of consecutive fixes) is one hypothesis: the
    other pass's fixes refuting it where both are fixed refute it at all its epochs, also where that pass had no
    fix of its own to object with (RtkOptions.combined_contest_distance_m). `anchors` (handover_anchors, index
    aligned): where the backward pass was pinned to the forward's fix and agrees with it, its hypothesis carries
    the forward's integers on, and the two are refuted together."""
    if contest_distance_m <= 0.0:  # every epoch on its own (RTKLIB's combination)
        return [combine(f, b) for f, b in zip(fwd, bwd, strict=True)]
    hf, hb = fix_hypotheses(fwd), fix_hypotheses(bwd)
    span_f, span_b = _hypothesis_spans_s(fwd, hf), _hypothesis_spans_s(bwd, hb)
    bad_f, bad_b = _contested(fwd, bwd, hf, hb, span_f, span_b, contest_distance_m, contest_min_span_s)
    links = [(lf, lb) for i, (lf, lb) in enumerate(zip(hf, hb, strict=True))
             if anchors is not None and anchors[i] is not None and lf is not None and lb is not None
             and float(np.linalg.norm(fwd[i].pos_ecef_m - bwd[i].pos_ecef_m)) <= COMBINE_FIX_AGREEMENT_M]
    while True:  # until no link carries a refutation further (each pass adds to the sets or stops)
        grown = [(lf, lb) for lf, lb in links if (lf in bad_f) != (lb in bad_b)]
        if not grown:
            break
        for lf, lb in grown:
            bad_f.add(lf)
            bad_b.add(lb)
    # nor is a hypothesis held over less than contest_min_span_s: fixed, then lost within seconds (a hold's
    # misfit, slips), it was not borne out by the epochs after it
    bad_f |= {k for k, v in span_f.items() if v < contest_min_span_s}
    bad_b |= {k for k, v in span_b.items() if v < contest_min_span_s}
    beside = beside_disputes(fwd, bwd, hf, hb)
    out = []
    for i, (f, b, kf, kb) in enumerate(zip(fwd, bwd, hf, hb, strict=True)):
        if (kf in bad_f or kb in bad_b or i in beside) and (kf is None) != (kb is None):
            out.append(_unvouched(f, b))
        elif kf in bad_f and kb in bad_b:  # two refuted sets agreeing (one pinned to the other) vouch for nothing
            both = combine(f, b)
            out.append(replace(both, q=Q_FLOAT) if both.q == Q_FIX else both)
        else:
            out.append(combine(f, b))
    return out


def beside_disputes(fwd: Sequence[Solution], bwd: Sequence[Solution], hf: Sequence[_Key | None],
                    hb: Sequence[_Key | None]) -> set[int]:
    """Epochs whose fix (of either pass) rests on the hypothesis that the next or the previous epoch has in
    dispute: there both passes are fixed and further apart than COMBINE_FIX_AGREEMENT_M, so neither is taken.

    A right set held through an undetected slip strays from the other pass's for a few epochs until the slip is
    caught, and its first and last stray epochs may be where the other pass has no fix to object: hil_sim
    harsh, LEA-6T, seed 10 (21 cm off on the epoch before two disputed ones) and seed 14 (12 cm)."""
    out: set[int] = set()
    n = len(fwd)
    for i in range(n):
        # a hypothesis key marks a fix: both fixed and apart, the epoch combine() writes as float
        if hf[i] is None or hb[i] is None or \
                float(np.linalg.norm(fwd[i].pos_ecef_m - bwd[i].pos_ecef_m)) <= COMBINE_FIX_AGREEMENT_M:
            continue
        out.update(j for j in (i - 1, i + 1) if 0 <= j < n and (hf[j] == hf[i] or hb[j] == hb[i]))
    return out


def _unvouched(fwd: Solution, bwd: Solution) -> Solution:
    """One pass fixed on a hypothesis not taken alone, the other not fixed: a float at the fix's position, its
    covariance widened to the distance from the other pass (at least COMBINE_FIX_AGREEMENT_M, whatever that pass
    is)."""
    fixed, other = (fwd, bwd) if fwd.q == Q_FIX else (bwd, fwd)
    dist = COMBINE_FIX_AGREEMENT_M
    if other.q != Q_NONE:
        dist = max(dist, float(np.linalg.norm(fixed.pos_ecef_m - other.pos_ecef_m)))
    return _combined(fwd, bwd, Q_FLOAT, fixed.pos_ecef_m, fixed.cov_pos_m2 + np.eye(3) * dist**2 / 4.0, fixed.ratio)


def postprocess(rover: Sequence[ObsEpoch], base: Sequence[ObsEpoch], nav: NavData, base_pos_ecef_m: Arr | None,
                options: RtkOptions, direction: str = "forward", init_pos_ecef_m: Arr | None = None,
                progress: Callable[[int], None] | None = None) -> tuple[list[Solution], list[RunStats]]:
    """Pair, then run forward, backward or both and combine (with options.combined_handover, the backward pass
    pinned to the forward's fixes: see handover_anchors). Rover epochs are processed in time order. Returns
    the solutions (time order) and the run statistics of each pass.

    Raises ValueError for a direction not in DIRECTIONS or a base/take-off position that is not three finite
    ECEF coordinates (m), and BasePositionRejected (a ValueError) for a base position the base's own
    single-point solution contradicts (check_base_position)."""
    if direction not in DIRECTIONS:
        raise ValueError(f"direction must be one of {DIRECTIONS}, not {direction!r}")
    base_pos_ecef_m = _finite_position("base position", base_pos_ecef_m)
    init_pos_ecef_m = _finite_position("take-off position", init_pos_ecef_m)
    if base_pos_ecef_m is not None:
        check_base_position(base, nav, base_pos_ecef_m, options)
    rov = sorted(rover, key=lambda e: e.time)
    layout = slot_layout(options.systems)
    paired = pair_epochs(rov, base, options.pair_tolerance_s, options.max_age_s,
                         None if layout.gps_only else frozenset(layout.first_slot))
    if direction == "forward":
        sols, st = run_filter(rov, paired, nav, base_pos_ecef_m, options, False, init_pos_ecef_m, progress)
        return sols, [st]
    if direction == "backward":
        sols, st = run_filter(rov, paired, nav, base_pos_ecef_m, options, True, init_pos_ecef_m, progress)
        return sols, [st]
    f, sf = run_filter(rov, paired, nav, base_pos_ecef_m, options, False, init_pos_ecef_m, progress)
    anchors = handover_anchors(f, options.handover_min_run_s) if options.combined_handover else None
    b, sb = run_filter(rov, paired, nav, base_pos_ecef_m, options, True, init_pos_ecef_m, progress, anchors)
    sols = combine_passes(f, b, options.combined_contest_distance_m, options.handover_min_run_s, anchors)
    for stats, pass_sols in ((sf, f), (sb, b)):
        stats.disputed = sum(p.q == Q_FIX and c.q != Q_FIX for p, c in zip(pass_sols, sols, strict=True))
    return sols, [sf, sb]


def first_time(epochs: Sequence[ObsEpoch]) -> GpsTime | None:
    """Time of the first epoch, None for an empty stream."""
    return min((e.time for e in epochs), default=None)
