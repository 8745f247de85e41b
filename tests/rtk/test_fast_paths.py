"""The engine's speed-oriented code paths give what the plain numpy/per-satellite formulations give, to the bit.

The speed work (whole-command CPU against the RTKLIB driver) replaced numpy conveniences by cheaper
equivalents that must not change a single result: these tests pin that equivalence on real data, so a later
edit that changes the numbers (not only the speed) shows up here rather than as a drift in the benchmarks.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest

from onboard.formats.rinex_nav import read_rinex_nav
from onboard.formats.rinex_obs import read_rinex_obs
from onboard.gnsstime import GpsTime
from onboard.rtk import linsolve
from onboard.rtk.ephemeris import EphemerisStore, eph_position_velocity, satellite_states
from onboard.rtk.geodesy import enu_rotation
from onboard.rtk.mlambda import ld_factor, mlambda
from onboard.rtk.models import median_of_few
from onboard.rtk.pntpos import _norm
from onboard.rtk.rtkpos import NSAT, NX, NX0, NXI, _dd_ambiguities, _dd_ambiguities_without
from tests.conftest import shared_file

M8P = "gnss/ublox-m8p-galway-2018/rinex/"


def test_small_median_and_norm_equal_numpy_to_the_bit() -> None:
    rng = np.random.default_rng(7)
    for n in range(1, 14):
        a = rng.normal(0.0, 3.0, n) * 10.0 ** rng.integers(-3, 4)
        assert median_of_few(a) == np.median(a)
        assert _norm(a) == np.linalg.norm(a)


def test_linsolve_equals_numpy_solve_to_the_bit_and_raises_on_singular() -> None:
    rng = np.random.default_rng(11)
    for n in (1, 3, 8, 24):
        a = rng.normal(size=(n, n))
        s = a @ a.T + np.eye(n) * 10.0 ** rng.integers(-6, 2)
        for b in (rng.normal(size=n), rng.normal(size=(n, 5)), rng.normal(size=(5, n)).T):  # also a transposed view
            assert linsolve.solve(s, b).tobytes() == np.linalg.solve(s, b).tobytes()
        assert linsolve.inv(s).tobytes() == np.linalg.inv(s).tobytes()
    with pytest.raises(linsolve.LinAlgError), np.errstate(invalid="ignore"):
        linsolve.solve(np.ones((3, 3)), np.ones(3))
    with pytest.raises(np.linalg.LinAlgError), np.errstate(invalid="ignore"):
        linsolve.solve(np.zeros((2, 2)), np.ones((2, 2)))
    with pytest.raises(linsolve.LinAlgError), np.errstate(invalid="ignore"):
        linsolve.inv(np.ones((3, 3)))


def test_linsolve_falls_back_to_numpy_where_its_private_gufuncs_are_gone(monkeypatch: pytest.MonkeyPatch) -> None:
    # numpy.linalg._umath_linalg is private: a numpy without it must still solve, through the public wrapper
    rng = np.random.default_rng(12)
    a = rng.normal(size=(6, 6))
    s, b = a @ a.T + np.eye(6), rng.normal(size=6)
    fast = linsolve.solve(s, b)
    fast_inv = linsolve.inv(s)
    monkeypatch.setattr(linsolve, "_umath_linalg", None)
    assert linsolve.solve(s, b).tobytes() == fast.tobytes()
    assert linsolve.inv(s).tobytes() == fast_inv.tobytes()
    with pytest.raises(linsolve.LinAlgError):
        linsolve.solve(np.ones((3, 3)), np.ones(3))


def test_satellite_states_on_32_slots_equal_the_per_satellite_formulas() -> None:
    nav = read_rinex_nav(shared_file(M8P + "rover-20181004-1237.nav.gz"))
    obs = read_rinex_obs(shared_file(M8P + "rover-20181004-1237.obs.gz"))
    store = EphemerisStore(nav.ephemerides)
    for ep in obs.epochs[::300]:
        g = ep.gps_only()
        pr = np.full(32, np.nan)
        pr[g.sv_id - 1] = g.pr_m
        slots = satellite_states(store, np.arange(1, 33), g.time, pr)
        subset = satellite_states(store, g.sv_id, g.time, g.pr_m)
        # the 32-slot call is the subset call scattered, empty slots zero and not ok
        k = g.sv_id - 1
        for name in ("pos_m", "vel_m_s", "clock_s", "drift_s_s", "var_m2", "ok"):
            assert np.array_equal(getattr(slots, name)[k], getattr(subset, name)), name
        empty = np.setdiff1d(np.arange(32), k)
        assert not slots.ok[empty].any() and not slots.pos_m[empty].any()
        assert slots.ok.sum() >= 5
        # and each state agrees with the scalar per-ephemeris formulas at the transmission time
        for i in np.flatnonzero(subset.ok):
            eph = store.select(int(g.sv_id[i]), g.time)
            assert eph is not None
            t_tx = g.time.add_s(-g.pr_m[i] / 299792458.0 - subset.clock_s[i] - eph.tgd_s)
            pos, vel, _, _ = eph_position_velocity(eph, t_tx)
            assert np.allclose(subset.pos_m[i], pos, atol=1e-3) and np.allclose(subset.vel_m_s[i], vel, atol=1e-3)


def _ld_reference(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The LtDL factorisation as first written with numpy row operations (RTKLIB LD())."""
    n = q.shape[0]
    a = q.copy()
    lmat = np.zeros((n, n))
    d = np.zeros(n)
    for i in range(n - 1, -1, -1):
        d[i] = a[i, i]
        lmat[i, : i + 1] = a[i, : i + 1] / np.sqrt(d[i])
        a[:i, :i] -= np.outer(lmat[i, :i], lmat[i, :i])
        lmat[i, : i + 1] /= lmat[i, i]
    return lmat, d


def test_ld_factor_and_lambda_on_list_code_match_the_numpy_formulation() -> None:
    rng = np.random.default_rng(3)
    for n in (3, 6, 9, 12):
        g = rng.normal(size=(n, n))
        q = g @ g.T * 0.01 + np.eye(n) * 1e-3
        lmat, d = ld_factor(q)
        ref_l, ref_d = _ld_reference(q)
        # LAPACK's Cholesky sums in its own order: equal to rounding, the unit triangle exact
        np.testing.assert_allclose(lmat, ref_l, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(d, ref_d, rtol=1e-12)
        assert np.array_equal(np.diag(lmat), np.ones(n)) and not np.triu(lmat, 1).any()
        a = rng.normal(size=n) * 5.0
        res = mlambda(a, q)
        assert res.fixed.shape == (n, 2) and res.sq_dist[0] <= res.sq_dist[1]
        # the best candidate is an integer vector at least as close (Q-norm) as rounding the float
        qi = np.linalg.inv(q)
        best, rounded = res.fixed[:, 0] - a, np.round(a) - a
        assert best @ qi @ best <= rounded @ qi @ rounded + 1e-9


def _random_dd_states(seed: int, min_sats: int) -> Iterator[tuple[int, np.ndarray, np.ndarray, np.ndarray, int]]:
    """(state size, P, x, candidate slots, reference slot) of random filter states, 50 per state size."""
    rng = np.random.default_rng(seed)
    for nx in (NXI, NX):
        for _ in range(50):
            g = rng.normal(size=(nx, nx))
            p = g @ g.T * 10.0 ** rng.integers(-4, 3)
            x = rng.normal(size=nx) * 100.0
            idx = np.sort(rng.choice(NSAT, size=int(rng.integers(min_sats, 12)), replace=False))
            yield nx, p, x, idx, int(rng.choice(idx))


def test_dd_ambiguities_equal_the_dense_dd_matrix_products_to_the_bit() -> None:
    for nx, p, x, idx, ref in _random_dd_states(5, 2):
        d = np.zeros((idx.size - 1, idx.size))  # RTKLIB's DD matrix: rows e_i − e_ref
        others = (idx != ref).nonzero()[0]
        d[np.arange(others.size), others] = 1.0
        d[:, int((idx == ref).nonzero()[0][0])] = -1.0
        ja = NX0 + idx
        a, qa, qba, qia = _dd_ambiguities(x, p, idx, ref)
        assert a.tobytes() == (d @ x[ja]).tobytes()
        assert qa.tobytes() == (d @ p[np.ix_(ja, ja)] @ d.T).tobytes()
        assert qba.tobytes() == (p[:3, ja] @ d.T).tobytes()
        if nx == NX:
            assert qia is not None and qia.tobytes() == (p[NXI:NX, ja] @ d.T).tobytes()
        else:
            assert qia is None


def test_dd_ambiguities_without_one_slot_equal_their_direct_computation_to_the_bit() -> None:
    """A partial-fixing retry subsets the larger set's DD ambiguities instead of recomputing them."""
    rng = np.random.default_rng(9)
    for _nx, p, x, idx, ref in _random_dd_states(8, 3):
        others = idx[idx != ref]
        k = int(rng.integers(others.size))
        sub = _dd_ambiguities_without(_dd_ambiguities(x, p, idx, ref), k)
        direct = _dd_ambiguities(x, p, idx[idx != others[k]], ref)
        for s, d in zip(sub, direct):
            assert (s is None and d is None) or (s is not None and d is not None and s.shape == d.shape
                                                 and s.tobytes() == d.tobytes() and s.flags.c_contiguous)


def test_gps_only_epoch_is_itself_and_mixed_epochs_are_filtered() -> None:
    obs = read_rinex_obs(shared_file(M8P + "rover-20181004-1237.obs.gz"))
    mixed = next(e for e in obs.epochs if (e.gnss_id != 0).any())
    g = mixed.gps_only()
    assert g is not mixed and (g.gnss_id == 0).all() and len(g) < len(mixed)
    assert g.gps_only() is g
    assert g.time == GpsTime(mixed.time.week, mixed.time.tow_ns)


def test_lambda_skips_the_search_only_when_the_ratio_provably_reaches_the_cap() -> None:
    """mlambda(..., ratio_cap) returns the full search's best integers and success rate and a ratio of at least
    the cap whenever it skips the search, with the full search's best distance and D to the bit, or, when a
    certificate skips the decorrelation too (Z = I), to rounding; otherwise it is the full search, unchanged."""
    rng = np.random.default_rng(11)
    cap = 999.9
    skipped = searched = certified = 0
    for trial in range(300):
        n = int(rng.integers(2, 12))
        g = rng.normal(size=(n, n))
        # from a held set (σ ~ 1e-3 cycles, floats within a few σ of integers) to a code-level float (σ ~ 1 cycle)
        scale = 10.0 ** rng.uniform(-7, 0)
        q = g @ g.T * scale + np.eye(n) * scale * 0.05
        ints = rng.integers(-50, 50, n).astype(float)
        a = ints + rng.multivariate_normal(np.zeros(n), q) * rng.uniform(0.2, 3.0)
        full = mlambda(a, q)
        fast = mlambda(a, q, ratio_cap=cap)
        assert np.array_equal(fast.fixed[:, 0], full.fixed[:, 0]), trial
        assert fast.success_rate == full.success_rate, trial
        if fast.sq_dist[0] != full.sq_dist[0] or not np.array_equal(fast.cond_var, full.cond_var):
            certified += 1  # the certificate: its own rounding of the best distance, D of Q undecorrelated
            assert np.array_equal(fast.z_mat, np.eye(n)) and fast.success_rate == 1.0, trial
            assert fast.sq_dist[0] == pytest.approx(full.sq_dist[0], rel=1e-9, abs=1e-12), trial
        if fast.fixed.shape[1] == 1:
            skipped += 1
            assert full.ratio >= cap and fast.ratio >= cap, trial
            assert fast.sq_dist[1] <= full.sq_dist[1] * (1 + 1e-12), trial  # a lower bound of the second best
        else:
            searched += 1
            assert np.array_equal(fast.fixed, full.fixed) and np.array_equal(fast.sq_dist, full.sq_dist)
    assert skipped > 30 and searched > 30 and certified > 10  # every branch exercised


def test_satellite_states_of_all_epochs_in_one_batch_equal_the_per_epoch_calls() -> None:
    """Post-processing computes every epoch's satellites before the filter (epoch_receivers): the batch must
    give each epoch exactly what the one-epoch call (the real-time path) gives, ephemeris choice included."""
    from onboard.rtk.rtkpos import epoch_receivers

    def epoch_satellites(epochs, store):  # type: ignore[no-untyped-def]
        return [r.sats for r in epoch_receivers(epochs, store)]

    nav = read_rinex_nav(shared_file(M8P + "rover-20181004-1237.nav.gz"))
    obs = read_rinex_obs(shared_file(M8P + "rover-20181004-1237.obs.gz"))
    store = EphemerisStore(nav.ephemerides)
    epochs = [e.gps_only() for e in obs.epochs[::7]]
    batch = epoch_satellites(epochs, store)
    assert len(batch) == len(epochs)
    for ep, b in zip(epochs, batch):
        one = satellite_states(store, np.arange(1, 33), ep.time, epoch_receivers([ep], store)[0].pr_m)
        for name in ("pos_m", "vel_m_s", "clock_s", "drift_s_s", "var_m2", "ok"):
            assert np.array_equal(getattr(b, name), getattr(one, name)), name
        assert b.ok.sum() >= 5
    # an ephemeris added later is seen by the next batch (the store's table is rebuilt)
    late = EphemerisStore(nav.ephemerides[: len(nav.ephemerides) // 2])
    before = epoch_satellites(epochs[:3], late)[0].ok.sum()
    for e in nav.ephemerides[len(nav.ephemerides) // 2:]:
        late.add(e)
    assert epoch_satellites(epochs[:3], late)[0].ok.sum() >= before
    assert np.array_equal(epoch_satellites(epochs[:3], late)[0].pos_m, batch[0].pos_m)


def test_receivers_of_all_epochs_in_one_batch_equal_the_per_epoch_slots() -> None:
    """Post-processing builds every epoch's slot data before the filter (epoch_receivers), with a base's
    modelled ranges from its known position in one batch: each epoch must get exactly what _slots and
    _model_range_m give it alone (the real-time path)."""
    from onboard.rtk.rtkpos import _geometry, _model_range_m, _slots, epoch_receivers

    nav = read_rinex_nav(shared_file(M8P + "rover-20181004-1237.nav.gz"))
    obs = read_rinex_obs(shared_file(M8P + "base-20181004-1236.rawx.obs.gz"))
    store = EphemerisStore(nav.ephemerides)
    epochs = obs.epochs[::5]  # mixed GNSS: the receivers keep GPS
    pos = np.array([3774089.2120, -601661.6157, 5089321.2474])
    batch = epoch_receivers(epochs, store, pos)
    assert len(batch) == len(epochs) and len(epoch_receivers([], store, pos)) == 0
    for ep, b in zip(epochs, batch):
        one = _slots(ep, store)
        assert b.memo and b.has.sum() >= 5
        for x, y in ((b.pr_m, one.pr_m), (b.cp_cyc, one.cp_cyc), (b.dop_hz, one.dop_hz), (b.lli, one.lli),
                     (b.has, one.has), (b.sats.pos_m, one.sats.pos_m), *zip(_geometry(b, pos), _geometry(one, pos)),
                     *zip(_model_range_m(b, pos), _model_range_m(one, pos))):
            assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f")
        assert not b.memo[("model", pos.tobytes())][0].flags.writeable


def test_spp_of_many_epochs_in_one_batch_equals_each_epoch_alone() -> None:
    """pntpos_batch over many epochs (post-processing) gives each epoch what pntpos (its batch of one, the
    real-time path) gives: same satellites used, same RAIM exclusion, positions/clock within micrometres."""
    from onboard.rtk.pntpos import pntpos, pntpos_batch
    from onboard.rtk.rtkpos import epoch_receivers

    nav = read_rinex_nav(shared_file(M8P + "rover-20181004-1237.nav.gz"))
    obs = read_rinex_obs(shared_file(M8P + "rover-20181004-1237.obs.gz"))
    store = EphemerisStore(nav.ephemerides)
    epochs = [e.gps_only() for e in obs.epochs[::25]]
    rcvs = epoch_receivers(epochs, store)
    sats = [r.sats for r in rcvs]
    prs = np.array([r.pr_m for r in rcvs])
    prs[3, np.flatnonzero(np.isfinite(prs[3]))[0]] += 400.0  # one epoch with a code outlier: RAIM must drop it
    dops = np.full(prs.shape, np.nan)
    for k, e in enumerate(epochs):
        dops[k, e.sv_id - 1] = e.dop_hz
    iono = (nav.iono_alpha, nav.iono_beta)
    tows = [e.time.tow_s for e in epochs]
    batch = pntpos_batch(prs, sats, tows, np.radians(15), dops, iono)
    assert len(batch) == len(epochs)
    for k, b in enumerate(batch):
        one = pntpos(prs[k], sats[k], tows[k], np.radians(15), dops[k], iono)
        assert b.ok and one.ok
        assert np.array_equal(b.used, one.used)
        assert np.abs(b.pos_ecef_m - one.pos_ecef_m).max() < 1e-6 and abs(b.clock_bias_m - one.clock_bias_m) < 1e-6
        assert np.abs(b.vel_ecef_m_s - one.vel_ecef_m_s).max() < 1e-6 and abs(b.gdop - one.gdop) < 1e-9
    assert not batch[3].used[np.flatnonzero(np.isfinite(prs[3]))[0]]  # the outlier excluded


def test_post_processing_with_precomputed_epoch_data_equals_the_real_time_path() -> None:
    """postprocess() hands rtk_pos every epoch's satellites and single-point solution computed in batches;
    rtk_pos fed epoch by epoch without them (as the real-time service does) gives the same Q at every epoch
    and positions within 0.1 mm (GEONET 0759/3040, 120 epochs)."""
    from dataclasses import replace

    from onboard.rtk.options import RtkOptions
    from onboard.rtk.postpro import pair_epochs, postprocess
    from onboard.rtk.rtkpos import Nav, rtk_init, rtk_pos

    geo = "gnss/geonet-0759-3040-20050402/"
    nav_f = read_rinex_nav(shared_file(geo + "07590920.05n.gz"))
    rover = read_rinex_obs(shared_file(geo + "07590920.05o.gz"))
    base = read_rinex_obs(shared_file(geo + "30400920.05o.gz"))
    nav = Nav(EphemerisStore(nav_f.ephemerides), (nav_f.iono_alpha, nav_f.iono_beta))
    base_pos = np.array([-3978241.958, 3382840.234, 3649900.853])
    opts = replace(RtkOptions(), elmask_deg=15.0)
    batch, _ = postprocess(rover.epochs, base.epochs, nav, base_pos, opts, "forward")
    rov = sorted(rover.epochs, key=lambda e: e.time)
    st = rtk_init(opts)
    live = [rtk_pos(st, r, b, nav, base_pos) for r, b in zip(rov, pair_epochs(rov, base.epochs, opts.pair_tolerance_s,
                                                                                    opts.max_age_s))]
    assert [s.q for s in batch] == [s.q for s in live]
    assert sum(s.q == 1 for s in batch) >= 100
    assert max(float(np.abs(a.pos_ecef_m - b.pos_ecef_m).max()) for a, b in zip(batch, live)) < 1e-4


def test_enu_rotation_on_math_sines_equals_the_numpy_formulation() -> None:
    # enu_rotation (and the Saastamoinen latitude term) take sin/cos from math (libm). On the x86-64 machine
    # this was measured on, numpy's float64 sin/cos are libm's and the .pos files stayed byte-identical; other
    # builds (aarch64, SIMD sin/cos) may differ in the last bit, which no figure can see: within 1 ulp here
    rng = np.random.default_rng(3)
    angles = rng.uniform(-np.pi, np.pi, 200_000)
    ulp = np.spacing(1.0)
    assert np.abs(np.sin(angles) - np.array([math.sin(a) for a in angles.tolist()])).max() <= ulp
    assert np.abs(np.cos(angles) - np.array([math.cos(a) for a in angles.tolist()])).max() <= ulp
    for lat, lon in rng.uniform(-np.pi / 2, np.pi / 2, (200, 2)).tolist():
        sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
        dense = np.array([[-so, co, 0.0], [-sl * co, -sl * so, cl], [cl * co, cl * so, sl]])
        assert np.abs(enu_rotation(lat, lon) - dense).max() <= 2 * ulp


def test_phase_fit_equals_the_phase_rows_of_the_dd_system_to_the_bit(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every post-fit and fix-validation check of a GEONET run (_phase_fit) gives the rows, test and reference
    of _ddres(..., jacobian=False) with _valid_residuals, to the bit."""
    from dataclasses import replace

    from onboard.rtk import rtkpos
    from onboard.rtk.options import RtkOptions
    from onboard.rtk.postpro import postprocess

    calls = [0]
    lean = rtkpos._phase_fit

    def both(st, ctx, x, use):  # type: ignore[no-untyped-def]
        rows, ok, ref = lean(st, ctx, x, use)
        dd, _ = rtkpos._ddres(st, ctx, x, use, np.zeros(NSAT, bool), False, jacobian=False)
        assert rows.tobytes() == dd.slot.tobytes() and (dd.kind == 0).all() and (ref == dd.ref_phase).all()
        assert ok.tobytes() == rtkpos._valid_residuals(dd, st.options.validation_sigma_factor).tobytes()
        calls[0] += 1
        return rows, ok, ref

    monkeypatch.setattr(rtkpos, "_phase_fit", both)
    geo = "gnss/geonet-0759-3040-20050402/"
    nav_f = read_rinex_nav(shared_file(geo + "07590920.05n.gz"))
    rover = read_rinex_obs(shared_file(geo + "07590920.05o.gz"))
    base = read_rinex_obs(shared_file(geo + "30400920.05o.gz"))
    nav = rtkpos.Nav(EphemerisStore(nav_f.ephemerides), (nav_f.iono_alpha, nav_f.iono_beta))
    base_pos = np.array([-3978241.958, 3382840.234, 3649900.853])
    postprocess(rover.epochs, base.epochs, nav, base_pos, replace(RtkOptions(), elmask_deg=15.0), "forward")
    assert calls[0] >= 200  # a check of the float and one of the fix at each held epoch
