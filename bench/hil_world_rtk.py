"""Bench: is the simulated world RTK-able as the project requires (≥ 99 % fixed epochs, ≤ 2 cm RMS)?

Simulates the default survey flight (rover + base, full error model, 1 Hz or the given rate), then runs two
RTK engines on it and scores them against the World's truth antenna positions at the solution times:
- RTKLIB (through pyrtklib, bench/rtklib_driver.py: RINEX written with onboard.formats.rinex_write, real
  broadcast navigation file, kinematic, fix-and-hold, ratio 3, 15° mask);
- our engine (onboard.rtk.rtkpos, default options, known-point start at the take-off antenna).

Run: `.venv/bin/python bench/hil_world_rtk.py [--model m8t|lea6t] [--rate-hz 1] [--seed 1] [--baseline-m 1000]`.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from hil_sim.scenario import Scenario
from hil_sim.world import World
from onboard.formats.rinex_write import ObsHeaderInfo, write_obs
from onboard.gnsstime import GpsTime
from onboard.rtk.ephemeris import EphemerisStore
from onboard.rtk.geodesy import enu_rotation

sys.path.insert(0, str(Path(__file__).resolve().parent))


def simulate(world: World, rate_hz: float) -> tuple[list, list]:
    n = int(world.scenario.duration_s * rate_hz)
    rover = [world.observe("rover", world.start.add_s(k / rate_hz)) for k in range(n)]
    base = [world.observe("base", world.start.add_s(k / rate_hz)) for k in range(n)]
    return rover, base


def score(world: World, label: str, sols: list[tuple[GpsTime, np.ndarray, int]], n_epochs: int) -> None:
    r = enu_rotation(world.trajectory.lat_rad, world.trajectory.lon_rad)
    fixed = [(t, p) for t, p, q in sols if q == 1]
    err = np.array([r @ (p - world.truth(t)["antenna_ecef_m"]) for t, p in fixed]) if fixed else np.zeros((0, 3))
    flying = [(t, p) for t, p in fixed if world.truth(t)["armed"]]
    rms = np.sqrt(np.mean(np.sum(err**2, axis=1))) if len(err) else float("nan")
    rms_h = np.sqrt(np.mean(np.sum(err[:, :2] ** 2, axis=1))) if len(err) else float("nan")
    rms_v = np.sqrt(np.mean(err[:, 2] ** 2)) if len(err) else float("nan")
    first_fix = (fixed[0][0].diff_s(world.start) if fixed else float("nan"))
    print(f"{label:8s} fixed {len(fixed):5d}/{n_epochs} = {100 * len(fixed) / n_epochs:5.1f} %  "
          f"(in flight {len(flying)})  first fix at {first_fix:6.1f} s  "
          f"3-D RMS {100 * rms:5.2f} cm  (H {100 * rms_h:4.2f}, V {100 * rms_v:4.2f})  "
          f"max {100 * np.max(np.linalg.norm(err, axis=1)) if len(err) else float('nan'):5.2f} cm")


def run_rtklib(world: World, rover: list, base: list, tmp: Path) -> list[tuple[GpsTime, np.ndarray, int]]:
    import rtklib_driver

    for name, eps, pos in (("rover", rover, world.trajectory.origin_ecef_m), ("base", base, world.base_ecef_m)):
        with open(tmp / f"{name}.obs", "w") as fp:
            write_obs(fp, eps, info=ObsHeaderInfo(marker_name=name, approx_pos_ecef_m=tuple(pos)))
    out = tmp / "rtklib.pos"
    rb = ",".join(f"{v:.4f}" for v in world.base_ecef_m)
    rtklib_driver.main([str(tmp / "rover.obs"), str(tmp / "base.obs"), str(world.scenario.nav_path),
                        "--base-pos", rb, "-o", str(out)])
    sols = []
    for line in out.read_text().splitlines():
        if line.startswith("%") or not line.strip():
            continue
        f = line.split()
        sols.append((GpsTime.from_week_tow_s(int(f[0]), float(f[1])), np.array([float(v) for v in f[2:5]]),
                     int(f[5])))
    return sols


def run_ours(world: World, rover: list, base: list) -> list[tuple[GpsTime, np.ndarray, int]]:
    from onboard.rtk.options import RtkOptions
    from onboard.rtk.postpro import pair_epochs
    from onboard.rtk.rtkpos import Nav, rtk_init, rtk_pos

    nav = Nav(EphemerisStore(world.ephemerides()), world.iono_params())
    st = rtk_init(RtkOptions(), init_pos_ecef_m=world.trajectory.origin_ecef_m)
    out = []
    for rov, bas in zip(rover, pair_epochs(rover, base)):
        sol = rtk_pos(st, rov, bas, nav, world.base_ecef_m)
        out.append((sol.time, sol.pos_ecef_m, sol.q))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default="m8t")
    ap.add_argument("--rate-hz", type=float, default=1.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--baseline-m", type=float, default=None)
    args = ap.parse_args()
    overrides: dict[str, object] = {"seed": args.seed}
    if args.baseline_m is not None:
        overrides["base_offset_enu_m"] = Scenario.base_offset_for(args.baseline_m)
    world = World(Scenario.default(args.model, **overrides))
    t0 = time.perf_counter()
    rover, base = simulate(world, args.rate_hz)
    print(f"simulated {len(rover)} epoch pairs ({args.model}, baseline {world.scenario.baseline_m:.0f} m, "
          f"seed {args.seed}) in {time.perf_counter() - t0:.1f} s")
    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        sols = run_rtklib(world, rover, base, Path(d))
        print(f"RTKLIB ran in {time.perf_counter() - t0:.1f} s")
        score(world, "RTKLIB", sols, len(rover))
    t0 = time.perf_counter()
    sols = run_ours(world, rover, base)
    print(f"onboard.rtk ran in {time.perf_counter() - t0:.1f} s")
    score(world, "ours", sols, len(rover))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
