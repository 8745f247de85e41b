"""Tracking statistics of one receiver's observations, per constellation: what the "harsh" error model is fitted to.

Pure functions of decoded epochs (`ObsEpoch`, real or simulated), the broadcast navigation and an approximate
antenna position (metres off is enough: elevations and the time-differenced geometry change by microradians):

- availability: of the satellites the ephemerides put above the mask, the fraction tracked with phase, per
  elevation band and per 45° azimuth sector (blockage under trees); loss events (tracked → not tracked) per
  visible satellite-hour and the mean outage length (s);
- arcs: stretches of continuous phase tracking (broken by a missing epoch or an LLI slip), their median length;
- slips: LLI slip flags (bit 0) on continuing tracking per tracked satellite-hour, and slips *without* LLI:
  time-differenced carrier phase (TDCP) between consecutive epochs, λ·ΔL − Δ(satellite range from the approximate
  position) + c·Δdt_s = −e·Δx + c·Δb, solved per epoch pair for the antenna motion and clock by least squares
  over all systems with outliers removed one by one; a satellite removed with |residual| > 0.5 cycle and no LLI
  is an unflagged slip when neither epoch carries an LLI bit (a half cycle resolved as its flag clears is not
  counted; the motion of a walking antenna is solved, not modelled);
- C/N0: percentiles and mean per elevation band; code noise by C/N0: code minus carrier (P − λL) per arc
  (≥ 60 s), a quadratic removed, RMS per C/N0 bin (multipath + noise, raw, not elevation-scaled).

`stream_losses(times)`: the loss pattern of a 1 Hz stream (the base's RTCM epochs): fraction of seconds missing
and the two-state Markov (Gilbert) parameters P(loss | previous received), P(loss | previous lost).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from hil_sim.scenario import RoverEnvironment
from onboard.rtk.consts import CLIGHT_M_S, l1_wavelength_m
from onboard.rtk.geodesy import ecef_to_llh, enu_rotation
from onboard.rtk.navstore import BroadcastNavigation, satellite_state
from onboard.rtk.types import FCN_NONE, GNSS_GLONASS, GNSS_GPS, LLI_HALF_CYCLE, LLI_SLIP, ObsEpoch

Vec = npt.NDArray[np.float64]
EL_BANDS_DEG = (10, 20, 30, 45, 60, 90)
CN0_BINS_DBHZ = (0, 30, 35, 40, 45, 60)
AZ_SECTORS = 8
SLIP_THRESHOLD_CYC = 0.5
CN0_REF_DBHZ = 45.0
EPOCH_GAP_S = 1.5
_Row = tuple[float, float, float, int, float, float]
"""(phase cyc, λ m, range − c·dt_s m, LLI, el rad, az rad) of one tracked satellite at one epoch."""


@dataclass
class SystemStats:
    """Statistics of one constellation (see module docstring); NaN where there was nothing to measure."""

    visible_sat_h: float = 0.0
    tracked_sat_h: float = 0.0
    avail_by_el: dict[str, float] = field(default_factory=dict)
    avail_by_az: list[float] = field(default_factory=list)
    losses_per_visible_h: float = math.nan
    outage_mean_s: float = math.nan
    arc_median_s: float = math.nan
    lli_slips_per_h: float = math.nan
    """LLI slips per tracked satellite-hour, the receiver-wide events included."""
    independent_lli_slips_per_h: float = math.nan
    """The same without the epochs of receiver-wide events."""
    common_slip_events_per_h: float = math.nan
    """Epochs where ≥ 60 % of this system's tracked satellites (≥ 3) flag a slip, per hour of data."""
    half_cycle_run_s: float = math.nan
    """Mean length of the half-cycle-unresolved runs (LLI bit 1) that follow a slip."""
    unflagged_slips_per_h: float = math.nan
    cn0_p10_p50_p90: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    cn0_mean_by_el: dict[str, float] = field(default_factory=dict)
    code_rms_by_cn0: dict[str, float] = field(default_factory=dict)
    code_sigma_at_ref_m: float = math.nan
    """σ at CN0_REF_DBHZ of the law σ = σ_ref·10^((ref − C/N0)/20), fitted to every code residual (ML)."""
    cn0_fit_dbhz: tuple[float, float] = (math.nan, math.nan)
    """(horizon, zenith) of C/N0 = horizon + (zenith − horizon)·sin(el), least squares on every sample."""
    cn0_resid_std_db: float = math.nan
    cn0_acf: dict[int, float] = field(default_factory=dict)
    """Autocorrelation of each satellite's C/N0 deviation from that law at lags of CN0_ACF_LAGS_S seconds."""


def _lam(gnss: int, fcn: int, fcn_of: dict[int, int], sv: int) -> float | None:
    if gnss == GNSS_GLONASS:
        k = fcn if fcn != FCN_NONE else fcn_of.get(sv)
        return l1_wavelength_m(gnss, k)
    return l1_wavelength_m(gnss)


def _band(edges: Sequence[float], x: float) -> str | None:
    for lo, hi in itertools.pairwise(edges):
        if lo <= x < hi:
            return f"{lo}-{hi}"
    return None


def tracking_stats(epochs: Sequence[ObsEpoch], nav: BroadcastNavigation, approx_ecef_m: Vec,
                   systems: Sequence[int], mask_deg: float = 10.0) -> dict[int, SystemStats]:
    """Per gnssId of `systems`: the statistics of the module docstring over `epochs` (time order).

    `approx_ecef_m` (3,) for an antenna that stays within some 50 m, or (len(epochs), 3) per epoch (a flight
    of hundreds of metres: the TDCP geometry needs the antenna to ~50 m, 0.3 cycles per 300 m otherwise)."""
    fcn_of = nav.glonass_channels()
    sats = [s for s in nav.satellites() if s[0] in systems]
    mask = math.radians(mask_deg)
    pos_all = np.asarray(approx_ecef_m, float)
    lat, lon, _ = ecef_to_llh(pos_all if pos_all.ndim == 1 else pos_all[0])
    r_enu = enu_rotation(lat, lon)
    t0 = epochs[0].time
    # per satellite: times (s), tracked flag, el, az; per epoch: the tracked rows for TDCP
    vis: dict[tuple[int, int], list[tuple[float, bool, float, float]]] = {s: [] for s in sats}
    rows: list[dict[tuple[int, int], _Row]] = []
    tt: list[float] = []
    cmc: dict[tuple[int, int], list[tuple[float, float, float, int]]] = {}
    cn0_el: dict[int, list[tuple[float, float, float, int]]] = {g: [] for g in systems}  # C/N0, el, t, sv
    for k_ep, ep in enumerate(epochs):
        approx = pos_all if pos_all.ndim == 1 else pos_all[k_ep]
        t = ep.time.diff_s(t0)
        here: dict[tuple[int, int], int] = {}
        for j in range(len(ep)):
            key = (int(ep.gnss_id[j]), int(ep.sv_id[j]))
            if key[0] in systems and math.isfinite(float(ep.cp_cyc[j])) and float(ep.cp_cyc[j]) != 0.0:
                here[key] = j
        row = {}
        for key in sats:
            eph = nav.select(*key, ep.time)
            if eph is None:
                continue
            i = here.get(key)
            tau = float(ep.pr_m[i]) / CLIGHT_M_S if i is not None else 0.075
            sat = satellite_state(eph, ep.time.add_s(-tau))
            if not sat.healthy:
                continue
            enu = r_enu @ (sat.pos_m - approx)
            az, el = math.atan2(enu[0], enu[1]) % (2 * math.pi), math.atan2(enu[2], math.hypot(enu[0], enu[1]))
            if el < mask:
                continue
            vis[key].append((t, i is not None, el, az))
            if i is None:
                continue
            lam = _lam(key[0], int(ep.glo_fcn[i]) if ep.glo_fcn.size else FCN_NONE, fcn_of, key[1])
            if lam is None:
                continue
            rng = float(np.linalg.norm(sat.pos_m - approx))
            row[key] = (float(ep.cp_cyc[i]), lam, rng - CLIGHT_M_S * sat.clock_s, int(ep.lli[i]), el, az)
            cmc.setdefault(key, []).append((t, float(ep.pr_m[i]) - lam * float(ep.cp_cyc[i]),
                                            float(ep.cn0_dbhz[i]), int(ep.lli[i])))
            cn0_el[key[0]].append((float(ep.cn0_dbhz[i]), el, t, key[1]))
        rows.append(row)
        tt.append(t)
    unflagged = _tdcp_slips(rows, tt)
    span_h = (tt[-1] - tt[0] + (tt[1] - tt[0] if len(tt) > 1 else 1.0)) / 3600.0
    out: dict[int, SystemStats] = {}
    for g in systems:
        st = SystemStats()
        keys = [k for k in sats if k[0] == g and vis[k]]
        if not keys:
            out[g] = st
            continue
        dt_nom = float(np.median(np.diff(tt))) if len(tt) > 1 else 1.0
        n_vis = sum(len(vis[k]) for k in keys)
        n_trk = sum(sum(1 for v in vis[k] if v[1]) for k in keys)
        st.visible_sat_h = n_vis * dt_nom / 3600.0
        st.tracked_sat_h = n_trk * dt_nom / 3600.0
        allv = [v for k in keys for v in vis[k]]
        for lo, hi in itertools.pairwise(EL_BANDS_DEG):
            sel = [v[1] for v in allv if lo <= math.degrees(v[2]) < hi]
            st.avail_by_el[f"{lo}-{hi}"] = float(np.mean(sel)) if len(sel) > 30 else math.nan
        for s in range(AZ_SECTORS):
            sel = [v[1] for v in allv if int(math.degrees(v[3]) // (360 / AZ_SECTORS)) % AZ_SECTORS == s]
            st.avail_by_az.append(float(np.mean(sel)) if len(sel) > 30 else math.nan)
        losses, outages, arcs, lli_n = 0, [], [], 0
        for k in keys:
            flags = [v[1] for v in vis[k]]
            times = [v[0] for v in vis[k]]
            run_start = None
            for j, f in enumerate(flags):
                if j and flags[j - 1] and not f and times[j] - times[j - 1] < EPOCH_GAP_S:
                    losses += 1
                if not f and run_start is None:
                    run_start = times[j]
                if f and run_start is not None:
                    if j and any(flags[:j]):
                        outages.append(times[j] - run_start)
                    run_start = None
            series = cmc.get(k, [])
            a0 = None
            for j, (t, _, _, lli) in enumerate(series):
                brk = j == 0 or t - series[j - 1][0] > EPOCH_GAP_S or bool(lli & LLI_SLIP)
                if j and lli & LLI_SLIP and t - series[j - 1][0] <= EPOCH_GAP_S:
                    lli_n += 1
                if brk:
                    if a0 is not None:
                        arcs.append(series[j - 1][0] - a0 + dt_nom)
                    a0 = t
            if a0 is not None:
                arcs.append(series[-1][0] - a0 + dt_nom)
        st.losses_per_visible_h = losses / st.visible_sat_h if st.visible_sat_h else math.nan
        st.outage_mean_s = float(np.mean(outages)) if outages else math.nan
        st.arc_median_s = float(np.median(arcs)) if arcs else math.nan
        st.lli_slips_per_h = lli_n / st.tracked_sat_h if st.tracked_sat_h else math.nan
        common, indep, runs = _slip_structure(rows, g)
        st.common_slip_events_per_h = common / span_h
        st.independent_lli_slips_per_h = indep / st.tracked_sat_h if st.tracked_sat_h else math.nan
        st.half_cycle_run_s = float(np.mean(runs)) * (tt[1] - tt[0] if len(tt) > 1 else 1.0) if runs else math.nan
        st.unflagged_slips_per_h = (sum(1 for key in unflagged if key[0] == g) / st.tracked_sat_h
                                    if st.tracked_sat_h else math.nan)
        c = np.array(cn0_el[g]) if cn0_el[g] else np.zeros((0, 4))
        if c.size:
            st.cn0_p10_p50_p90 = tuple(float(x) for x in np.percentile(c[:, 0], (10, 50, 90)))  # type: ignore[assignment]
            for lo, hi in itertools.pairwise(EL_BANDS_DEG):
                m = (np.degrees(c[:, 1]) >= lo) & (np.degrees(c[:, 1]) < hi)
                st.cn0_mean_by_el[f"{lo}-{hi}"] = float(c[m, 0].mean()) if m.sum() > 30 else math.nan
            a_mat = np.stack([1.0 - np.sin(c[:, 1]), np.sin(c[:, 1])], axis=1)
            coef, *_ = np.linalg.lstsq(a_mat, c[:, 0], rcond=None)
            st.cn0_fit_dbhz = (float(coef[0]), float(coef[1]))
            st.cn0_resid_std_db = float(np.std(c[:, 0] - a_mat @ coef))
            st.cn0_acf = _lag_correlation(c[:, 3], c[:, 2], c[:, 0] - a_mat @ coef, CN0_ACF_LAGS_S)
        st.code_rms_by_cn0, st.code_sigma_at_ref_m = _code_by_cn0({k: v for k, v in cmc.items() if k[0] == g})
        out[g] = st
    return out


CN0_ACF_LAGS_S = (1, 2, 5, 10, 20, 30, 60)


def _lag_correlation(sat: Vec, t_s: Vec, x: Vec, lags_s: Sequence[int]) -> dict[int, float]:
    """Correlation of x with itself `lag` whole seconds later on the same satellite, per lag (NaN: no pair)."""
    index = {(int(s), round(t)): v for s, t, v in zip(sat.tolist(), t_s.tolist(), x.tolist())}
    out: dict[int, float] = {}
    for lag in lags_s:
        pairs = [(v, index[(s, t + lag)]) for (s, t), v in index.items() if (s, t + lag) in index]
        out[lag] = float(np.corrcoef(np.array(pairs).T)[0, 1]) if len(pairs) > 30 else math.nan
    return out


def fit_cn0_tau_s(acf: dict[int, float]) -> tuple[float, ...]:
    """(fast, slow) correlation times (s) of two first-order Gauss-Markov processes with equal shares of the
    variance whose autocorrelation is closest (least squares over the lags) to `acf`; () without any lag."""
    lags = [k for k, v in acf.items() if math.isfinite(v)]
    if not lags:
        return ()
    target = np.array([acf[k] for k in lags])
    lag_s = np.array(lags, float)
    best: tuple[float, tuple[float, ...]] = (math.inf, ())
    for fast in (1.0, 2.0, 3.0, 5.0, 7.0, 10.0, 15.0):
        for slow in (20.0, 30.0, 45.0, 60.0, 90.0, 120.0, 180.0, 300.0, 600.0):
            model = 0.5 * (np.exp(-lag_s / fast) + np.exp(-lag_s / slow))
            err = float(np.sum((model - target) ** 2))
            if err < best[0]:
                best = (err, (fast, slow))
    return best[1]


def _slip_structure(rows: list[dict[tuple[int, int], _Row]], g: int) -> tuple[int, int, list[int]]:
    """(receiver-wide slip epochs, slips outside them, lengths in epochs of the LLI-bit-1 runs after a slip)."""
    common = indep = 0
    run: dict[tuple[int, int], int] = {}
    runs: list[int] = []
    for k, row in enumerate(rows):
        keys = [s for s in row if s[0] == g]
        slipped = [s for s in keys if row[s][3] & LLI_SLIP and k and s in rows[k - 1]]
        if len(keys) >= 3 and len(slipped) >= 0.6 * len(keys):
            common += 1
        else:
            indep += len(slipped)
        for s in keys:
            if row[s][3] & LLI_SLIP:
                run[s] = 1 if row[s][3] & LLI_HALF_CYCLE else 0
            elif s in run and row[s][3] & LLI_HALF_CYCLE:
                run[s] += 1
            elif s in run:
                if run[s]:
                    runs.append(run[s])
                del run[s]
    return common, indep, runs


def _code_by_cn0(cmc: dict[tuple[int, int], list[tuple[float, float, float, int]]]) -> tuple[dict[str, float], float]:
    res: list[float] = []
    cn0: list[float] = []
    for series in cmc.values():
        a = np.array(series)
        brk = np.ones(len(a), bool)
        brk[1:] = (np.diff(a[:, 0]) > EPOCH_GAP_S) | ((a[1:, 3].astype(int) & (LLI_SLIP | LLI_HALF_CYCLE)) != 0) | \
            (np.abs(np.diff(a[:, 1])) > 5.0)
        starts = np.flatnonzero(brk)
        for s, e in zip(starts, [*starts[1:], len(a)], strict=True):
            t, y = a[s:e, 0], a[s:e, 1]
            if e - s < 30 or t[-1] - t[0] < 60.0:
                continue
            tn = (t - t.mean()) / max(1.0, float(np.ptp(t)))
            r = y - np.polyval(np.polyfit(tn, y, 2), tn)
            keep = np.abs(r) < 6.0 * np.std(r) + 1e-9
            res += r[keep].tolist()
            cn0 += a[s:e, 2][keep].tolist()
    r_arr, c_arr = np.array(res), np.array(cn0)
    out = {}
    for lo, hi in itertools.pairwise(CN0_BINS_DBHZ):
        m = (c_arr >= lo) & (c_arr < hi)
        out[f"{lo}-{hi}"] = float(np.sqrt(np.mean(r_arr[m] ** 2))) if m.sum() > 30 else math.nan
    ref = math.sqrt(float(np.mean(r_arr**2 * 10.0 ** ((c_arr - CN0_REF_DBHZ) / 10.0)))) if r_arr.size else math.nan
    return out, ref


def _tdcp_slips(rows: list[dict[tuple[int, int], _Row]], tt: list[float]) -> list[tuple[int, int]]:
    """Satellites (one entry per event) whose time-differenced phase jumps by > 0.5 cycle without LLI."""
    events: list[tuple[int, int]] = []
    for k in range(1, len(rows)):
        if tt[k] - tt[k - 1] > EPOCH_GAP_S:
            continue
        a, b = rows[k - 1], rows[k]
        keys = [s for s in b if s in a and not (b[s][3] | a[s][3]) & (LLI_SLIP | LLI_HALF_CYCLE)]
        if len(keys) < 6:
            continue
        y = np.array([b[s][1] * (b[s][0] - a[s][0]) - (b[s][2] - a[s][2]) for s in keys])
        lam = np.array([b[s][1] for s in keys])
        h = np.array([(-math.cos(b[s][4]) * math.sin(b[s][5]), -math.cos(b[s][4]) * math.cos(b[s][5]),
                       -math.sin(b[s][4]), 1.0) for s in keys])  # [−e_enu, 1]: antenna motion (ENU) and clock
        ok = np.ones(len(keys), bool)
        while ok.sum() >= 6:
            x, *_ = np.linalg.lstsq(h[ok], y[ok], rcond=None)
            r = (y - h @ x) / lam
            worst = int(np.argmax(np.where(ok, np.abs(r), -1.0)))
            if abs(r[worst]) <= 0.25:
                break
            ok[worst] = False
        if ok.sum() < 6:
            continue
        x, *_ = np.linalg.lstsq(h[ok], y[ok], rcond=None)
        r = (y - h @ x) / lam
        events += [keys[j] for j in np.flatnonzero(~ok & (np.abs(r) > SLIP_THRESHOLD_CYC))]
    return events


def stream_losses(times_s: Sequence[float], period_s: float = 1.0) -> dict[str, float]:
    """Loss pattern of a periodic stream from the times (s) of the epochs received: fraction lost and the
    Gilbert parameters p_loss_after_ok, p_loss_after_loss, the mean length of a loss run (s)."""
    t = np.unique(np.round(np.asarray(times_s, float) / period_s).astype(int))
    if t.size < 2:
        return {"lost_fraction": math.nan, "p_loss_after_ok": math.nan, "p_loss_after_loss": math.nan,
                "mean_run_s": math.nan}
    got = np.zeros(int(t[-1] - t[0]) + 1, bool)
    got[t - t[0]] = True
    prev, cur = got[:-1], got[1:]
    p_ok = float(np.mean(~cur[prev])) if prev.any() else math.nan
    p_loss = float(np.mean(~cur[~prev])) if (~prev).any() else math.nan
    runs = np.diff(np.flatnonzero(np.diff(np.concatenate(([1], got.astype(int), [1]))) != 0))[::2]
    return {"lost_fraction": float(1.0 - got.mean()), "p_loss_after_ok": p_ok, "p_loss_after_loss": p_loss,
            "mean_run_s": float(runs.mean() * period_s) if runs.size else 0.0}


IONO_JUMP_M = 0.3
"""A 1-s step of a slant-ionosphere series larger than this (m), the epoch's median step removed, is a cycle
slip of the geometry-free phase: the series is not differenced across it."""


def iono_change_stats(series: Mapping[Any, Mapping[int, float]], lags_s: Sequence[int] = (1, 5, 10, 20),
                      fit_s: int = 20, ahead_s: Sequence[int] = (5, 10, 20)) -> dict[str, dict[int, float]]:
    """How fast the slant ionosphere changes between satellites: what a rover differenced with a base epoch
    `lag` seconds old sees in its double differences.

    `series`: per satellite, slant L1 ionospheric delay (m, any constant offset) by whole second. Returns
    "rms_mm"/"p95_mm" per lag: the change over the lag, the epoch's median over satellites taken off (the part
    common to all cancels in double differences), RMS and 95th percentile of |·| over satellites and epochs;
    "fit_rms_mm" per `ahead_s`: the same for the miss of a straight line fitted over the previous `fit_s`
    seconds and carried that far ahead (the engine's carry-forward of an aged base, every 5th epoch)."""
    keys = list(series)
    times = sorted({t for s in series.values() for t in s})
    out: dict[str, dict[int, float]] = {"rms_mm": {}, "p95_mm": {}, "fit_rms_mm": {}}
    if not keys or not times:
        return out
    t0 = times[0]
    m = np.full((times[-1] - t0 + 1, len(keys)), np.nan)
    for j, k in enumerate(keys):
        for t, iono_m in series[k].items():
            m[t - t0, j] = iono_m
    with np.errstate(all="ignore"):
        step = np.diff(m, axis=0)
        common = np.nanmedian(step, axis=1, keepdims=True) if np.isfinite(step).any() \
            else np.zeros((step.shape[0], 1))
        broken = ~(np.abs(step - common) <= IONO_JUMP_M)  # NaN steps (gaps) break an arc too
    cum = np.vstack([np.zeros((1, len(keys)), int), np.cumsum(broken, axis=0)])  # breaks before each epoch

    def between(d: Vec) -> Vec:  # epochs with two satellites or more: one alone has nothing to differ from
        ok = np.isfinite(d)
        med = np.array([np.median(r[o]) if np.count_nonzero(o) >= 2 else np.nan for r, o in zip(d, ok)])
        return (d - med[:, None])[ok & np.isfinite(med)[:, None]]

    for lag in lags_s:
        if lag >= m.shape[0]:
            continue
        d = m[lag:] - m[:-lag]
        d[cum[lag:] != cum[:-lag]] = np.nan
        v = between(d)
        if v.size:
            out["rms_mm"][lag] = float(np.sqrt(np.mean(v**2)) * 1e3)
            out["p95_mm"][lag] = float(np.percentile(np.abs(v), 95) * 1e3)
    tk = np.arange(-fit_s, 1, dtype=float)
    a = np.vstack([np.ones_like(tk), tk]).T
    for h in ahead_s:
        miss: list[Vec] = []
        for i in range(fit_s, m.shape[0] - h, 5):
            ok = np.all(np.isfinite(m[i - fit_s:i + 1]), axis=0) & np.isfinite(m[i + h]) \
                & (cum[i - fit_s] == cum[i + h])
            if np.count_nonzero(ok) < 4:
                continue
            coef = np.linalg.lstsq(a, m[i - fit_s:i + 1][:, ok], rcond=None)[0]
            e = m[i + h, ok] - (coef[0] + coef[1] * h)
            miss.append(e - np.median(e))
        if miss:
            out["fit_rms_mm"][h] = float(np.sqrt(np.mean(np.concatenate(miss) ** 2)) * 1e3)
    return out


def fit_environment(stats: dict[int, SystemStats], phase_sigma_ref_m: float) -> RoverEnvironment:
    """The RoverEnvironment whose parameters are the measured statistics: blockage per elevation band and
    azimuth sector, outage length, slip rates and half-cycle time pooled over the systems (weighted by tracked
    hours), C/N0 law and code σ at CN0_REF_DBHZ from GPS, GLONASS code factor = its σ_ref / GPS's.
    `phase_sigma_ref_m` is given (a moving antenna without truth has no measurable phase noise)."""
    sys_ = [st for st in stats.values() if st.tracked_sat_h > 0]
    w = np.array([st.tracked_sat_h for st in sys_])

    def pooled(values: list[float]) -> float:
        v = np.array(values, float)
        ok = np.isfinite(v)
        return float(np.sum(v[ok] * w[ok]) / np.sum(w[ok])) if ok.any() else math.nan

    bands = [b for b in sys_[0].avail_by_el]
    unavail = tuple(max(0.0, 1.0 - pooled([st.avail_by_el[b] for st in sys_])) for b in bands)
    u_az = np.array([1.0 - pooled([st.avail_by_az[k] for st in sys_]) for k in range(AZ_SECTORS)])
    mean_u = float(np.nanmean(u_az)) if np.isfinite(u_az).any() else math.nan
    az = tuple(float(x / mean_u) if math.isfinite(x) and mean_u > 0 else 1.0 for x in u_az)
    gps = stats.get(GNSS_GPS, sys_[0])
    glo = stats.get(GNSS_GLONASS)
    glo_factor = (glo.code_sigma_at_ref_m / gps.code_sigma_at_ref_m
                  if glo is not None and math.isfinite(glo.code_sigma_at_ref_m) else 1.0)
    return RoverEnvironment(
        el_bands_deg=tuple(float(b.split("-")[0]) for b in bands), unavailability=unavail, az_factor=az,
        outage_mean_s=pooled([st.outage_mean_s for st in sys_]),
        lli_slips_per_h=pooled([st.independent_lli_slips_per_h for st in sys_]),
        common_slip_events_per_h=pooled([st.common_slip_events_per_h for st in sys_]),
        unflagged_slips_per_h=pooled([st.unflagged_slips_per_h for st in sys_]),
        half_cycle_resolve_s=pooled([st.half_cycle_run_s for st in sys_]),
        cn0_horizon_dbhz=gps.cn0_fit_dbhz[0], cn0_zenith_dbhz=gps.cn0_fit_dbhz[1],
        cn0_sigma_dbhz=gps.cn0_resid_std_db, cn0_tau_s=fit_cn0_tau_s(gps.cn0_acf), cn0_ref_dbhz=CN0_REF_DBHZ,
        code_sigma_ref_m=gps.code_sigma_at_ref_m,
        phase_sigma_ref_m=phase_sigma_ref_m, glonass_code_factor=glo_factor,
    )
