"""Fixtures of the adjustment tests: simulated blocks (seeded) and their problems."""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
import pytest

from ground.adjust.model import AdjustmentProblem
from ground.adjust.simulate import BlockOptions, SimulatedBlock, simulate_block
from ground.adjust.solve import build_problem

# a quiet block: noise far below the tolerances, so a round trip isolates the model and the signs
QUIET = {
    "gnss_white_sigma_m": (0.001, 0.001, 0.001),
    "gnss_correlated_sigma_m": (0.0, 0.0, 0.0),
    "velocity_sigma_m_s": 0.001,
    "camera_centre_noise_m": 0.001,
    "camera_angle_noise_deg": 0.001,
    "ground_sigma_m": 0.001,
    "rel_point_noise_m": 0.001,
    "n_lines": 6,
    "line_length_m": 100.0,
    "photo_interval_s": 1.0,
}


@pytest.fixture(autouse=True)
def _quiet_adjust_logs(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.ERROR, logger="ground.adjust.solve")


def make_block(seed: int = 0, **overrides: object) -> SimulatedBlock:
    """A simulated block with BlockOptions overrides."""
    return simulate_block(BlockOptions(**overrides), np.random.default_rng(seed))  # type: ignore[arg-type]


def problem_of(block: SimulatedBlock, with_gcps: bool = True) -> AdjustmentProblem:
    """The adjustment problem of a block (all control points, or check points only)."""
    control = block.control if with_gcps else tuple(c for c in block.control if c.role == "check")
    return build_problem(block.poses, block.events, block.trajectory, control, block.origin_ecef_m)


@pytest.fixture
def block_factory() -> Callable[..., SimulatedBlock]:
    return make_block


@pytest.fixture
def problem_factory() -> Callable[..., AdjustmentProblem]:
    return problem_of


@pytest.fixture(scope="module")
def quiet_block() -> SimulatedBlock:
    """Quiet block, one GCP (P05), trigger events with a 64 ms delay."""
    return make_block(3, gcp_names=("P05",), **QUIET)


@pytest.fixture
def quiet() -> dict[str, object]:
    """BlockOptions overrides for a quiet block."""
    return dict(QUIET)
