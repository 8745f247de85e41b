"""RTK benchmark: `python -m onboard rtk` beside RTKLIB 2.4.3 (pyrtklib) and demo5 (pyrtklib5), same inputs.

Per dataset (../shared/data/gnss) and engine, each run as its own process on the same RINEX files with the same
options (GPS, L1, kinematic, fix-and-hold, ratio 3, 15° mask, broadcast iono, Saastamoinen):

    rtklib-2.4.3  RTKLIB postpos() through pyrtklib       (what rnx2rtkp does: reproduces the README rows)
    demo5         RTKLIB demo5 postpos() through pyrtklib5
    2.4.3-driver  bench/rtklib_driver.py: a Python process calling RTKLIB rtkpos() epoch by epoch (the speed peer)
    ours          python -m onboard rtk (forward)

Printed: output epochs, fix ratio, time to first fix, fixed-epoch horizontal/vertical RMS against the
reference, fixed epochs more than 10 cm (3D) off, whole-process CPU µs per epoch (resource RUSAGE_CHILDREN),
the README's RTKLIB figure, and ours/RTKLIB ratios (fix %, CPU). Then the engine alone (our filter in this
process, reading excluded) in ms per epoch against the Pi budget of 200 ms/epoch at 5 Hz.

    demo5-driver  the same driver on demo5 (not with --quick)

Run: `.venv/bin/python bench/bench_rtk.py [--quick] [--only SUBSTRING ...]` (about 1.5 min; `--quick`: GEONET
0759/3040 and the M8P static README pairing, about 15 s).

Reproduction of the README's RTKLIB rows with these options (measured 2026-11-23): GEONET 0759/3040 2.4.3
99.1 % (README 99 %), demo5 95.8 % (95 %); GLW1 base 98.3 % / 97.8 % (98 % / 98 %); GEONET 3034/Sept 2.4.3
30.6 %, 3.7 cm h (31 %, 3.7 cm), demo5 0 % (0 %). M8P static: the README row is the base's RXM-RAWX RINEX with
the RTCM 1005 position (its header holds only an approximate one): 2.4.3 74.3 %, first fix 285 s, 1.6 cm h,
2.4 cm v; demo5 89.1 %, 130 s, 1.1 cm h (README 75.3 %, 277 s / 89.3 %, 128 s, 1.2-1.6 cm h, 2.3 cm v). With the
lossy RTCM base instead: 79.6 % / 88.5 %. M8P walk (RAWX base, 1005 position): demo5 17.7 % (README 16 %),
2.4.3 1.6 % (README 18 %: not reproduced). The lead's epoch-by-epoch driver pairs each rover epoch with the
nearest base epoch and differs from postpos on the lossy RTCM base (9.7 % vs 79.6 %); elsewhere it matches.
"""

from __future__ import annotations

import argparse
import csv
import importlib
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

PROJECT = Path(__file__).resolve().parents[1]
GNSS = PROJECT.parent / "shared" / "data" / "gnss"
M8P = GNSS / "ublox-m8p-galway-2018"
GEO = GNSS / "geonet-0759-3040-20050402"
SEPT = GNSS / "geonet-3034-sept-20210922"
PY = sys.executable
WRONG_M = 0.10
PI_BUDGET_MS = 200.0


def _static(xyz: tuple[float, float, float]) -> Callable[[np.ndarray], np.ndarray]:
    ref = np.array(xyz)
    return lambda tow: np.tile(ref, (len(tow), 1))


def _csv_ref(path: Path, tol_s: float = 0.06) -> Callable[[np.ndarray], np.ndarray]:
    """Reference positions by time of week from a `tow,x,y,z,...` csv (NaN where none within `tol_s`)."""
    with open(path) as f:
        rows = sorted((float(r["tow"]), float(r["x"]), float(r["y"]), float(r["z"])) for r in csv.DictReader(f))
    arr = np.array(rows)

    def ref(tow: np.ndarray) -> np.ndarray:
        i = np.clip(np.searchsorted(arr[:, 0], tow), 1, len(arr) - 1)
        j = np.where(np.abs(arr[i - 1, 0] - tow) < np.abs(arr[i, 0] - tow), i - 1, i)
        out = arr[j, 1:].copy()
        out[np.abs(arr[j, 0] - tow) > tol_s] = np.nan
        return out

    return ref


@dataclass
class Dataset:
    name: str
    rover: Path
    base: Path
    navs: list[Path]
    base_pos: str | None
    ref: Callable[[np.ndarray], np.ndarray]
    readme: str
    quick: bool = False
    rtcm_stream: Path | None = None


DATASETS = [
    Dataset("geonet 0759/3040 static 3.3 km 30 s", GEO / "07590920.05o.gz", GEO / "30400920.05o.gz",
            [GEO / "07590920.05n.gz"], "-3978241.958,3382840.234,3649900.853",
            _static((-3976219.1873, 3382371.6051, 3652511.1423)), "2.4.3 99 % | demo5 95 % | 6 mm h, 1.1 cm v",
            quick=True),
    Dataset("m8p static, M8P base RAWX (0.33 m)", M8P / "rinex/rover-20181004-1237.obs.gz",
            M8P / "rinex/base-20181004-1236.rawx.obs.gz", [M8P / "rinex/rover-20181004-1237.nav.gz"],
            "3774089.2120,-601661.6157,5089321.2474", _static((3774088.9931, -601661.8217, 5089321.3853)),
            "2.4.3 75.3 % 1st 277 s | demo5 89.3 % 1st 128 s | 1.2-1.6 cm h, 2.3 cm v", quick=True),
    Dataset("m8p static, M8P base lossy RTCM", M8P / "rinex/rover-20181004-1237.obs.gz",
            M8P / "rinex/base-20181004-1236.rtcm.obs.gz", [M8P / "rinex/rover-20181004-1237.nav.gz"], None,
            _static((3774088.9931, -601661.8217, 5089321.3853)), "(the README row above uses the RAWX base)",
            rtcm_stream=M8P / "rtcm3/base-20181004-1236.rtcm3.gz"),
    Dataset("m8p static, GLW1 CORS base (197 m)", M8P / "rinex/rover-20181004-1237.obs.gz",
            M8P / "cors-glw1/glw1277m.18o.gz", [M8P / "rinex/rover-20181004-1237.nav.gz"], None,
            _static((3774088.6821, -601663.0350, 5089318.2304)), "2.4.3 98 % | demo5 98 % 1st 17-26 s | 7 mm h"),
    Dataset("geonet 3034/Septentrio moving 5.3 km", SEPT / "SEPT265G.21O.gz", SEPT / "3034265G.21O.gz",
            [SEPT / "SEPT2650.21P.gz"], "-3959400.631,3385704.533,3667523.111",
            _csv_ref(SEPT / "SEPT265G.ref_l1l2_GEJ_fixed.csv", 0.01), "2.4.3 31 % | demo5 0 % | 3.7 cm h"),
    Dataset("m8p walk under trees (vs M8P's RTK)", M8P / "rinex/rover-20181004-1532.obs.gz",
            M8P / "rinex/base-20181004-1452.rawx.obs.gz", [M8P / "rinex/rover-20181004-1532.nav.gz"],
            "3774085.6456,-601662.5769,5089316.3970",
            _csv_ref(M8P / "ref/rover-20181004-1532.m8p_rtk_fixed.csv"), "2.4.3 18 % | demo5 16 % | no truth"),
]


# --- RTKLIB postpos() in a child process ----------------------------------------------------------------


def postpos_main(argv: list[str]) -> int:
    """Child mode: `--postpos LIB OUT [--base-pos X,Y,Z] FILES...` runs RTKLIB postpos() on RINEX files."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from rtklib_driver import _plain, configure

    ap = argparse.ArgumentParser()
    ap.add_argument("--postpos", nargs=2, metavar=("LIB", "OUT"))
    ap.add_argument("--base-pos")
    ap.add_argument("files", nargs="+")
    args = ap.parse_args(argv)
    lib, out = args.postpos
    mod = importlib.import_module(lib)
    with tempfile.TemporaryDirectory() as tmpdir:
        files = [_plain(f, Path(tmpdir)) for f in args.files]
        popt = configure(mod)
        if args.base_pos:
            # the ECEF form of "reference position given" differs: 2.4.3 POSOPT_POS, demo5 POSOPT_POS_XYZ
            popt.refpos = getattr(mod, "POSOPT_POS_XYZ", getattr(mod, "POSOPT_POS", 0))
            for i, v in enumerate(args.base_pos.split(",")):
                popt.rb[i] = float(v)
        else:
            popt.refpos = mod.POSOPT_RINEX
        sopt = mod.solopt_default
        sopt.posf = mod.SOLF_XYZ
        sopt.timef = 0
        t0 = mod.gtime_t()
        outarg = mod.Arr1Dchar(out) if lib == "pyrtklib" else out  # the two bindings differ here
        return int(mod.postpos(t0, t0, 0.0, 0.0, popt, sopt, mod.filopt_t(), files, len(files), outarg, "", ""))


# --- running and scoring --------------------------------------------------------------------------------


def read_solutions(path: Path) -> np.ndarray:
    """Rows (week, tow, x, y, z, q) of any of the three .pos flavours (week/tow time, ECEF)."""
    rows = []
    if not path.exists():
        return np.zeros((0, 6))
    for line in path.read_text().splitlines():
        if not line.strip() or line.startswith("%"):
            continue
        t = line.split()
        rows.append((float(t[0]), float(t[1]), float(t[2]), float(t[3]), float(t[4]), float(t[5])))
    return np.array(rows).reshape(-1, 6)


def run_child(cmd: list[str]) -> tuple[float, float, int]:
    """Run one engine process; returns (child CPU s, wall s, exit code)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.monotonic()
    env = dict(os.environ, PYTHONPATH=str(PROJECT))
    proc = subprocess.run(cmd, cwd=PROJECT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                          check=False)
    wall = time.monotonic() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if proc.returncode != 0:
        print(f"    ! {' '.join(cmd[:4])} ... exit {proc.returncode}: {proc.stderr.strip()[-300:]}", file=sys.stderr)
    return cpu, wall, proc.returncode


def engine_commands(ds: Dataset, out: Path, demo5_driver: bool = True) -> dict[str, list[str]]:
    files = [str(ds.rover), str(ds.base), *map(str, ds.navs)]
    bp = [f"--base-pos={ds.base_pos}"] if ds.base_pos else []
    me = str(Path(__file__).resolve())
    cmds = {
        "rtklib-2.4.3": [PY, me, "--postpos", "pyrtklib", str(out / "243.pos"), *bp, *files],
        "demo5": [PY, me, "--postpos", "pyrtklib5", str(out / "demo5.pos"), *bp, *files],
        "2.4.3-driver": [PY, "bench/rtklib_driver.py", "--lib", "pyrtklib", *files, *bp, "-o",
                         str(out / "drv243.pos")],
    }
    if demo5_driver:
        cmds["demo5-driver"] = [PY, "bench/rtklib_driver.py", "--lib", "pyrtklib5", *files, *bp, "-o",
                                str(out / "drvdemo5.pos")]
    nav_args = [a for n in ds.navs for a in ("--nav", str(n))]
    cmds["ours"] = [PY, "-m", "onboard", "rtk", "--rover", str(ds.rover), "--base", str(ds.base), *nav_args, *bp,
                    "--no-progress", "-o", str(out / "ours.pos")]
    return cmds


def _out_file(cmd: list[str]) -> Path:
    return Path(cmd[cmd.index("-o") + 1]) if "-o" in cmd else Path(cmd[4])


def score(sol: np.ndarray, ref: Callable[[np.ndarray], np.ndarray]) -> dict[str, float]:
    from onboard.rtk.geodesy import ecef_to_enu

    n = len(sol)
    if n == 0:
        return {"epochs": 0, "fix": float("nan"), "ttff": float("nan"), "h": float("nan"), "v": float("nan"),
                "wrong": 0, "fixed": 0}
    q = sol[:, 5]
    fixed = q == 1
    tow = sol[:, 1] + (sol[:, 0] - sol[0, 0]) * 604800.0
    refs = ref(sol[:, 1])
    has = np.all(np.isfinite(refs), axis=1)
    sel = fixed & has
    enu = np.array([ecef_to_enu(p, r) for p, r in zip(sol[sel, 2:5], refs[sel])]).reshape(-1, 3)
    return {
        "epochs": n,
        "fixed": int(fixed.sum()),
        "fix": 100.0 * float(fixed.mean()),
        "ttff": float(tow[np.argmax(fixed)] - tow[0]) if fixed.any() else float("nan"),
        "h": 100 * float(np.sqrt(np.mean(enu[:, 0] ** 2 + enu[:, 1] ** 2))) if len(enu) else float("nan"),
        "v": 100 * float(np.sqrt(np.mean(enu[:, 2] ** 2))) if len(enu) else float("nan"),
        "wrong": int(np.sum(np.linalg.norm(enu, axis=1) > WRONG_M)),
    }


def rtcm_stream_run(ds: Dataset) -> dict[str, float]:
    """Ours with the base read from the raw RTCM3 stream (the path `onboard rtk` gets with the rtk_inputs hook)."""
    from dataclasses import replace

    from onboard.postpro.inputs import read_base_observations, read_navigation, read_observations
    from onboard.rtk.options import RtkOptions
    from onboard.rtk.postpro import postprocess

    assert ds.rtcm_stream is not None
    rover = read_observations(ds.rover)
    base = read_base_observations(ds.rtcm_stream, rover.epochs[0].time)
    nav = read_navigation([str(n) for n in ds.navs])
    rov = [e for e in rover.epochs if len(e.gps_only())]
    sols, _ = postprocess(rov, base.epochs, nav, base.antenna_pos_ecef_m, replace(RtkOptions(), elmask_deg=15.0),
                          "forward")
    rows = np.array([(s.time.week, s.time.tow_s, *s.pos_ecef_m, s.q) for s in sols]).reshape(-1, 6)
    return score(rows, ds.ref)


def engine_alone_ms(ds: Dataset) -> tuple[float, int]:
    """Our filter's CPU ms per epoch in this process (inputs read first, not timed)."""
    from dataclasses import replace

    from onboard.postpro.inputs import read_navigation, read_observations
    from onboard.rtk.options import RtkOptions
    from onboard.rtk.postpro import postprocess

    rover, base = read_observations(ds.rover), read_observations(ds.base)
    nav = read_navigation([str(n) for n in ds.navs])
    bp = np.array([float(v) for v in ds.base_pos.split(",")]) if ds.base_pos else base.antenna_pos_ecef_m
    rov = [e for e in rover.epochs if len(e.gps_only())]
    t = time.process_time()
    sols, _ = postprocess(rov, base.epochs, nav, bp, replace(RtkOptions(), elmask_deg=15.0), "forward")
    return 1e3 * (time.process_time() - t) / max(len(sols), 1), len(sols)


def compile_project() -> None:
    """Byte-compile the project's packages before timing whole commands: a wheel installed by pip (the Pi)
    ships compiled modules, as pyrtklib's are; an editable checkout under PYTHONDONTWRITEBYTECODE=1 (this
    workplace sets it) would otherwise recompile ours at every start (20-25 ms of CPU per run)."""
    subprocess.run([PY, "-m", "compileall", "-q", "onboard", "hil_sim"], cwd=PROJECT, check=False,
                   stdout=subprocess.DEVNULL)


def main() -> int:
    if "--postpos" in sys.argv:
        return postpos_main(sys.argv[1:])
    compile_project()
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="two small datasets only")
    ap.add_argument("--only", nargs="*", help="substrings of dataset names")
    args = ap.parse_args()
    if not GNSS.is_dir():
        print(f"{GNSS} not found: the benchmark needs the real datasets", file=sys.stderr)
        return 2
    chosen = [d for d in DATASETS if (not args.quick or d.quick) and (not args.only or any(s in d.name for s in args.only))]
    print("GPS L1, kinematic, fix-and-hold, ratio 3, 15 deg mask; CPU = whole process (RUSAGE_CHILDREN)")
    hdr = (f"{'engine':13s} {'epochs':>6s} {'fixed':>6s} {'fix %':>6s} {'/rover':>6s} {'1st fix':>8s} {'h RMS':>7s} {'v RMS':>7s} "
           f"{'>10cm':>5s} {'CPU s':>6s} {'us/ep':>7s}")
    engine_ms: list[tuple[str, float, int]] = []
    for ds in chosen:
        print(f"\n== {ds.name}\n   README (RTKLIB rnx2rtkp): {ds.readme}\n{hdr}")
        with tempfile.TemporaryDirectory() as tmpdir:
            results: dict[str, tuple[dict[str, float], float]] = {}
            for name, cmd in engine_commands(ds, Path(tmpdir), not args.quick).items():
                cpu, _wall, rc = run_child(cmd)
                sol = read_solutions(_out_file(cmd)) if rc == 0 else np.zeros((0, 6))
                results[name] = (score(sol, ds.ref), cpu)
            # RTKLIB writes no line for rover epochs it could not solve; ours writes every rover epoch. The
            # second fix column counts fixes over all rover epochs (ours' count), the same denominator for all.
            n_rover = max(r["epochs"] for r, _ in results.values())
            for name, (r, cpu) in results.items():
                us = 1e6 * cpu / max(r["epochs"], 1)
                print(f"{name:13s} {r['epochs']:6d} {r['fixed']:6d} {r['fix']:6.1f} {100 * r['fixed'] / n_rover:6.1f} "
                      f"{r['ttff']:7.0f}s {r['h']:6.1f}c {r['v']:6.1f}c {r['wrong']:5d} {cpu:6.2f} {us:7.0f}",
                      flush=True)
            ours, cpu_ours = results["ours"]
            parts = []
            for peer in ("rtklib-2.4.3", "demo5", "2.4.3-driver"):
                r, cpu = results[peer]
                fix_ratio = ours["fix"] / r["fix"] if r["fix"] else float("nan")
                parts.append(f"{peer}: fix x{fix_ratio:.2f}, CPU x{cpu_ours / cpu:.2f}")
            print("   ours/RTKLIB  " + "; ".join(parts))
            if ds.rtcm_stream is not None:
                r = rtcm_stream_run(ds)
                print(f"   ours on the raw RTCM3 stream ({ds.rtcm_stream.name}, decoded by onboard.postpro.inputs, "
                      f"in process): {r['epochs']} epochs, fix {r['fix']:.1f} %, 1st fix {r['ttff']:.0f} s, "
                      f"h {r['h']:.1f} cm, v {r['v']:.1f} cm, >10 cm {r['wrong']}")
        ms, n = engine_alone_ms(ds)
        engine_ms.append((ds.name, ms, n))
    print("\nengine alone (onboard.rtk forward filter, this process, reading excluded):")
    for name, ms, n in engine_ms:
        print(f"  {name:40s} {ms:7.2f} ms/epoch over {n} epochs  (Pi budget {PI_BUDGET_MS:.0f} ms at 5 Hz; "
              f"x86 figure, a Pi 4 is roughly 3-5x slower)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
