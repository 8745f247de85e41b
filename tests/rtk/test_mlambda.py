"""LAMBDA / MLAMBDA on fixed vectors and against brute-force integer least squares."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from onboard.rtk.mlambda import LambdaError, ld_factor, mlambda, reduction


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


@pytest.mark.slow
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


@pytest.mark.parametrize("bad", [np.nan, np.inf, -1.0, 0.0])
def test_non_finite_or_singular_covariance_is_refused(bad: float) -> None:
    q = np.eye(3) * 0.01
    q[1, 1] = bad
    with pytest.raises(LambdaError):
        mlambda(np.array([1.1, 2.0, -0.9]), q)


def _reduction_reference(lmat: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """RTKLIB reduction() as written there (gauss() and perm() on dense arrays, restart at n − 2, Z as floats)."""
    lmat, d = lmat.copy(), d.copy()
    n = d.size
    z = np.eye(n)
    j, k = n - 2, n - 2
    while j >= 0:
        if j <= k:
            for i in range(j + 1, n):
                mu = round(lmat[i, j])
                if mu != 0:
                    lmat[i:, j] -= mu * lmat[i:, i]
                    z[:, j] -= mu * z[:, i]
        delta = d[j] + lmat[j + 1, j] ** 2 * d[j + 1]
        if delta + 1e-6 < d[j + 1]:
            eta, lam = d[j] / delta, d[j + 1] * lmat[j + 1, j] / delta
            d[j], d[j + 1] = eta * d[j + 1], delta
            a0, a1 = lmat[j, :j].copy(), lmat[j + 1, :j].copy()
            lmat[j, :j] = -lmat[j + 1, j] * a0 + a1
            lmat[j + 1, :j] = eta * a0 + lam * a1
            lmat[j + 1, j] = lam
            lmat[j + 2:, [j, j + 1]] = lmat[j + 2:, [j + 1, j]]
            z[:, [j, j + 1]] = z[:, [j + 1, j]]
            k, j = j, n - 2
        else:
            j -= 1
    return lmat, d, z


def test_reduction_matches_rtklib_formulation_to_the_bit_with_large_and_negative_z():
    """The list code (Z packed as integers, the early restart) gives RTKLIB's L, D and Z exactly, also for
    strongly correlated ambiguities whose Z has large entries of both signs (the packed digits borrow)."""
    rng = np.random.default_rng(11)
    big = 0
    for _ in range(60):
        n = int(rng.integers(2, 13))
        g = rng.normal(size=(n, n))
        # nearly collinear rows: long decorrelations, |Z| up to thousands
        g += rng.normal(size=n) * float(10.0 ** rng.integers(0, 4))
        q = g @ g.T * 0.01 + np.eye(n) * 1e-4
        lmat0, d0 = ld_factor(q)
        lmat, d, z = reduction(lmat0, d0)
        ref_l, ref_d, ref_z = _reduction_reference(lmat0, d0)
        assert lmat.tobytes() == ref_l.tobytes() and d.tobytes() == ref_d.tobytes()
        assert z.tobytes() == ref_z.tobytes() and z.flags.c_contiguous
        big += int(np.abs(z).max() > 100 and (z < 0).any())
    assert big > 5


def test_certificate_replaces_the_search_only_next_to_an_integer_vector_with_certain_success():
    """A held-like float (σ 1 mm-cycle) is certified: the search's integers, ratio past the cap, success rate
    exactly 1.0 as the decorrelated one. Refused: variances too large for a success rate of exactly 1 (the
    full search runs: its D), or a float half-way between integers (no ratio bound)."""
    g = np.array([[1.0, 0.3, 0.2], [0.3, 1.0, 0.4], [0.2, 0.4, 1.0]])
    ints = np.array([12.0, -3.0, 40.0])
    held = g * 1e-6
    a = ints + np.array([0.001, -0.002, 0.0015])
    full, capped = mlambda(a, held), mlambda(a, held, ratio_cap=999.9)
    assert np.array_equal(capped.z_mat, np.eye(3))  # certified: no decorrelation
    assert np.array_equal(capped.fixed[:, 0], full.fixed[:, 0]) and list(capped.fixed[:, 0]) == list(ints)
    assert capped.success_rate == full.success_rate == 1.0 and capped.ratio >= 999.9 and full.ratio >= 999.9
    assert capped.sq_dist[0] == pytest.approx(full.sq_dist[0], rel=1e-9)
    loose = g * 0.01  # D up to 0.01 cycles² > 1/300: the success rate is below 1
    res = mlambda(ints + 0.01, loose, ratio_cap=999.9)
    assert np.array_equal(res.cond_var, mlambda(ints + 0.01, loose).cond_var) and res.success_rate < 1.0
    halfway = mlambda(ints + np.array([0.5, 0.0, 0.0]), held, ratio_cap=999.9)
    assert not np.array_equal(halfway.z_mat, np.eye(3)) or halfway.ratio < 999.9


def test_warm_start_keeps_the_integers_and_ratio_and_gives_a_reduced_basis():
    """Decorrelating from the previous epoch's Z (z_start) of a slowly changing, strongly correlated
    covariance: the same best and second-best integer vectors and distances as from the identity, and a Z that
    is an integer transform of determinant ±1 whose ZᵀQZ has the returned D and an L below ½ off the diagonal."""
    rng = np.random.default_rng(17)
    for _ in range(30):
        n = int(rng.integers(4, 16))
        g = rng.normal(size=(n, n)) + rng.normal(size=n) * 30.0  # nearly collinear: a float of code and geometry
        q = g @ g.T * 0.002 + np.eye(n) * 1e-4
        a = rng.normal(size=n) * 20.0
        first = mlambda(a, q)
        drift = rng.normal(size=(n, n)) * 1e-3
        q2 = q + (drift @ drift.T) * 0.002  # the next epoch's covariance
        a2 = a + rng.normal(size=n) * 0.01
        cold, warm = mlambda(a2, q2), mlambda(a2, q2, z_start=first.z_mat)
        assert np.array_equal(warm.fixed, cold.fixed)
        np.testing.assert_allclose(warm.sq_dist, cold.sq_dist, rtol=1e-8)
        z = warm.z_mat
        assert np.array_equal(z, np.round(z)) and abs(round(float(np.linalg.det(z)))) == 1
        lmat, d = ld_factor(z.T @ q2 @ z)
        assert np.all(np.abs(np.tril(lmat, -1)) <= 0.5 + 1e-9)
        np.testing.assert_allclose(d, warm.cond_var, rtol=1e-6)


def test_warm_start_of_the_wrong_shape_or_too_large_is_ignored():
    q = np.array([[6.290, 5.978, 0.544], [5.978, 6.292, 2.340], [0.544, 2.340, 6.288]])
    a = np.array([5.450, 3.100, 2.970])
    cold = mlambda(a, q)
    for z0 in (np.eye(2), np.eye(3) * float(1 << 21)):
        res = mlambda(a, q, z_start=z0)
        assert np.array_equal(res.fixed, cold.fixed) and np.array_equal(res.z_mat, cold.z_mat)
