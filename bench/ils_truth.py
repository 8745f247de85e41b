"""Could any ratio test fix the M8P walk right? The true integers against our float, epoch by epoch.

`python bench/ils_truth.py [--systems G GR] [--ar-mode continuous]` runs our forward filter on the M8P walk under
trees (bench_rtk's dataset, 15° mask) and, at every epoch where the M8P's own RTK is fixed, takes the full
candidate set of double-difference ambiguities the engine hands to LAMBDA (first try of the epoch: no satellite
dropped). The true integers are the float ones moved by the geometry between our float position and the M8P's:
N = a + (e_ref − e_k)·(x_float − x_M8P)/λ_k, kept where that lands within 0.2 cycles of an integer (the M8P's
fix, a few cm, is then unambiguous). It prints how often the true set is the integer least-squares best and the
ratio second-best/best when it is and when a wrong set is: a ratio threshold can fix right only where the first
exceeds it and the second does not.

The probe wraps the engine's per-epoch LAMBDA step (onboard.rtk.rtkpos._resamb_lambda) to read the state it
is handed, and changes nothing in it. Needs ../shared (the walk is not redistributable).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_rtk import DATASETS, M8P

TRUTH_FRACTION_CYC = 0.2
"""Largest distance of a true float integer from its rounding for the epoch to be judged (cycles)."""


def probe(systems: str, ar_mode: str) -> np.ndarray:
    """Rows (tow, n DD, true set is best, best distance, second distance, true distance) at the M8P's fixes."""
    from onboard.postpro.inputs import load_rtk_inputs
    from onboard.rtk import rtkpos
    from onboard.rtk.mlambda import LambdaError, mlambda
    from onboard.rtk.options import RtkOptions
    from onboard.rtk.postpro import postprocess

    ds = next(d for d in DATASETS if "walk" in d.name)
    assert ds.base_pos is not None
    run = load_rtk_inputs(ds.rover, ds.base, ds.navs, [float(v) for v in ds.base_pos.split(",")], systems=systems)
    m8p = np.loadtxt(M8P / "ref/rover-20181004-1532.m8p_rtk_fixed.csv", delimiter=",", skiprows=1, ndmin=2)
    fixed_tow = set(np.round(m8p[:, 0]).astype(int).tolist())
    engine_step = rtkpos._resamb_lambda
    rows: list[tuple[float, ...]] = []

    def look(st: Any, ctx: Any, cand: np.ndarray) -> Any:
        tow = ctx.time.tow_s
        idx = cand.nonzero()[0]
        if round(tow) in fixed_tow and idx.size >= 4:
            others, refs = rtkpos._dd_pairs(st, idx, ctx.el)
            x, p = st.x, st.p
            if st.layout.gps_only:
                a, qa, _, _ = rtkpos._dd_ambiguities(x, p, idx, int(refs[0]))
            else:
                a, qa, _, _ = rtkpos._dd_ambiguities_multi(x, p, others, refs, st.ns)
            los = ctx.rov.sats.pos_m - x[:3]
            los /= np.linalg.norm(los, axis=1)[:, None]
            true_float = a + (los[refs] - los[others]) @ (x[:3] - ds.ref(np.array([tow]))[0]) / ctx.rov.lam[others]
            true = np.round(true_float)
            if np.abs(true_float - true).max() < TRUTH_FRACTION_CYC:
                try:
                    res = mlambda(a, qa)
                except LambdaError:
                    res = None
                if res is not None:
                    d = a - true
                    rows.append((tow, others.size, float(np.array_equal(true, res.fixed[:, 0])), res.sq_dist[0],
                                 res.sq_dist[1], float(d @ np.linalg.solve(qa, d))))
        return engine_step(st, ctx, cand)

    rtkpos._resamb_lambda = look
    try:
        postprocess(run.rover, run.base, run.nav, run.base_pos_ecef_m,
                    replace(RtkOptions(), systems=systems, elmask_deg=15.0, ar_mode=ar_mode), "forward")
    finally:
        rtkpos._resamb_lambda = engine_step
    return np.array(rows, float).reshape(-1, 6)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--systems", nargs="*", default=["G", "GR"], help="system sets (default: G GR)")
    ap.add_argument("--ar-mode", default="continuous",
                    help="the engine's ar_mode (default continuous: a held float would trivially sit on its integers)")
    args = ap.parse_args()
    if not M8P.is_dir():
        print(f"needs {M8P} (../shared beside the project): not redistributable, nothing measured")
        return 2
    print(f"{'systems':8s} {'epochs':>6s} {'DD p50':>6s} {'true best':>10s} {'ratio true p10/50/90':>22s} "
          f"{'true>=3':>7s} {'true>=2':>7s} {'ratio wrong p10/50/90':>22s} {'wrong>=3':>8s} {'wrong>=2':>8s}")
    for systems in args.systems:
        r = probe(systems, args.ar_mode)
        best = r[:, 2] == 1.0
        ratio = r[:, 4] / np.maximum(r[:, 3], 1e-300)

        def pct(v: np.ndarray) -> str:
            return "/".join(f"{x:.2f}" if x < 1e3 else ">1e3" for x in np.percentile(v, [10, 50, 90])) if v.size \
                else "-"

        print(f"{systems:8s} {len(r):6d} {np.median(r[:, 1]) if len(r) else 0:6.0f} "
              f"{best.sum():4d} ({100 * best.mean() if len(r) else 0:4.1f}%) {pct(ratio[best]):>22s} "
              f"{(ratio[best] >= 3).sum():7d} {(ratio[best] >= 2).sum():7d} {pct(ratio[~best]):>22s} "
              f"{(ratio[~best] >= 3).sum():8d} {(ratio[~best] >= 2).sum():8d}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
