"""Synthetic round trips (truth → observations → estimates) for every parameter combination.

Each of similarity / lever arm / delay is free, fixed or given a prior; with and without GCPs; absolute and
relative control. The block is quiet (mm noise), so a wrong sign, frame or Jacobian shows as a cm-level error.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pytest

from ground.adjust.model import (
    AdjustmentOptions,
    AdjustmentRefused,
    DelaySpec,
    LeverArmSpec,
    SimilaritySpec,
)
from ground.adjust.similarity import so3_log
from ground.adjust.simulate import SimulatedBlock
from ground.adjust.solve import adjust

MODES = ("free", "fixed", "prior")


def _spec_options(
    block: SimulatedBlock, sim: str, lever: str, delay: str, relative: bool
) -> AdjustmentOptions:
    s = block.truth_similarity
    # priors sit slightly off the truth with a loose σ, so the data, not the prior, must bring the answer
    sim_spec = SimilaritySpec(
        mode=sim,  # type: ignore[arg-type]
        scale=s.scale * (1 + (2e-4 if sim == "prior" else 0.0)),
        rotation=tuple(tuple(r) for r in s.rotation),  # type: ignore[arg-type]
        translation_m=tuple(s.translation + (0.05 if sim == "prior" else 0.0)),  # type: ignore[arg-type]
        scale_sigma=1e-3,
        rotation_sigma_rad=1e-2,
        translation_sigma_m=1.0,
    )
    lev = block.truth_lever_arm_m + (0.01 if lever == "prior" else 0.0)
    lever_spec = LeverArmSpec(mode=lever, value_m=tuple(lev), sigma_m=(0.05, 0.05, 0.05))  # type: ignore[arg-type]
    delay_spec = DelaySpec(
        mode=delay,  # type: ignore[arg-type]
        value_s=block.truth_delay_s + (0.005 if delay == "prior" else 0.0),
        sigma_s=0.05,
    )
    return AdjustmentOptions(
        similarity=sim_spec, lever_arm=lever_spec, delay=delay_spec, relative_control=relative,
        camera_centre_sigma_m=0.001,
    )  # fmt: skip


CASES = list(itertools.product(MODES, MODES, MODES, (False, True)))


@pytest.mark.parametrize(("sim", "lever", "delay", "relative"), CASES)
def test_round_trip_every_combination_with_one_gcp(
    quiet_block: SimulatedBlock, problem_factory: Any, sim: str, lever: str, delay: str, relative: bool
) -> None:
    block = quiet_block
    result = adjust(problem_factory(block), _spec_options(block, sim, lever, delay, relative))
    truth = block.truth_similarity
    # lever arm and delay come back to the truth (fixed ones exactly, with σ 0)
    tol_lever = 0.004 if relative else 0.002
    assert np.allclose(result.lever_arm_m, block.truth_lever_arm_m, atol=tol_lever), result.lever_arm_m
    assert result.delay_s == pytest.approx(block.truth_delay_s, abs=0.001)
    if lever == "fixed":
        assert np.all(result.lever_arm_sigma_m == 0.0)
        assert np.array_equal(result.lever_arm_m, block.truth_lever_arm_m)
    else:
        assert np.all(result.lever_arm_sigma_m > 0)
    if delay == "fixed":
        assert result.delay_sigma_s == 0.0
    # similarity: scale, rotation, translation back to the truth
    assert result.scale == pytest.approx(truth.scale, rel=2e-4)
    assert np.degrees(np.linalg.norm(so3_log(result.rotation @ truth.rotation.T))) < 0.01
    assert np.allclose(result.translation_m, truth.translation, atol=0.01 * max(1.0, truth.scale))
    # the mapping itself (what matters): check points within a few mm
    assert result.checkpoint_rms_m["3d"] < 0.006
    names = set(result.parameter_names)
    assert ("O_x" in names) == (lever != "fixed")
    assert ("t_d" in names) == (delay != "fixed")
    assert ("scale" in names) == (sim != "fixed")


@pytest.mark.parametrize(("sim", "lever", "delay"), list(itertools.product(MODES, ("fixed", "prior"), MODES)))
def test_round_trip_without_gcp(
    block_factory: Any, problem_factory: Any, quiet: dict[str, object], sim: str, lever: str, delay: str
) -> None:
    block = block_factory(4, **quiet)  # no GCP at all
    problem = problem_factory(block)
    assert not problem.gcps and problem.checks
    result = adjust(problem, _spec_options(block, sim, lever, delay, False))
    assert np.allclose(result.lever_arm_m, block.truth_lever_arm_m, atol=0.003)
    assert result.delay_s == pytest.approx(block.truth_delay_s, abs=0.001)
    assert result.checkpoint_rms_m["3d"] < 0.006


def test_free_lever_arm_without_gcp_is_refused(block_factory: Any, problem_factory: Any, quiet: dict) -> None:
    block = block_factory(4, **quiet)
    with pytest.raises(AdjustmentRefused, match="no GCP and no prior"):
        adjust(problem_factory(block), AdjustmentOptions(lever_arm=LeverArmSpec(mode="free")))


def test_relative_control_without_gcp_is_refused(
    block_factory: Any, problem_factory: Any, quiet: dict
) -> None:
    block = block_factory(4, **quiet)
    opts = AdjustmentOptions(
        lever_arm=LeverArmSpec(mode="fixed", value_m=tuple(block.truth_lever_arm_m)), relative_control=True
    )
    with pytest.raises(AdjustmentRefused, match="needs ≥ 1 GCP"):
        adjust(problem_factory(block), opts)


@pytest.mark.slow
def test_relative_control_cancels_a_gnss_bias(block_factory: Any, problem_factory: Any, quiet: dict) -> None:
    """A 25 cm constant GNSS offset (wrong fix / datum) ruins absolute control but not differenced control."""
    bias = (0.25, -0.15, 0.2)
    block = block_factory(5, gnss_bias_m=bias, gcp_names=("P00", "P10"), **quiet)
    problem = problem_factory(block)
    lever = LeverArmSpec(mode="prior", value_m=tuple(block.truth_lever_arm_m), sigma_m=(0.005,) * 3)
    # GNSS outweighs two GCPs: the bias would go to the ground; the leave-one-out test sees both GCPs
    # contradict the images and refuses rather than deliver a block 30 cm off
    with pytest.raises(AdjustmentRefused, match="2 of 2 GCPs contradict the others"):
        adjust(problem, AdjustmentOptions(lever_arm=lever, camera_centre_sigma_m=0.001))
    absolute = adjust(problem, AdjustmentOptions(lever_arm=lever, camera_centre_sigma_m=0.001,
                                                 gcp_blunder_test=False))
    relative = adjust(
        problem, AdjustmentOptions(lever_arm=lever, relative_control=True, camera_centre_sigma_m=0.001)
    )
    assert absolute.checkpoint_rms_m["3d"] > 0.15  # without the test: the bias goes to the ground
    assert relative.checkpoint_rms_m["3d"] < 0.01
    assert relative.delay_s == pytest.approx(block.truth_delay_s, abs=0.001)
    assert relative.relative_control and relative.to_dict()["relative_control"] is True


@pytest.mark.slow
def test_relative_control_cancels_a_bias_that_jumps_between_lines(
    block_factory: Any, problem_factory: Any, quiet: dict
) -> None:
    """Float RTK re-converging after each turn: a different 10–30 cm offset per line. Differences never span a
    turn (dt > max_pair_dt_s), so each line's offset cancels; absolute control spreads them into the result."""
    from dataclasses import replace

    block = block_factory(6, gcp_names=("P00", "P08"), **quiet)
    problem = problem_factory(block)
    order = np.argsort(problem.event_time_s)
    seg = np.zeros(len(order), dtype=int)
    seg[order[1:]] = np.cumsum(np.diff(problem.event_time_s[order]) > 5.0)
    rng = np.random.default_rng(0)
    offsets = rng.uniform(0.1, 0.3, (seg.max() + 1, 3)) * rng.choice([-1, 1], (seg.max() + 1, 3))
    biased = replace(problem, antenna_enu_m=problem.antenna_enu_m + offsets[seg])
    lever = LeverArmSpec(mode="prior", value_m=tuple(block.truth_lever_arm_m), sigma_m=(0.005,) * 3)
    opts = AdjustmentOptions(lever_arm=lever, camera_centre_sigma_m=0.001, max_pair_dt_s=8.0)
    absolute = adjust(biased, opts)
    relative = adjust(biased, replace(opts, relative_control=True))
    # absolute control sees inconsistent lines: residuals far above their σ, said in a warning
    assert absolute.sigma0 > 10 and any(w.startswith("σ̂₀ = ") for w in absolute.warnings)
    assert absolute.checkpoint_rms_m["3d"] > 0.05
    assert len(relative.outliers) <= 0.01 * len(problem.images)  # the χ²₃ 99.9 % test keeps good images
    assert relative.checkpoint_rms_m["3d"] < 0.01
    assert relative.delay_s == pytest.approx(block.truth_delay_s, abs=0.002)
