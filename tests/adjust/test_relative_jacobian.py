"""Relative-control whitening (banded covariance of overlapping differences) and the analytic Jacobian."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from ground.adjust.model import AdjustmentOptions, DelaySpec, LeverArmSpec, SimilaritySpec
from ground.adjust.relative import consecutive_pairs
from ground.adjust.similarity import so3_exp
from ground.adjust.solve import _Data, _Model


def test_banded_whitening_equals_the_dense_covariance() -> None:
    rng = np.random.default_rng(0)
    t = np.array([0.0, 1.0, 2.0, 3.0, 20.0, 21.0, 22.5, 40.0])  # two chains and a lone image
    sig = rng.uniform(0.005, 0.03, (t.size, 3))
    pairs = consecutive_pairs(t, sig, max_pair_dt_s=10.0)
    assert list(zip(pairs.first, pairs.second, strict=True)) == [(0, 1), (1, 2), (2, 3), (4, 5), (5, 6)]
    e = rng.normal(0, 0.02, (t.size, 3))
    je = rng.normal(size=(t.size, 3, 2))
    w, jw = pairs.whiten(e, je)
    # the dense way: D = differencing matrix, Cov = D·diag(σ²)·Dᵀ per axis, whitened norm dᵀ Cov⁻¹ d
    n_p = pairs.n_pairs
    dmat = np.zeros((n_p, t.size))
    dmat[np.arange(n_p), pairs.second] = 1.0
    dmat[np.arange(n_p), pairs.first] = -1.0
    total = 0.0
    for ax in range(3):
        cov = dmat @ np.diag(sig[:, ax] ** 2) @ dmat.T
        d = dmat @ e[:, ax]
        total += d @ np.linalg.solve(cov, d)
        jd = dmat @ je[:, ax, :]
        jw_ax = jw[ax * n_p : (ax + 1) * n_p]
        assert np.allclose(jw_ax.T @ jw_ax, jd.T @ np.linalg.solve(cov, jd))
    assert np.isclose(w @ w, total)
    # ignoring the correlation (diagonal weights) gives a different, wrong norm
    naive = sum(((dmat @ e[:, ax]) ** 2 / (dmat**2 @ sig[:, ax] ** 2)).sum() for ax in range(3))
    assert not np.isclose(naive, total, rtol=0.05)


def test_analytic_jacobian_matches_finite_differences(block_factory: Any, quiet: dict) -> None:
    block = block_factory(21, gcp_names=("P05", "P07"), **quiet)
    rng = np.random.default_rng(1)
    n = len(block.poses)
    c = np.array([p.centre_rel for p in block.poses])
    r = np.array([p.r_cam_to_rel for p in block.poses])
    g = rng.normal(0, 30, (n, 3))
    v = rng.normal(0, 4, (n, 3))
    a = rng.normal(0, 1, (n, 3))
    sig = rng.uniform(0.01, 0.02, (n, 3))
    gcps = tuple(cp for cp in block.control if cp.role == "gcp")
    for relative in (False, True):
        opts = AdjustmentOptions(
            similarity=SimilaritySpec(mode="prior", translation_sigma_m=0.3),
            lever_arm=LeverArmSpec("prior", (0.1, 0.0, -0.1), (0.01,) * 3),
            delay=DelaySpec("prior", 0.05, 0.01),
            relative_control=relative,
        )
        base = np.zeros(11)
        base[6] = 1.3
        model = _Model(opts, so3_exp([0.3, -0.2, 1.0]), base, gcps, c.mean(axis=0), g.mean(axis=0))
        pairs = consecutive_pairs(np.arange(n, dtype=float), sig, 10.0) if relative else None
        model.data = _Data(c - c.mean(axis=0), r, g - g.mean(axis=0), v, a, sig, pairs)
        x = np.concatenate([rng.normal(0, 1, 3), rng.normal(0, 0.01, 3), [1.3], [0.1, 0.05, -0.1], [0.07]])
        _, jac = model.residuals_and_jacobian(x)
        num = np.empty_like(jac)
        for k in range(x.size):
            h = 1e-6 * max(1.0, abs(x[k]))
            xp, xm = x.copy(), x.copy()
            xp[k] += h
            xm[k] -= h
            num[:, k] = (model.residuals_and_jacobian(xp)[0] - model.residuals_and_jacobian(xm)[0]) / (2 * h)
        assert np.allclose(jac, num, rtol=1e-5, atol=1e-4 * np.abs(num).max())


def test_variance_inflation_sees_time_correlated_residuals() -> None:
    from ground.adjust.solve import variance_inflation

    rng = np.random.default_rng(2)
    t = np.concatenate(
        [np.arange(0, 40.0), np.arange(60.0, 100.0), np.arange(120.0, 160.0), np.arange(180, 220.0)]
    )
    white = rng.normal(size=(t.size, 3))
    assert variance_inflation(white, t, n_params=0) < 2.0
    # a per-segment offset of 0.5σ (e.g. RTK multipath over a line) inflates: the segment means are 40× too big
    offsets = np.repeat(rng.normal(0, 0.5, (4, 3)), 40, axis=0)
    assert variance_inflation(white + offsets, t, n_params=0) > 4.0
    assert variance_inflation(white[:5], t[:5], n_params=0) == 1.0  # too little to say: no inflation


def test_linear_delay_start_recovers_the_delay_of_an_affine_model() -> None:
    from ground.adjust.solve import _delay_start

    rng = np.random.default_rng(3)
    c = rng.uniform(-50, 50, (200, 3))
    v = rng.normal(0, 4, (200, 3))
    a = rng.normal(size=(3, 3))
    g = c @ a.T + np.array([10.0, -3.0, 2.0]) - v * 0.064
    assert _delay_start(c, g, v) == pytest.approx(0.064, abs=1e-9)
    assert _delay_start(c[:4], g[:4], v[:4]) == 0.0  # too few images for 13 unknowns: no start, not a guess
