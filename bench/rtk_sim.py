"""RTK on hil_sim flights: the issue-3 scenario matrix, through the real byte paths, against the World's truth.

Per scenario and model (LEA-6T RXM-RAW, M8T RXM-RAWX, both receivers): rover UBX bytes → our decoder; base UBX
→ decoder → `BaseCore` RTCM3 1004 + 1006 + 1019 → radio with dropouts → `collect_rtcm`; our engine forward with
default options (GPS L1, 15° mask, fix-and-hold, max age 30 s). The pipeline is `hil_sim.rtk_scenarios`.

Printed: airborne epochs (motors armed, base data ≤ 30 s old), airborne fix %, fixed-epoch 3D RMS and max,
wrong fixes (Q=1 more than 10 cm from the true antenna in 3D, over all epochs, stale ones included), first fix
(s after the first epoch), epochs excluded because their newest base data are older than 30 s ("stale"),
slips the engine detected, engine CPU µs per epoch. Flights: the standard survey flight, 600 s (take-off at
60 s, climb to 84 s, 6 lines, landing), 1 Hz rover and base. The whole matrix: about 3 min of CPU.

Run: `.venv/bin/python bench/rtk_sim.py [--only SUBSTR ...] [--model lea6t|m8t] [--seed N | --seeds 1-16]
[--systems GREJ --world gr-2012|gej-2021]` (the LEA-6T tracks GPS only in any world)
(`--seeds`: one summary line per scenario over the seeds: min/median/mean airborne fix %, wrong fixes)
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from dataclasses import replace
from typing import Any

import numpy as np

from hil_sim.rtk_scenarios import HARSH_RADIO_LOSS, SimCase, evaluate

GAPS_S = ((130.0, 135.0), (200.0, 210.0), (290.0, 310.0), (400.0, 420.0))
"""5, 10, 20 and 20 s dropouts, all while the drone flies its lines and turns (climb ends at 84 s)."""

CASES = [
    SimCase("nominal", ">= 99 % airborne, <= 2 cm 3D, 0 wrong"),
    SimCase("radio gaps 5/10/20/20 s", ">= 99 % airborne, <= 2 cm 3D, 0 wrong", gaps_s=GAPS_S),
    SimCase("radio gap 45 s", "float/single past 30 s, 0 wrong, fix after", gaps_s=((200.0, 245.0),)),
    SimCase("5 km baseline", ">= 99 % airborne, <= 2 cm 3D, 0 wrong", baseline_m=5000.0),
    SimCase("undetected slips 2/h/sat", ">= 95 % airborne, 0 wrong", undetected_slips_per_h=2.0),
    SimCase("5 satellites", "as the data support, 0 wrong", max_sats=5),
    SimCase("5 satellites, known take-off", "0 wrong", max_sats=5, known_start=True),
    SimCase("known take-off point", "fix at the first epoch, 0 wrong", known_start=True),
    SimCase("harsh: trees + real base loss", "as the data support, 0 wrong", harsh=True, radio_loss=HARSH_RADIO_LOSS),
]


HEADER = (f"{'scenario':30s} {'model':6s} {'air ep':>6s} {'air %':>6s} {'3D RMS':>7s} {'max':>6s} {'wrong':>5s} "
          f"{'1st fix':>7s} {'stale':>5s} {'slips':>5s} {'us/ep':>6s}  target")


def row(case: SimCase, model: str, r: dict[str, Any]) -> str:
    """One printed line of the matrix."""
    return (f"{case.name:30s} {model:6s} {r['airborne']:6d} {r['air fix %']:6.1f} {r['3D RMS cm']:5.2f}cm "
            f"{r['max cm']:4.1f}cm {r['wrong']:5d} {r['first fix s']:6.0f}s {r['stale']:5d} {r['slips']:5d} "
            f"{r['us/epoch']:6.0f}  {case.target}")


def _runs(only: list[str] | None, models: tuple[str, ...]) -> Iterator[tuple[SimCase, str]]:
    """(scenario, model) pairs to run: scenarios whose name contains one of `only`, or all."""
    for case in CASES:
        if not only or any(s in case.name for s in only):
            yield from ((case, model) for model in models)


def _sky(hour: float | None) -> str:
    return "" if hour is None else f", start {hour:g}:00 GPST"


def run_matrix(only: list[str] | None = None, models: tuple[str, ...] = ("lea6t", "m8t"), seed: int = 1,
               start_hour: float | None = None, systems: str = "G", world: str = "gr-2012",
               direction: str = "forward") -> None:
    """Print the matrix (scenarios whose name contains one of `only`, or all); `systems` other than "G" runs
    it in the multi-constellation `world` with the engine's RtkOptions(systems=...)."""
    sky = "GPS L1" if systems == "G" else f"systems {systems}, world {world}"
    print(f"hil_sim flights (seed {seed}{_sky(start_hour)}), directgeo onboard.rtk {direction}, {sky}, 15 deg mask, "
          "fix-and-hold, max age 30 s")
    print(HEADER)
    print("-" * len(HEADER))
    for case, model in _runs(only, models):
        c = replace(case, seed=seed, start_hour=start_hour, systems=systems, world=world)
        print(row(c, model, evaluate(c, model, direction=direction)), flush=True)


def run_seeds(seeds: list[int], only: list[str] | None = None, models: tuple[str, ...] = ("lea6t", "m8t"),
              start_hour: float | None = None, systems: str = "G", world: str = "gr-2012",
              direction: str = "forward") -> None:
    """Print, per scenario and model, the airborne fix % over several World seeds (min, median, mean), the
    wrong fixes summed over the seeds (naming the seeds that had any) and the median first fix: one line each,
    so that a change is judged on more than one draw of the errors."""
    sky = "GPS L1" if systems == "G" else f"systems {systems}, world {world}"
    print(f"hil_sim flights, seeds {seeds[0]}-{seeds[-1]} ({len(seeds)}){_sky(start_hour)}, directgeo onboard.rtk "
          f"{direction}, {sky}, 15 deg mask, fix-and-hold, max age 30 s")
    head = (f"{'scenario':30s} {'model':6s} {'air % min':>9s} {'median':>7s} {'mean':>6s} {'wrong':>6s}  "
            "seeds with wrong fixes / first fix s (median) (the seed of the min)")
    print(head)
    print("-" * len(head))
    for case, model in _runs(only, models):
        runs = {seed: evaluate(replace(case, seed=seed, start_hour=start_hour, systems=systems, world=world), model,
                               direction=direction) for seed in seeds}
        air = np.array([r["air fix %"] for r in runs.values()], float)
        wrong = {seed: r["wrong"] for seed, r in runs.items() if r["wrong"]}
        firsts = np.array([r["first fix s"] for r in runs.values()], float)
        first = float(np.median(firsts[np.isfinite(firsts)])) if np.isfinite(firsts).any() else float("nan")
        bad = ", ".join(f"s{k}: {v}" for k, v in wrong.items()) or "none"
        worst = seeds[int(np.nanargmin(air))] if np.isfinite(air).any() else seeds[0]
        print(f"{case.name:30s} {model:6s} {np.nanmin(air):9.1f} {np.nanmedian(air):7.1f} {np.nanmean(air):6.1f} "
              f"{sum(wrong.values()):6d}  {bad} / {first:.0f} (lowest: s{worst})", flush=True)


def _seed_range(text: str) -> list[int]:
    """"1-16" or "3" or "1,4,9" → the seeds."""
    out: list[int] = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b or a) + 1))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", help="substrings of scenario names to run")
    ap.add_argument("--model", choices=("lea6t", "m8t"), action="append", help="default: both")
    ap.add_argument("--seed", type=int, default=1, help="World seed (errors, slips; default 1)")
    ap.add_argument("--seeds", type=_seed_range, help="several seeds, e.g. 1-16: one summary line per scenario")
    ap.add_argument("--start-hour", type=float, help="start at this hour (GPST) of 2010-07-01 for another sky "
                    "(default 13: the matrix's targets are set there)")
    ap.add_argument("--systems", default="G", help="constellations, e.g. GREJ (default G: the GPS world)")
    ap.add_argument("--world", default="gr-2012", help="multi-constellation world (hil_sim.scenario.MULTI_WORLDS): "
                    "gr-2012 (GPS+GLONASS) or gej-2021 (GPS+Galileo+QZSS)")
    ap.add_argument("--direction", choices=("forward", "combined"), default="forward",
                    help="forward (default): the drone's real-time solution, the matrix's targets; combined: the "
                    "forward and backward passes combined, the ground's RTK job's default deliverable")
    args = ap.parse_args()
    models = tuple(args.model or ("lea6t", "m8t"))
    if args.seeds:
        run_seeds(args.seeds, args.only, models, args.start_hour, args.systems, args.world, args.direction)
    else:
        run_matrix(args.only, models, args.seed, args.start_hour, args.systems, args.world, args.direction)


if __name__ == "__main__":
    main()
