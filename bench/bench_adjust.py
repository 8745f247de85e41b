"""Benchmark: final adjustment time for 100 / 1 000 / 10 000 images, next to the plain Umeyama closed form.

Each size is a simulated block (ground.adjust.simulate: lines at 4–5 m/s, turns, wobble, climb/descent photos,
RTK-like noise) with one GCP, lever arm free, delay free. The peer is the plain closed-form similarity (Umeyama,
camera centres → antenna positions, no lever arm, no delay) on the same data in the same process. The adjustment
must scale linearly: its time per image should stay flat while the image count grows 100×.

    .venv/bin/python bench/bench_adjust.py [--repeat 3]

On a shared or loaded machine, multithreaded OpenBLAS spins on the tall-thin products of the solver and the
10 000-image time jumps by up to 10×; `OPENBLAS_NUM_THREADS=1` gives stable figures (best of --repeat runs).
"""

from __future__ import annotations

import argparse
import logging
import time
from collections.abc import Callable
from functools import partial

import numpy as np

from ground.adjust.model import AdjustmentOptions, AdjustmentProblem, LeverArmSpec
from ground.adjust.similarity import umeyama
from ground.adjust.simulate import BlockOptions, SimulatedBlock, simulate_block
from ground.adjust.solve import adjust, build_problem

PHOTOS_PER_LINE = 42  # 150 m at ~4.5 m/s, one photo every 0.8 s


def _block_for(n_images: int, seed: int) -> tuple[SimulatedBlock, AdjustmentProblem]:
    n_lines = max(2, round(n_images / PHOTOS_PER_LINE))
    opts = BlockOptions(
        n_lines=n_lines,
        photos_in_climb_descent=n_images >= 200,
        gcp_names=("P04",),
        n_ground_points=9,
    )
    block = simulate_block(opts, np.random.default_rng(seed))
    return block, build_problem(
        block.poses, block.events, block.trajectory, block.control, block.origin_ecef_m
    )


def _best_of(fn: Callable[[], object], repeat: int) -> float:
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per size; the best is kept")
    args = parser.parse_args()
    logging.basicConfig(level=logging.ERROR)
    options = AdjustmentOptions(lever_arm=LeverArmSpec(mode="free"), camera_centre_sigma_m=0.0058)
    print(f"{'images':>7} {'adjust_s':>9} {'umeyama_s':>10} {'ratio':>7} {'adjust_us/img':>14} "
          f"{'sigma0':>7} {'|dO|_mm':>8} {'dt_ms':>7} {'check3d_mm':>10}")  # fmt: skip
    per_image: list[float] = []
    times: list[float] = []
    counts: list[int] = []
    peer: list[float] = []
    for target in (100, 1_000, 10_000):
        block, problem = _block_for(target, seed=target)
        n = len(problem.images)
        result = adjust(problem, options)
        t_adj = _best_of(partial(adjust, problem, options), args.repeat)
        t_ume = _best_of(partial(umeyama, problem.centre_rel, problem.antenna_enu_m), args.repeat)
        per_image.append(t_adj / n * 1e6)
        times.append(t_adj)
        counts.append(n)
        peer.append(t_ume)
        d_lever = np.linalg.norm(result.lever_arm_m - block.truth_lever_arm_m) * 1e3
        d_t = (result.delay_s - block.truth_delay_s) * 1e3
        print(f"{n:>7} {t_adj:>9.3f} {t_ume:>10.5f} {t_adj / t_ume:>7.0f} {per_image[-1]:>14.1f} "
              f"{result.sigma0:>7.2f} {d_lever:>8.2f} {d_t:>7.3f} {result.checkpoint_rms_m['3d'] * 1e3:>10.1f}")  # fmt: skip
    print(
        f"10 000 vs 1 000 images: time ×{times[2] / times[1]:.1f} for ×{counts[2] / counts[1]:.1f} images "
        f"(Umeyama peer ×{peer[2] / peer[1]:.1f}); time per image 10 000 vs 100: ×{per_image[2] / per_image[0]:.2f}"
    )


if __name__ == "__main__":
    main()
