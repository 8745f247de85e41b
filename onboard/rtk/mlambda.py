"""Integer least-squares ambiguity resolution: LAMBDA decorrelation + MLAMBDA search.

Follows Teunissen's LAMBDA (LtDL decomposition, integer Gauss transformations and permutations) and the
modified search of Chang, Yang & Zhou (2005), as RTKLIB lambda.c: LD(), reduction(), search(), lambda().
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from onboard.rtk.linsolve import solve

Arr = npt.NDArray[np.float64]

_LOOP_MAX = 10000


class LambdaError(ValueError):
    """The covariance is not positive definite or the search did not terminate."""


def ld_factor(q: Arr) -> tuple[Arr, Arr]:
    """Q = Lᵀ·diag(D)·L with L unit lower-triangular (RTKLIB LD()). Returns (L, D)."""
    lmat, d = _ld_lists(np.asarray(q, dtype=float))
    return np.array(lmat).reshape(q.shape), np.array(d)


# The decorrelation and search below work on nested Python lists: for the n ≤ ~20 ambiguities of single-frequency
# RTK, element-wise numpy indexing costs more than the arithmetic.


def _ld_lists(q: Arr) -> tuple[list[list[float]], list[float]]:
    """ld_factor() as lists, from LAPACK's Cholesky factor of Q with its order reversed.

    RTKLIB's LD() eliminates from the last ambiguity up; with J the order reversal, JQJ = CCᵀ (C lower), so
    Q = UUᵀ with U = JCJ upper triangular, and Lᵀ = U·diag(U)⁻¹, D = diag(U)²: the same factors as the
    element-by-element elimination, to rounding (1e-15 relative), in one call instead of n³/6 interpreted
    operations (n = 20: 0.2 ms)."""
    try:
        c = np.linalg.cholesky(q[::-1, ::-1])
    except np.linalg.LinAlgError:
        raise LambdaError("ambiguity covariance not positive definite") from None
    u = c[::-1, ::-1]
    du = u.diagonal()
    if not np.isfinite(du).all():
        raise LambdaError("ambiguity covariance not finite")
    # L = (U·diag(U)⁻¹)ᵀ: row i of L is column i of U over U[i, i]; its upper part is LAPACK's zeros
    return (u / du).T.tolist(), (du * du).tolist()


def reduction(lmat_in: Arr, d_in: Arr) -> tuple[Arr, Arr, Arr]:
    """Decorrelate (integer Gauss transforms + permutations, RTKLIB reduction()): returns (L, D, Z)."""
    lmat, d, z = _reduction_lists(lmat_in.tolist(), d_in.tolist())
    return np.array(lmat), np.array(d), z


_DIGIT_BITS = 64
"""Bits per entry of a column of Z packed into one Python integer (see _reduction_lists)."""
_DIGIT_HALF = 1 << (_DIGIT_BITS - 1)


@functools.lru_cache(maxsize=64)
def _digit_offset(n: int) -> int:
    """2⁶³ in each of the n·n digits of the packed Z: makes every digit non-negative for the unpacking."""
    return sum(_DIGIT_HALF << (_DIGIT_BITS * i) for i in range(n * n))


def _unpack_columns(cols: list[int], n: int) -> Arr:
    """Z (n, n) float, row-major, from its columns packed as Σᵣ Z[r, c]·2^(64·r) (entries |Z| < 2⁶³)."""
    packed = 0
    for c in range(n - 1, -1, -1):
        packed = (packed << (_DIGIT_BITS * n)) + cols[c]
    raw = np.frombuffer((packed + _digit_offset(n)).to_bytes(8 * n * n, "little"), dtype="<u8")
    # an offset digit x = v + 2⁶³ has the bits of v in two's complement with its top bit flipped
    zt = (raw ^ np.uint64(_DIGIT_HALF)).view(np.int64).reshape(n, n)
    return zt.T.astype(float, order="C")  # C order as before: the products with Z take the same path


def _reduction_lists(lmat: list[list[float]], d: list[float]) -> tuple[list[list[float]], list[float], Arr]:
    """reduction() on lists, in place on `d`; returns (L, D, Z), L row-major as `lmat` (which it leaves alone).

    L is worked on by columns (cols[c][r] = L[r][c]): a Gauss transform updates column j from column i, and a
    permutation's swap of columns j and j + 1 below row j + 1 is a swap of two list items (their entries on rows
    j and j + 1 are the triangle's known 1, 0 and the new λ); only the permutation's update of rows j and j + 1
    runs across the columns. The same operations on the same numbers as RTKLIB's row-by-row code.

    Z is exact integer arithmetic whatever its representation: each column is one Python integer holding the
    column's entries as 64-bit digits (Σᵣ Z[r, c]·2^(64·r), negative entries borrowing from the next digit,
    which the unpacking undoes), so a Gauss transform's column update is one integer operation instead of n
    (the six bench sets: 13 transforms per call, n = 6.6 on average) and a permutation swaps two list items.

    The integer Gauss transformation (RTKLIB gauss()) and the permutation (RTKLIB perm()) are inlined: on a
    poorly determined float (M8P walk, GPS+GLONASS) the loop runs 150 times per call with 75 permutations."""
    n = len(d)
    cols = [list(c) for c in zip(*lmat)]
    zc = [1 << (_DIGIT_BITS * c) for c in range(n)]
    j = n - 2
    k = n - 2
    while j >= 0:
        cj = cols[j]
        if j <= k:
            for i in range(j + 1, n):
                x = cj[i]
                # round(x) == 0 exactly for |x| ≤ ½ (round half to even): most entries, no round() call
                if -0.5 <= x <= 0.5:
                    continue
                mu = round(x)
                cj[i] = x - mu  # L[i][i] = 1 exactly: mu·1 = mu
                ci = cols[i]
                for kk in range(i + 1, n):
                    cj[kk] -= mu * ci[kk]
                zc[j] -= mu * zc[i]
        j1 = j + 1
        l10 = cj[j1]
        dj1 = d[j1]
        dj = d[j]
        delta = dj + l10 ** 2 * dj1
        if delta + 1e-6 < dj1:
            # permute ambiguities j and j + 1 (RTKLIB perm()); Z by columns: a swap of two list items
            eta = dj / delta
            lam = dj1 * l10 / delta
            d[j] = eta * dj1
            d[j1] = delta
            neg_l10 = -l10  # -l10 * a0 is (-l10) * a0
            for cc in cols[:j]:
                a0 = cc[j]
                a1 = cc[j1]
                cc[j] = neg_l10 * a0 + a1
                cc[j1] = eta * a0 + lam * a1
            # rows > j + 1 of columns j and j + 1 swap with the lists; rows j, j + 1: 1, λ and 0, 1 (unit triangle)
            cj1 = cols[j1]
            cj1[j] = 1.0
            cj1[j1] = lam
            cj[j] = 0.0
            cj[j1] = 1.0
            cols[j] = cj1
            cols[j1] = cj
            zc[j], zc[j1] = zc[j1], zc[j]
            # RTKLIB restarts at j = n − 2; the tests above j + 1 would repeat exactly (their d and L entries are
            # untouched by the permutation and by the transforms since, which only change columns ≤ j + 1):
            # all passed, so they pass again, without a transform (j > k) or any other effect
            k = j
            j = j1 if j1 < n - 1 else n - 2
        else:
            j -= 1
    return [list(r) for r in zip(*cols)], d, _unpack_columns(zc, n)


def search(lmat_a: Arr, d_a: Arr, zs_a: Arr, m: int = 2) -> tuple[Arr, Arr]:
    """MLAMBDA search: the `m` best integer vectors (n, m) and their squared distances (m,), best first."""
    return _search_lists(lmat_a.tolist(), d_a.tolist(), zs_a.tolist(), m)


def _search_lists(lmat: list[list[float]], d: list[float], zs: list[float], m: int,
                  ratio_cap: float | None = None) -> tuple[Arr, Arr]:
    """search() on lists; with `ratio_cap`, mlambda's early exit on its first leaf (see there).

    The first descent reaches the bootstrapped (Babai) point, sequential rounding from the last ambiguity down.
    Any other vector first differs from it at some level k (counting from the top); above k it follows the
    leaf's path, so its distance is at least the path's distance above k plus (1 − |yₖ|)²/Dₖ, yₖ the leaf's
    rounding residual at k (the conditional mean is the leaf's, the integer at least 1 − |yₖ| from it). The
    minimum over k, taken along that descent, bounds the second-best distance from below: when it is at least
    `ratio_cap` times the leaf's distance, the leaf alone (n, 1) and [its distance, the bound] are returned.
    """
    n = len(d)
    first = ratio_cap is not None  # on the first descent, bounding the second-best distance
    cap = math.inf if ratio_cap is None else ratio_cap
    bound = float("inf")
    s_mat = [[0.0] * n for _ in range(n)]
    dist = [0.0] * n
    zb = [0.0] * n
    z = [0.0] * n
    step = [0.0] * n
    cands: list[list[float]] = [[0.0] * n for _ in range(m)]
    sdist = [0.0] * m
    nn, imax = 0, 0
    maxdist = float("inf")
    k = n - 1
    zb[k] = zs[k]
    z[k] = float(round(zb[k]))
    y = zb[k] - z[k]
    step[k] = 1.0 if y > 0 else -1.0
    for _ in range(_LOOP_MAX):
        if first:
            miss = 1.0 - abs(y)
            bound = min(bound, dist[k] + miss * miss / d[k])
        newdist = dist[k] + y * y / d[k]
        if newdist < maxdist:
            if k != 0:
                k1 = k
                k -= 1
                dist[k] = newdist
                dz = z[k1] - zb[k1]
                lrow = lmat[k1]
                srow, sprev = s_mat[k], s_mat[k1]
                for i in range(k1):
                    srow[i] = sprev[i] + dz * lrow[i]
                zbk = zs[k] + srow[k]
                zb[k] = zbk
                zk = float(round(zbk))
                z[k] = zk
                y = zbk - zk
                step[k] = 1.0 if y > 0 else -1.0
            else:
                if first:
                    first = False
                    if bound >= cap * max(newdist, 1e-12) * _BOUND_MARGIN:
                        return np.array(z).reshape(n, 1), np.array([newdist, bound])
                if nn < m:
                    if nn == 0 or newdist > sdist[imax]:
                        imax = nn
                    cands[nn] = list(z)
                    sdist[nn] = newdist
                    nn += 1
                else:
                    if newdist < sdist[imax]:
                        cands[imax] = list(z)
                        sdist[imax] = newdist
                        imax = max(range(m), key=sdist.__getitem__)
                    maxdist = sdist[imax]
                stp = step[0]
                z0 = z[0] + stp
                z[0] = z0
                y = zb[0] - z0
                step[0] = -stp - (1.0 if stp > 0 else -1.0)
        else:
            if k == n - 1:
                break
            k += 1
            stp = step[k]
            zk = z[k] + stp
            z[k] = zk
            y = zb[k] - zk
            step[k] = -stp - (1.0 if stp > 0 else -1.0)
    else:
        raise LambdaError("MLAMBDA search did not terminate")
    order = sorted(range(nn), key=sdist.__getitem__)
    return np.array([cands[i] for i in order]).T.reshape(n, nn), np.array([sdist[i] for i in order])


@dataclass
class LambdaResult:
    """Best `m` integer candidates `fixed` (n, m), squared distances `sq_dist` (m,) and ratio s2/s1."""

    sq_dist: Arr
    cond_var: Arr
    """Conditional variances D of the decorrelated ambiguities (cycles²)."""
    z_mat: Arr
    """The decorrelating integer transform Z (n, n)."""
    z_fixed: Arr
    """The candidates in the decorrelated space, E (n, m)."""

    @functools.cached_property
    def fixed(self) -> Arr:
        """The candidates F = Z⁻ᵀE (n, m), mapped back on first use: a failed ratio test (partial fixing's
        retries) reads only the distances."""
        return solve(self.z_mat.T, self.z_fixed).round()  # np.round's own call, without its wrapper

    @property
    def success_rate(self) -> float:
        """Bootstrapped success rate Π(2Φ(1/(2√Dᵢ))−1), a sharp lower bound of the ILS success rate
        (Teunissen 1998); computed in the decorrelated space."""
        # math.prod: the sequential product np.prod gives for these few factors (checked to the bit), without
        # building an array
        return math.prod([math.erf(1.0 / (2.0 * math.sqrt(2.0 * d))) for d in self.cond_var.tolist()])

    @property
    def ratio(self) -> float:
        if self.sq_dist.shape[0] < 2:
            return 0.0
        return float(self.sq_dist[1] / max(self.sq_dist[0], 1e-12))


_BOUND_MARGIN = 1.0 + 1e-9
"""Relative margin on the second-best bound against the rounding of the distance sums (~1e-16 relative)."""


_CERTAIN_MAX_VAR = 1.0 / 300.0
"""Largest conditional variance (cycles²) at which every factor erf(1/(2·√(2·D))) of the bootstrapped success
rate is exactly 1.0 in double precision (its argument ≥ 6.1; erf rounds to 1 from 5.9 on)."""
_CERTAIN_MARGIN = 10.0
"""Factor by which the certificate's lower bound of the second-best distance must exceed ratio_cap times the
best distance: room for the different roundings of the search's own distances (relative ~1e-12)."""


def _certain_nearest(a: Arr, q: Arr, lmat: list[list[float]], d: list[float], ratio_cap: float
                     ) -> LambdaResult | None:
    """mlambda's result for a float ambiguity vector `a` provably next to its rounding (held fixes), without
    the decorrelation and search, or None when the certificate fails. (`lmat`, `d`) = the LtDL factors of `q`.

    For any integer vector y other than x = round(a): ‖a − y‖ ≥ ‖x − y‖ − ‖a − x‖ in the Q⁻¹ norm, and a
    non-zero integer u has ‖u‖² ≥ 1/λmax(Q) ≥ 1/trace(Q) (Q = LᵀDL with every D > 0: positive definite). So
    when (1/√trace − √s₁)² ≥ _CERTAIN_MARGIN·ratio_cap·s₁ (s₁ = ‖a − x‖², from the factors), x is the best
    vector and the ratio is at least ratio_cap, as the search would report. The decorrelation keeps every
    conditional variance at most max(D) (a Gauss transform leaves D alone; a permutation replaces dⱼ, dⱼ₊₁ by
    values ≤ dⱼ₊₁), so with max(D) ≤ _CERTAIN_MAX_VAR the bootstrapped success rate is exactly 1.0 with or
    without it: the result holds Z = I, these D, x (also as `fixed`, no Z⁻ᵀ solve) and [s₁, the bound] as
    sq_dist (M8P static sets under a hold: 80-95 % of the calls)."""
    if max(d) > _CERTAIN_MAX_VAR:
        return None
    n = len(d)
    af = a.tolist()
    x = [float(round(v)) for v in af]
    # s₁ = rᵀQ⁻¹r = Σ yᵢ²/dᵢ with Lᵀy = r (Lᵀ unit upper triangular): back substitution from the last
    y = [0.0] * n
    s1 = 0.0
    for i in range(n - 1, -1, -1):
        yi = af[i] - x[i]
        for k in range(i + 1, n):
            yi -= lmat[k][i] * y[k]
        y[i] = yi
        s1 += yi * yi / d[i]
    gap = 1.0 / math.sqrt(float(q.trace())) - math.sqrt(s1)
    if gap <= 0.0 or gap * gap < _CERTAIN_MARGIN * ratio_cap * max(s1, 1e-12):
        return None
    best = np.array(x).reshape(n, 1)
    res = LambdaResult(np.array([s1, gap * gap]), np.array(d), np.eye(n), best)
    res.fixed = best  # Z = I: the candidates are the decorrelated ones (the cached property, set)
    return res


_WARM_MAX_Z = 1 << 20
"""Largest |entry| of a warm start's Z kept: the products Zᵀ·Q·Z and Z·Z' stay exact in integers and well within
double precision's 53 bits; beyond it the decorrelation starts from the identity again."""


def mlambda(a_float: Arr, q: Arr, m: int = 2, ratio_cap: float | None = None, z_start: Arr | None = None
            ) -> LambdaResult:
    """Integer least-squares estimates of float ambiguities `a_float` (n,) with covariance `q` (n,n).

    Follows RTKLIB lambda(): z = Zᵀa is searched in the decorrelated space, F = Z⁻ᵀE mapped back.

    `ratio_cap`: when the search's first leaf provably has a ratio of at least `ratio_cap` (a float next to
    an integer set held for minutes: most fixed epochs), the search is skipped: `fixed` holds that best vector
    alone (n, 1) and `sq_dist[1]` is the lower bound of the second-best distance, so `ratio` ≥ `ratio_cap`
    instead of the exact value. For callers that report the ratio capped there (a .pos file's 999.9). A float
    provably next to its rounding skips the decorrelation too (see _certain_nearest: Z = I, D of Q itself).

    `z_start`: an integer unimodular (n, n) transform to decorrelate from, e.g. the previous epoch's Z of the
    same ambiguities (LambdaResult.z_mat): the reduction then starts from ZₛᵀQZₛ, which a slowly changing
    covariance leaves nearly reduced, and Z = Zₛ·Z'. The best and second-best integer vectors (the ratio) do
    not depend on the start; the conditional variances D (the success rate) are those of another reduced basis.
    """
    a = np.asarray(a_float, float)
    n = a.shape[0]
    if n == 0 or q.shape != (n, n):
        raise LambdaError(f"bad shapes: a {a.shape}, Q {q.shape}")
    q = np.asarray(q, dtype=float)
    warm = z_start is not None and z_start.shape == (n, n) and float(np.abs(z_start).max()) <= _WARM_MAX_Z
    factors = None
    # the certificate needs every D ≤ _CERTAIN_MAX_VAR, and the last D is Q's own last variance: a warm start
    # skips the factors of Q when that one is already larger (its own factors check positive definiteness)
    if not warm or (ratio_cap is not None and q[n - 1, n - 1] <= _CERTAIN_MAX_VAR * (1.0 + 1e-9)):
        factors = _ld_lists(q)  # also the positive-definiteness check, whatever follows
        if ratio_cap is not None:
            certain = _certain_nearest(a, q, *factors, ratio_cap)
            if certain is not None:
                return certain
    if warm:
        assert z_start is not None
        lmat, d, zw = _reduction_lists(*_ld_lists(z_start.T @ q @ z_start))
        z = z_start @ zw
        if float(np.abs(z).max()) > _WARM_MAX_Z:
            lmat, d, z = _reduction_lists(*(factors or _ld_lists(q)))
    else:
        assert factors is not None
        lmat, d, z = _reduction_lists(*factors)  # Z row-major as RTKLIB's: the products below the same
    zs = z.T @ a
    zs_list = zs.tolist()
    e, s = _search_lists(lmat, d, zs_list, m, ratio_cap)
    return LambdaResult(s, np.array(d), z, e)
