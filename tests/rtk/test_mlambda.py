"""LAMBDA / MLAMBDA on fixed vectors and against brute-force integer least squares."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from onboard.rtk.mlambda import LambdaError, ld_factor, mlambda


def test_ld_factor_reconstructs_q():
    q = np.array([[6.29, 5.978, 0.544], [5.978, 6.292, 2.34], [0.544, 2.34, 6.288]])
    lmat, d = ld_factor(q)
    np.testing.assert_allclose(lmat.T @ np.diag(d) @ lmat, q, atol=1e-12)
    assert np.allclose(np.diag(lmat), 1.0) and np.allclose(np.triu(lmat, 1), 0.0)


def test_teunissen_textbook_example():
    """The 3-D example of de Jonge & Tiberius (1996) / Teunissen's LAMBDA papers: float a, Q below,
    integer least-squares solution (5, 3, 4)."""
    q = np.array([[6.290, 5.978, 0.544], [5.978, 6.292, 2.340], [0.544, 2.340, 6.288]])
    a = np.array([5.450, 3.100, 2.970])
    res = mlambda(a, q)
    assert list(res.fixed[:, 0]) == [5, 3, 4]
    d0 = a - res.fixed[:, 0]
    d1 = a - res.fixed[:, 1]
    qi = np.linalg.inv(q)
    assert res.sq_dist[0] == pytest.approx(d0 @ qi @ d0)
    assert res.sq_dist[1] == pytest.approx(d1 @ qi @ d1)
    assert res.ratio == pytest.approx(res.sq_dist[1] / res.sq_dist[0])


def test_matches_brute_force_on_random_problems():
    rng = np.random.default_rng(3)
    for _ in range(25):
        n = int(rng.integers(2, 5))
        a_mat = rng.normal(size=(n, n))
        q = a_mat @ a_mat.T * 0.2 + np.eye(n) * 0.02
        a = rng.normal(size=n) * 10
        res = mlambda(a, q)
        qi = np.linalg.inv(q)
        c = np.round(a)
        cands = sorted(((a - (c + np.array(d))) @ qi @ (a - (c + np.array(d))), tuple(c + np.array(d)))
                       for d in itertools.product(range(-4, 5), repeat=n))
        np.testing.assert_array_equal(res.fixed[:, 0], cands[0][1])
        assert res.sq_dist[0] == pytest.approx(cands[0][0])
        assert res.sq_dist[1] == pytest.approx(cands[1][0])


def test_near_integer_float_has_high_ratio_and_success_rate():
    q = np.diag([0.001, 0.002, 0.0015, 0.001])
    res = mlambda(np.array([3.01, -7.02, 12.0, 0.99]), q)
    assert list(res.fixed[:, 0]) == [3, -7, 12, 1]
    assert res.ratio > 10 and res.success_rate > 0.999


def test_poorly_determined_ambiguities_have_low_success_rate():
    res = mlambda(np.array([0.4, 1.6, -2.3]), np.eye(3) * 4.0)
    assert res.success_rate < 0.3


def test_not_positive_definite_is_refused():
    with pytest.raises(LambdaError):
        mlambda(np.array([1.0, 2.0]), np.array([[1.0, 2.0], [2.0, 1.0]]))
