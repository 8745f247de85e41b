"""Sign conventions, proved by synthetic round trips.

Ours (shared/docs/adjustment.md): O = antenna phase centre − optical centre in the camera frame (x right, y down,
z forward), antenna = C + R_cam→world·O (Daakir 2016 eq. 9, Rehak & Skaloud eq. 1); t_d = event → exposure,
so the antenna at exposure is G(t_event + t_d) ≈ G + V·t_d. Daakir 2016 eq. 1 and Daakir 2015 eqs. 3, 4, 6 write
S(C) = G + R·O, the opposite sign: converted at the boundary.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from ground.adjust.calibration import lever_arm_from_daakir_eq1, lever_arm_to_daakir_eq1
from ground.adjust.model import AdjustmentOptions, AdjustmentProblem, DelaySpec, LeverArmSpec
from ground.adjust.solve import adjust


def _synthetic(lever_m: np.ndarray, delay_s: float, daakir_sign: bool, seed: int = 0) -> AdjustmentProblem:
    """Exact observations built straight from the equations (no trajectory): a 10×10 grid of images at 50 m with
    headings alternating per line, varied speeds, tilts of a few degrees, and the relative frame = ENU/2."""
    rng = np.random.default_rng(seed)
    n_side = 10
    images, centres, rots, ants, vels = [], [], [], [], []
    for i in range(n_side):
        heading = 0.0 if i % 2 == 0 else np.pi
        speed = 4.0 + 0.2 * i
        for j in range(n_side):
            c = np.array([10.0 * i, 8.0 * j, 50.0 + rng.normal(0, 0.5)])
            d = np.array([np.sin(heading), np.cos(heading), 0.0])
            base = np.column_stack([np.cross(-d, [0, 0, -1.0]), -d, [0, 0, -1.0]])
            tilt = rng.normal(0, np.radians(3), 3)
            k = np.array([[0, -tilt[2], tilt[1]], [tilt[2], 0, -tilt[0]], [-tilt[1], tilt[0], 0]])
            r = base @ (np.eye(3) + k + k @ k / 2)
            u, _, vt = np.linalg.svd(r)
            r = u @ vt
            v = speed * d + np.array([0, 0, rng.normal(0, 0.5)])
            offset = r @ lever_m
            antenna_exposure = c - offset if daakir_sign else c + offset  # Daakir eq. 1: S(C) = G + R·O
            images.append(f"I{i}{j}")
            centres.append(c / 2.0)
            rots.append(r)
            ants.append(antenna_exposure - v * delay_s)  # G at the event, t_d before the exposure
            vels.append(v)
    return AdjustmentProblem.from_arrays(images, centres, rots, ants, vels, 0.002)


@pytest.mark.parametrize("lever", [(0.30, -0.20, -0.25), (-0.05, 0.12, 0.40)])
def test_lever_arm_and_delay_signs_round_trip(lever: tuple[float, float, float]) -> None:
    truth = np.array(lever)
    problem = _synthetic(truth, 0.064, daakir_sign=False)
    opts = AdjustmentOptions(lever_arm=LeverArmSpec(mode="prior", value_m=(0, 0, 0), sigma_m=(1.0, 1.0, 1.0)),
                             camera_centre_sigma_m=0.001)  # fmt: skip
    result = adjust(problem, opts)
    assert np.allclose(result.lever_arm_m, truth, atol=1e-3)
    assert result.delay_s == pytest.approx(0.064, abs=2e-4)  # positive: the exposure comes after the event
    assert result.scale == pytest.approx(2.0, rel=1e-5)
    assert np.allclose(result.rotation, np.eye(3), atol=1e-5)


def test_daakir_eq1_lever_arm_comes_back_with_the_opposite_sign() -> None:
    o_daakir = np.array([0.086, -0.052, -0.082])  # Daakir 2016 Table 1 magnitudes
    problem = _synthetic(o_daakir, 0.0, daakir_sign=True)
    opts = AdjustmentOptions(
        lever_arm=LeverArmSpec(mode="prior", value_m=(0, 0, 0), sigma_m=(1.0, 1.0, 1.0)),
        delay=DelaySpec(mode="fixed", value_s=0.0), camera_centre_sigma_m=0.001,
    )  # fmt: skip
    result = adjust(problem, opts)
    assert np.allclose(result.lever_arm_m, -o_daakir, atol=1e-3)
    assert np.allclose(lever_arm_from_daakir_eq1(o_daakir), result.lever_arm_m, atol=1e-3)
    assert np.allclose(lever_arm_to_daakir_eq1(result.lever_arm_m), o_daakir, atol=1e-3)
    # feeding Daakir's vector unconverted as a tight prior is visibly wrong: the residuals blow up
    wrong = adjust(problem, replace(opts, lever_arm=LeverArmSpec("fixed", tuple(o_daakir))))
    assert wrong.sigma0 > 20 * result.sigma0


def test_negative_delay_is_not_folded_into_a_positive_one() -> None:
    """A flash mark recorded 5 ms after the exposure gives t_d = −5 ms, not +5 ms."""
    problem = _synthetic(np.array([0.0, -0.1, -0.1]), -0.005, daakir_sign=False, seed=2)
    opts = AdjustmentOptions(lever_arm=LeverArmSpec("fixed", (0.0, -0.1, -0.1)), camera_centre_sigma_m=0.001)
    assert adjust(problem, opts).delay_s == pytest.approx(-0.005, abs=2e-4)


def test_simulated_flight_lever_arm_sign(block_factory: Any, problem_factory: Any, quiet: dict) -> None:
    """Through the whole chain (trajectory ECEF → Hermite → ENU, relative frame) a large lever arm keeps its sign."""
    block = block_factory(7, gcp_names=("P05",), lever_arm_m=(0.25, 0.15, -0.30), **quiet)
    result = adjust(problem_factory(block), AdjustmentOptions(lever_arm=LeverArmSpec("free"),
                                                              camera_centre_sigma_m=0.001))  # fmt: skip
    assert np.allclose(result.lever_arm_m, [0.25, 0.15, -0.30], atol=0.003)
