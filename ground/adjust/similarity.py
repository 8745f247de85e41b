"""Closed-form similarity/rigid fits (Umeyama 1991) with RANSAC, and small SO(3) helpers.

Umeyama, S. (1991) "Least-squares estimation of transformation parameters between two point patterns",
IEEE PAMI 13(4): SVD of the cross-covariance, with the reflection guard diag(1, 1, det(U·Vᵀ)).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

Arr = npt.NDArray[np.float64]


class DegenerateGeometry(ValueError):
    """The points cannot fix a similarity (too few, coincident or collinear)."""


@dataclass(frozen=True)
class Similarity:
    """dst ≈ translation + scale · rotation · src (rotation 3×3 proper, scale > 0)."""

    scale: float
    rotation: Arr
    translation: Arr

    def apply(self, points: npt.ArrayLike) -> Arr:
        """Map points (…,3)."""
        return self.translation + self.scale * np.asarray(points, dtype=float) @ self.rotation.T

    def inverse(self) -> Similarity:
        """The inverse transform."""
        r_inv = self.rotation.T
        return Similarity(1.0 / self.scale, r_inv, -(r_inv @ self.translation) / self.scale)


def collinearity_ratio(points: npt.ArrayLike) -> float:
    """Second over first singular value of the centred points: 0 for collinear, ~1 for a well-spread set."""
    p = np.asarray(points, dtype=float)
    if p.shape[0] < 3:
        return 0.0
    sv = np.linalg.svd(p - p.mean(axis=0), compute_uv=False)
    return float(sv[1] / sv[0]) if sv[0] > 0 else 0.0


def umeyama(src: npt.ArrayLike, dst: npt.ArrayLike, with_scale: bool = True) -> Similarity:
    """Least-squares similarity (or rigid transform when `with_scale` is False) mapping src (n,3) onto dst (n,3).

    Raises DegenerateGeometry for fewer than 3 points or collinear/coincident points.
    """
    a = np.asarray(src, dtype=float)
    b = np.asarray(dst, dtype=float)
    if a.shape != b.shape or a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"src and dst must both be (n,3); got {a.shape} and {b.shape}")
    if a.shape[0] < 3:
        raise DegenerateGeometry(f"a similarity needs ≥ 3 points, got {a.shape[0]}")
    if collinearity_ratio(a) < 1e-6:
        raise DegenerateGeometry(
            "points are collinear or coincident: rotation about their line is undetermined"
        )
    ma, mb = a.mean(axis=0), b.mean(axis=0)
    da, db = a - ma, b - mb
    n = a.shape[0]
    cov = db.T @ da / n
    u, d, vt = np.linalg.svd(cov)
    sign = np.ones(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:  # reflection guard
        sign[2] = -1.0
    rot = (u * sign) @ vt
    var_a = float(np.sum(da * da) / n)
    scale = float(np.sum(d * sign) / var_a) if with_scale else 1.0
    t = mb - scale * rot @ ma
    return Similarity(scale, rot, t)


def ransac_umeyama(
    src: npt.ArrayLike,
    dst: npt.ArrayLike,
    threshold_m: float,
    iterations: int,
    rng: np.random.Generator,
    min_spread: float = 0.05,
) -> tuple[Similarity, npt.NDArray[np.bool_]]:
    """Robust similarity: 3-point samples (near-collinear ones rejected), inliers |S(src) − dst| < threshold_m.

    Returns the Umeyama fit on the largest inlier set and the inlier mask. Linear in n per iteration.
    Raises DegenerateGeometry when no non-collinear sample exists.
    """
    a = np.asarray(src, dtype=float)
    b = np.asarray(dst, dtype=float)
    n = a.shape[0]
    if n < 3:
        raise DegenerateGeometry(f"a similarity needs ≥ 3 points, got {n}")
    if collinearity_ratio(a) < 1e-3:
        raise DegenerateGeometry(
            "camera centres (and GCPs) are nearly collinear (a single strip): the roll about the strip is "
            "undetermined; add GCPs off the line or fix/prior the similarity"
        )
    best_mask: npt.NDArray[np.bool_] | None = None
    best_count = -1
    best_err = np.inf
    for _ in range(iterations):
        idx = rng.choice(n, size=3, replace=False)
        if collinearity_ratio(a[idx]) < min_spread:
            continue
        try:
            s = umeyama(a[idx], b[idx])
        except DegenerateGeometry:
            continue
        err = np.linalg.norm(s.apply(a) - b, axis=1)
        mask = err < threshold_m
        count = int(mask.sum())
        sum_err = float(np.sum(np.minimum(err, threshold_m)))
        if count > best_count or (count == best_count and sum_err < best_err):
            best_mask, best_count, best_err = mask, count, sum_err
    if best_mask is None or best_count < 3:
        # fall back to all points (e.g. every sample collinear by chance in a tiny set)
        best_mask = np.ones(n, dtype=bool)
    fit = umeyama(a[best_mask], b[best_mask])
    # one refinement round: recompute inliers with the all-inlier fit
    mask = np.linalg.norm(fit.apply(a) - b, axis=1) < threshold_m
    if mask.sum() >= 3 and collinearity_ratio(a[mask]) >= 1e-3:
        fit = umeyama(a[mask], b[mask])
        best_mask = mask
    return fit, best_mask


def skew(v: npt.ArrayLike) -> Arr:
    """Cross-product matrix [v]× (3×3) or stacked (n,3,3) for v (n,3)."""
    w = np.asarray(v, dtype=float)
    out = np.zeros(w.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -w[..., 2], w[..., 1]
    out[..., 1, 0], out[..., 1, 2] = w[..., 2], -w[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -w[..., 1], w[..., 0]
    return out


def so3_exp(omega: npt.ArrayLike) -> Arr:
    """Rodrigues: rotation matrix of the rotation vector omega (rad)."""
    w = np.asarray(omega, dtype=float)
    th = float(np.linalg.norm(w))
    k = skew(w)
    if th < 1e-12:
        return np.eye(3) + k
    return np.eye(3) + np.sin(th) / th * k + (1 - np.cos(th)) / th**2 * (k @ k)


def so3_log(rot: npt.ArrayLike) -> Arr:
    """Rotation vector (rad) of a rotation matrix (angle < π)."""
    r = np.asarray(rot, dtype=float)
    c = np.clip((np.trace(r) - 1) / 2, -1.0, 1.0)
    th = float(np.arccos(c))
    w = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / 2
    if th < 1e-9:
        return w
    return w * th / np.sin(th)


def so3_left_jacobian(omega: npt.ArrayLike) -> Arr:
    """Left Jacobian J_l(ω): d(exp([ω])·y)/dω = −[exp([ω])·y]× · J_l(ω)."""
    w = np.asarray(omega, dtype=float)
    th = float(np.linalg.norm(w))
    k = skew(w)
    if th < 1e-8:
        return np.eye(3) + 0.5 * k
    return np.eye(3) + (1 - np.cos(th)) / th**2 * k + (th - np.sin(th)) / th**3 * (k @ k)
