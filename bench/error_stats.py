"""Receiver error statistics of real u-blox data next to hil_sim's: the evidence for hil_sim's ErrorModel.

Code: code minus carrier (CMC = P − λ·L) per receiver and satellite arc is free of geometry, clocks and
troposphere; it holds code noise + code multipath − phase errors (negligible) + 2·ionosphere + a constant (the
ambiguity). Per arc (split at LLI, gaps > 10 s or a jump > 5 m) a low-order polynomial in time (degree 2, +1
per 400 s of arc) removes the constant and the slow ionospheric divergence; the residuals, multiplied by
sin(el) ("zenith-equivalent", the scaling hil_sim uses), give the autocovariance C(k) at lags of k whole
seconds (pairs within an arc, so 3-4 s base sampling works). A first-order Gauss–Markov fit
C(k) = σ_c²·exp(−k/τ) over k = 1 s … (where C falls to 1/e², at most 120 s) gives the correlated (multipath)
part σ_c, τ; the white part σ_w² = C(0) − σ_c². The polynomial also removes multipath correlated over
hundreds of seconds, for the real and simulated series alike (hil_sim is run through the same code; its
input values are printed for comparison: the estimator's own bias is visible there).
Raw (not elevation-scaled) RMS per elevation and per C/N0 bin, and the mean C/N0 per elevation bin, check the
1/sin(el) law and the C/N0 model.

Phase: double-differenced (between receivers and against the highest satellite) carrier phase minus DD
geometric range at the known antenna positions (satellites at their transmission time from the pseudorange,
Sagnac; the 0.33 m and 197 m baselines leave no atmosphere), per DD arc minus its mean (the ambiguity).
Zenith-equivalent per-receiver σ: the DD variance is Σ over its 4 one-way terms of σ²/sin²(el), solved for σ
by least squares (both receivers assumed alike: true for M8P/M8P and hil_sim; for M8P/GLW1 it is the mean of
the two).

Real data (../shared/data/gnss): u-blox M8P static rover 20181004-1237 (RINEX 3, 1 Hz, 20 min) against the M8P
base (0.33 m, RAWX every 3-4 s) and the GLW1 CORS (Leica GR30, 197 m, 5 s); the M8P walking rover 1532 (moving,
under trees: an upper bound for a moving antenna); the 2008 u-blox RXM-RAW log (LEA-4T era, 4 min, ../ubx) and a NEO-6P RXM-RAW log (u-blox 6,
9 min at ~2 s).
hil_sim: the base (static ground antenna, 1200 s) and the rover's flight (take-off at 60 s, airborne after
84 s) of the standard scenario, LEA-6T and M8T, seed 1.

Harsh (`--harsh`): the M8P walk under trees against hil_sim's harsh rover (RoverEnvironment HARSH, GPS +
GLONASS world gr-2012) through hil_sim.obs_stats, per constellation: availability by elevation, losses and
outages, arcs, slips with and without LLI, half-cycle time, C/N0 distribution, code RMS by C/N0, and the base
RTCM stream's loss pattern; then the environment fitted to each (the real fit is HARSH, rounded).

Code by arc (`--code-arcs`): the rover's single-differenced code (rover − base) at the reference antenna
position (the walk: the M8P's own RTK fixes; hil_sim: the truth), GPS, the median of each epoch removed (the
clocks), base epochs at most 10 s older (metres of code against millimetres of atmosphere and clock
drift); RMS by the rover's C/N0, split by the length of the rover's phase arc
the sample belongs to (LLI or a gap > 1.5 s ends it) and by its age in the arc: the per-arc code error that the
code minus carrier of one receiver cannot see (docs/hil-sim-error-model.md).

Run: `.venv/bin/python bench/error_stats.py [--no-sim] [--seed N] [--harsh] [--code-arcs]` (about 1 min;
--harsh 20 s, --code-arcs 30 s).
"""

from __future__ import annotations

import argparse
import gzip
import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from onboard.formats.rinex_nav import read_rinex_nav
from onboard.formats.rinex_obs import read_rinex_obs
from onboard.rtk.consts import CLIGHT_M_S, LAMBDA_L1_M
from onboard.rtk.ephemeris import EphemerisStore, geometric_range, satellite_states
from onboard.rtk.pntpos import sat_az_el
from onboard.rtk.types import GNSS_GPS, LLI_HALF_CYCLE, LLI_SLIP, ObsEpoch

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
M8P = DATA / "gnss" / "ublox-m8p-galway-2018"
ROVER_1237_ECEF_M = np.array([3774088.9931, -601661.8217, 5089321.3853])
"""Static rover, mean of the M8P's fixed epochs (frame of the M8P base; dataset README)."""
BASE_1236_ECEF_M = np.array([3774089.2120, -601661.6157, 5089321.2474])
ROVER_1237_GLW1_FRAME_ECEF_M = np.array([3774088.6821, -601663.0350, 5089318.2304])
"""The same antenna in the GLW1 frame (dataset README)."""
TOKYO_APPROX_ECEF_M = np.array([-3869302.2, 3436557.8, 3717357.2])
MASK_RAD = math.radians(15.0)
MAX_LAG_S = 120
EL_BINS_DEG = (15, 30, 45, 60, 90)
CN0_BINS_DBHZ = (0, 35, 40, 45, 60)


@dataclass
class Series:
    """One receiver's per-satellite observables on its epochs: time (s), P, L (cycles), C/N0, el (rad), LLI."""

    t_s: list[float] = field(default_factory=list)
    prn: list[int] = field(default_factory=list)
    pr_m: list[float] = field(default_factory=list)
    cp_cyc: list[float] = field(default_factory=list)
    cn0: list[float] = field(default_factory=list)
    el: list[float] = field(default_factory=list)
    lli: list[int] = field(default_factory=list)
    rng_m: list[float] = field(default_factory=list)
    """Geometric range minus c·satellite clock at the known antenna position (NaN when moving/unknown)."""
    t_tag_s: list[float] = field(default_factory=list)

    def arrays(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(v) for k, v in self.__dict__.items()}


def series_from_epochs(epochs: list[ObsEpoch], store: EphemerisStore,
                       pos_of: Callable[[int], np.ndarray | None], approx_ecef_m: np.ndarray) -> Series:
    """Observables of GPS satellites above the 15° mask with phase; `pos_of(k)` the known antenna (or None)."""
    s = Series()
    t0 = epochs[0].time
    for k, ep in enumerate(epochs):
        g = ep.gnss_id == GNSS_GPS
        prn = ep.sv_id[g].astype(int)
        pr = ep.pr_m[g]
        if prn.size == 0:
            continue
        sats = satellite_states(store, prn, ep.time, pr)
        pos = pos_of(k)
        at = approx_ecef_m if pos is None else pos
        r, e = geometric_range(sats.pos_m, at)
        _, el = sat_az_el(at, e)
        rng = r - CLIGHT_M_S * sats.clock_s if pos is not None else np.full(prn.size, np.nan)
        t = ep.time.diff_s(t0)
        for j in range(prn.size):
            if not sats.ok[j] or not np.isfinite(ep.cp_cyc[g][j]) or el[j] < MASK_RAD:
                continue
            s.t_s.append(t)
            s.prn.append(int(prn[j]))
            s.pr_m.append(float(pr[j]))
            s.cp_cyc.append(float(ep.cp_cyc[g][j]))
            s.cn0.append(float(ep.cn0_dbhz[g][j]))
            s.el.append(float(el[j]))
            s.lli.append(int(ep.lli[g][j]))
            s.rng_m.append(float(rng[j]))
            s.t_tag_s.append(t)
    return s


def _arcs(t: np.ndarray, lli: np.ndarray, y: np.ndarray, jump: float, max_gap_s: float = 10.0) -> list[np.ndarray]:
    """Index arrays of continuous arcs of one satellite (sorted by time): split at LLI, gaps and jumps."""
    if t.size == 0:
        return []
    brk = np.zeros(t.size, bool)
    brk[1:] = (np.diff(t) > max_gap_s) | ((lli[1:] & (LLI_SLIP | LLI_HALF_CYCLE)) != 0) | \
        (np.abs(np.diff(y)) > jump)
    starts = np.flatnonzero(brk | (np.arange(t.size) == 0))
    ends = np.append(starts[1:], t.size)
    return [np.arange(a, b) for a, b in zip(starts, ends)]


def _detrend(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """y minus a polynomial in t: degree 2, +1 per 400 s of arc (ambiguity + ionospheric divergence)."""
    deg = min(5, 2 + int((t[-1] - t[0]) / 400.0))
    tt = (t - t.mean()) / max(1.0, float(np.ptp(t)))
    return y - np.polyval(np.polyfit(tt, y, deg), tt)


@dataclass
class Residuals:
    """Detrended residuals, arc by arc: time (s), zenith-equivalent value (m), raw value (m), el, C/N0."""

    arcs: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    raw: list[np.ndarray] = field(default_factory=list)
    el: list[np.ndarray] = field(default_factory=list)
    cn0: list[np.ndarray] = field(default_factory=list)


def cmc_residuals(s: Series, min_arc_s: float = 120.0) -> Residuals:
    """Per-satellite code-minus-carrier arcs, detrended (see module docstring)."""
    a = s.arrays()
    out = Residuals()
    cmc = a["pr_m"] - LAMBDA_L1_M * a["cp_cyc"]
    for prn in np.unique(a["prn"]):
        m = np.flatnonzero(a["prn"] == prn)
        m = m[np.argsort(a["t_s"][m])]
        for idx in _arcs(a["t_s"][m], a["lli"][m], cmc[m], 5.0):
            ii = m[idx]
            t = a["t_s"][ii]
            if t.size < 20 or t[-1] - t[0] < min_arc_s:
                continue
            r = _detrend(t, cmc[ii])
            keep = np.abs(r) < 6.0 * np.std(r) + 1e-9  # a rare code outlier would dominate C(0)
            out.arcs.append((t[keep], (r * np.sin(a["el"][ii]))[keep]))
            out.raw.append(r[keep])
            out.el.append(a["el"][ii][keep])
            out.cn0.append(a["cn0"][ii][keep])
    return out


def dd_phase_residuals(rov: Series, base: Series, pair_tol_s: float = 0.2) -> tuple[Residuals, list[np.ndarray]]:
    """DD phase minus DD range per DD arc (reference: highest common satellite), minus the arc mean.

    Returns the residuals (m; `arcs` values NOT elevation-scaled here) and, per arc, the summed one-way
    1/sin²(el) of its four terms (for the zenith-equivalent fit)."""
    ra, ba = rov.arrays(), base.arrays()
    b_times = np.unique(ba["t_s"])
    by_t_r: dict[float, np.ndarray] = {}
    for tt in np.unique(ra["t_s"]):
        by_t_r[tt] = np.flatnonzero(ra["t_s"] == tt)
    rows: dict[tuple[int, int], list[tuple[float, float, float, int]]] = {}
    for tt, ir in by_t_r.items():
        j = int(np.argmin(np.abs(b_times - tt)))
        if abs(b_times[j] - tt) > pair_tol_s:
            continue
        ib = np.flatnonzero(ba["t_s"] == b_times[j])
        common = sorted(set(ra["prn"][ir].tolist()) & set(ba["prn"][ib].tolist()))
        if len(common) < 2:
            continue
        sd: dict[int, tuple[float, float, int]] = {}
        for p in common:
            kr = ir[ra["prn"][ir] == p][0]
            kb = ib[ba["prn"][ib] == p][0]
            v = (LAMBDA_L1_M * ra["cp_cyc"][kr] - ra["rng_m"][kr]) - (LAMBDA_L1_M * ba["cp_cyc"][kb] - ba["rng_m"][kb])
            w = 1.0 / math.sin(ra["el"][kr]) ** 2 + 1.0 / math.sin(ba["el"][kb]) ** 2
            sd[p] = (v, w, int(ra["lli"][kr] | ba["lli"][kb]), float(ra["el"][kr]))
        ref = max(common, key=lambda p: sd[p][3])
        for p in common:
            if p == ref:
                continue
            rows.setdefault((ref, p), []).append(
                (tt, sd[p][0] - sd[ref][0], sd[p][1] + sd[ref][1], sd[p][2] | sd[ref][2]))
    out = Residuals()
    weights: list[np.ndarray] = []
    for (_, p), lst in rows.items():
        arr = np.array(lst)
        t, y, w, lli = arr[:, 0], arr[:, 1], arr[:, 2], arr[:, 3].astype(int)
        for idx in _arcs(t, lli, y, 0.05):
            if idx.size < 20:
                continue
            r = y[idx] - y[idx].mean()
            r = r - np.polyval(np.polyfit(t[idx] - t[idx].mean(), r, 1), t[idx] - t[idx].mean())
            out.arcs.append((t[idx], r))
            weights.append(w[idx])
    return out, weights


def autocov(arcs: list[tuple[np.ndarray, np.ndarray]], max_lag_s: int = MAX_LAG_S) -> tuple[np.ndarray, np.ndarray]:
    """Autocovariance C(k), k = 0 … max_lag_s whole seconds, over all pairs within arcs, and pair counts."""
    acc = np.zeros(max_lag_s + 1)
    cnt = np.zeros(max_lag_s + 1)
    for t, y in arcs:
        ti = np.round(t).astype(int)
        for lag in range(max_lag_s + 1):
            if lag == 0:
                acc[0] += float(y @ y)
                cnt[0] += y.size
                continue
            # pairs (i, j) with t_j − t_i == lag (times strictly increasing)
            j = np.searchsorted(ti, ti + lag)
            ok = j < ti.size
            ok[ok] = ti[j[ok]] == ti[ok] + lag
            acc[lag] += float(y[ok] @ y[j[ok]])
            cnt[lag] += int(ok.sum())
    with np.errstate(invalid="ignore"):
        return acc / cnt, cnt


def gauss_markov_fit(c: np.ndarray, cnt: np.ndarray) -> tuple[float, float, float]:
    """(σ_white, σ_correlated, τ s) from the autocovariance: log-linear fit of C(k) for k ≥ 1 down to C(1)/e²."""
    c0 = float(c[0])
    ks = [k for k in range(1, c.size) if cnt[k] > 50 and np.isfinite(c[k]) and c[k] > 0]
    ks2: list[int] = []
    for k in ks:  # the first contiguous stretch above C(1)/e²
        if ks2 and k != ks2[-1] + 1:
            break
        if c[k] < c[ks[0]] * math.exp(-2.0):
            break
        ks2.append(k)
    if len(ks2) < 3:
        return math.sqrt(max(c0, 0.0)), 0.0, float("nan")
    k = np.array(ks2, float)
    slope, icpt = np.polyfit(k, np.log(c[ks2]), 1, w=np.sqrt(cnt[ks2]))
    tau = -1.0 / slope if slope < 0 else float("inf")
    sc2 = min(math.exp(icpt), c0)
    return math.sqrt(max(c0 - sc2, 0.0)), math.sqrt(sc2), tau


def binned(vals: list[np.ndarray], key: list[np.ndarray], edges: tuple[float, ...], stat: str = "rms") -> str:
    """RMS (`stat` "rms", as 'lo-hi:rms(count)') or mean ("mean", as 'lo-hi:mean') of `vals` per bin of `key`
    (e.g. elevation in degrees); bins with 30 values or fewer print as '-'."""
    v = np.concatenate(vals) if vals else np.zeros(0)
    k = np.concatenate(key) if key else np.zeros(0)
    parts = []
    for lo, hi in itertools.pairwise(edges):
        m = (k >= lo) & (k < hi)
        if m.sum() <= 30:
            parts.append(f"{lo}-{hi}:  - " if stat == "rms" else f"{lo}-{hi}: - ")
        elif stat == "rms":
            parts.append(f"{lo}-{hi}:{np.sqrt(np.mean(v[m] ** 2)):.2f}({m.sum()})")
        else:
            parts.append(f"{lo}-{hi}:{np.mean(v[m]):.1f}")
    return " ".join(parts)


def report_code(label: str, s: Series, truth: str = "") -> None:
    res = cmc_residuals(s)
    if not res.arcs:
        print(f"{label:34s} no arcs")
        return
    c, cnt = autocov(res.arcs)
    sw, sc, tau = gauss_markov_fit(c, cnt)
    n = sum(a[0].size for a in res.arcs)
    print(f"{label:34s} {len(res.arcs):4d} arcs {n:6d} pts  zenith-eq total {math.sqrt(c[0]):.3f} m  "
          f"white {sw:.3f} m  multipath {sc:.3f} m  tau {tau:5.1f} s   C(k)/C(0) k=1,2,10,30: {c[1] / c[0]:.2f} "
          f"{c[2] / c[0]:.2f} {c[10] / c[0]:.2f} "
          f"{c[30] / c[0]:.2f}{truth}")
    deg = [e * 180 / math.pi for e in res.el]
    print(f"{'':34s} raw RMS (m) by el deg  {binned(res.raw, deg, EL_BINS_DEG)}")
    print(f"{'':34s} raw RMS (m) by C/N0    {binned(res.raw, res.cn0, CN0_BINS_DBHZ)}")
    print(f"{'':34s} mean C/N0 by el deg    {binned(res.cn0, deg, EL_BINS_DEG, 'mean')}")


def report_sd_code(label: str, rov: Series, base: Series, pair_tol_s: float = 0.2) -> None:
    """Between-receiver single difference of code minus carrier (what the engine's CodeScatter sees), per
    satellite arc at paired epochs, detrended and zenith-equivalent as above: its RMS against the two
    receivers' own RMS tells whether their multipath is independent (SD² = sum of both) or shared."""
    ra, ba = rov.arrays(), base.arrays()
    cr = ra["pr_m"] - LAMBDA_L1_M * ra["cp_cyc"]
    cb = ba["pr_m"] - LAMBDA_L1_M * ba["cp_cyc"]
    bt = np.unique(ba["t_s"])
    sd = Series()
    for k in range(ra["t_s"].size):
        j = int(np.argmin(np.abs(bt - ra["t_s"][k])))
        if abs(bt[j] - ra["t_s"][k]) > pair_tol_s:
            continue
        m = np.flatnonzero((ba["t_s"] == bt[j]) & (ba["prn"] == ra["prn"][k]))
        if m.size == 0:
            continue
        sd.t_s.append(float(ra["t_s"][k]))
        sd.prn.append(int(ra["prn"][k]))
        sd.pr_m.append(float(cr[k] - cb[m[0]]))
        sd.cp_cyc.append(0.0)
        sd.cn0.append(float(ra["cn0"][k]))
        sd.el.append(float(ra["el"][k]))
        sd.lli.append(int(ra["lli"][k] | ba["lli"][m[0]]))
        sd.rng_m.append(0.0)
        sd.t_tag_s.append(float(ra["t_s"][k]))
    res = cmc_residuals(sd, min_arc_s=60.0)
    if not res.arcs:
        print(f"{label:34s} no arcs")
        return
    y = np.concatenate([a[1] for a in res.arcs])
    print(f"{label:34s} {len(res.arcs):4d} arcs {y.size:6d} pts  SD code-minus-carrier zenith-eq RMS "
          f"{math.sqrt(float(np.mean(y * y))):.3f} m")


def report_phase(label: str, rov: Series, base: Series, truth: str = "") -> None:
    res, w = dd_phase_residuals(rov, base)
    if not res.arcs:
        print(f"{label:34s} no DD arcs")
        return
    y = np.concatenate([a[1] for a in res.arcs])
    ww = np.concatenate(w)
    # E[r²] = σ0²·Σ 1/sin²: least squares for σ0² (the per-arc mean removal costs a little: ignored)
    s0 = math.sqrt(float(np.sum(y * y * ww) / np.sum(ww * ww)))
    zen = [(t, r / np.sqrt(wi / 4.0)) for (t, r), wi in zip(res.arcs, w)]  # → one-way zenith-equivalent
    c, cnt = autocov(zen, 60)
    sw, sc, tau = gauss_markov_fit(c, cnt)
    print(f"{label:34s} {len(res.arcs):4d} DD arcs {y.size:6d} pts  DD RMS {1000 * math.sqrt(np.mean(y * y)):.1f} mm"
          f"  one-way zenith-eq {1000 * s0:.2f} mm (white {1000 * sw / 2:.2f}, correlated {1000 * sc / 2:.2f} mm, "
          f"tau {tau:.0f} s){truth}")


def _nav_store(*paths: Path) -> EphemerisStore:
    store = EphemerisStore()
    for p in paths:
        for e in read_rinex_nav(p).ephemerides:
            store.add(e)
    return store


def real() -> None:
    print("== real receivers ==")
    nav = _nav_store(M8P / "rinex/rover-20181004-1237.nav.gz", M8P / "rinex/base-20181004-1236.nav.gz")
    rov = read_rinex_obs(M8P / "rinex/rover-20181004-1237.obs.gz").epochs
    bas = read_rinex_obs(M8P / "rinex/base-20181004-1236.rawx.obs.gz").epochs
    t0 = rov[0].time
    bas = [e for e in bas if e.time.diff_s(t0) >= -1.0]
    s_r = series_from_epochs(rov, nav, lambda k: ROVER_1237_ECEF_M, ROVER_1237_ECEF_M)
    s_b = series_from_epochs(bas, nav, lambda k: BASE_1236_ECEF_M, BASE_1236_ECEF_M)
    _shift(s_b, bas[0].time.diff_s(t0))
    report_code("M8P static rover (1 Hz)", s_r)
    report_code("M8P base (RAWX every 3-4 s)", s_b)
    report_phase("DD phase M8P/M8P 0.33 m", s_r, s_b)
    report_sd_code("SD code M8P-M8P 0.33 m", s_r, s_b)
    glw = read_rinex_obs(M8P / "cors-glw1/glw1277m.18o.gz")
    glw_epochs = [e for e in glw.epochs if e.time.diff_s(t0) >= -1.0]
    glw_pos = glw.header.antenna_position_ecef_m()
    s_g = series_from_epochs(glw_epochs, nav, lambda k: glw_pos, glw_pos)
    _shift(s_g, glw_epochs[0].time.diff_s(t0))
    s_r2 = series_from_epochs(rov, nav, lambda k: ROVER_1237_GLW1_FRAME_ECEF_M, ROVER_1237_GLW1_FRAME_ECEF_M)
    report_code("GLW1 Leica GR30 (5 s, geodetic)", s_g)
    report_phase("DD phase M8P/GLW1 197 m", s_r2, s_g)
    walk = read_rinex_obs(M8P / "rinex/rover-20181004-1532.obs.gz").epochs
    nav2 = _nav_store(M8P / "rinex/rover-20181004-1532.nav.gz")
    report_code("M8P walking rover, trees (1 Hz)", series_from_epochs(walk, nav2, lambda k: None, BASE_1236_ECEF_M))
    from onboard.receiver.ubx_collect import collect
    raw = (DATA / "ubx" / "rtklib_ubx_20080526.ubx").read_bytes()
    col = collect(iter([raw]))
    report_code("u-blox RXM-RAW 2008 static (1 Hz)",
                series_from_epochs(col.epochs, EphemerisStore(col.ephemerides), lambda k: None, TOKYO_APPROX_ECEF_M))
    col = collect(iter([(DATA / "ubx" / "pyublox_6P-raw-PPP.ubx").read_bytes()]))
    report_code("u-blox NEO-6P RXM-RAW static (~2 s)",
                series_from_epochs(col.epochs, EphemerisStore(col.ephemerides), lambda k: None,
                                   np.array(col.fixes_ecef_m[0])))


def _shift(s: Series, dt_s: float) -> None:
    """Re-reference a series' times (s since its first epoch) to another series' first epoch."""
    s.t_s = [t + dt_s for t in s.t_s]


def sim(seed: int) -> None:
    from hil_sim.scenario import Scenario
    from hil_sim.world import World

    for model in ("lea6t", "m8t"):
        sc = Scenario.default(model, duration_s=1300.0, seed=seed)
        em = sc.errors
        truth = (f"   [model: white {em.code_sigma_zenith_m}, multipath {em.mp_code_sigma_zenith_m} m, "
                 f"tau {em.mp_tau_s} s]")
        ptruth = f"   [model: white {1000 * em.phase_sigma_zenith_m}, multipath {1000 * em.mp_phase_sigma_zenith_m} mm]"
        world = World(sc)
        series = {}
        for rcv in ("rover", "base"):
            s = Series()
            for k in range(1290):
                ep, d = world.observe_detailed(rcv, sc.start.add_s(k))
                if rcv == "rover" and not world.truth(d["timing"].t_true)["armed"]:
                    continue
                if rcv == "rover" and k >= 600:  # the flight ends (landing) at about 560 s
                    break
                # the atmosphere too (the flying rover is up to 100 m above the base: centimetres of troposphere
                # the real 0.33 m / 197 m pairs do not have)
                rng = d["rho_m"] - CLIGHT_M_S * d["sat_clock_s"] + d["tropo_m"] - d["iono_m"]
                for j in range(len(ep)):
                    if d["el_rad"][j] < MASK_RAD or not np.isfinite(ep.cp_cyc[j]):
                        continue
                    s.t_s.append(float(k))
                    s.prn.append(int(ep.sv_id[j]))
                    s.pr_m.append(float(ep.pr_m[j]))
                    s.cp_cyc.append(float(ep.cp_cyc[j]))
                    s.cn0.append(float(ep.cn0_dbhz[j]))
                    s.el.append(float(d["el_rad"][j]))
                    s.lli.append(int(ep.lli[j]))
                    s.rng_m.append(float(rng[j]))
                    s.t_tag_s.append(float(k))
            series[rcv] = s
        report_code(f"hil_sim {model} base, ground, 1290 s", series["base"], truth)
        report_code(f"hil_sim {model} rover, airborne", series["rover"], truth)
        report_phase(f"DD phase hil_sim {model} (truth pos)", series["rover"], series["base"], ptruth)
        report_sd_code(f"SD code hil_sim {model} rover-base", series["rover"], series["base"])


WALK_NAV = ("rinex/rover-20181004-1532.nav.gz", "rinex/base-20181004-1452.nav.gz", "cors-glw1/glw1277p.18n.gz",
            "cors-glw1/glw1277p.18g.gz")
"""The walk's own ephemerides miss satellites it hardly tracked (blocked): the base's and GLW1's complete them."""


def harsh_rows(seed: int = 1, duration_s: float = 1200.0) -> tuple[list[tuple[str, str, str]], Any, Any]:
    """(rows of (statistic, real, simulated), fitted real environment, refit of the simulation): the M8P walk
    under trees (20181004-1532, GPS + GLONASS, 10° mask) against the harsh scenario (hil_sim HARSH rover,
    world gr-2012, standard flight, `duration_s` at 1 Hz), through the same hil_sim.obs_stats code."""
    from hil_sim.constellations import read_navigation
    from hil_sim.obs_stats import fit_environment, stream_losses, tracking_stats
    from hil_sim.rtk_scenarios import HARSH_RADIO_LOSS, radio_drops
    from hil_sim.scenario import HARSH, Scenario
    from hil_sim.world import World
    from onboard.receiver.base_epochs import collect_rtcm
    from onboard.rtk.navstore import BroadcastNavigation
    from onboard.rtk.types import GNSS_GLONASS

    walk = read_rinex_obs(M8P / "rinex/rover-20181004-1532.obs.gz")
    ephs, _, _ = read_navigation([M8P / p for p in WALK_NAV])
    real_st = tracking_stats(walk.epochs, BroadcastNavigation(ephs), walk.header.approx_pos_ecef_m,
                             (GNSS_GPS, GNSS_GLONASS))
    sc = Scenario.multi("gr-2012", duration_s=duration_s, seed=seed, rover_environment=HARSH)
    world = World(sc)
    n = int(duration_s) - 10
    eps = [world.observe("rover", sc.start.add_s(k)) for k in range(n)]
    pos = np.array([world.truth(sc.start.add_s(k))["antenna_ecef_m"] for k in range(n)])
    sim_st = tracking_stats(eps, world.broadcast_navigation(), pos, (GNSS_GPS, GNSS_GLONASS))
    rows: list[tuple[str, str, str]] = []
    for g, name in ((GNSS_GPS, "GPS"), (GNSS_GLONASS, "GLO")):
        r, s = real_st[g], sim_st[g]

        def add(label: str, a: float, b: float, fmt: str = "{:.2f}") -> None:
            rows.append((f"{name} {label}", fmt.format(a), fmt.format(b)))  # noqa: B023

        add("tracked sat-h", r.tracked_sat_h, s.tracked_sat_h)
        for band in r.avail_by_el:
            add(f"availability el {band}", r.avail_by_el[band], s.avail_by_el[band], "{:.3f}")
        add("losses / visible sat-h", r.losses_per_visible_h, s.losses_per_visible_h, "{:.1f}")
        add("mean outage s", r.outage_mean_s, s.outage_mean_s, "{:.1f}")
        add("median arc s", r.arc_median_s, s.arc_median_s, "{:.0f}")
        add("LLI slips / sat-h", r.lli_slips_per_h, s.lli_slips_per_h, "{:.1f}")
        add("LLI slips / sat-h, independent", r.independent_lli_slips_per_h, s.independent_lli_slips_per_h, "{:.1f}")
        add("receiver-wide slip events / h", r.common_slip_events_per_h, s.common_slip_events_per_h, "{:.1f}")
        add("half-cycle run after slip s", r.half_cycle_run_s, s.half_cycle_run_s, "{:.1f}")
        add("slips without LLI / sat-h", r.unflagged_slips_per_h, s.unflagged_slips_per_h, "{:.1f}")
        for q, a, b in zip(("p10", "p50", "p90"), r.cn0_p10_p50_p90, s.cn0_p10_p50_p90, strict=True):
            add(f"C/N0 {q} dB-Hz", a, b, "{:.1f}")
        for band in r.cn0_mean_by_el:
            add(f"mean C/N0 el {band}", r.cn0_mean_by_el[band], s.cn0_mean_by_el[band], "{:.1f}")
        for band in r.code_rms_by_cn0:
            add(f"code RMS m, C/N0 {band}", r.code_rms_by_cn0[band], s.code_rms_by_cn0[band])
        add("code sigma at 45 dB-Hz m", r.code_sigma_at_ref_m, s.code_sigma_at_ref_m)
    with gzip.open(M8P / "rtcm3/base-20181004-1452.rtcm3.gz") as fh:
        rtcm = collect_rtcm([fh.read()], walk.epochs[0].time)
    t0 = rtcm.gnss_epochs[0].time

    def fmt(loss: dict[str, float]) -> str:
        return (f"{loss['lost_fraction']:.2f}, {loss['p_loss_after_ok']:.2f}, {loss['p_loss_after_loss']:.2f}, "
                f"{loss['mean_run_s']:.1f}")

    sim_loss = stream_losses(np.flatnonzero(~radio_drops(3600, *HARSH_RADIO_LOSS, seed)).astype(float))
    for g, name in ((GNSS_GPS, "GPS MSM7 1077"), (GNSS_GLONASS, "GLO MSM7 1087")):
        loss = stream_losses([e.time.diff_s(t0) for e in rtcm.gnss_epochs if g in e.systems])
        rows.append((f"base stream {name}: lost fraction, P(loss after ok), P(loss after loss), mean loss run s",
                     fmt(loss), fmt(sim_loss) + " (HARSH_RADIO_LOSS, 1 h)"))
    return rows, fit_environment(real_st, HARSH.phase_sigma_ref_m), fit_environment(sim_st, HARSH.phase_sigma_ref_m)


def harsh(seed: int) -> None:
    """Print the real walk's statistics next to the harsh scenario's (a Markdown table) and both fits."""
    rows, fit_real, fit_sim = harsh_rows(seed)
    print("| statistic | M8P walk, trees (real) | hil_sim harsh (sim) |\n|---|---|---|")
    for name, a, b in rows:
        print(f"| {name} | {a} | {b} |")
    print(f"\nfit of the real walk: {fit_real}\nrefit of the simulation: {fit_sim}")


ARC_CN0_BINS_DBHZ = (30, 35, 40, 45, 60)


def code_by_arc(rov: Series, base: Series, pair_tol_s: float = 10.0, gap_s: float = 1.5) -> dict[str, dict[str, float]]:
    """RMS (m) of the rover − base code at the reference positions (`rng_m` of both series; rover samples
    without one are left out of the residuals but still make its arcs), each epoch's median removed, per C/N0
    bin of the rover: over all samples, samples of arcs shorter / not shorter than 60 s, samples in their arc's
    first 30 s / later. An entry is NaN with fewer than 10 samples."""
    ra, ba = rov.arrays(), base.arrays()
    # the rover's arcs: by satellite, split at LLI (slip or half cycle) and at gaps
    arc_len = np.full(ra["t_s"].size, np.nan)
    arc_age = np.full(ra["t_s"].size, np.nan)
    for prn in np.unique(ra["prn"]):
        idx = np.flatnonzero(ra["prn"] == prn)
        idx = idx[np.argsort(ra["t_s"][idx], kind="stable")]
        t = ra["t_s"][idx]
        brk = np.ones(idx.size, bool)
        brk[1:] = (np.diff(t) > gap_s) | ((ra["lli"][idx][1:] & (LLI_SLIP | LLI_HALF_CYCLE)) != 0)
        starts = np.flatnonzero(brk)
        for a, b in zip(starts, [*starts[1:], idx.size], strict=True):
            arc_len[idx[a:b]] = t[b - 1] - t[a]
            arc_age[idx[a:b]] = t[a:b] - t[a]
    base_of = {(round(float(t), 3), int(p)): k for k, (t, p) in enumerate(zip(ba["t_s"], ba["prn"], strict=True))}
    bt = np.unique(ba["t_s"])
    rows: list[tuple[float, float, float, float, float]] = []  # t, residual, C/N0, arc length, age
    for t in np.unique(ra["t_s"][np.isfinite(ra["rng_m"])]):
        j = int(np.searchsorted(bt, t, side="right")) - 1  # the latest base epoch at or before the rover's
        if j < 0 or t - bt[j] > pair_tol_s:
            continue
        ks = np.flatnonzero((ra["t_s"] == t) & np.isfinite(ra["rng_m"]))
        sd, keep = [], []
        for k in ks:
            m = base_of.get((round(float(bt[j]), 3), int(ra["prn"][k])))
            if m is None or not np.isfinite(ba["rng_m"][m]):
                continue
            sd.append((ra["pr_m"][k] - ra["rng_m"][k]) - (ba["pr_m"][m] - ba["rng_m"][m]))
            keep.append(k)
        if len(sd) < 4:
            continue
        res = np.array(sd) - float(np.median(sd))
        rows += [(float(t), float(r), float(ra["cn0"][k]), float(arc_len[k]), float(arc_age[k]))
                 for r, k in zip(res, keep, strict=True)]
    x = np.array(rows).reshape(-1, 5)
    out: dict[str, dict[str, float]] = {}
    for lo, hi in itertools.pairwise(ARC_CN0_BINS_DBHZ):
        m = (x[:, 2] >= lo) & (x[:, 2] < hi)
        parts = {"all": m, "arc < 60 s": m & (x[:, 3] < 60.0), "arc >= 60 s": m & (x[:, 3] >= 60.0),
                 "first 30 s": m & (x[:, 4] < 30.0), "later": m & (x[:, 4] >= 30.0)}
        out[f"{lo}-{hi}"] = {name: float(np.sqrt(np.mean(x[sel, 1] ** 2))) if sel.sum() >= 10 else math.nan
                             for name, sel in parts.items()}
        out[f"{lo}-{hi}"]["n"] = float(m.sum())
    return out


def code_arcs(seed: int) -> None:
    """Print code_by_arc of the M8P walk (its own RTK fixes as truth, its RAWX base) beside the harsh flight's."""
    from bench_rtk import DATASETS  # the walk's reference and base position, as the RTK benchmark reads them

    from hil_sim.rtk_scenarios import HARSH_RADIO_LOSS, SimCase, simulate

    ds = next(d for d in DATASETS if "walk" in d.name)
    assert ds.base_pos is not None
    walk = read_rinex_obs(ds.rover).epochs
    wbase = read_rinex_obs(ds.base).epochs
    nav = _nav_store(*(M8P / p for p in WALK_NAV[:2]))
    base_pos = np.array([float(v) for v in ds.base_pos.split(",")])
    ref = ds.ref(np.array([e.time.tow_s for e in walk]))  # NaN rows where the M8P did not fix
    t0 = walk[0].time
    s_r = series_from_epochs(walk, nav, lambda k: ref[k] if np.isfinite(ref[k]).all() else None, base_pos)
    wbase = [e for e in wbase if e.time.diff_s(t0) >= -2.0]
    s_b = series_from_epochs(wbase, nav, lambda k: base_pos, base_pos)
    _shift(s_b, wbase[0].time.diff_s(t0))
    tables = {"M8P walk (real)": code_by_arc(s_r, s_b)}
    # the phase at the same reference: what moves within an arc (a constant is the ambiguity's)
    at_ref = Series(**{k: [v for v, r in zip(vals, s_r.rng_m, strict=True) if math.isfinite(r)]
                       for k, vals in s_r.__dict__.items()})
    report_phase("DD phase M8P walk at its RTK fixes", at_ref, s_b)
    data = simulate(SimCase("harsh", "", harsh=True, radio_loss=HARSH_RADIO_LOSS, seed=seed, systems="GR"), "m8t")
    rover = sorted(data.rover, key=lambda e: e.time)
    store = data.nav.store
    t1 = rover[0].time
    sim_r = series_from_epochs(rover, store, lambda k: data.truth(rover[k].time)["antenna_ecef_m"],
                               data.base_pos_ecef_m)
    sbase = [e for e in data.base if e.time.diff_s(t1) >= -2.0]
    sim_b = series_from_epochs(sbase, store, lambda k: data.base_pos_ecef_m, data.base_pos_ecef_m)
    _shift(sim_b, sbase[0].time.diff_s(t1))
    tables[f"hil_sim harsh, gr-2012, seed {seed}"] = code_by_arc(sim_r, sim_b)
    for label, tab in tables.items():
        print(f"{label}: GPS code rover - base at the reference, RMS m (samples)")
        print(f"  {'C/N0':8s} " + " ".join(f"{k:>12s}" for k in ("all", "arc < 60 s", "arc >= 60 s", "first 30 s",
                                                                  "later")))
        for band, row in tab.items():
            print(f"  {band:8s} {row['all']:7.2f} ({int(row['n']):4d})" + " ".join(
                f"{row[k]:12.2f}" for k in ("arc < 60 s", "arc >= 60 s", "first 30 s", "later")))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-sim", action="store_true")
    ap.add_argument("--no-real", action="store_true")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--harsh", action="store_true", help="only the walk under trees vs the harsh scenario")
    ap.add_argument("--code-arcs", action="store_true",
                    help="only the walk's code at its RTK fixes by arc vs the harsh scenario's at the truth")
    args = ap.parse_args()
    if args.code_arcs:
        code_arcs(args.seed if args.seed != 1 else 5)
        return
    if args.harsh:
        harsh(args.seed)
        return
    if not args.no_real:
        real()
    if not args.no_sim:
        print(f"== hil_sim (seed {args.seed}) ==")
        sim(args.seed)


if __name__ == "__main__":
    main()
