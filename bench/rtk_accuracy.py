"""RTK accuracy on the real datasets (and hil_sim flights), next to RTKLIB's figures for the same settings.

Per dataset: epochs, fix ratio, time to first fix, fixed-epoch horizontal/vertical RMS vs the reference,
wrong fixes (Q=1 more than 10 cm off in 3D), µs per epoch (CPU time of the filter runs, reading excluded;
`whole` includes reading the files). GPS L1 only, 15° mask, fix-and-hold, as the RTKLIB rows in
../shared/data/gnss/README.md.

Then (forward only, unless --no-sim) the hil_sim scenario matrix of bench/rtk_sim.py (LEA-6T and M8T).

Run: `.venv/bin/python bench/rtk_accuracy.py [--direction forward|combined] [--only NAME ...] [--no-sim]`
"""

from __future__ import annotations

import argparse
import csv
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from onboard.formats.rinex_obs import read_rinex_obs
from onboard.gnsstime import GpsTime
from onboard.postpro.inputs import read_navigation
from onboard.rtk.geodesy import ecef_to_enu
from onboard.rtk.options import RtkOptions
from onboard.rtk.postpro import postprocess
from onboard.rtk.rtkpos import Nav
from onboard.rtk.types import Q_FIX, ObsEpoch

GNSS = Path(__file__).resolve().parents[2] / "shared" / "data" / "gnss"
M8P = GNSS / "ublox-m8p-galway-2018"
GEO = GNSS / "geonet-0759-3040-20050402"
SEPT = GNSS / "geonet-3034-sept-20210922"


@dataclass
class Case:
    name: str
    rtklib: str
    load: Callable[[], tuple[list[ObsEpoch], list[ObsEpoch], Nav, np.ndarray, Callable[[GpsTime], np.ndarray | None],
                             np.ndarray | None]]
    options: RtkOptions = field(default_factory=RtkOptions)


def _nav(*paths: Path) -> Nav:
    return read_navigation(paths)


def _static(ref: np.ndarray) -> Callable[[GpsTime], np.ndarray]:
    return lambda t: ref


def _m8p(base_file: Path, ref: np.ndarray):
    def load():
        r = read_rinex_obs(M8P / "rinex/rover-20181004-1237.obs.gz")
        b = read_rinex_obs(base_file)
        return r.epochs, b.epochs, _nav(M8P / "rinex/rover-20181004-1237.nav.gz"), \
            b.header.antenna_position_ecef_m(), _static(ref), None
    return load


def _geonet():
    r = read_rinex_obs(GEO / "07590920.05o.gz")
    b = read_rinex_obs(GEO / "30400920.05o.gz")
    ref = np.array([-3976219.1873, 3382371.6051, 3652511.1423])
    return r.epochs, b.epochs, _nav(GEO / "07590920.05n.gz"), np.array([-3978241.958, 3382840.234, 3649900.853]), \
        _static(ref), None


def _sept():
    r = read_rinex_obs(SEPT / "SEPT265G.21O.gz")
    b = read_rinex_obs(SEPT / "3034265G.21O.gz")
    with open(SEPT / "SEPT265G.ref_l1l2_GEJ_fixed.csv") as f:
        rows = {round(float(x["tow"]) * 1000): np.array([float(x["x"]), float(x["y"]), float(x["z"])])
                for x in csv.DictReader(f)}
    return r.epochs, b.epochs, _nav(SEPT / "SEPT2650.21P.gz"), np.array([-3959400.631, 3385704.533, 3667523.111]), \
        (lambda t: rows.get(round(t.tow_s * 1000))), None


CASES = [
    Case("m8p-static (M8P base, 0.33 m)", "2.4.3 75.3 % / demo5 89.3 %, 1st fix 128 s, 1.2-1.6 cm h",
         _m8p(M8P / "rinex/base-20181004-1236.rtcm.obs.gz", np.array([3774088.9931, -601661.8217, 5089321.3853]))),
    Case("m8p-static (GLW1 CORS, 197 m)", "98 %, 1st fix 17-26 s, 7 mm h",
         _m8p(M8P / "cors-glw1/glw1277m.18o.gz", np.array([3774088.6821, -601663.0350, 5089318.2304]))),
    Case("geonet 0759/3040 (3.3 km, 30 s)", "2.4.3 99 % / demo5 95 %, 6 mm h, 1.1 cm v", _geonet),
    Case("geonet 3034/Sept moving (5.3 km)", "2.4.3 31 % / demo5 0 %, 3.7 cm h", _sept),
]


def evaluate(case: Case, direction: str) -> dict[str, object]:
    t_whole = time.process_time()
    rov, bas, nav, base_pos, truth, init = case.load()
    t_run = time.process_time()
    opts = case.options if init is None else replace(case.options, static_start=True)
    sols, _ = postprocess(rov, bas, nav, base_pos, opts, direction, init)
    t_end = time.process_time()
    passes = 2 if direction == "combined" else 1
    q = np.array([s.q for s in sols])
    tow = np.array([s.time.total_ns for s in sols]) / 1e9
    enu = []
    refs = []
    for s in sols:
        ref = truth(s.time)
        refs.append(ref if ref is not None else np.full(3, np.nan))
        enu.append(ecef_to_enu(s.pos_ecef_m, ref) if ref is not None else np.full(3, np.nan))
    enu = np.array(enu)
    refs = np.array(refs)
    origin = refs[np.argmax(np.all(np.isfinite(refs), axis=1))]
    up_m = ecef_to_enu(refs, origin)[:, 2]
    airborne = up_m > 1.0  # more than 1 m above the first (take-off) position
    fixed = q == Q_FIX
    has_ref = np.all(np.isfinite(enu), axis=1)
    e = enu[fixed & has_ref]
    first = float(tow[np.argmax(fixed)] - tow[0]) if fixed.any() else float("nan")
    return {
        "epochs": len(sols),
        "fix %": 100.0 * fixed.mean() if len(sols) else 0.0,
        "first fix s": first,
        "h RMS cm": 100 * float(np.sqrt(np.mean(e[:, 0] ** 2 + e[:, 1] ** 2))) if len(e) else float("nan"),
        "v RMS cm": 100 * float(np.sqrt(np.mean(e[:, 2] ** 2))) if len(e) else float("nan"),
        "wrong": int(np.sum(np.linalg.norm(e, axis=1) > 0.10)),
        "ref epochs": int(np.sum(fixed & has_ref)),
        "air fix %": 100.0 * float(np.mean(fixed[airborne])) if airborne.any() else float("nan"),
        "3D RMS cm": 100 * float(np.sqrt(np.mean(np.sum(e**2, axis=1)))) if len(e) else float("nan"),
        "us/epoch": 1e6 * (t_end - t_run) / max(len(sols) * passes, 1),
        "whole us/epoch": 1e6 * (t_end - t_whole) / max(len(sols), 1),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--direction", default="forward", choices=("forward", "backward", "combined"))
    ap.add_argument("--only", nargs="*", help="substrings of case names to run")
    ap.add_argument("--no-sim", action="store_true")
    args = ap.parse_args()
    if not GNSS.is_dir():
        raise SystemExit(f"{GNSS} not found: the real datasets are needed")
    print(f"directgeo onboard.rtk, GPS L1, 15 deg mask, fix-and-hold, {args.direction}")
    hdr = f"{'dataset':36s} {'epochs':>6s} {'fix %':>6s} {'1st fix':>7s} {'h RMS':>6s} {'v RMS':>6s} " \
          f"{'wrong':>5s} {'air %':>6s} {'us/ep':>6s} {'whole':>6s}  RTKLIB (README)"
    print(hdr)
    print("-" * len(hdr))
    for case in CASES:
        if args.only and not any(s in case.name for s in args.only):
            continue
        r = evaluate(case, args.direction)
        print(f"{case.name:36s} {r['epochs']:6d} {r['fix %']:6.1f} {r['first fix s']:6.0f}s {r['h RMS cm']:5.1f}c "
              f"{r['v RMS cm']:5.1f}c {r['wrong']:5d} {r['air fix %']:6.1f} {r['us/epoch']:6.0f} {r['whole us/epoch']:6.0f}  {case.rtklib}",
              flush=True)
    if not args.no_sim and args.direction == "forward":
        # the hil_sim scenario matrix (bench/rtk_sim.py): LEA-6T and M8T through the real byte paths
        import sys

        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from rtk_sim import CASES as SIM_CASES
        from rtk_sim import run_matrix

        only = [s for s in args.only or [] if any(s in c.name for c in SIM_CASES)]
        if not args.only or only:
            print()
            run_matrix(only or None)


if __name__ == "__main__":
    main()
