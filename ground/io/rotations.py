"""Rotation conversions used by importers/exporters (pure numpy).

Internal convention (shared/docs/adjustment.md): camera axes are computer-vision axes (x right, y down,
z forward) and poses carry `r_cam_to_world`. Photogrammetric (PATB/OPK) axes are x right, y up, z back:
R_PATB = R_cv→w · diag(1, −1, −1), and R_PATB = Rx(ω)·Ry(φ)·Rz(κ).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

Mat3 = npt.NDArray[np.float64]

CV_TO_PATB = np.diag([1.0, -1.0, -1.0])  # its own inverse


def rotation_from_axis_angle(rotvec_rad: npt.ArrayLike) -> Mat3:
    """Rodrigues: axis-angle vector (axis × angle, rad) → 3×3 rotation matrix."""
    v = np.asarray(rotvec_rad, dtype=float).reshape(3)
    angle = float(np.linalg.norm(v))
    if angle < 1e-15:
        return np.eye(3)
    k = v / angle
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * kx + (1.0 - np.cos(angle)) * (kx @ kx)


def axis_angle_from_rotation(r: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """3×3 rotation matrix → axis-angle vector (rad); inverse of :func:`rotation_from_axis_angle`."""
    m = np.asarray(r, dtype=float)
    q = quaternion_wxyz_from_rotation(m)
    w, xyz = q[0], q[1:]
    s = float(np.linalg.norm(xyz))
    if s < 1e-15:
        return np.zeros(3)
    angle = 2.0 * np.arctan2(s, w)
    return xyz / s * angle


def rotation_from_quaternion_wxyz(q: npt.ArrayLike) -> Mat3:
    """Hamilton unit quaternion (w, x, y, z) → 3×3 rotation matrix (normalised first)."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(np.asarray(q, dtype=float))
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def quaternion_wxyz_from_rotation(r: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """3×3 rotation matrix → Hamilton unit quaternion (w, x, y, z) with w ≥ 0 (Shepperd's method)."""
    m = np.asarray(r, dtype=float)
    tr = np.trace(m)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = np.array([0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s])
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = np.array([(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s])
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = np.array([(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s])
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = np.array([(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s])
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


def _rx(a: float) -> Mat3:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(a: float) -> Mat3:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rz(a: float) -> Mat3:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def r_cam_to_world_from_opk_deg(omega_deg: float, phi_deg: float, kappa_deg: float) -> Mat3:
    """OPK angles (degrees, PATB convention) → camera→world rotation in computer-vision camera axes."""
    r_patb = _rx(np.radians(omega_deg)) @ _ry(np.radians(phi_deg)) @ _rz(np.radians(kappa_deg))
    return r_patb @ CV_TO_PATB


def opk_deg_from_r_cam_to_world(r_cam_to_world: npt.ArrayLike) -> tuple[float, float, float]:
    """Camera→world rotation (computer-vision camera axes) → (ω, φ, κ) in degrees, PATB convention.

    ω = atan2(−R12, R22), φ = asin(R02), κ = atan2(−R01, R00) of R_PATB = R · diag(1, −1, −1).
    """
    r = np.asarray(r_cam_to_world, dtype=float) @ CV_TO_PATB
    omega = np.degrees(np.arctan2(-r[1, 2], r[2, 2]))
    phi = np.degrees(np.arcsin(np.clip(r[0, 2], -1.0, 1.0)))
    kappa = np.degrees(np.arctan2(-r[0, 1], r[0, 0]))
    return float(omega), float(phi), float(kappa)


def is_rotation(r: npt.ArrayLike, tol: float = 1e-6) -> bool:
    """True when `r` is a proper 3×3 rotation (orthonormal, determinant +1) within `tol`."""
    m = np.asarray(r, dtype=float)
    return m.shape == (3, 3) and bool(np.allclose(m @ m.T, np.eye(3), atol=tol)) and abs(np.linalg.det(m) - 1) < tol
