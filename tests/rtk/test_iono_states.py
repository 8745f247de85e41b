"""The per-satellite ionosphere states (RtkOptions.iono_sigma_m_per_km) on noise-free simulated data: with a
known differential ionosphere at 5 km the fix is right and less biased than without the states (measured: 6.0
vs 6.2-6.5 mm; with L1 alone and 4 static minutes the states themselves stay near their prior)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from onboard.formats.rinex_nav import read_rinex_nav
from onboard.rtk import rtkpos
from onboard.rtk.consts import LAMBDA_L1_M
from onboard.rtk.ephemeris import EphemerisStore, satellite_states
from onboard.rtk.geodesy import azimuth_elevation, enu_to_ecef
from onboard.rtk.models import iono_mapping
from onboard.rtk.options import RtkOptions
from onboard.rtk.rtkpos import NSAT, NX0, NXI, Nav, rtk_init, rtk_pos
from onboard.rtk.types import Q_FIX, ObsEpoch
from tests.conftest import shared_file
from tests.rtk._sim import BASE_ECEF_M, T0, SimReceiver, observe

ROVER_ENU_M = np.array([3000.0, -4000.0, 2.0])  # 5 km from the base
VERTICAL_SD_IONO_M = np.linspace(-4e-3, 4e-3, NSAT)[np.random.default_rng(3).permutation(NSAT)]
"""The true SD (rover − base) vertical ionospheric delay of each PRN: ±4 mm, ~1.6 σ of the 0.5 mm/km prior."""


@pytest.fixture(scope="module")
def nav() -> Nav:
    f = read_rinex_nav(shared_file("gnss/broadcast-nav-20100701/brdc1820.10n"))
    return Nav(EphemerisStore(f.ephemerides), (f.iono_alpha, f.iono_beta))


def _with_iono(store: EphemerisStore, obs: ObsEpoch, pos: np.ndarray) -> tuple[ObsEpoch, np.ndarray]:
    """The rover epoch with the SD ionosphere added (code delayed, phase advanced); the slant delays (m)."""
    prns = obs.sv_id.astype(int)
    sats = satellite_states(store, list(prns), obs.time, list(obs.pr_m))
    _, el = azimuth_elevation(pos, sats.pos_m)
    slant = iono_mapping(el) * VERTICAL_SD_IONO_M[prns - 1]
    return replace(obs, pr_m=obs.pr_m + slant, cp_cyc=obs.cp_cyc - slant / LAMBDA_L1_M), slant


def _run(nav: Nav, options: RtkOptions, n: int = 240):
    """Static rover 5 km away, n 1-Hz epochs: (solutions, final state, true slant delays per slot)."""
    rover_clk = SimReceiver(clock_s=-0.8e-3, drift_s_s=2e-9, seed=1)
    base_clk = SimReceiver(clock_s=1e-6, seed=2)
    pos = enu_to_ecef(ROVER_ENU_M, BASE_ECEF_M)
    st = rtk_init(options)
    sols = []
    slant = np.full(NSAT, np.nan)
    for k in range(n):
        t = T0.add_s(k)
        rov, s = _with_iono(nav.store, observe(nav.store, rover_clk, pos, np.zeros(3), t), pos)
        bas = observe(nav.store, base_clk, BASE_ECEF_M, np.zeros(3), t)
        slant[:] = np.nan
        slant[rov.sv_id.astype(int) - 1] = s
        sols.append(rtk_pos(st, rov, bas, nav, BASE_ECEF_M))
    return sols, st, slant, pos


ON = RtkOptions()


@pytest.mark.slow
def test_iono_states_fix_the_right_integers_and_less_biased_than_the_ambiguity_walk(nav):
    # (with L1 alone the states stay near their prior: what they change is the fixed position's bias)
    sols, st, _slant, pos = _run(nav, ON)
    assert st.iono_on and st.x.size == rtkpos.NX
    fixed = [s for s in sols if s.q == Q_FIX]
    assert len(fixed) >= 100
    err = np.array([np.linalg.norm(s.pos_ecef_m - pos) for s in fixed])
    assert err.max() < 0.03  # the right integers (a wrong one is ≥ 10 cm off)
    j = NXI + np.arange(NSAT)
    assert np.count_nonzero(st.p[j, j] > 0) >= 6  # one state per tracked satellite
    # without the states (the ambiguity random walk alone) the same data fix further from the truth
    off, _, _, _ = _run(nav, replace(ON, iono_sigma_m_per_km=0.0))
    err_off = np.array([np.linalg.norm(s.pos_ecef_m - pos) for s in off if s.q == Q_FIX])
    assert err_off.size and np.sqrt(np.mean(err**2)) < np.sqrt(np.mean(err_off**2))


@pytest.mark.slow
def test_no_iono_states_on_short_baselines(nav):
    """Below iono_min_baseline_km the filter is the one without them (short baselines unchanged)."""
    o = ON
    assert o.iono_min_baseline_km >= 1.5
    rover_clk = SimReceiver(clock_s=-0.8e-3, seed=1)
    base_clk = SimReceiver(clock_s=1e-6, seed=2)
    pos = enu_to_ecef(np.array([30.0, -20.0, 2.0]), BASE_ECEF_M)
    a, b = rtk_init(o), rtk_init(replace(o, iono_sigma_m_per_km=0.0))
    for k in range(20):
        t = T0.add_s(k)
        rov = observe(nav.store, rover_clk, pos, np.zeros(3), t)
        bas = observe(nav.store, base_clk, BASE_ECEF_M, np.zeros(3), t)
        sa, sb = rtk_pos(a, rov, bas, nav, BASE_ECEF_M), rtk_pos(b, rov, bas, nav, BASE_ECEF_M)
        assert np.array_equal(sa.pos_ecef_m, sb.pos_ecef_m) and sa.q == sb.q
    assert not a.iono_on and a.x.size == NXI and a.p.shape == (NXI, NXI)  # no ionosphere columns at all


@pytest.mark.slow
def test_dropping_the_states_folds_them_into_the_ambiguities(nav):
    """_drop_iono keeps what the phase sees: λ·N − m(el)·I per satellite (value and variance) becomes λ·N'."""
    _, st, _, _ = _run(nav, ON, n=60)
    j = NXI + np.arange(NSAT)
    a = NX0 + np.arange(NSAT)
    both = (st.p[j, j] > 0) & (st.p[a, a] > 0)
    assert both.sum() >= 6
    el = np.where(both, np.radians(20.0 + 60.0 * np.arange(NSAT) / NSAT), np.nan)
    m = iono_mapping(el)
    t = np.zeros((NSAT, rtkpos.NX))  # phase delay rows: λ·N − m·I
    t[np.arange(NSAT), a] = LAMBDA_L1_M
    t[np.arange(NSAT), j] = -np.nan_to_num(m)
    seen_x, seen_p = t @ st.x, t @ st.p @ t.T
    x_pos, p_pos = st.x[:3].copy(), st.p[:3, :3].copy()
    rtkpos._drop_iono(st, np.ones(NSAT, bool), el)
    assert not np.any(st.p[j, :]) and not np.any(st.x[j])
    k = np.flatnonzero(both)
    after_x = LAMBDA_L1_M * st.x[a]
    after_p = LAMBDA_L1_M**2 * st.p[np.ix_(a, a)]
    np.testing.assert_allclose(after_x[k], seen_x[k], rtol=0, atol=1e-9)
    np.testing.assert_allclose(after_p[np.ix_(k, k)], seen_p[np.ix_(k, k)], rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(st.x[:3], x_pos)  # the position is untouched
    np.testing.assert_allclose(st.p[:3, :3], p_pos, rtol=1e-12, atol=0)
