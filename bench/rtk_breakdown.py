"""Where the CPU time of `python -m onboard rtk` goes, beside the RTKLIB 2.4.3 driver, per bench_rtk dataset.

`python bench/rtk_breakdown.py [--only SUBSTRING ...]` prints, in CPU seconds:

    startup   a child interpreter doing `onboard rtk --help` after importing the RINEX readers and the .pos
              writer (resource RUSAGE_CHILDREN); for the driver, an interpreter importing pyrtklib
    read      reading the rover and base observations and the navigation file (this process)
    engine    the forward filter (onboard.rtk.postpro.postprocess, this process) and its µs per epoch
    write     writing the .pos file (this process)
    sum       startup + read + engine + write: compare with the whole-command figures of bench_rtk.py
    driver    the whole driver process (bench/rtklib_driver.py: interpreter, RINEX reading, rtkpos())

Every figure is the minimum of `--repeat` runs (default 3): the machine is shared, the minimum is the least
disturbed. Same datasets and options as bench_rtk.py.
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_rtk import DATASETS, PROJECT, PY, compile_project, engine_commands

# `onboard rtk --help` after importing the readers/writer a RINEX run loads: the command line's own start-up
STARTUP_OURS = ("import sys, onboard.formats.rinex_obs, onboard.formats.rinex_nav, onboard.formats.pos\n"
                "from onboard.__main__ import main\nsys.argv = ['onboard', 'rtk', '--help']\nmain()")
STARTUP_DRIVER = "import argparse, gzip, importlib, shutil, tempfile, pathlib, pyrtklib"


def child_cpu_s(cmd: list[str]) -> float:
    """CPU seconds (user + system) of one child process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, cwd=PROJECT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def in_process(ds, out: Path) -> tuple[float, float, float, int]:  # type: ignore[no-untyped-def]
    """(read s, engine s, write s, epochs) of ours on one dataset, CPU time of this process."""
    from onboard.formats.pos import write_pos
    from onboard.postpro.inputs import read_navigation, read_observations
    from onboard.rtk.options import RtkOptions
    from onboard.rtk.postpro import postprocess

    t0 = time.process_time()
    rover, base = read_observations(ds.rover), read_observations(ds.base)
    nav = read_navigation([str(n) for n in ds.navs])
    t1 = time.process_time()
    bp = np.array([float(v) for v in ds.base_pos.split(",")]) if ds.base_pos else base.antenna_pos_ecef_m
    rov = [e for e in rover.epochs if len(e.gps_only())]
    bas = [e for e in base.epochs if len(e.gps_only())]
    opts = replace(RtkOptions(), elmask_deg=15.0)
    t2 = time.process_time()
    sols, _ = postprocess(rov, bas, nav, bp, opts, "forward")
    t3 = time.process_time()
    write_pos(out, sols, ["breakdown"])
    t4 = time.process_time()
    return t1 - t0, t3 - t2, t4 - t3, len(sols)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", help="substrings of dataset names")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    chosen = [d for d in DATASETS if not args.only or any(s in d.name for s in args.only)]
    compile_project()
    start_ours = min(child_cpu_s([PY, "-c", STARTUP_OURS]) for _ in range(args.repeat))
    start_drv = min(child_cpu_s([PY, "-c", STARTUP_DRIVER]) for _ in range(args.repeat))
    print(f"startup CPU: ours {start_ours:.3f} s, driver {start_drv:.3f} s (interpreter + imports)")
    print(f"{'dataset':40s} {'read':>6s} {'engine':>7s} {'us/ep':>6s} {'write':>6s} {'sum':>6s} {'driver':>7s} "
          f"{'ratio':>6s}")
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        for ds in chosen:
            runs = [in_process(ds, tmp / "ours.pos") for _ in range(args.repeat)]
            read, engine, write = (min(r[k] for r in runs) for k in range(3))
            n = runs[0][3]
            drv_cmd = engine_commands(ds, tmp, demo5_driver=False)["2.4.3-driver"]
            drv = min(child_cpu_s(drv_cmd) for _ in range(args.repeat))
            total = start_ours + read + engine + write
            print(f"{ds.name:40s} {read:6.3f} {engine:7.3f} {1e6 * engine / max(n, 1):6.0f} {write:6.3f} "
                  f"{total:6.3f} {drv:7.3f} {total / drv:6.2f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
