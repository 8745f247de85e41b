"""Relative (differenced) aerial control, Rehak & Skaloud (2017) eq. 2.

For consecutive images i, j (dt < max): d_ij = e_j − e_i
  = μR(C_j − C_i) + R(R_j − R_i)·O − (G_j − G_i) − (V_j − V_i)·t_d,
so T and any constant GNSS bias (float ambiguities, datum offset) cancel; ≥ 1 GCP then fixes the translation.
Overlapping differences share an image, so they are correlated: with independent per-image σ, per axis the
covariance of a chain of differences is tridiagonal (σ_i² + σ_j² on the diagonal, −σ_j² between the pairs
sharing image j). We whiten with its banded Cholesky factor (O(n) per evaluation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.linalg import cholesky_banded, solve_banded

Arr = npt.NDArray[np.float64]


@dataclass(frozen=True)
class RelativePairs:
    """Consecutive pairs (first, second) as indices into the image arrays, and the banded whitening factors.

    `chol` (3, 2, n_pairs): per axis, the lower banded Cholesky factor of the difference covariance (m²).
    """

    first: npt.NDArray[np.int64]
    second: npt.NDArray[np.int64]
    chol: Arr

    @property
    def n_pairs(self) -> int:
        return int(self.first.size)

    def differences(self, e: Arr, je: Arr) -> tuple[Arr, Arr]:
        """d_k = e_second − e_first (n_pairs,3) and its Jacobian (n_pairs,3,n_param)."""
        return e[self.second] - e[self.first], je[self.second] - je[self.first]

    def whiten(self, e: Arr, je: Arr) -> tuple[Arr, Arr]:
        """Whitened differences (3·n_pairs,) and Jacobian (3·n_pairs, n_param), axis-major."""
        d, jd = self.differences(e, je)
        w = np.empty((3, self.n_pairs))
        jw = np.empty((3, self.n_pairs, je.shape[2]))
        for ax in range(3):
            rhs = np.column_stack([d[:, ax], jd[:, ax, :]])
            sol = solve_banded((1, 0), self.chol[ax], rhs)
            w[ax] = sol[:, 0]
            jw[ax] = sol[:, 1:]
        return w.ravel(), jw.reshape(-1, je.shape[2])


def consecutive_pairs(
    event_time_s: npt.ArrayLike, sigma_enu_m: npt.ArrayLike, max_pair_dt_s: float
) -> RelativePairs:
    """Pairs of time-consecutive images closer than `max_pair_dt_s`, with the banded covariance factor.

    `sigma_enu_m` (n,3) is the per-image σ (antenna ⊕ camera centre), assumed independent between images.
    """
    t = np.asarray(event_time_s, dtype=float)
    s = np.asarray(sigma_enu_m, dtype=float).reshape(-1, 3)
    order = np.argsort(t, kind="stable")
    ok = np.diff(t[order]) < max_pair_dt_s
    first = order[:-1][ok].astype(np.int64)
    second = order[1:][ok].astype(np.int64)
    n = first.size
    chol = np.zeros((3, 2, n))
    if n == 0:
        return RelativePairs(first, second, chol)
    shares = np.zeros(n, dtype=bool)
    shares[1:] = first[1:] == second[:-1]  # pair k starts where pair k−1 ended
    for ax in range(3):
        v = s[:, ax] ** 2
        ab = np.zeros((2, n))
        ab[0] = v[first] + v[second]
        sub = np.where(shares[1:], -v[first[1:]], 0.0)
        ab[1, :-1] = sub
        chol[ax] = cholesky_banded(ab, lower=True)
    return RelativePairs(first, second, chol)
