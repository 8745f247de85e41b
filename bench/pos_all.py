"""Every `.pos` the post-processing command writes on the real bench sets, into one folder, for before/after checks.

`python bench/pos_all.py OUTDIR [--jobs 2]` runs `python -m onboard rtk` (as a user would) on the six datasets of
`bench/bench_rtk.py` forward, plus backward and combined on the M8P walk and the lossy RTCM base, and the M8P base's
raw RTCM3 stream as `--base` (GPS only: eleven runs), then the same directions with each set's wider
constellation sets (`Dataset.systems`: GPS+GLONASS on the three M8P sets, GPS+Galileo+QZSS on GEONET 3034:
eight runs), one `<name>.pos` each. Compare two folders with
`python bench/compare_pos.py BEFORE AFTER` (a refactoring must leave every file byte-identical: `cmp`).
Needs `../shared/data`.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_rtk import DATASETS, M8P, PROJECT, Dataset


def _dataset_args(ds: Dataset) -> list[str]:
    """`onboard rtk` input arguments of a bench_rtk dataset."""
    args = ["--rover", str(ds.rover), "--base", str(ds.base)]
    for nav in ds.navs:
        args += ["--nav", str(nav)]
    if ds.base_pos:
        args.append(f"--base-pos={ds.base_pos}")
    return args


def _directions(name: str, args: list[str], both_ways: bool) -> list[tuple[str, list[str]]]:
    """The forward run, and backward and combined when `both_ways`."""
    out = [(f"{name}-forward", args)]
    if both_ways:
        out += [(f"{name}-backward", [*args, "--direction", "backward"]),
                (f"{name}-combined", [*args, "--direction", "combined"])]
    return out


def runs() -> list[tuple[str, list[str]]]:
    """(name, onboard rtk arguments without -o) for the nineteen runs (the GPS-only eleven first)."""
    out: list[tuple[str, list[str]]] = []
    for i, ds in enumerate(DATASETS):
        out += _directions(f"set{i}", _dataset_args(ds), "walk" in ds.name or "lossy" in ds.name)
    rover = M8P / "rinex/rover-20181004-1237.obs.gz"
    out.append(("rtcm3-stream", ["--rover", str(rover), "--base", str(M8P / "rtcm3/base-20181004-1236.rtcm3.gz"),
                                 "--nav", str(M8P / "rinex/rover-20181004-1237.nav.gz")]))
    for i, ds in enumerate(DATASETS):
        for systems in ds.systems:
            if systems != "G":
                out += _directions(f"set{i}-{systems}", [*_dataset_args(ds), f"--systems={systems}"],
                                   "walk" in ds.name or "lossy" in ds.name)
    return out


def _one(outdir: Path, name: str, args: list[str]) -> tuple[str, int, str]:
    target = outdir / f"{name}.pos"
    proc = subprocess.run([sys.executable, "-m", "onboard", "rtk", *args, "--no-progress", "-o", str(target)],
                          check=False, cwd=PROJECT, capture_output=True, text=True)
    lines = (proc.stdout.strip() or proc.stderr.strip()).splitlines()
    return name, proc.returncode, lines[-1] if lines else ""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("outdir", type=Path)
    ap.add_argument("--jobs", type=int, default=2, help="runs in parallel (default 2)")
    args = ap.parse_args(argv)
    if not M8P.is_dir():
        print(f"needs ../shared/data: {M8P} not found", file=sys.stderr)
        return 2
    args.outdir.mkdir(parents=True, exist_ok=True)
    failed = 0
    with ThreadPoolExecutor(args.jobs) as pool:
        for name, code, last in pool.map(lambda r: _one(args.outdir, *r), runs()):
            print(f"{name}: exit {code}: {last}")
            failed += code != 0
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
