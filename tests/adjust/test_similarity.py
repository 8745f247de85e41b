"""Umeyama closed form, RANSAC, reflection guard, collinearity, SO(3) helpers."""

from __future__ import annotations

import numpy as np
import pytest

from ground.adjust.similarity import (
    DegenerateGeometry,
    Similarity,
    ransac_umeyama,
    so3_exp,
    so3_left_jacobian,
    so3_log,
    umeyama,
)


def _random_similarity(rng: np.random.Generator) -> Similarity:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return Similarity(float(rng.uniform(0.1, 10)), q, rng.uniform(-1000, 1000, 3))


def test_umeyama_recovers_a_similarity_and_a_rigid_transform() -> None:
    rng = np.random.default_rng(1)
    truth = _random_similarity(rng)
    src = rng.uniform(-50, 50, (20, 3))
    fit = umeyama(src, truth.apply(src))
    assert fit.scale == pytest.approx(truth.scale, rel=1e-10)
    assert np.allclose(fit.rotation, truth.rotation, atol=1e-10)
    assert np.allclose(fit.translation, truth.translation, atol=1e-7)
    rigid = Similarity(1.0, truth.rotation, truth.translation)
    fit_rigid = umeyama(src, rigid.apply(src), with_scale=False)
    assert fit_rigid.scale == 1.0 and np.allclose(fit_rigid.rotation, truth.rotation, atol=1e-10)
    assert np.allclose(fit.inverse().apply(fit.apply(src)), src, atol=1e-8)


def test_reflection_guard_returns_a_proper_rotation() -> None:
    rng = np.random.default_rng(2)
    src = rng.uniform(-10, 10, (10, 3))
    mirrored = src * np.array([1.0, 1.0, -1.0])  # no proper rotation maps src onto its mirror image
    fit = umeyama(src, mirrored)
    assert np.linalg.det(fit.rotation) == pytest.approx(1.0)


def test_collinear_and_too_few_points_are_refused() -> None:
    line = np.column_stack([np.arange(10.0), 2 * np.arange(10.0), np.zeros(10)])
    with pytest.raises(DegenerateGeometry, match="collinear"):
        umeyama(line, line)
    with pytest.raises(DegenerateGeometry, match="≥ 3"):
        umeyama(line[:2], line[:2])
    with pytest.raises(DegenerateGeometry, match="single strip"):
        ransac_umeyama(line, line, 1.0, 10, np.random.default_rng(0))


def test_ransac_ignores_thirty_percent_gross_outliers() -> None:
    rng = np.random.default_rng(3)
    truth = _random_similarity(rng)
    src = rng.uniform(-100, 100, (100, 3))
    dst = truth.apply(src) + rng.normal(0, 0.01, (100, 3))
    bad = rng.choice(100, 30, replace=False)
    dst[bad] += rng.uniform(5, 50, (30, 3))
    fit, inliers = ransac_umeyama(src, dst, 0.1, 200, np.random.default_rng(0))
    assert not inliers[bad].any() and inliers.sum() == 70
    assert fit.scale == pytest.approx(truth.scale, rel=1e-4)
    plain = umeyama(src, dst)
    assert abs(plain.scale - truth.scale) > 10 * abs(fit.scale - truth.scale)


def test_so3_exp_log_and_left_jacobian() -> None:
    rng = np.random.default_rng(4)
    for _ in range(5):
        w = rng.normal(0, 0.8, 3)
        assert np.allclose(so3_log(so3_exp(w)), w, atol=1e-10)
        y = rng.normal(size=3)
        jl = so3_left_jacobian(w)
        analytic = (
            np.cross(np.eye(3), so3_exp(w) @ y).T @ jl
        )  # rows e_i × a, transposed: −[a]×; so −[R y]× · J_l
        numeric = np.column_stack(
            [(so3_exp(w + 1e-6 * e) @ y - so3_exp(w - 1e-6 * e) @ y) / 2e-6 for e in np.eye(3)]
        )
        assert np.allclose(analytic, numeric, atol=1e-7)
