"""Integer least-squares ambiguity resolution: LAMBDA decorrelation + MLAMBDA search.

Follows Teunissen's LAMBDA (LtDL decomposition, integer Gauss transformations and permutations) and the
modified search of Chang, Yang & Zhou (2005), as RTKLIB lambda.c: LD(), reduction(), search(), lambda().
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

Arr = npt.NDArray[np.float64]

_LOOP_MAX = 10000


class LambdaError(ValueError):
    """The covariance is not positive definite or the search did not terminate."""


def ld_factor(q: Arr) -> tuple[Arr, Arr]:
    """Q = Lᵀ·diag(D)·L with L unit lower-triangular (RTKLIB LD()). Returns (L, D)."""
    n = q.shape[0]
    a = np.array(q, dtype=float, copy=True)
    lmat = np.zeros((n, n))
    d = np.zeros(n)
    for i in range(n - 1, -1, -1):
        d[i] = a[i, i]
        if d[i] <= 0.0:
            raise LambdaError("ambiguity covariance not positive definite")
        s = np.sqrt(d[i])
        lmat[i, : i + 1] = a[i, : i + 1] / s
        # rank-one downdate of the leading block
        a[:i, :i] -= np.outer(lmat[i, :i], lmat[i, :i])
        lmat[i, : i + 1] /= lmat[i, i]
    return lmat, d


def _gauss(lmat: Arr, z: Arr, i: int, j: int) -> None:
    mu = round(lmat[i, j])
    if mu != 0:
        lmat[i:, j] -= mu * lmat[i:, i]
        z[:, j] -= mu * z[:, i]


def _perm(lmat: Arr, d: Arr, j: int, delta: float, z: Arr) -> None:
    eta = d[j] / delta
    lam = d[j + 1] * lmat[j + 1, j] / delta
    d[j] = eta * d[j + 1]
    d[j + 1] = delta
    a0 = lmat[j, :j].copy()
    a1 = lmat[j + 1, :j].copy()
    lmat[j, :j] = -lmat[j + 1, j] * a0 + a1
    lmat[j + 1, :j] = eta * a0 + lam * a1
    lmat[j + 1, j] = lam
    lmat[j + 2 :, [j, j + 1]] = lmat[j + 2 :, [j + 1, j]]
    z[:, [j, j + 1]] = z[:, [j + 1, j]]


def reduction(lmat: Arr, d: Arr) -> Arr:
    """Decorrelate in place (integer Gauss transforms + permutations); returns the unimodular Z (RTKLIB reduction())."""
    n = d.shape[0]
    z = np.eye(n)
    j = n - 2
    k = n - 2
    while j >= 0:
        if j <= k:
            for i in range(j + 1, n):
                _gauss(lmat, z, i, j)
        delta = d[j] + lmat[j + 1, j] ** 2 * d[j + 1]
        if delta + 1e-6 < d[j + 1]:
            _perm(lmat, d, j, delta, z)
            k = j
            j = n - 2
        else:
            j -= 1
    return z


def search(lmat: Arr, d: Arr, zs: Arr, m: int = 2) -> tuple[Arr, Arr]:
    """MLAMBDA search: the `m` best integer vectors (n, m) and their squared distances (m,), best first."""
    n = d.shape[0]
    s_mat = np.zeros((n, n))
    dist = np.zeros(n)
    zb = np.zeros(n)
    z = np.zeros(n)
    step = np.zeros(n)
    cands = np.zeros((n, m))
    sdist = np.zeros(m)
    nn, imax = 0, 0
    maxdist = np.inf
    k = n - 1
    zb[k] = zs[k]
    z[k] = round(zb[k])
    y = zb[k] - z[k]
    step[k] = 1.0 if y > 0 else -1.0
    for _ in range(_LOOP_MAX):
        newdist = dist[k] + y * y / d[k]
        if newdist < maxdist:
            if k != 0:
                k -= 1
                dist[k] = newdist
                s_mat[k, : k + 1] = s_mat[k + 1, : k + 1] + (z[k + 1] - zb[k + 1]) * lmat[k + 1, : k + 1]
                zb[k] = zs[k] + s_mat[k, k]
                z[k] = round(zb[k])
                y = zb[k] - z[k]
                step[k] = 1.0 if y > 0 else -1.0
            else:
                if nn < m:
                    if nn == 0 or newdist > sdist[imax]:
                        imax = nn
                    cands[:, nn] = z
                    sdist[nn] = newdist
                    nn += 1
                else:
                    if newdist < sdist[imax]:
                        cands[:, imax] = z
                        sdist[imax] = newdist
                        imax = int(np.argmax(sdist))
                    maxdist = sdist[imax]
                z[0] += step[0]
                y = zb[0] - z[0]
                step[0] = -step[0] - (1.0 if step[0] > 0 else -1.0)
        else:
            if k == n - 1:
                break
            k += 1
            z[k] += step[k]
            y = zb[k] - z[k]
            step[k] = -step[k] - (1.0 if step[k] > 0 else -1.0)
    else:
        raise LambdaError("MLAMBDA search did not terminate")
    order = np.argsort(sdist[:nn])
    return cands[:, order], sdist[order]


@dataclass
class LambdaResult:
    """Best `m` integer candidates `fixed` (n, m), squared distances `sq_dist` (m,) and ratio s2/s1."""

    fixed: Arr
    sq_dist: Arr
    cond_var: Arr
    """Conditional variances D of the decorrelated ambiguities (cycles²)."""

    @property
    def success_rate(self) -> float:
        """Bootstrapped success rate Π(2Φ(1/(2√Dᵢ))−1), a sharp lower bound of the ILS success rate
        (Teunissen 1998); computed in the decorrelated space."""
        return float(np.prod([math.erf(1.0 / (2.0 * math.sqrt(2.0 * d))) for d in self.cond_var]))

    @property
    def ratio(self) -> float:
        if self.sq_dist.shape[0] < 2:
            return 0.0
        return float(self.sq_dist[1] / max(self.sq_dist[0], 1e-12))


def mlambda(a_float: Arr, q: Arr, m: int = 2) -> LambdaResult:
    """Integer least-squares estimates of float ambiguities `a_float` (n,) with covariance `q` (n,n).

    Follows RTKLIB lambda(): z = Zᵀa is searched in the decorrelated space, F = Z⁻ᵀE mapped back.
    """
    a = np.asarray(a_float, float)
    n = a.shape[0]
    if n == 0 or q.shape != (n, n):
        raise LambdaError(f"bad shapes: a {a.shape}, Q {q.shape}")
    lmat, d = ld_factor(q)
    z = reduction(lmat, d)
    zs = z.T @ a
    e, s = search(lmat, d, zs, m)
    f = np.linalg.solve(z.T, e)
    return LambdaResult(np.round(f), s, d)
