"""Lever-arm ground calibration (pseudo-materialization, Daakir 2016 eqs. 6–9) and its CSV input."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from ground.adjust.calibration import (
    CalibrationError,
    CalibrationInput,
    CalibrationOptions,
    calibrate_lever_arm,
    compare_calibrations,
)
from ground.adjust.model import AdjustmentOptions, LeverArmSpec
from ground.adjust.similarity import Similarity, so3_exp
from ground.adjust.solve import adjust
from ground.io.calibration_csv import read_calibration_csv
from ground.io.errors import FormatError

CAM_TARGETS = {  # targets glued on the camera body, camera frame (x right, y down, z forward), m
    "C1": [0.045, -0.030, -0.010], "C2": [-0.045, -0.030, -0.010], "C3": [0.045, 0.030, -0.020],
    "C4": [-0.045, 0.032, -0.020], "C5": [0.0, -0.035, 0.030], "C6": [0.020, 0.036, 0.025],
}  # fmt: skip
BOX_TARGETS = {  # targets on the receiver box, box frame, m
    "B1": [0.04, 0.03, 0.0], "B2": [-0.04, 0.03, 0.0], "B3": [0.04, -0.03, 0.0], "B4": [-0.04, -0.03, 0.01],
    "B5": [0.0, 0.0, 0.025],
}  # fmt: skip
PHASE_CENTRE_BOX = np.array([0.002, -0.001, 0.041])


def _acquisition(
    lever_truth: np.ndarray,
    box_rot: np.ndarray,
    noise_m: float,
    seed: int,
    box_shift_m: np.ndarray | None = None,
) -> tuple[CalibrationInput, Similarity]:
    """Targets as one photogrammetric acquisition of the drone would give them (arbitrary frame and scale)."""
    rng = np.random.default_rng(seed)
    # box pose in the camera frame such that the phase centre lands exactly on the lever arm
    box_t = lever_truth - box_rot @ PHASE_CENTRE_BOX + (0 if box_shift_m is None else box_shift_m)
    box_in_cam = {k: box_rot @ np.array(v) + box_t for k, v in BOX_TARGETS.items()}
    cam_to_acq = Similarity(3.7, so3_exp(rng.normal(0, 1, 3)), rng.uniform(-10, 10, 3))
    noise = lambda: rng.normal(0, noise_m, 3)
    return (
        CalibrationInput(
            camera_frame={k: np.array(v) + noise() for k, v in CAM_TARGETS.items()},
            camera_acq={k: cam_to_acq.apply(np.array(v) + noise()) for k, v in CAM_TARGETS.items()},
            box_acq={k: cam_to_acq.apply(v + noise()) for k, v in box_in_cam.items()},
            box_frame={k: np.array(v) + noise() for k, v in BOX_TARGETS.items()},
            phase_centre_box_m=PHASE_CENTRE_BOX + noise(),
        ),
        cam_to_acq,
    )


LEVER = np.array([0.086, -0.152, -0.082])
BOX_ROT = so3_exp([0.1, -0.05, 2.0])


def test_noise_free_calibration_returns_antenna_minus_optical_centre() -> None:
    inp, truth = _acquisition(LEVER, BOX_ROT, 0.0, 0)
    cal = calibrate_lever_arm(inp, CalibrationOptions(n_monte_carlo=50))
    assert np.allclose(cal.lever_arm_m, LEVER, atol=1e-9)
    assert cal.camera_fit.scale == pytest.approx(1 / truth.scale)
    assert np.allclose(cal.box_fit.rotation, BOX_ROT, atol=1e-9)
    assert all(np.linalg.norm(r) < 1e-9 for r in cal.camera_residuals_m.values())


@pytest.mark.slow
def test_noisy_calibration_errors_within_three_sigma_over_seeds() -> None:
    z = []
    for seed in range(8):
        inp, _ = _acquisition(LEVER, BOX_ROT, 0.0007, seed)
        cal = calibrate_lever_arm(
            inp, CalibrationOptions(n_monte_carlo=400, seed=seed, phase_centre_sigma_m=0.0007)
        )
        err = cal.lever_arm_m - LEVER
        assert np.all(np.abs(err) <= 3 * cal.sigma_m), (err, cal.sigma_m)
        assert np.all(cal.sigma_m < 0.005)
        z.append(err / cal.sigma_m)
        assert set(cal.camera_residuals_m) == set(CAM_TARGETS) and set(cal.box_residuals_m) == set(
            BOX_TARGETS
        )
    # σ is neither wildly optimistic nor pessimistic: the normalised errors have an RMS of order 1
    assert 0.3 < float(np.sqrt(np.mean(np.square(z)))) < 2.0


def test_a_bad_target_shows_in_its_residual() -> None:
    inp, _ = _acquisition(LEVER, BOX_ROT, 0.0003, 1)
    inp.camera_acq["C3"] = inp.camera_acq["C3"] + np.array(
        [0.02, 0.0, 0.0]
    )  # a mis-measured target (acq units)
    cal = calibrate_lever_arm(inp, CalibrationOptions(n_monte_carlo=50))
    worst = max(cal.camera_residuals_m, key=lambda k: np.linalg.norm(cal.camera_residuals_m[k]))
    assert worst == "C3"


def test_before_after_comparison_detects_a_moved_box() -> None:
    before, _ = _acquisition(LEVER, BOX_ROT, 0.0005, 2)
    after_same, _ = _acquisition(LEVER, BOX_ROT, 0.0005, 3)
    after_moved, _ = _acquisition(LEVER, BOX_ROT, 0.0005, 4, box_shift_m=np.array([0.0, 0.012, 0.0]))
    opts = CalibrationOptions(n_monte_carlo=300, phase_centre_sigma_m=0.0005)
    a = calibrate_lever_arm(before, opts)
    same = compare_calibrations(a, calibrate_lever_arm(after_same, opts))
    moved = compare_calibrations(a, calibrate_lever_arm(after_moved, opts))
    assert same.stable and same.abs_m < 0.004
    assert not moved.stable and moved.difference_m[1] == pytest.approx(0.012, abs=0.004)
    assert set(moved.to_dict()) == {"difference_m", "abs_m", "sigma_m", "box_rotation_change_deg", "stable"}


def test_too_few_common_targets_is_a_clear_error() -> None:
    inp, _ = _acquisition(LEVER, BOX_ROT, 0.0, 0)
    sparse = CalibrationInput(inp.camera_frame, {k: inp.camera_acq[k] for k in ("C1", "C2")}, inp.box_acq,
                              inp.box_frame, inp.phase_centre_box_m)  # fmt: skip
    with pytest.raises(CalibrationError, match="2 common target"):
        calibrate_lever_arm(sparse)


def test_calibrated_lever_arm_feeds_the_adjustment(block_factory: Any, problem_factory: Any) -> None:
    """Ground calibration → prior of the in-flight adjustment: same sign, same vector (one convention end to end)."""
    lever = np.array([0.04, -0.11, -0.09])
    inp, _ = _acquisition(lever, BOX_ROT, 0.0005, 5)
    cal = calibrate_lever_arm(inp, CalibrationOptions(n_monte_carlo=300))
    block = block_factory(22, gcp_names=("P05",), lever_arm_m=tuple(lever))
    spec = LeverArmSpec("prior", tuple(cal.lever_arm_m), tuple(np.maximum(cal.sigma_m, 0.002)))
    result = adjust(problem_factory(block), AdjustmentOptions(lever_arm=spec, camera_centre_sigma_m=0.0058))
    assert np.allclose(result.lever_arm_m, lever, atol=0.006)
    assert result.checkpoint_rms_m["3d"] < 0.02


def _write_csv(path: Path, inp: CalibrationInput) -> None:
    lines = ["# lever-arm calibration, metres", "target,group,x,y,z"]
    for group in ("camera_frame", "camera_acq", "box_frame", "box_acq"):
        for name, xyz in getattr(inp, group).items():
            lines.append(f"{name},{group},{xyz[0]:.6f},{xyz[1]:.6f},{xyz[2]:.6f}")
    pc = inp.phase_centre_box_m
    lines.append(f"phase_centre,box_frame,{pc[0]:.6f},{pc[1]:.6f},{pc[2]:.6f}")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def test_csv_round_trip(tmp_path: Path) -> None:
    inp, _ = _acquisition(LEVER, BOX_ROT, 0.0, 0)
    path = tmp_path / "before.csv"
    _write_csv(path, inp)
    back = read_calibration_csv(path)
    assert set(back.camera_frame) == set(CAM_TARGETS) and set(back.box_acq) == set(BOX_TARGETS)
    cal = calibrate_lever_arm(back, CalibrationOptions(n_monte_carlo=50))
    assert np.allclose(cal.lever_arm_m, LEVER, atol=2e-6)  # 1 µm rounding in the file


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda s: s.replace("target,group,x,y,z", "name,kind,x,y,z"), ":2: first row must be the header"),
        (lambda s: s.replace("C1,camera_acq", "C1,camera_aq"), "unknown group 'camera_aq'"),
        (lambda s: s.replace("C2,camera_frame,", "C2,camera_frame,abc"), "coordinates must be numbers"),
        (lambda s: s.replace("B1,box_acq", "B2,box_acq"), "'B2' appears twice in group box_acq"),
        (
            lambda s: "\n".join(ln for ln in s.splitlines() if not ln.startswith("phase_centre")),
            "no phase_centre",
        ),
        (
            lambda s: s.replace("phase_centre,box_frame", "phase_centre,camera_frame"),
            "must be given in the box frame",
        ),
        (lambda s: s + "B9,box_frame,1,2\n", "expected 5 fields"),
        (lambda s: s + "B9,box_frame,1,2,nan\n", "finite"),
        (
            lambda s: "\n".join(
                ln for ln in s.splitlines() if ",box_frame," not in ln or ln.startswith("phase")
            ),
            "no target in group box_frame",
        ),
        (lambda s: "# only a comment\n", "empty file"),
    ],
)
def test_csv_errors_name_file_and_line(tmp_path: Path, edit: Any, message: str) -> None:
    inp, _ = _acquisition(LEVER, BOX_ROT, 0.0, 0)
    path = tmp_path / "cal.csv"
    _write_csv(path, inp)
    path.write_text(edit(path.read_text(encoding="utf-8")), encoding="utf-8")
    with pytest.raises(FormatError, match=message) as info:
        read_calibration_csv(path)
    assert str(path) in str(info.value)


def test_csv_not_utf8(tmp_path: Path) -> None:
    path = tmp_path / "cal.csv"
    path.write_bytes(b"target,group,x,y,z\n\xff\xfe,camera_frame,1,2,3\n")
    with pytest.raises(FormatError, match="not UTF-8"):
        read_calibration_csv(path)
