"""np.linalg.solve (and inv) of one small float64 system, through the LAPACK gufunc numpy itself calls.

np.linalg.solve spends more time in its wrapper (array conversion, shape and type checks, an errstate
context) than LAPACK spends on the engine's 3×3 to 30×30 systems: about 2 µs of a 4-8 µs call, five to seven
calls per epoch. solve() calls the same gufunc with the same signature as numpy does for float64 input, so the
results are the same to the bit (checked against numpy in tests/rtk/test_fast_paths.py). Float64 arrays only, one
system per call (no stacks), and for systems regular by construction (an innovation covariance, a float
ambiguity covariance, an integer transform): a singular one is not silent but noisier than numpy's. Pure.

A singular matrix raises LinAlgError as numpy's does (LAPACK reports it by filling the result with NaN, which
the first element tells; the gufunc's RuntimeWarning for it is not silenced as numpy's wrapper does). NaN in the
input likewise raises, where numpy would return NaN.
"""

from __future__ import annotations

from types import ModuleType

import numpy as np
import numpy.typing as npt
from numpy.linalg import LinAlgError

_umath_linalg: ModuleType | None
try:
    from numpy.linalg import _umath_linalg  # the gufuncs behind np.linalg (numpy 1.x and 2.x)
except ImportError:  # a numpy that moved its private module: its public wrapper, same results, slower
    _umath_linalg = None

Arr = npt.NDArray[np.float64]

__all__ = ["LinAlgError", "inv", "solve"]


def _checked(x: Arr) -> Arr:
    """`x` unless LAPACK flagged a singular system (every element NaN: the first tells)."""
    if x.size and x.flat[0] != x.flat[0]:
        raise LinAlgError("Singular matrix")
    return x


def solve(a: Arr, b: Arr) -> Arr:
    """x with a·x = b: `a` (n, n), `b` (n,) or (n, k), float64 (np.linalg.solve to the bit)."""
    if _umath_linalg is None:
        return np.asarray(np.linalg.solve(a, b), np.float64)
    if b.ndim == 1:
        return _checked(_umath_linalg.solve1(a, b, signature="dd->d"))
    return _checked(_umath_linalg.solve(a, b, signature="dd->d"))


def inv(a: Arr) -> Arr:
    """a⁻¹ of one float64 matrix `a` (n, n) (np.linalg.inv to the bit), LinAlgError when singular."""
    if _umath_linalg is None:
        return np.asarray(np.linalg.inv(a), np.float64)
    return _checked(_umath_linalg.inv(a, signature="d->d"))
