"""Single-point positioning from L1 C/A pseudoranges and Doppler (follows RTKLIB pntpos.c).

Iterative weighted least squares for position and receiver clock with Saastamoinen + Klobuchar corrections,
elevation mask and a RAIM-like exclusion of the worst satellite while residuals stay too large; then the
receiver velocity and clock drift from Doppler.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from onboard.rtk.consts import CLIGHT_M_S, LAMBDA_L1_M, OMEGA_E_RAD_S
from onboard.rtk.ephemeris import SatState, geometric_range
from onboard.rtk.geodesy import ecef_to_llh, enu_rotation
from onboard.rtk.models import klobuchar_m, saastamoinen_m

Arr = npt.NDArray[np.float64]

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
    """Azimuth/elevation (rad) from unit line-of-sight vectors (n,3) at receiver position (3,).

    `llh` = ecef_to_llh(rcv_ecef_m) when the caller already has it (saves the conversion)."""
    lat, lon, _ = ecef_to_llh(rcv_ecef_m) if llh is None else llh
    enu = e_ecef @ enu_rotation(lat, lon).T
    up = np.minimum(np.maximum(enu[:, 2], -1.0), 1.0)  # np.clip to the bit, without its dispatch overhead
    return np.arctan2(enu[:, 0], enu[:, 1]) % (2 * np.pi), np.arcsin(up)


_MIN_WEIGHT_EL_RAD = float(np.radians(5.0))


def _norm(v: Arr) -> float:
    """np.linalg.norm of a 1-D vector, to the bit (√(v·v), as numpy computes it), without its dispatch."""
    return math.sqrt(v.dot(v))


def _design(e: Arr) -> Arr:
    """Design matrix [−LOS | 1] (n,4) of position + receiver clock (np.c_ costs more than the arithmetic)."""
    h = np.empty((e.shape[0], 4))
    np.negative(e, out=h[:, :3])
    h[:, 3] = 1.0
    return h


def _least_squares(h: Arr, y: Arr) -> Arr:
    """Least-squares solution of h·x ≈ y (h (n,4) full column rank) through the 4×4 normal equations: a
    fraction of np.linalg.lstsq's cost (SVD, per-call set-up) for a well-conditioned SPP design (GDOP ≤ 30);
    lstsq only where the normal matrix is singular."""
    try:
        return np.linalg.solve(h.T @ h, h.T @ y)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(h, y, rcond=None)[0]


def _atmosphere_m(llh: Arr, az: Arr, el: Arr, tow_s: float, iono: tuple | None) -> Arr:
    """Troposphere + ionosphere delays (m) at geodetic position `llh` (rad, rad, m)."""
    lat, lon, h = llh
    alpha, beta = (iono if iono is not None else (None, None))
    return saastamoinen_m(lat, h, el) + klobuchar_m(tow_s, lat, lon, az, el, alpha, beta)


def pntpos(pr_m: Arr, sats: SatState, tow_s: float, elmask_rad: float, dop_hz: Arr | None = None,
           iono: tuple | None = None, x0_ecef_m: Arr | None = None, max_iter: int = 10,
           outlier_m: float = 60.0, max_gdop: float = 30.0, clock0_m: float = 0.0) -> SppSolution:
    """Position and clock (m) from pseudoranges `pr_m` (n,) with satellite states `sats` (aligned).

    `tow_s` receiver time (s of week) for the ionosphere model, `iono` (alpha, beta) Klobuchar coefficients.
    Follows RTKLIB pntpos() estpos()/raim_fde(): drops the satellite with the largest normalised residual
    while the residual RMS exceeds `outlier_m`/… and at least 5 remain.
    """
    n = pr_m.shape[0]
    base_ok = sats.ok & np.isfinite(pr_m)
    with np.errstate(invalid="ignore", divide="ignore"):  # slots without a satellite give NaN, never used
        return _pntpos(pr_m, sats, tow_s, elmask_rad, dop_hz, iono, x0_ecef_m, max_iter, outlier_m, max_gdop,
                       n, base_ok, clock0_m)


def _pntpos(pr_m: Arr, sats: SatState, tow_s: float, elmask_rad: float, dop_hz: Arr | None,
            iono: tuple | None, x0_ecef_m: Arr | None, max_iter: int, outlier_m: float, max_gdop: float,
            n: int, base_ok: npt.NDArray[np.bool_], clock0_m: float = 0.0) -> SppSolution:
    # work on the satellites with data only; results are scattered back to the caller's n slots
    idx = base_ok.nonzero()[0]
    m = idx.size
    pr = pr_m[idx]
    spos = sats.pos_m[idx]
    sclk = CLIGHT_M_S * sats.clock_s[idx]
    x = np.zeros(4) if x0_ecef_m is None else np.append(x0_ecef_m, clock0_m)  # np.r_ costs more
    excluded = np.zeros(m, bool)
    az = np.zeros(m)
    el = np.full(m, np.pi / 2)
    corr = np.zeros(m)
    corr_at: Arr | None = None  # position where az/el/atmosphere were last evaluated

    def full(a: np.ndarray, fill: float | bool) -> np.ndarray:
        out = np.full(n, fill, dtype=a.dtype)
        out[idx] = a
        return out

    def geometry(xx: Arr) -> tuple[Arr, Arr]:
        nonlocal az, el, corr, corr_at
        r, e = geometric_range(spos, xx[:3])
        # the atmosphere and elevations change negligibly within 50 m: evaluate them once there
        if _norm(xx[:3]) > 1e6 and (corr_at is None or _norm(xx[:3] - corr_at) > 50.0):
            llh = ecef_to_llh(xx[:3])
            az, el = sat_az_el(xx[:3], e, llh)
            corr = _atmosphere_m(llh, az, el, tow_s, iono)
            corr_at = xx[:3].copy()
        return r, e

    for _attempt in range(m):
        use = ~excluded
        converged = False
        for _it in range(max_iter):
            r, e = geometry(x)
            mask = use & (el >= elmask_rad) if corr_at is not None else use
            if np.count_nonzero(mask) < 4:
                return SppSolution(x[:3], x[3], np.full(3, np.nan), np.nan, full(mask, False), full(az, 0.0),
                                   full(el, 0.0), False, np.inf, np.inf, f"only {int(mask.sum())} usable satellites")
            res = pr - (r + x[3] - sclk + corr)
            h = _design(e)[mask]
            w = np.sin(np.maximum(el[mask], _MIN_WEIGHT_EL_RAD)) / ERR_CODE_BASE_M
            dx = _least_squares(h * w[:, None], res[mask] * w)
            x = x + dx
            if _norm(dx) < 1e-4 and corr_at is not None:
                converged = True
                break
        r, e = geometry(x)
        mask = use & (el >= elmask_rad)
        res = pr - (r + x[3] - sclk + corr)
        h = _design(e)[mask]
        try:
            gdop = float(np.sqrt(np.trace(np.linalg.inv(h.T @ h))))
        except np.linalg.LinAlgError:
            gdop = np.inf
        n_used = np.count_nonzero(mask)
        # √(mean of squares) as np.mean computes it (sum, then ÷ count), without its dispatch
        rms = math.sqrt(np.add.reduce(res[mask] ** 2) / n_used) if n_used else np.inf
        dof = n_used - 4
        if converged and (rms <= outlier_m / 3.0 or dof < 2):
            e_full = np.zeros((n, 3))
            e_full[idx] = e
            mask_full = full(mask, False)
            vel, drift = doppler_velocity(dop_hz, sats, e_full, x[:3], mask_full)
            ok = gdop <= max_gdop and rms <= outlier_m
            return SppSolution(x[:3].copy(), float(x[3]), vel, drift, mask_full, full(az, 0.0), full(el, 0.0), ok,
                               gdop, rms, "" if ok else f"gdop {gdop:.1f} / rms {rms:.1f} m too large")
        if dof < 2:
            break
        # RAIM-like: exclude the worst residual and try again
        worst = np.flatnonzero(mask)[np.argmax(np.abs(res[mask]) * np.sin(el[mask]))]
        excluded[worst] = True
    return SppSolution(x[:3], float(x[3]), np.full(3, np.nan), np.nan, np.zeros(n, bool), full(az, 0.0),
                       full(el, 0.0), False, np.inf, np.inf, "no consistent solution")


def doppler_velocity(dop_hz: Arr | None, sats: SatState, e: Arr, pos: Arr,
                     mask: npt.NDArray[np.bool_]) -> tuple[Arr, float]:
    """Receiver velocity (ECEF m/s) and clock drift (m/s) from Doppler (RTKLIB estvel/resdop), NaN if < 4."""
    dop = dop_hz
    if dop is None:
        return np.full(3, np.nan), np.nan
    m = mask & np.isfinite(dop)
    if m.sum() < 4:
        return np.full(3, np.nan), np.nan
    rate_obs = -LAMBDA_L1_M * dop[m]
    vs = sats.vel_m_s[m]
    # range-rate model incl. Sagnac rate (RTKLIB resdop())
    sag = OMEGA_E_RAD_S / CLIGHT_M_S * (vs[:, 1] * pos[0] - vs[:, 0] * pos[1])
    em = e[m]
    h = _design(em)
    y = rate_obs - (np.einsum("ij,ij->i", em, vs) + sag - CLIGHT_M_S * sats.drift_s_s[m])
    x = _least_squares(h, y)
    return x[:3], float(x[3])
