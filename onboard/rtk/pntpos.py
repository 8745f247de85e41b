"""Single-point positioning from L1 C/A pseudoranges and Doppler (follows RTKLIB pntpos.c).

Iterative weighted least squares for position and receiver clock with Saastamoinen + Klobuchar corrections,
elevation mask and a RAIM-like exclusion of the worst satellite while residuals stay too large; then the
receiver velocity and clock drift from Doppler, without a Doppler far off the others' fit. Pseudoranges outside
physical bounds, or (from a start position) thousands of km off the others, are left out first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from onboard.rtk.consts import CLIGHT_M_S, LAMBDA_L1_M, OMEGA_E_RAD_S, PR_MAX_M, PR_MIN_M
from onboard.rtk.ephemeris import SatState
from onboard.rtk.geodesy import ecef_to_llh, enu_rotation
from onboard.rtk.models import klobuchar_m, median_of_few, saastamoinen_m

Arr = npt.NDArray[np.float64]

PREFIT_GROSS_M = 1.0e6
"""A pseudorange whose residual at the start position misses its constellation's median by more than this (m)
is a gross error, left out before the least squares (see _gross_errors)."""
DOPPLER_OUTLIER_M_S = 10.0
"""A Doppler whose range rate misses the velocity solution of the others by more than this (m/s; 53 Hz at L1)
is left out of it. Why: a u-blox's Doppler fits to 0.1-1 m/s even under trees; a corrupt value or a wrong
ephemeris misses by far more and would move the velocity, hence the motion and slip tests that read it."""
DOPPLER_MAX_EXCLUSIONS = 2
"""Dopplers left out of one epoch's velocity at most (one at a time, the worst first, while 5 or more remain)."""
ERR_CODE_BASE_M = 0.3
"""Pseudorange σ at zenith for SPP weighting (m; RTKLIB err[1..2] × eratio order of magnitude)."""


@dataclass
class SppSolution:
    """Single-point result. `pos_ecef_m` (3,), `clock_bias_m` receiver clock × c (m), `vel_ecef_m_s` (3,)
    (NaN without Doppler), `clock_drift_m_s`, `used` (n,) mask of satellites in the fix, `az_rad`/`el_rad`
    (n,) at the solution, `ok` whether a solution was found, `gdop`, `residual_rms_m`."""

    pos_ecef_m: Arr
    clock_bias_m: float
    vel_ecef_m_s: Arr
    clock_drift_m_s: float
    used: npt.NDArray[np.bool_]
    az_rad: Arr
    el_rad: Arr
    ok: bool
    gdop: float
    residual_rms_m: float
    message: str = ""


def sat_az_el(rcv_ecef_m: Arr, e_ecef: Arr, llh: Arr | None = None) -> tuple[Arr, Arr]:
    """Azimuth/elevation (rad) from unit line-of-sight vectors (n,3) at receiver position (3,); or of k
    receivers at once: positions (k,3), LOS (k,n,3), results (k,n).

    `llh` = ecef_to_llh(rcv_ecef_m) when the caller already has it (saves the conversion), (k,3) for k."""
    if e_ecef.ndim == 3:
        lat_lon = np.array([ecef_to_llh(p) for p in rcv_ecef_m]) if llh is None else llh
        enu = e_ecef @ _enu_rotations_t(lat_lon[:, 0], lat_lon[:, 1])
    else:
        lat, lon, _ = ecef_to_llh(rcv_ecef_m) if llh is None else llh
        enu = e_ecef @ enu_rotation(lat, lon).T
    up = np.minimum(np.maximum(enu[..., 2], -1.0), 1.0)  # np.clip to the bit, without its dispatch overhead
    return np.arctan2(enu[..., 0], enu[..., 1]) % (2 * np.pi), np.arcsin(up)


def _enu_rotations_t(lat_rad: Arr, lon_rad: Arr) -> Arr:
    """enu_rotation(lat, lon).T of k receivers (k, 3, 3) from four array sines/cosines instead of k calls."""
    sl, cl = np.sin(lat_rad), np.cos(lat_rad)
    so, co = np.sin(lon_rad), np.cos(lon_rad)
    rot = np.empty((lat_rad.shape[0], 3, 3))
    rot[:, 0, 0], rot[:, 1, 0], rot[:, 2, 0] = -so, co, 0.0
    rot[:, 0, 1], rot[:, 1, 1], rot[:, 2, 1] = -sl * co, -sl * so, cl
    rot[:, 0, 2], rot[:, 1, 2], rot[:, 2, 2] = cl * co, cl * so, sl
    return rot


_MIN_WEIGHT_EL_RAD = float(np.radians(5.0))


def _norm(v: Arr) -> float:
    """np.linalg.norm of a 1-D vector, to the bit (√(v·v), as numpy computes it), without its dispatch."""
    return math.sqrt(v.dot(v))


def _design(e: Arr, clock_onehot: Arr | None = None) -> Arr:
    """Design matrix [−LOS | 1] (…, n, 4) of position + receiver clock from LOS vectors (…, n, 3); with
    `clock_onehot` (n, g), one clock per constellation: [−LOS | onehot] (…, n, 3 + g)."""
    h = np.empty(e.shape[:-1] + (4 if clock_onehot is None else 3 + clock_onehot.shape[1],))
    np.negative(e, out=h[..., :3])
    if clock_onehot is None:
        h[..., 3] = 1.0
    else:
        h[..., 3:] = clock_onehot
    return h


def _least_squares(h: Arr, y: Arr, free_unused: bool = False) -> Arr:
    """Least-squares solutions of h·x ≈ y per epoch, `h` (k, n, m), `y` (k, n) (zero rows for unused
    satellites), through the m×m normal equations: a fraction of np.linalg.lstsq's cost for well-conditioned
    SPP designs (GDOP ≤ 30); lstsq for an epoch whose normal matrix is singular. `free_unused`: a column no
    row uses (a constellation's clock without satellites this epoch) is solved as zero."""
    nmat = np.einsum("kni,knj->kij", h, h)
    rhs = np.einsum("kni,kn->ki", h, y)
    if free_unused:
        _pin_unused(nmat)
    try:
        return np.linalg.solve(nmat, rhs[:, :, None])[:, :, 0]
    except np.linalg.LinAlgError:
        return np.array([np.linalg.lstsq(h[k], y[k], rcond=None)[0] for k in range(h.shape[0])])


def _pin_unused(nmat: Arr) -> None:
    """Put 1 on the diagonal of normal-matrix columns no observation uses (k, m, m), in place: their
    unknowns (a clock without satellites) stay where they are instead of making the matrix singular."""
    j = np.arange(nmat.shape[1])
    diag = nmat[:, j, j]
    nmat[:, j, j] = np.where(diag == 0.0, 1.0, diag)


def _atmosphere_m(llh: Arr, az: Arr, el: Arr, tow_s: float | Arr, iono: tuple | None,
                  iono_scale: Arr | None = None) -> Arr:
    """Troposphere + ionosphere delays (m) at geodetic position `llh` (rad, rad, m); or of k receivers at
    once: `llh` (3, k, 1), az/el (k, n), `tow_s` (k, 1). `iono_scale` (n,) (f_L1/f)² per satellite on
    another carrier than GPS L1 (the Klobuchar delay is GPS L1's)."""
    lat, lon, h = llh
    alpha, beta = (iono if iono is not None else (None, None))
    if iono_scale is None:
        return saastamoinen_m(lat, h, el) + klobuchar_m(tow_s, lat, lon, az, el, alpha, beta)
    return saastamoinen_m(lat, h, el) + klobuchar_m(tow_s, lat, lon, az, el, alpha, beta) * iono_scale


def pntpos(pr_m: Arr, sats: SatState, tow_s: float, elmask_rad: float, dop_hz: Arr | None = None,
           iono: tuple | None = None, x0_ecef_m: Arr | None = None, max_iter: int = 10,
           outlier_m: float = 60.0, max_gdop: float = 30.0, clock0_m: float = 0.0,
           clock_group: npt.NDArray[np.int8] | None = None, lam_m: Arr | None = None) -> SppSolution:
    """Position and clock (m) from pseudoranges `pr_m` (n,) with satellite states `sats` (aligned).

    `tow_s` receiver time (s of week) for the ionosphere model, `iono` (alpha, beta) Klobuchar coefficients.
    Follows RTKLIB pntpos() estpos()/raim_fde(): drops the satellite with the largest normalised residual
    while the residual RMS exceeds `outlier_m`/… and at least 5 remain, each retry from the start point. A
    pseudorange outside [PR_MIN_M, PR_MAX_M], or with `x0_ecef_m` more than PREFIT_GROSS_M off its clock
    group's others, is not used. pntpos_batch with one epoch.
    Several constellations: `clock_group` (n,) the constellation of each satellite (0, 1, …: one receiver
    clock each, as RTKLIB's inter-system biases; clock_bias_m is then the first one's with satellites), `lam_m`
    (n,) their carrier wavelengths (m; Doppler, ionosphere scaling).
    """
    ng = 1 if clock_group is None else int(clock_group.max()) + 1
    x0 = None if x0_ecef_m is None else np.append(x0_ecef_m, [clock0_m] * ng).reshape(1, 3 + ng)
    return pntpos_batch(pr_m.reshape(1, -1), [sats], [tow_s], elmask_rad,
                        None if dop_hz is None else dop_hz.reshape(1, -1), iono, x0, max_iter, outlier_m,
                        max_gdop, clock_group, lam_m)[0]


def pntpos_batch(pr_m: Arr, sats: list[SatState], tow_s: npt.ArrayLike, elmask_rad: float,
                 dop_hz: Arr | None = None, iono: tuple | None = None, x0: Arr | None = None,
                 max_iter: int = 10, outlier_m: float = 60.0, max_gdop: float = 30.0,
                 clock_group: npt.NDArray[np.int8] | None = None, lam_m: Arr | None = None) -> list[SppSolution]:
    """pntpos() of E epochs at once: pseudoranges `pr_m` (E, n) (m, NaN where absent), their satellite states
    (E of n), receiver times `tow_s` (E,), Doppler `dop_hz` (E, n) or None; `x0` (E, 4) start position (ECEF m)
    and clock (m), zeros when None. The least-squares iterations, the RAIM-like exclusion and the Doppler
    velocity run on every epoch still iterating at once (post-processing solves all rover epochs before the
    filter); each epoch's atmosphere (Klobuchar + Saastamoinen) and elevations are evaluated at its first
    iterate away from the Earth's centre and again whenever it moves more than 50 m. `clock_group`, `lam_m`:
    see pntpos; `x0` then (E, 3 + clocks)."""
    with np.errstate(invalid="ignore", divide="ignore"):  # slots without a satellite give NaN, never used
        return _pntpos_batch(np.asarray(pr_m, float), sats, np.asarray(tow_s, float), elmask_rad, dop_hz, iono,
                             x0, max_iter, outlier_m, max_gdop, clock_group, lam_m)


def _pntpos_batch(pr: Arr, sats: list[SatState], tow_s: Arr, elmask_rad: float, dop_hz: Arr | None,
                  iono: tuple | None, x0: Arr | None, max_iter: int, outlier_m: float,
                  max_gdop: float, clock_group: npt.NDArray[np.int8] | None = None,
                  lam_m: Arr | None = None) -> list[SppSolution]:
    n_ep, n = pr.shape
    # one clock per constellation (onehot columns of the design), or the single GPS clock
    onehot = None if clock_group is None else (clock_group[:, None] == np.arange(int(clock_group.max()) + 1)).astype(float)
    nc = 1 if onehot is None else onehot.shape[1]
    multi = onehot is not None
    iono_scale = None if lam_m is None else (lam_m / LAMBDA_L1_M) ** 2
    spos = np.stack([s.pos_m for s in sats]).reshape(n_ep, n, 3)
    sclk = CLIGHT_M_S * np.stack([s.clock_s for s in sats]).reshape(n_ep, n)
    # a pseudorange outside what any GNSS satellite's range and both clocks can make is corrupt, not an outlier
    # for the exclusion below: one at 0 m pulls the solution thousands of km away, where no exclusion recovers
    valid = np.stack([s.ok for s in sats]).reshape(n_ep, n) & (pr >= PR_MIN_M) & (pr <= PR_MAX_M)
    x = np.zeros((n_ep, 3 + nc)) if x0 is None else np.array(x0, float).reshape(n_ep, 3 + nc)
    x_start = x.copy()
    if x0 is not None:
        valid &= ~_gross_errors(pr, spos, sclk, x[:, :3], valid, clock_group)
    excluded = np.zeros((n_ep, n), bool)
    az = np.zeros((n_ep, n))
    el = np.full((n_ep, n), np.pi / 2)
    corr = np.zeros((n_ep, n))
    corr_at = np.full((n_ep, 3), np.nan)  # where each epoch's az/el/atmosphere were last evaluated
    out: list[SppSolution | None] = [None] * n_ep

    def fail(k: int, mask: npt.NDArray[np.bool_], message: str) -> None:
        out[k] = SppSolution(x[k, :3].copy(), float(x[k, 3]), np.full(3, np.nan), np.nan, mask.copy(),
                             np.where(valid[k], az[k], 0.0), np.where(valid[k], el[k], 0.0), False, np.inf, np.inf,
                             message)

    def geometry(ks: npt.NDArray[np.int64]) -> tuple[Arr, Arr]:
        """Ranges with Sagnac (k, n) and LOS (k, n, 3) at the epochs' current positions (geometric_range)."""
        xs = x[ks, :3]
        sp = spos[ks]
        d = sp - xs[:, None, :]
        r = np.sqrt(np.add.reduce(d * d, axis=2))
        e = d / r[:, :, None]
        sagnac = OMEGA_E_RAD_S * (sp[:, :, 0] * xs[:, 1:2] - sp[:, :, 1] * xs[:, 0:1]) / CLIGHT_M_S
        # the atmosphere and elevations change negligibly within 50 m: evaluate them once there
        norm = np.sqrt(np.add.reduce(xs * xs, axis=1))
        moved = np.sqrt(np.add.reduce((xs - corr_at[ks]) ** 2, axis=1))
        due = np.flatnonzero((norm > 1e6) & ~(moved <= 50.0))
        if due.size:
            kd = ks[due]
            llh = np.array([ecef_to_llh(p) for p in xs[due]])  # (k, 3)
            az[kd], el[kd] = sat_az_el(xs[due], e[due], llh)
            corr[kd] = _atmosphere_m(llh.T[:, :, None], az[kd], el[kd], tow_s[kd, None], iono, iono_scale)
            corr_at[kd] = xs[due]
        return r + sagnac, e

    todo = np.arange(n_ep)
    for _attempt in range(n + 1):
        if todo.size == 0:
            break
        converged = np.zeros(n_ep, bool)
        act = todo
        for _it in range(max_iter):
            if act.size == 0:
                break
            r, e = geometry(act)
            use = valid[act] & ~excluded[act]
            has_corr = np.isfinite(corr_at[act, 0])
            mask = use & ((el[act] >= elmask_rad) | ~has_corr[:, None])
            count = mask.sum(axis=1)
            # 3 + one per clock with satellites
            keep = count >= (4 if not multi else 3 + (mask[:, :, None] & (onehot > 0)).any(axis=1).sum(axis=1))
            if not keep.all():
                for j in np.flatnonzero(~keep).tolist():
                    fail(int(act[j]), mask[j], f"only {int(count[j])} usable satellites")
                act, r, e, mask, has_corr = act[keep], r[keep], e[keep], mask[keep], has_corr[keep]
            res = pr[act] - (r + _clock_m(x[act], clock_group) - sclk[act] + corr[act])
            w = np.where(mask, np.sin(np.maximum(el[act], _MIN_WEIGHT_EL_RAD)) / ERR_CODE_BASE_M, 0.0)
            dx = _least_squares(np.where(mask[:, :, None], _design(e, onehot) * w[:, :, None], 0.0),
                                np.where(mask, res, 0.0) * w, multi)
            x[act] += dx
            done = (np.sqrt(np.add.reduce(dx * dx, axis=1)) < 1e-4) & has_corr
            converged[act[done]] = True
            act = act[~done]
        todo = todo[[out[k] is None for k in todo.tolist()]]  # less the epochs that failed
        if todo.size == 0:
            break
        # the solution of each epoch still to decide: residuals, GDOP, RMS at its final position
        r, e = geometry(todo)
        mask = valid[todo] & ~excluded[todo] & (el[todo] >= elmask_rad)
        res = pr[todo] - (r + _clock_m(x[todo], clock_group) - sclk[todo] + corr[todo])
        h = np.where(mask[:, :, None], _design(e, onehot), 0.0)  # empty slots have NaN LOS
        gdop = _gdop(h, multi)
        n_used = mask.sum(axis=1)
        rms = np.where(n_used > 0, np.sqrt(np.add.reduce(np.where(mask, res, 0.0) ** 2, axis=1)
                                           / np.maximum(n_used, 1)), np.inf)
        dof = n_used - (4 if not multi else 3 + (np.abs(h[:, :, 3:]).sum(axis=1) > 0).sum(axis=1))
        good = converged[todo] & ((rms <= outlier_m / 3.0) | (dof < 2))
        if good.any():
            ks = todo[good]
            masks = np.zeros((ks.size, n), bool)
            masks[:] = mask[good]
            vel, drift = _doppler_batch(None if dop_hz is None else dop_hz[ks], [sats[k] for k in ks.tolist()],
                                        e[good], x[ks, :3], masks, lam_m)
            # per-epoch rows of whole-batch arrays (one selection each, not one per epoch)
            az_ok, el_ok = np.where(valid[ks], az[ks], 0.0), np.where(valid[ks], el[ks], 0.0)
            pos_ok = x[ks, :3]
            if multi:  # the first constellation's clock that has satellites (the solution's time tag)
                used_clock = (masks[:, :, None] & (onehot > 0)).any(axis=1)
                clk_ok = x[ks, 3 + np.argmax(used_clock, axis=1)].tolist()
            else:
                clk_ok = x[ks, 3].tolist()
            for j, (k, g, rm) in enumerate(zip(ks.tolist(), gdop[good].tolist(), rms[good].tolist(), strict=True)):
                ok = g <= max_gdop and rm <= outlier_m
                out[k] = SppSolution(pos_ok[j], clk_ok[j], vel[j], float(drift[j]), masks[j], az_ok[j], el_ok[j], ok,
                                     g, rm, "" if ok else f"gdop {g:.1f} / rms {rm:.1f} m too large")
        stuck = ~good & (dof < 2)
        for j in np.flatnonzero(stuck).tolist():
            fail(int(todo[j]), np.zeros(n, bool), "no consistent solution")
        # RAIM-like: exclude each remaining epoch's worst residual and try again
        again = ~good & ~stuck
        for j in np.flatnonzero(again).tolist():
            cand = np.flatnonzero(mask[j])
            excluded[todo[j], cand[np.argmax(np.abs(res[j, cand]) * np.sin(el[todo[j], cand]))]] = True
        todo = todo[again]
        # from the start again: a gross outlier may have pulled the position where the iteration cannot return
        x[todo] = x_start[todo]
    for k in todo.tolist():
        fail(k, np.zeros(n, bool), "no consistent solution")
    return [s for s in out if s is not None] if all(s is not None for s in out) else _missing(out)


def _gross_errors(pr: Arr, spos: Arr, sclk_m: Arr, pos0: Arr, valid: npt.NDArray[np.bool_],
                  clock_group: npt.NDArray[np.int8] | None) -> npt.NDArray[np.bool_]:
    """Pseudoranges (E, n) more than PREFIT_GROSS_M from the others of their clock group at the start positions
    `pos0` (E, 3; ECEF m): the median of range residuals stands in for the unknown clock. Why: a value
    thousands of km off pulls the least squares so far that the exclusion by largest residual then takes good
    satellites; at a start within tens of km of the receiver (the filter's position, the batch's first
    solution) no measurement misses its group by a thousand."""
    d = spos - pos0[:, None, :]
    res = np.where(valid, pr - np.sqrt(np.add.reduce(d * d, axis=2)) + sclk_m, np.nan)
    if res.shape[0] == 1:  # the real-time epoch: a pass over a few dozen values costs less than nanmedian's
        row = res[0].tolist()
        groups_of = [0] * len(row) if clock_group is None else clock_group.tolist()
        members: dict[int, list[float]] = {}
        for v, g in zip(row, groups_of, strict=True):
            if not math.isnan(v):
                members.setdefault(g, []).append(v)
        center = {g: median_of_few(np.array(v)) for g, v in members.items() if len(v) >= 3}
        return np.array([[g in center and abs(v - center[g]) > PREFIT_GROSS_M
                          for v, g in zip(row, groups_of, strict=True)]])
    gross = np.zeros(pr.shape, bool)
    groups = [np.ones(pr.shape[1], bool)] if clock_group is None else [clock_group == g for g in np.unique(clock_group)]
    for in_group in groups:
        r = res[:, in_group]
        enough = np.count_nonzero(np.isfinite(r), axis=1) >= 3  # a median of two cannot tell which is off
        if not enough.any():
            continue
        with np.errstate(invalid="ignore"):
            med = np.nanmedian(np.where(enough[:, None], r, 0.0), axis=1)
            gross[:, in_group] = enough[:, None] & (np.abs(r - med[:, None]) > PREFIT_GROSS_M)
    return gross


def _missing(out: list[SppSolution | None]) -> list[SppSolution]:
    raise AssertionError(f"SPP left {sum(s is None for s in out)} epochs without a result")


def _clock_m(x: Arr, clock_group: npt.NDArray[np.int8] | None) -> Arr:
    """Receiver clock (m) per epoch and satellite from the states `x` (k, 3 + clocks): (k, 1) with one clock,
    (k, n) with one per constellation."""
    return x[:, 3:4] if clock_group is None else x[:, 3 + clock_group]


def _gdop(h: Arr, free_unused: bool = False) -> Arr:
    """GDOP √trace((HᵀH)⁻¹) per epoch of designs `h` (k, n, m) (rows of unused satellites zero); inf where
    singular. `free_unused`: as _least_squares (an unused clock column adds 1 to the trace)."""
    nmat = np.einsum("kni,knj->kij", h, h)
    if free_unused:
        _pin_unused(nmat)
    try:
        return np.sqrt(np.trace(np.linalg.inv(nmat), axis1=1, axis2=2))
    except np.linalg.LinAlgError:
        out = np.full(h.shape[0], np.inf)
        for k in range(h.shape[0]):
            try:
                out[k] = np.sqrt(np.trace(np.linalg.inv(nmat[k])))
            except np.linalg.LinAlgError:
                pass
        return out


def doppler_velocity(dop_hz: Arr | None, sats: SatState, e: Arr, pos: Arr,
                     mask: npt.NDArray[np.bool_]) -> tuple[Arr, float]:
    """Receiver velocity (ECEF m/s) and clock drift (m/s) from Doppler (RTKLIB estvel/resdop), NaN if < 4."""
    vel, drift = _doppler_batch(None if dop_hz is None else dop_hz.reshape(1, -1), [sats], e.reshape(1, -1, 3),
                                pos.reshape(1, 3), mask.reshape(1, -1))
    return vel[0], float(drift[0])


def _doppler_batch(dop_hz: Arr | None, sats: list[SatState], e: Arr, pos: Arr,
                   mask: npt.NDArray[np.bool_], lam_m: Arr | None = None) -> tuple[Arr, Arr]:
    """doppler_velocity() of k epochs: Doppler (k, n) Hz, LOS (k, n, 3), positions (k, 3), masks (k, n);
    velocities (k, 3) and drifts (k,), NaN where fewer than 4 Dopplers."""
    k, n = mask.shape
    vel = np.full((k, 3), np.nan)
    drift = np.full(k, np.nan)
    if dop_hz is None or k == 0:
        return vel, drift
    m = mask & np.isfinite(dop_hz)
    enough = m.sum(axis=1) >= 4
    if not enough.any():
        return vel, drift
    vs = np.stack([s.vel_m_s for s in sats]).reshape(k, n, 3)
    sdrift = np.stack([s.drift_s_s for s in sats]).reshape(k, n)
    rate_obs = -(LAMBDA_L1_M if lam_m is None else lam_m) * dop_hz
    # range-rate model incl. Sagnac rate (RTKLIB resdop())
    sag = OMEGA_E_RAD_S / CLIGHT_M_S * (vs[:, :, 1] * pos[:, 0:1] - vs[:, :, 0] * pos[:, 1:2])
    y = rate_obs - (np.add.reduce(e * vs, axis=2) + sag - CLIGHT_M_S * sdrift)
    sel = np.flatnonzero(enough)
    h = _design(e[sel])
    ms, ys = m[sel], y[sel]
    for attempt in range(DOPPLER_MAX_EXCLUSIONS + 1):
        sol = _least_squares(np.where(ms[:, :, None], h, 0.0), np.where(ms, ys, 0.0))
        if attempt == DOPPLER_MAX_EXCLUSIONS:
            break
        # one Doppler far off every other's fit (a corrupt value, a wrong ephemeris) moves the whole solution:
        # the worst is left out while at least 5 remain, as the code's RAIM-like exclusion
        res = np.where(ms, np.abs(ys - np.einsum("kni,ki->kn", h, sol)), 0.0)
        worst = res.argmax(axis=1)
        bad = (res[np.arange(sel.size), worst] > DOPPLER_OUTLIER_M_S) & (ms.sum(axis=1) >= 5)
        if not bad.any():
            break
        ms = ms.copy()
        ms[np.flatnonzero(bad), worst[bad]] = False
    vel[sel] = sol[:, :3]
    drift[sel] = sol[:, 3]
    return vel, drift
