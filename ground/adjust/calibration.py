"""Lever-arm ground calibration by pseudo-materialization (Daakir et al. 2016, § 3.2.3, eqs. 6–9).

One photogrammetric acquisition of the drone on the ground measures, in its own (arbitrary) acquisition frame,
targets on the camera and targets on the receiver box. Beforehand, the camera targets were calibrated in the
camera frame (x right, y down, z forward, origin at the optical centre) and the box targets with the antenna
phase centre in the box frame. Then:

1. 7-parameter similarity S (Umeyama) from the acquisition frame to the camera frame, on the camera targets;
2. the box targets mapped into the camera frame with S;
3. 6-parameter rigid transform D (R2, T2) from the box frame onto those camera-frame coordinates;
4. O = R2·C_gps|box + T2 (eq. 9): the phase centre in the camera frame, i.e. antenna − optical centre,
   the sign convention of the adjustment (antenna = C + R_cam→world·O).

σ by Monte Carlo: every coordinate is perturbed with the a-posteriori σ of its fit (the a-priori σ when the fit
has fewer than 3 degrees of freedom) split evenly between the two point sets of that fit, and the phase centre
with its own σ. Two acquisitions (before/after the flight) are compared with `compare_calibrations`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from ground.adjust.similarity import DegenerateGeometry, Similarity, so3_log, umeyama

Arr = npt.NDArray[np.float64]


class CalibrationError(ValueError):
    """The calibration input cannot give a lever arm (too few common targets, degenerate geometry)."""


@dataclass(frozen=True)
class CalibrationInput:
    """Target coordinates (m) by name, per group (see module docstring), and the phase centre in the box frame."""

    camera_frame: dict[str, Arr]
    camera_acq: dict[str, Arr]
    box_acq: dict[str, Arr]
    box_frame: dict[str, Arr]
    phase_centre_box_m: Arr


@dataclass(frozen=True)
class CalibrationOptions:
    """σ used when a fit has no redundancy, phase-centre σ, Monte Carlo draws and seed (deterministic)."""

    target_sigma_m: float = 0.001
    phase_centre_sigma_m: float = 0.002
    n_monte_carlo: int = 2000
    seed: int = 0


@dataclass(frozen=True)
class LeverArmCalibration:
    """Result: O (camera frame, m) with its covariance, both fits and their per-target residuals (m)."""

    lever_arm_m: Arr
    sigma_m: Arr
    covariance_m2: Arr
    camera_fit: Similarity  # acquisition → camera frame
    box_fit: Similarity  # box frame → camera frame (scale 1)
    camera_residuals_m: dict[str, Arr]
    box_residuals_m: dict[str, Arr]
    camera_sigma_m: float  # a-posteriori σ of a coordinate in fit 1
    box_sigma_m: float  # a-posteriori σ of a coordinate in fit 2

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary."""
        return {
            "lever_arm_m": [float(x) for x in self.lever_arm_m],
            "lever_arm_sigma_m": [float(x) for x in self.sigma_m],
            "covariance_m2": [[float(x) for x in row] for row in self.covariance_m2],
            "acquisition_scale": float(self.camera_fit.scale),
            "camera_residuals_m": {k: [float(x) for x in v] for k, v in self.camera_residuals_m.items()},
            "box_residuals_m": {k: [float(x) for x in v] for k, v in self.box_residuals_m.items()},
            "camera_sigma_m": float(self.camera_sigma_m),
            "box_sigma_m": float(self.box_sigma_m),
        }


@dataclass(frozen=True)
class CalibrationComparison:
    """b − a of two calibrations (camera frame, m), its σ, and the change of the box attitude (deg)."""

    difference_m: Arr
    abs_m: float
    sigma_m: Arr
    box_rotation_change_deg: float
    stable: bool  # every component within 3σ

    def to_dict(self) -> dict[str, Any]:
        return {
            "difference_m": [float(x) for x in self.difference_m],
            "abs_m": float(self.abs_m),
            "sigma_m": [float(x) for x in self.sigma_m],
            "box_rotation_change_deg": float(self.box_rotation_change_deg),
            "stable": bool(self.stable),
        }


def _common(a: dict[str, Arr], b: dict[str, Arr], what: str) -> list[str]:
    names = sorted(set(a) & set(b))
    if len(names) < 3:
        raise CalibrationError(f"{what}: {len(names)} common target(s), at least 3 are needed ({names})")
    return names


def _fit(src: Arr, dst: Arr, with_scale: bool, what: str) -> Similarity:
    try:
        return umeyama(src, dst, with_scale=with_scale)
    except DegenerateGeometry as exc:
        raise CalibrationError(f"{what}: {exc}") from exc


def _lever_arm(
    cam_acq: Arr, cam_frame: Arr, box_acq: Arr, box_frame: Arr, phase_centre: Arr
) -> tuple[Arr, Similarity, Similarity]:
    s1 = _fit(cam_acq, cam_frame, True, "camera targets (acquisition → camera frame)")
    box_cam = s1.apply(box_acq)
    d = _fit(box_frame, box_cam, False, "box targets (box frame → camera frame)")
    return d.apply(phase_centre), s1, d


def calibrate_lever_arm(
    inp: CalibrationInput, options: CalibrationOptions | None = None
) -> LeverArmCalibration:
    """Lever arm O (camera frame) from one ground acquisition, with σ and per-target residuals.

    Raises CalibrationError with fewer than 3 common targets in either fit or collinear targets.
    """
    opt = options or CalibrationOptions()
    cam_names = _common(inp.camera_acq, inp.camera_frame, "camera targets")
    box_names = _common(inp.box_acq, inp.box_frame, "box targets")
    cam_acq = np.array([inp.camera_acq[n] for n in cam_names], dtype=float)
    cam_frame = np.array([inp.camera_frame[n] for n in cam_names], dtype=float)
    box_acq = np.array([inp.box_acq[n] for n in box_names], dtype=float)
    box_frame = np.array([inp.box_frame[n] for n in box_names], dtype=float)
    pc = np.asarray(inp.phase_centre_box_m, dtype=float)
    lever, s1, d = _lever_arm(cam_acq, cam_frame, box_acq, box_frame, pc)

    res1 = s1.apply(cam_acq) - cam_frame
    box_cam = s1.apply(box_acq)
    res2 = d.apply(box_frame) - box_cam
    dof1 = 3 * len(cam_names) - 7
    dof2 = 3 * len(box_names) - 6
    # a-posteriori σ of one coordinate (residual in camera-frame units); a priori when there is no redundancy
    sig1 = float(np.sqrt(np.sum(res1**2) / dof1)) if dof1 >= 3 else opt.target_sigma_m
    sig2 = float(np.sqrt(np.sum(res2**2) / dof2)) if dof2 >= 3 else opt.target_sigma_m

    rng = np.random.default_rng(opt.seed)
    draws = np.empty((opt.n_monte_carlo, 3))
    # each fit's residual σ is shared by its two point sets; the acquisition sets are in acquisition units
    half1, half2 = sig1 / np.sqrt(2), sig2 / np.sqrt(2)
    acq_unit = 1.0 / s1.scale
    for k in range(opt.n_monte_carlo):
        lever_k, _, _ = _lever_arm(
            cam_acq + rng.normal(0, half1 * acq_unit, cam_acq.shape),
            cam_frame + rng.normal(0, half1, cam_frame.shape),
            box_acq + rng.normal(0, half2 * acq_unit, box_acq.shape),
            box_frame + rng.normal(0, half2, box_frame.shape),
            pc + rng.normal(0, opt.phase_centre_sigma_m, 3),
        )
        draws[k] = lever_k
    cov = np.cov(draws.T)
    return LeverArmCalibration(
        lever_arm_m=lever,
        sigma_m=np.sqrt(np.diag(cov)),
        covariance_m2=cov,
        camera_fit=s1,
        box_fit=d,
        camera_residuals_m={n: r for n, r in zip(cam_names, res1, strict=True)},
        box_residuals_m={n: r for n, r in zip(box_names, res2, strict=True)},
        camera_sigma_m=sig1,
        box_sigma_m=sig2,
    )


def compare_calibrations(a: LeverArmCalibration, b: LeverArmCalibration) -> CalibrationComparison:
    """Stability between two acquisitions (e.g. before/after the flight): b − a, its σ, box attitude change."""
    diff = b.lever_arm_m - a.lever_arm_m
    sigma = np.sqrt(a.sigma_m**2 + b.sigma_m**2)
    rot_change = float(np.degrees(np.linalg.norm(so3_log(b.box_fit.rotation @ a.box_fit.rotation.T))))
    stable = bool(np.all(np.abs(diff) <= 3 * np.maximum(sigma, 1e-12)))
    return CalibrationComparison(diff, float(np.linalg.norm(diff)), sigma, rot_change, stable)


def lever_arm_from_daakir_eq1(o_daakir_m: npt.ArrayLike) -> Arr:
    """Convert a lever arm written as in Daakir 2016 eq. 1 / Daakir 2015 eqs. 3, 4, 6 (S(C) = G + R·O, i.e.
    optical centre minus antenna) to ours (antenna minus optical centre, Daakir 2016 eq. 9): O = −O_daakir."""
    return -np.asarray(o_daakir_m, dtype=float)


def lever_arm_to_daakir_eq1(o_m: npt.ArrayLike) -> Arr:
    """Inverse of `lever_arm_from_daakir_eq1`."""
    return -np.asarray(o_m, dtype=float)
