"""Options, problem and result of the final adjustment (similarity + lever arm + shutter delay).

Model (shared/docs/adjustment.md), per image i, in a local ENU frame (metres)::

    e_i = T + μ·R·C_i + (R·R_i)·O − G_i − V_i·t_d − ½·A_i·t_d²     (3 residuals)

S(x) = T + μ·R·x maps the bundle adjustment's relative frame into ENU; `C_i`, `R_i` are the camera centre and
camera→relative rotation (camera axes x right, y down, z forward); O is antenna phase centre minus optical
centre in the camera frame (antenna = C + R_cam→world·O, Daakir 2016 eq. 9); G_i, V_i are the antenna position
velocity (and acceleration, a second-order term that matters for 60–90 ms trigger delays while the drone
speeds up) interpolated at the event time; t_d is the event→exposure delay (s).
GCP j: S(P_rel) − P_ground = 0 (weighted). Check points never enter the adjustment.

This module holds the data types only; `ground.adjust.solve.adjust` does the work.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from ground.adjust.types import ControlPoint

Mode = Literal["free", "fixed", "prior"]
Loss = Literal["linear", "soft_l1", "huber", "cauchy", "arctan"]

#: Names of the 11 parameters, in the order of every covariance/correlation matrix we return.
#: T_* translation (ENU m) of the block centroid (the model works on centred coordinates so that translation
#: and rotation do not correlate; `AdjustmentResult.translation_m` is the plain T of S(x) = T + μ·R·x, with its
#: σ propagated), rot_* small rotation about the E/N/U axes (rad, applied on the left of R), scale (unitless),
#: O_* lever arm (camera frame m), t_d delay (s).
PARAMETER_NAMES: tuple[str, ...] = (
    "T_e", "T_n", "T_u", "rot_e", "rot_n", "rot_u", "scale", "O_x", "O_y", "O_z", "t_d",
)  # fmt: skip

CHI2_3DOF_95 = 7.815
#: χ² with 3 degrees of freedom at 99.9 %: the per-image outlier test. At 95 % (7.815) the test flags 5 % of
#: perfectly good images by construction (15 of a 300-image block), more with time-correlated GNSS errors;
#: at 99.9 % a good block loses ~0.1 % while a 5σ gross error is still caught.
CHI2_3DOF_999 = 16.266
#: σ̂₀ above which a solution is flagged as holding a blunder: residuals ten times the σ the inputs state. A
#: receiver that misstates its σ does so by ×2–3 (time-correlated RTK errors); float RTK states its own larger
#: σ; a GCP or base position metres to kilometres off, or inputs of another flight, give σ̂₀ of 10²–10⁵.
BLUNDER_SIGMA0 = 10.0


def _num(x: Any) -> float | None:
    """float for JSON; None for NaN/±inf (strict JSON has no Infinity)."""
    v = float(x)
    return v if np.isfinite(v) else None


class AdjustmentRefused(ValueError):
    """The problem as posed cannot be solved meaningfully; the message says why and what to add."""


@dataclass(frozen=True)
class LeverArmSpec:
    """How the lever arm O (camera frame x right, y down, z forward; m) enters the adjustment.

    free: estimated (needs ≥ 1 GCP, else refused); fixed: `value_m` used as is; prior: estimated with the
    extra observation O = value_m ± sigma_m (e.g. from the ground calibration, `ground.adjust.calibration`).
    """

    mode: Mode = "free"
    value_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sigma_m: tuple[float, float, float] = (0.005, 0.005, 0.005)


@dataclass(frozen=True)
class DelaySpec:
    """How the shutter delay t_d (event → exposure, s) enters: free, fixed at value_s, or prior value_s ± sigma_s."""

    mode: Mode = "free"
    value_s: float = 0.0
    sigma_s: float = 0.001


@dataclass(frozen=True)
class SimilaritySpec:
    """How the 7-parameter similarity (relative frame → ENU) enters.

    free: estimated (closed-form start); fixed: the bundle adjustment is already in ENU up to the given
    transform; prior: estimated with extra observations on scale, rotation (rad, about E/N/U) and translation.
    `rotation` is the 3×3 relative→ENU matrix, row-major.
    """

    mode: Mode = "free"
    scale: float = 1.0
    rotation: tuple[tuple[float, float, float], ...] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    translation_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    scale_sigma: float = 1e-4
    rotation_sigma_rad: float = 1e-4
    translation_sigma_m: float = 0.05


@dataclass(frozen=True)
class AdjustmentOptions:
    """Options of the final adjustment (one frozen object; units in names)."""

    similarity: SimilaritySpec = field(default_factory=SimilaritySpec)
    lever_arm: LeverArmSpec = field(default_factory=LeverArmSpec)
    delay: DelaySpec = field(default_factory=DelaySpec)
    #: robust loss of the first pass (scipy.optimize.least_squares `loss`); the final pass is always linear
    loss: Loss = "soft_l1"
    #: robust loss scale, in whitened units (σ)
    f_scale: float = 2.5
    #: per-image χ² (3 dof, after dividing by a robust σ̂₀²) above which an image is an outlier (χ²₃ 99.9 %)
    chi2_threshold: float = CHI2_3DOF_999
    #: RANSAC inlier threshold on |S(C) − G| at the closed-form start (m); lever arm and delay are not yet known
    ransac_threshold_m: float = 1.0
    ransac_iterations: int = 300
    ransac_seed: int = 0
    #: σ of the bundle adjustment's camera centres, in ENU metres, added in quadrature to the antenna σ
    camera_centre_sigma_m: float = 0.01
    #: use differenced (relative) aerial control between consecutive images instead of absolute positions
    relative_control: bool = False
    #: longest time between two consecutive images that still form a relative-control pair (s)
    max_pair_dt_s: float = 10.0
    #: |ρ| above which a parameter pair is reported as correlated
    correlation_warning: float = 0.9
    #: inflate the covariance for time-correlated GNSS errors (batch means over flight segments, see
    #: solve.variance_inflation); segments are runs of images less than segment_gap_s apart
    inflate_for_time_correlation: bool = True
    segment_gap_s: float = 3.0
    #: largest fraction of images that may be flagged before the adjustment gives up
    max_outlier_fraction: float = 0.3
    #: leave-one-out test of every GCP: each is predicted by the adjustment without it; a GCP whose χ²₃
    #: (residual over its propagated σ) exceeds `gcp_chi2_threshold` is excluded, the worst first, one at a time
    gcp_blunder_test: bool = True
    gcp_chi2_threshold: float = CHI2_3DOF_999
    #: largest fraction of the GCPs that may be excluded before the adjustment gives up
    max_excluded_gcp_fraction: float = 0.5
    #: σ̂₀ above which the result is flagged `blunder_suspected` (see BLUNDER_SIGMA0)
    blunder_sigma0: float = BLUNDER_SIGMA0


@dataclass(frozen=True)
class AdjustmentProblem:
    """Everything the adjustment needs, in a local ENU frame (metres) about `origin_ecef_m`.

    Arrays are per image, in one order: `images` (n,) names, `centre_rel` (n,3) camera centres in the relative
    frame, `r_cam_to_rel` (n,3,3), `antenna_enu_m` (n,3) G_i at the event time, `velocity_enu_m_s` (n,3) V_i,
    `antenna_sigma_enu_m` (n,3) σ of G_i per axis, `event_time_s` (n,) seconds since the first event (used only
    to form relative-control pairs), `quality` (n,) RTKLIB q of the trajectory around the event (1 fix, 2 float,
    5 single). `control` holds GCPs (role "gcp") and check points (role "check").
    Build it with `AdjustmentProblem.from_arrays` or `ground.adjust.solve.build_problem`.
    """

    images: tuple[str, ...]
    centre_rel: npt.NDArray[np.float64]
    r_cam_to_rel: npt.NDArray[np.float64]
    antenna_enu_m: npt.NDArray[np.float64]
    velocity_enu_m_s: npt.NDArray[np.float64]
    antenna_sigma_enu_m: npt.NDArray[np.float64]
    event_time_s: npt.NDArray[np.float64]
    quality: npt.NDArray[np.int8]
    control: tuple[ControlPoint, ...] = ()
    origin_ecef_m: npt.NDArray[np.float64] | None = None
    #: antenna acceleration (n,3) m/s² at the event (second-order delay term ½·A·t_d²); None = zero
    acceleration_enu_m_s2: npt.NDArray[np.float64] | None = None
    #: images left out while building the problem, with the reason (no event, outside the trajectory, gap …)
    skipped: tuple[tuple[str, str], ...] = ()
    #: what building the problem changed on the way (e.g. trigger events converted to flash times)
    notes: tuple[str, ...] = ()

    @classmethod
    def from_arrays(
        cls,
        images: list[str] | tuple[str, ...],
        centre_rel: npt.ArrayLike,
        r_cam_to_rel: npt.ArrayLike,
        antenna_enu_m: npt.ArrayLike,
        velocity_enu_m_s: npt.ArrayLike,
        antenna_sigma_enu_m: npt.ArrayLike,
        event_time_s: npt.ArrayLike | None = None,
        quality: npt.ArrayLike | None = None,
        control: list[ControlPoint] | tuple[ControlPoint, ...] = (),
        origin_ecef_m: npt.ArrayLike | None = None,
        acceleration_enu_m_s2: npt.ArrayLike | None = None,
    ) -> AdjustmentProblem:
        """Validate shapes and build a problem; σ may be a scalar or (n,3). Raises ValueError on bad shapes."""
        n = len(images)
        c = np.asarray(centre_rel, dtype=float).reshape(-1, 3)
        r = np.asarray(r_cam_to_rel, dtype=float).reshape(-1, 3, 3)
        g = np.asarray(antenna_enu_m, dtype=float).reshape(-1, 3)
        v = np.asarray(velocity_enu_m_s, dtype=float).reshape(-1, 3)
        s = np.broadcast_to(np.asarray(antenna_sigma_enu_m, dtype=float), (n, 3)).copy()
        t = (
            np.arange(n, dtype=float)
            if event_time_s is None
            else np.asarray(event_time_s, dtype=float).ravel()
        )
        q = np.ones(n, dtype=np.int8) if quality is None else np.asarray(quality, dtype=np.int8).ravel()
        for name, arr in (("centre_rel", c), ("r_cam_to_rel", r), ("antenna_enu_m", g),
                          ("velocity_enu_m_s", v), ("event_time_s", t), ("quality", q)):  # fmt: skip
            if arr.shape[0] != n:
                raise ValueError(f"{name} has {arr.shape[0]} rows for {n} images")
        if len(set(images)) != n:
            raise ValueError("image names must be unique")
        if not np.all(np.isfinite(c)) or not np.all(np.isfinite(g)) or not np.all(np.isfinite(v)):
            raise ValueError("non-finite camera centre, antenna position or velocity")
        if np.any(s <= 0) or not np.all(np.isfinite(s)):
            raise ValueError("antenna σ must be positive and finite")
        origin = None if origin_ecef_m is None else np.asarray(origin_ecef_m, dtype=float)
        acc = None
        if acceleration_enu_m_s2 is not None:
            acc = np.asarray(acceleration_enu_m_s2, dtype=float).reshape(-1, 3)
            if acc.shape[0] != n or not np.all(np.isfinite(acc)):
                raise ValueError("acceleration_enu_m_s2 must be finite with one row per image")
        return cls(tuple(images), c, r, g, v, s, t, q, tuple(control), origin, acc)

    @property
    def gcps(self) -> tuple[ControlPoint, ...]:
        """Ground control points (enter the adjustment)."""
        return tuple(p for p in self.control if p.role == "gcp")

    @property
    def checks(self) -> tuple[ControlPoint, ...]:
        """Check points (never enter the adjustment)."""
        return tuple(p for p in self.control if p.role == "check")


@dataclass(frozen=True)
class ExcludedGcp:
    """A GCP the leave-one-out test excluded: its residual predicted without it (ENU m) and its χ²₃."""

    name: str
    residual_enu_m: tuple[float, float, float]
    chi2: float


@dataclass(frozen=True)
class CheckPointResidual:
    """One check point: S(P_rel) − P_ground in ENU (m), its length, and its propagated 3D σ (m)."""

    name: str
    de_m: float
    dn_m: float
    du_m: float
    abs_m: float
    sigma_m: float
    sigma_enu_m: tuple[float, float, float]


@dataclass(frozen=True)
class AdjustmentResult:
    """Everything the adjustment estimated and diagnosed. `to_dict()` is the JSON form used by the CLI/API/report.

    Covariance/correlation matrices are over `parameter_names` (the free parameters only, a subset of
    `PARAMETER_NAMES` in that order); σ of fixed parameters is reported as 0.
    """

    scale: float
    scale_sigma: float
    rotation: npt.NDArray[np.float64]  # 3×3 relative → ENU
    rotation_sigma_rad: npt.NDArray[np.float64]  # (3,) about E, N, U
    translation_m: npt.NDArray[np.float64]
    translation_sigma_m: npt.NDArray[np.float64]
    lever_arm_m: npt.NDArray[np.float64]
    lever_arm_sigma_m: npt.NDArray[np.float64]
    delay_s: float
    delay_sigma_s: float
    sigma0: float
    parameter_names: tuple[str, ...]
    covariance: npt.NDArray[np.float64]
    correlations: npt.NDArray[np.float64]
    condition_number: float
    weakest_combination: str
    warnings: tuple[str, ...]
    outliers: tuple[tuple[str, float], ...]  # (image, χ² normalised by the robust σ̂₀²)
    images: tuple[str, ...]
    residuals_enu_m: npt.NDArray[np.float64]  # (n,3) e_i at the solution, every image (outliers included)
    outlier_mask: npt.NDArray[np.bool_]
    checkpoints: tuple[CheckPointResidual, ...]
    checkpoint_rms_m: dict[str, float]
    checkpoint_mean_m: dict[str, float]
    checkpoint_std_m: dict[str, float]
    gcp_residuals_enu_m: dict[str, tuple[float, float, float]]
    n_observations: int
    relative_control: bool
    variance_inflation: float = 1.0  # factor applied to Σ for time-correlated residuals (1 = none)
    #: (n,3) σ of each corrected camera centre, ENU m: the parameters' covariance propagated to it ⊕ the bundle
    #: adjustment's own camera-centre σ scaled by max(1, σ̂₀·√inflation): the accuracy the adjustment reached
    camera_sigma_enu_m: npt.NDArray[np.float64] | None = None
    excluded_gcps: tuple[ExcludedGcp, ...] = ()
    #: σ̂₀ > options.blunder_sigma0: the residuals show a blunder; no deliverable should be made from it
    blunder_suspected: bool = False

    def corrected_positions_enu_m(self, centre_rel: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Map relative-frame points (…,3) into ENU with the estimated similarity."""
        p = np.asarray(centre_rel, dtype=float)
        return self.translation_m + self.scale * p @ self.rotation.T

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary (lists, floats; a non-finite number — σ of an undeterminable parameter — is None)."""
        return {
            "lever_arm_m": [_num(x) for x in self.lever_arm_m],
            "lever_arm_sigma_m": [_num(x) for x in self.lever_arm_sigma_m],
            "delay_s": _num(self.delay_s),
            "delay_sigma_s": _num(self.delay_sigma_s),
            "scale": _num(self.scale),
            "scale_sigma": _num(self.scale_sigma),
            "rotation": [[_num(x) for x in row] for row in self.rotation],
            "rotation_sigma_rad": [_num(x) for x in self.rotation_sigma_rad],
            "translation_m": [_num(x) for x in self.translation_m],
            "translation_sigma_m": [_num(x) for x in self.translation_sigma_m],
            "sigma0": _num(self.sigma0),
            "correlations": {
                "names": list(self.parameter_names),
                "matrix": [[_num(x) for x in row] for row in self.correlations],
            },
            "condition_number": _num(self.condition_number),
            "weakest_combination": self.weakest_combination,
            "warnings": list(self.warnings),
            "outliers": [{"image": name, "chi2": _num(c2)} for name, c2 in self.outliers],
            "residuals": [
                {
                    "image": name,
                    "e_m": _num(r[0]),
                    "n_m": _num(r[1]),
                    "u_m": _num(r[2]),
                    "outlier": bool(o),
                }
                for name, r, o in zip(self.images, self.residuals_enu_m, self.outlier_mask, strict=True)
            ],
            "gcp_residuals": [
                {"name": name, "de_m": _num(d[0]), "dn_m": _num(d[1]), "du_m": _num(d[2])}
                for name, d in self.gcp_residuals_enu_m.items()
            ],
            "checkpoints": [
                {
                    "name": c.name,
                    "de_m": _num(c.de_m),
                    "dn_m": _num(c.dn_m),
                    "du_m": _num(c.du_m),
                    "abs_m": _num(c.abs_m),
                    "sigma_m": _num(c.sigma_m),
                    "sigma_enu_m": [_num(x) for x in c.sigma_enu_m],
                }
                for c in self.checkpoints
            ],
            "checkpoint_rms_m": {k: _num(v) for k, v in self.checkpoint_rms_m.items()},
            "checkpoint_mean_m": {k: _num(v) for k, v in self.checkpoint_mean_m.items()},
            "checkpoint_std_m": {k: _num(v) for k, v in self.checkpoint_std_m.items()},
            "n_images": len(self.images),
            "n_observations": int(self.n_observations),
            "variance_inflation": _num(self.variance_inflation),
            "relative_control": bool(self.relative_control),
            "excluded_gcps": [
                {"name": g.name, "de_m": _num(g.residual_enu_m[0]), "dn_m": _num(g.residual_enu_m[1]),
                 "du_m": _num(g.residual_enu_m[2]), "chi2": _num(g.chi2)}
                for g in self.excluded_gcps
            ],
            "blunder_suspected": bool(self.blunder_suspected),
        }
