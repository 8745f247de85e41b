"""RTK benchmark: `python -m onboard rtk` beside RTKLIB 2.4.3 (pyrtklib) and demo5 (pyrtklib5), same inputs.

Per dataset (../shared/data/gnss), constellation set (`Dataset.systems`: "G", and "GR" for the M8P sets,
"GEJ" for GEONET 3034/Septentrio) and engine, each run as its own process on the same RINEX files with the same
options (L1, kinematic, fix-and-hold, ratio 3, 15° mask, broadcast iono, Saastamoinen; RTKLIB navsys from the
set, GLONASS ambiguities fixed: glomodear=1, both receivers of one type; ours `--systems`):

    rtklib-2.4.3  RTKLIB postpos() through pyrtklib       (what rnx2rtkp does: reproduces the README rows)
    demo5         RTKLIB demo5 postpos() through pyrtklib5
    2.4.3-driver  bench/rtklib_driver.py: a Python process calling RTKLIB rtkpos() epoch by epoch (the speed peer)
    demo5-driver  the same driver on demo5 (not with --quick)
    ours          python -m onboard rtk (forward)

With more than GPS only demo5 and ours run. Printed per (set, systems, engine): output epochs, fixed epochs,
fix ratio (of the engine's epochs, and of the most epochs any engine wrote), time to first fix, fixed-epoch
horizontal/vertical RMS against the reference, fixed epochs checked against it and how many are > 10 cm off
(3D, and horizontally) and > 5 cm (3D); on the walk, whose reference (the M8P's own RTK fixes) covers few
epochs, also the fixed epochs > 10 cm (3D) from a pseudo-reference: demo5's combined forward/backward fixed
solution with the widest set (GPS+GLONASS; demo5's own forward run is part of it, so its count there is not
independent), and how many of the fixed epochs > 5 cm from the reference lie within 5 cm of that
pseudo-reference (where two engines' fixes agree and the reference departs from both). Then whole-process CPU
(resource RUSAGE_CHILDREN), µs per output epoch, and ours/demo5 CPU (total CPU of the same job on the same
files), the raw-RTCM3 run of ours and our filter alone in ms per epoch (this process, reading excluded; with
`--bare` also without its tests beyond relpos()) against the Pi budget of 200 ms/epoch at 5 Hz.
`--markdown PATH` writes the table (and the notes) as markdown, atomically.

Run: `.venv/bin/python bench/bench_rtk.py [--quick] [--only SUBSTRING ...] [--systems G GR ...] [--engines
demo5 ours ...] [--repeat N] [--markdown PATH]` (about 2 min, N times that with --repeat; `--quick`: GEONET
0759/3040 and the M8P static README pairing, GPS only). The bindings are the `bench` extra (pyrtklib 0.2.7, pyrtklib5 0.2.8); an inherited PYTHONPATH is
passed to the child processes after this checkout (e.g. `pip install --target DIR pyrtklib5==0.2.8`).

Inputs: the M8P RINEX files (convbin -r ubx) hold GPS, GLONASS (and QZSS on the walk) observations, and their
.nav files are mixed GPS+GLONASS (convbin; `onboard convert` writes GPS ephemerides only); GEONET 3034/Sept has
GPS, Galileo and QZSS, SEPT2650.21P is mixed GPS+Galileo+QZSS; GEONET 0759/3040 is GPS only.

Reproduction of the README's RTKLIB rows with these options (measured 2026-11-23): GEONET 0759/3040 2.4.3
99.1 % (README 99 %), demo5 95.8 % (95 %); GLW1 base 98.3 % / 97.8 % (98 % / 98 %); GEONET 3034/Sept 2.4.3
30.6 %, 3.7 cm h (31 %, 3.7 cm), demo5 0 % (0 %). M8P static: the README row is the base's RXM-RAWX RINEX with
the RTCM 1005 position (its header holds only an approximate one): 2.4.3 74.3 %, first fix 285 s, 1.6 cm h,
2.4 cm v; demo5 89.1 %, 130 s, 1.1 cm h (README 75.3 %, 277 s / 89.3 %, 128 s, 1.2-1.6 cm h, 2.3 cm v). With the
lossy RTCM base instead: 79.6 % / 88.5 %. M8P walk (RAWX base, 1005 position): demo5 17.7 % (README 16 %),
2.4.3 1.6 % (README 18 %: not reproduced). The lead's epoch-by-epoch driver pairs each rover epoch with the
nearest base epoch and differs from postpos on the lossy RTCM base (9.7 % vs 79.6 %); elsewhere it matches.

demo5 with more systems (measured 2026-12-03). The bindings' default receiver dynamics differ (pyrtklib 2.4.3
off, pyrtklib5 demo5 on) and `configure` keeps them unless --rtklib-dynamics is given; issue 16's demo5 figures
are with dynamics off. With off: M8P static, RAWX base, GPS+GLONASS 98.3 %, first fix 20 s, 0 of 1184 fixed
epochs > 10 cm (the same with on; the lossy RTCM base: 89.0 %, 34 s, 0 wrong); GEONET 3034 GPS+Galileo+QZSS
89.4 %, 22 s, 2 (vertical) of 319 > 10 cm (issue 16's figures exactly; with on: 81.1 %, 22 s, 45 of 288);
M8P walk GPS+GLONASS 58.1 %, 76 s, 6 (3D) / 0 (horizontal) of 406 checked > 10 cm from the M8P's fixes (with on:
53.6 %, 61 s, 45 / 38 of 401; issue 16 quotes 53.1 %, 78 s, 8 / 1 of 408: with the base RINEX from `onboard
convert`, 882 epochs instead of convbin's 763, 54.7 %, 76 s, 9 / 0 of 409 — close, not exact).
"""

from __future__ import annotations

import argparse
import csv
import importlib
import math
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
if str(PROJECT) not in sys.path:  # the in-process parts use this checkout's onboard, as the child processes do
    sys.path.insert(0, str(PROJECT))
WRONG_M = 0.10
NEAR_M = 0.05
PI_BUDGET_MS = 200.0


def _static(xyz: tuple[float, float, float]) -> Callable[[np.ndarray], np.ndarray]:
    ref = np.array(xyz)
    return lambda tow: np.tile(ref, (len(tow), 1))


def _csv_ref(path: Path, tol_s: float = 0.06) -> Callable[[np.ndarray], np.ndarray]:
    """Reference positions by time of week from a `tow,x,y,z,...` csv (NaN where none within `tol_s`); the file
    is read at the first call (the module imports without the datasets)."""
    loaded: list[Callable[[np.ndarray], np.ndarray]] = []

    def ref(tow: np.ndarray) -> np.ndarray:
        if not loaded:
            with open(path) as f:
                rows = [(float(r["tow"]), float(r["x"]), float(r["y"]), float(r["z"])) for r in csv.DictReader(f)]
            loaded.append(nearest_ref(np.array(rows).reshape(-1, 4), tol_s))
        return loaded[0](tow)

    return ref


def solution_ref(sol: np.ndarray, tol_s: float = 0.06) -> Callable[[np.ndarray], np.ndarray]:
    """A pseudo-reference from the fixed (Q=1) epochs of a solution's rows (week, tow, x, y, z, q)."""
    fixed = sol[sol[:, 5] == 1]
    return nearest_ref(fixed[:, [1, 2, 3, 4]], tol_s)


def nearest_ref(rows: np.ndarray, tol_s: float) -> Callable[[np.ndarray], np.ndarray]:
    """Positions by time of week from rows (tow, x, y, z): the nearest in time, NaN where none within `tol_s`."""
    arr = rows[np.argsort(rows[:, 0])] if len(rows) else np.full((1, 4), np.nan)
    if len(arr) == 1:
        arr = np.vstack([arr, arr])

    def ref(tow: np.ndarray) -> np.ndarray:
        i = np.clip(np.searchsorted(arr[:, 0], tow), 1, len(arr) - 1)
        j = np.where(np.abs(arr[i - 1, 0] - tow) < np.abs(arr[i, 0] - tow), i - 1, i)
        out = arr[j, 1:].copy()
        out[~(np.abs(arr[j, 0] - tow) <= tol_s)] = np.nan
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
    systems: tuple[str, ...] = ("G",)
    """Constellation sets (RINEX letters) each engine runs with; the RINEX and nav files hold them all."""
    pseudo_ref: bool = False
    """The reference covers few epochs: also score against demo5's combined (forward/backward) fixed solution
    with the last (widest) system set."""


M8P_STATIC = _static((3774088.9931, -601661.8217, 5089321.3853))

DATASETS = [
    Dataset("geonet 0759/3040 static 3.3 km 30 s", GEO / "07590920.05o.gz", GEO / "30400920.05o.gz",
            [GEO / "07590920.05n.gz"], "-3978241.958,3382840.234,3649900.853",
            _static((-3976219.1873, 3382371.6051, 3652511.1423)), "2.4.3 99 % | demo5 95 % | 6 mm h, 1.1 cm v",
            quick=True),
    Dataset("m8p static, M8P base RAWX (0.33 m)", M8P / "rinex/rover-20181004-1237.obs.gz",
            M8P / "rinex/base-20181004-1236.rawx.obs.gz", [M8P / "rinex/rover-20181004-1237.nav.gz"],
            "3774089.2120,-601661.6157,5089321.2474", M8P_STATIC,
            "2.4.3 75.3 % 1st 277 s | demo5 89.3 % 1st 128 s | 1.2-1.6 cm h, 2.3 cm v", quick=True,
            systems=("G", "GR")),
    Dataset("m8p static, M8P base lossy RTCM", M8P / "rinex/rover-20181004-1237.obs.gz",
            M8P / "rinex/base-20181004-1236.rtcm.obs.gz", [M8P / "rinex/rover-20181004-1237.nav.gz"], None,
            M8P_STATIC, "(the README row above uses the RAWX base)",
            rtcm_stream=M8P / "rtcm3/base-20181004-1236.rtcm3.gz", systems=("G", "GR")),
    Dataset("m8p static, GLW1 CORS base (197 m)", M8P / "rinex/rover-20181004-1237.obs.gz",
            M8P / "cors-glw1/glw1277m.18o.gz", [M8P / "rinex/rover-20181004-1237.nav.gz"], None,
            _static((3774088.6821, -601663.0350, 5089318.2304)), "2.4.3 98 % | demo5 98 % 1st 17-26 s | 7 mm h"),
    Dataset("geonet 3034/Septentrio moving 5.3 km", SEPT / "SEPT265G.21O.gz", SEPT / "3034265G.21O.gz",
            [SEPT / "SEPT2650.21P.gz"], "-3959400.631,3385704.533,3667523.111",
            _csv_ref(SEPT / "SEPT265G.ref_l1l2_GEJ_fixed.csv", 0.01), "2.4.3 31 % | demo5 0 % | 3.7 cm h",
            systems=("G", "GEJ")),
    Dataset("m8p walk under trees (vs M8P's RTK)", M8P / "rinex/rover-20181004-1532.obs.gz",
            M8P / "rinex/base-20181004-1452.rawx.obs.gz", [M8P / "rinex/rover-20181004-1532.nav.gz"],
            "3774085.6456,-601662.5769,5089316.3970",
            _csv_ref(M8P / "ref/rover-20181004-1532.m8p_rtk_fixed.csv"), "2.4.3 18 % | demo5 16 % | no truth",
            systems=("G", "GR"), pseudo_ref=True),
]
SYSTEM_NAMES = {"G": "GPS", "R": "GLO", "E": "GAL", "C": "BDS", "J": "QZSS"}


def systems_label(systems: str) -> str:
    """"GEJ" → "GPS+GAL+QZSS"."""
    return "+".join(SYSTEM_NAMES[s] for s in systems)


# --- RTKLIB postpos() in a child process ----------------------------------------------------------------


def postpos_main(argv: list[str]) -> int:
    """Child mode: `--postpos LIB OUT [--base-pos X,Y,Z] [--systems GR] [--combined] FILES...` runs RTKLIB
    postpos() on RINEX files (forward, or combined forward/backward)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from rtklib_driver import _plain, configure, dynamics_flag

    ap = argparse.ArgumentParser()
    ap.add_argument("--postpos", nargs=2, metavar=("LIB", "OUT"))
    ap.add_argument("--base-pos")
    ap.add_argument("--systems", default="G")
    ap.add_argument("--combined", action="store_true")
    ap.add_argument("--dynamics", choices=("on", "off"))
    ap.add_argument("files", nargs="+")
    args = ap.parse_args(argv)
    lib, out = args.postpos
    mod = importlib.import_module(lib)
    with tempfile.TemporaryDirectory() as tmpdir:
        files = [_plain(f, Path(tmpdir)) for f in args.files]
        popt = configure(mod, systems=args.systems, dynamics=dynamics_flag(args.dynamics))
        popt.soltype = 2 if args.combined else 0
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
    # the project first; an inherited PYTHONPATH after it (e.g. where the bench extra's bindings are installed)
    path = os.pathsep.join(p for p in (str(PROJECT), os.environ.get("PYTHONPATH", "")) if p)
    env = dict(os.environ, PYTHONPATH=path)
    proc = subprocess.run(cmd, cwd=PROJECT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                          check=False)
    wall = time.monotonic() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if proc.returncode != 0:
        print(f"    ! {' '.join(cmd[:4])} ... exit {proc.returncode}: {proc.stderr.strip()[-300:]}", file=sys.stderr)
    return cpu, wall, proc.returncode


ENGINES = ("rtklib-2.4.3", "demo5", "2.4.3-driver", "demo5-driver", "ours", "demo5-combined", "ours-combined")
MULTI_ENGINES = ("demo5", "ours", "demo5-combined", "ours-combined")
"""Engines run with more than GPS: the drivers are GPS-only, 2.4.3 is not the peer any more."""
PEER = {"ours": "demo5", "ours-combined": "demo5-combined"}
"""Each of our runs' CPU is given as a ratio to the demo5 run of the same direction."""


def engine_commands(ds: Dataset, systems: str, out: Path, engines: tuple[str, ...] = ENGINES,
                    rtklib_args: tuple[str, ...] = ()) -> dict[str, list[str]]:
    """The command line of each engine in `engines` on `ds` with `systems` (output .pos files under `out`;
    `rtklib_args` added to the RTKLIB ones, e.g. ("--dynamics=off",))."""
    files = [str(ds.rover), str(ds.base), *map(str, ds.navs)]
    bp = [f"--base-pos={ds.base_pos}"] if ds.base_pos else []
    me = str(Path(__file__).resolve())
    sy = [f"--systems={systems}", *rtklib_args]
    nav_args = [a for n in ds.navs for a in ("--nav", str(n))]
    cmds = {
        "rtklib-2.4.3": [PY, me, "--postpos", "pyrtklib", str(out / "243.pos"), *bp, *sy, *files],
        "demo5": [PY, me, "--postpos", "pyrtklib5", str(out / "demo5.pos"), *bp, *sy, *files],
        "2.4.3-driver": [PY, "bench/rtklib_driver.py", "--lib", "pyrtklib", *files, *bp, *rtklib_args, "-o",
                         str(out / "drv243.pos")],
        "demo5-driver": [PY, "bench/rtklib_driver.py", "--lib", "pyrtklib5", *files, *bp, *rtklib_args, "-o",
                         str(out / "drvdemo5.pos")],
        "ours": [PY, "-m", "onboard", "rtk", "--rover", str(ds.rover), "--base", str(ds.base), *nav_args, *bp,
                 f"--systems={systems}",
                 "--no-progress", "-o", str(out / "ours.pos")],
    }
    # the post-processing mode of both (forward and backward passes combined), as a surveyor runs it on the ground
    cmds["demo5-combined"] = [*cmds["demo5"][:4], str(out / "demo5-combined.pos"), "--combined", *cmds["demo5"][5:]]
    cmds["ours-combined"] = [*cmds["ours"][:-2], "--direction=combined", "-o", str(out / "ours-combined.pos")]
    allowed = ENGINES if systems == "G" else MULTI_ENGINES
    return {k: v for k, v in cmds.items() if k in engines and k in allowed}


def pseudo_ref_command(ds: Dataset, out: Path, rtklib_args: tuple[str, ...] = ()) -> list[str]:
    """demo5 combined forward/backward with the widest system set: the pseudo-reference's solution."""
    return engine_commands(ds, ds.systems[-1], out, ("demo5-combined",), rtklib_args)["demo5-combined"]


def _out_file(cmd: list[str]) -> Path:
    return Path(cmd[cmd.index("-o") + 1]) if "-o" in cmd else Path(cmd[4])


def _enu(sol: np.ndarray, ref: Callable[[np.ndarray], np.ndarray], sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ENU offsets (m) of the rows `sel` of `sol` that `ref` covers, and the mask of those rows."""
    from onboard.rtk.geodesy import ecef_to_enu

    refs = ref(sol[:, 1])
    has = sel & np.all(np.isfinite(refs), axis=1)
    enu = np.array([ecef_to_enu(p, r) for p, r in zip(sol[has, 2:5], refs[has])]).reshape(-1, 3)
    return enu, has


def score(sol: np.ndarray, ref: Callable[[np.ndarray], np.ndarray],
          pseudo: Callable[[np.ndarray], np.ndarray] | None = None) -> dict[str, float]:
    """Metrics of a solution's rows (week, tow, x, y, z, q) against a reference (position by tow, NaN where it
    has none): epochs, fixed, fix %, first fix (s after the first epoch), fixed-epoch horizontal/vertical RMS
    (cm), fixed epochs checked against the reference and how many are > 10 cm off in 3D (wrong), > 10 cm
    horizontally (wrong_h), > 5 cm in 3D (off5); with `pseudo`, fixed epochs checked against it and > 10 cm
    3D off (pseudo_checked, pseudo_wrong), and of the off5 epochs those within 5 cm of the pseudo-reference
    (off5_pseudo_near: an independent engine's fix agrees with ours where the reference departs from both)."""
    nan = float("nan")
    n = len(sol)
    out: dict[str, float] = {"epochs": n, "fixed": 0, "fix": nan, "ttff": nan, "h": nan, "v": nan, "checked": 0,
                             "wrong": 0, "wrong_h": 0, "off5": 0, "pseudo_checked": 0, "pseudo_wrong": 0,
                             "off5_pseudo_near": 0}
    if n == 0:
        return out
    fixed = sol[:, 5] == 1
    tow = sol[:, 1] + (sol[:, 0] - sol[0, 0]) * 604800.0
    enu, has = _enu(sol, ref, fixed)
    d3 = np.linalg.norm(enu, axis=1)
    dh = np.hypot(enu[:, 0], enu[:, 1])
    out.update({
        "fixed": int(fixed.sum()),
        "fix": 100.0 * float(fixed.mean()),
        "ttff": float(tow[np.argmax(fixed)] - tow[0]) if fixed.any() else nan,
        "h": 100 * float(np.sqrt(np.mean(dh**2))) if len(enu) else nan,
        "v": 100 * float(np.sqrt(np.mean(enu[:, 2] ** 2))) if len(enu) else nan,
        "checked": len(enu),
        "wrong": int(np.sum(d3 > WRONG_M)),
        "wrong_h": int(np.sum(dh > WRONG_M)),
        "off5": int(np.sum(d3 > NEAR_M)),
    })
    if pseudo is not None:
        penu, phas = _enu(sol, pseudo, fixed)
        p3 = np.linalg.norm(penu, axis=1)
        out["pseudo_checked"] = len(penu)
        out["pseudo_wrong"] = int(np.sum(p3 > WRONG_M))
        off5 = np.zeros(n, bool)
        off5[has] = d3 > NEAR_M
        near = np.zeros(n, bool)
        near[phas] = p3 <= NEAR_M
        out["off5_pseudo_near"] = int(np.count_nonzero(off5 & near))
    return out


# --- the table ------------------------------------------------------------------------------------------

COLUMNS = [  # (header, width, format of a row's value)
    ("set", 36, "{}"), ("systems", 12, "{}"), ("engine", 12, "{}"), ("epochs", 6, "{:d}"), ("fixed", 6, "{:d}"),
    ("fix %", 6, "{:.1f}"), ("/rover %", 8, "{:.1f}"), ("1st fix s", 9, "{:.0f}"), ("h RMS cm", 8, "{:.1f}"),
    ("v RMS cm", 8, "{:.1f}"), ("checked", 7, "{:d}"), (">10cm 3D", 8, "{:d}"), (">10cm h", 7, "{:d}"),
    (">5cm 3D", 7, "{:d}"), ("pseudo chk", 10, "{}"), ("pseudo >10cm", 12, "{}"),
    ("of >5cm: pseudo <=5cm", 21, "{}"), ("CPU s", 6, "{:.2f}"),
    ("us/epoch", 8, "{:.0f}"), ("CPU ours/demo5", 14, "{}"),
]


def table_row(values: list[object]) -> list[str]:
    """A row's values formatted by COLUMNS ("-" for NaN)."""
    cells = []
    for (_, _, fmt), v in zip(COLUMNS, values):
        if isinstance(v, float) and math.isnan(v):
            cells.append("-")
        else:
            cells.append(fmt.format(int(v) if fmt == "{:d}" else v))
    return cells


def text_table(rows: list[list[str]]) -> str:
    """Fixed-width text table with COLUMNS' headers."""
    lines = [" ".join(f"{h:>{w}s}" if i > 2 else f"{h:{w}s}" for i, (h, w, _) in enumerate(COLUMNS))]
    for r in rows:
        lines.append(" ".join(f"{c:>{w}s}" if i > 2 else f"{c:{w}s}" for i, (c, (_, w, _)) in enumerate(zip(r, COLUMNS))))
    return "\n".join(lines)


def markdown_table(headers: list[str], rows: list[list[str]]) -> str:
    """A GitHub markdown table ('|' in cells escaped)."""
    def line(cells: list[str]) -> str:
        return "| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |"

    return "\n".join([line(headers), "|" + "---|" * len(headers), *(line(r) for r in rows)]) + "\n"


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


BARE_OPTIONS: dict[str, object] = {
    "standstill": False, "tdcp_slip_test": False, "tdcp_float_slip_threshold_cyc": 0.0, "use_doppler": False,
    "partial_ar": False, "slip_outlier_factor": 0.0, "code_scatter_reference": 0.0, "code_cn0_ref_dbhz": 0.0,
    "base_rate_skill_min": 1.0, "base_extrapolate_min_age_s": 1e9, "max_outlier_passes": 1,
}
"""`--bare`: every test our filter has beyond RTKLIB's relpos() turned off (standstill, time-differenced phase,
Doppler rows, partial fixing, the robust slip threshold, measured code scatter and C/N0 weights, the base's
carry-forward, outlier passes): what the filter's core costs without what its fix rates rest on."""


def engine_alone_ms(ds: Dataset, systems: str, repeat: int = 1, bare: bool = False) -> tuple[float, int, int]:
    """Our filter's CPU ms per epoch in this process (inputs read as `onboard rtk` reads them, first, not timed):
    the least of `repeat` runs; also its epochs and fixed epochs. `bare`: with BARE_OPTIONS."""
    from dataclasses import replace

    from onboard.postpro.inputs import load_rtk_inputs
    from onboard.rtk.options import RtkOptions
    from onboard.rtk.postpro import postprocess
    from onboard.rtk.types import Q_FIX

    bp = [float(v) for v in ds.base_pos.split(",")] if ds.base_pos else None
    run = load_rtk_inputs(ds.rover, ds.base, ds.navs, bp, systems=systems)
    options = replace(RtkOptions(), systems=systems, elmask_deg=15.0, **(BARE_OPTIONS if bare else {}))
    best = math.inf
    n = fixed = 0
    for _ in range(max(repeat, 1)):
        t = time.process_time()
        sols, _ = postprocess(run.rover, run.base, run.nav, run.base_pos_ecef_m, options, "forward")
        best = min(best, time.process_time() - t)
        n = len(sols)
        fixed = sum(1 for sol in sols if sol.q == Q_FIX)
    return 1e3 * best / max(n, 1), n, fixed


def compile_project() -> None:
    """Byte-compile the project's packages before timing whole commands: a wheel installed by pip (the Pi)
    ships compiled modules, as pyrtklib's are; an editable checkout under PYTHONDONTWRITEBYTECODE=1 (this
    workplace sets it) would otherwise recompile ours at every start (20-25 ms of CPU per run)."""
    subprocess.run([PY, "-m", "compileall", "-q", "onboard", "hil_sim"], cwd=PROJECT, check=False,
                   stdout=subprocess.DEVNULL)


def run_set(ds: Dataset, systems: str, engines: tuple[str, ...],
            pseudo: Callable[[np.ndarray], np.ndarray] | None, rtklib_args: tuple[str, ...] = (),
            repeat: int = 1) -> tuple[list[list[str]], dict[str, float]]:
    """Run the engines on one (set, systems): the table rows, and each engine's CPU µs per output epoch.

    With `repeat` > 1 each engine runs that many times and its least CPU is kept (a shared machine's noise only
    adds); the solutions must be the same every time (RuntimeError otherwise: an engine is not deterministic)."""
    with tempfile.TemporaryDirectory() as tmpdir:
        results: dict[str, tuple[dict[str, float], float]] = {}
        for name, cmd in engine_commands(ds, systems, Path(tmpdir), engines, rtklib_args).items():
            cpu, _wall, rc = run_child(cmd)
            sol = read_solutions(_out_file(cmd)) if rc == 0 else np.zeros((0, 6))
            for _ in range(repeat - 1):
                again, _wall, rc_again = run_child(cmd)
                if rc_again != rc or not np.array_equal(read_solutions(_out_file(cmd)) if rc == 0 else sol, sol):
                    raise RuntimeError(f"{name} on {ds.name} ({systems}) gave another solution when run again")
                cpu = min(cpu, again)
            results[name] = (score(sol, ds.ref, pseudo), cpu)
    if not results:
        return [], {}
    # RTKLIB writes no line for rover epochs it could not solve; ours writes every solved rover epoch. The
    # /rover column counts fixes over the most epochs any engine wrote, the same denominator for all.
    n_rover = max(r["epochs"] for r, _ in results.values())
    rows = []
    for name, (r, cpu) in results.items():
        peer_cpu = results[PEER[name]][1] if PEER.get(name) in results else 0.0
        ratio = f"x{cpu / peer_cpu:.2f}" if peer_cpu > 0 else ""
        pc = ((str(r["pseudo_checked"]), str(r["pseudo_wrong"]), str(r["off5_pseudo_near"])) if pseudo is not None
              else ("", "", ""))
        rows.append(table_row([ds.name, systems_label(systems), name, r["epochs"], r["fixed"], r["fix"],
                               100 * r["fixed"] / max(n_rover, 1), r["ttff"], r["h"], r["v"], r["checked"],
                               r["wrong"], r["wrong_h"], r["off5"], *pc, cpu, 1e6 * cpu / max(r["epochs"], 1),
                               ratio]))
    return rows, {name: 1e6 * cpu / max(r["epochs"], 1) for name, (r, cpu) in results.items()}


def pseudo_reference(ds: Dataset, rtklib_args: tuple[str, ...] = ()) -> tuple[Callable[[np.ndarray], np.ndarray],
                                                                             int]:
    """demo5 combined fixed solution with the widest system set: the callable and its fixed epochs."""
    with tempfile.TemporaryDirectory() as tmpdir:
        cmd = pseudo_ref_command(ds, Path(tmpdir), rtklib_args)
        _cpu, _wall, rc = run_child(cmd)
        sol = read_solutions(_out_file(cmd)) if rc == 0 else np.zeros((0, 6))
    return solution_ref(sol), int(np.sum(sol[:, 5] == 1))


def main() -> int:
    if "--postpos" in sys.argv:
        return postpos_main(sys.argv[1:])
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="two small datasets only, GPS only")
    ap.add_argument("--only", nargs="*", help="substrings of dataset names")
    ap.add_argument("--systems", nargs="*", help="only these system sets (e.g. G GR)")
    ap.add_argument("--engines", nargs="*", choices=ENGINES, help=f"only these engines (default all: {ENGINES})")
    ap.add_argument("--no-engine-alone", action="store_true", help="skip the in-process timing of our filter")
    ap.add_argument("--bare", action="store_true",
                    help="also time our filter alone with every test beyond RTKLIB's relpos() off (BARE_OPTIONS), "
                         "with its fixed epochs: what the core costs without what the fix rates rest on")
    ap.add_argument("--repeat", type=int, default=1, metavar="N",
                    help="run every engine (and our filter alone) N times and keep the least CPU, for figures less "
                         "at the mercy of a shared machine (default 1)")
    ap.add_argument("--rtklib-dynamics", choices=("on", "off"),
                    help="RTKLIB receiver dynamics (pos1-dynamics) of every RTKLIB run (default: each binding's own, "
                         "2.4.3 off, demo5 on; issue 16's demo5 figures are with off)")
    ap.add_argument("--markdown", type=Path, metavar="PATH", help="also write the table as markdown (atomically)")
    args = ap.parse_args()
    if args.repeat < 1:
        ap.error("--repeat must be at least 1")
    if not GNSS.is_dir():
        print(f"{GNSS} not found: the benchmark needs the real datasets", file=sys.stderr)
        return 2
    compile_project()
    engines = tuple(args.engines) if args.engines else tuple(e for e in ENGINES if not (args.quick and e ==
                                                                                       "demo5-driver"))
    chosen = [d for d in DATASETS if (not args.quick or d.quick) and (not args.only or any(s in d.name for s in args.only))]
    rtklib_args = (f"--dynamics={args.rtklib_dynamics}",) if args.rtklib_dynamics else ()
    options_line = ("L1, kinematic, fix-and-hold, ratio 3, 15 deg mask, broadcast iono, Saastamoinen; GLONASS AR on "
                    f"(demo5 glomodear=1); RTKLIB dynamics {args.rtklib_dynamics or 'binding default (2.4.3 off, demo5 on)'}"
                    "; CPU = whole process (RUSAGE_CHILDREN)")
    print(options_line)
    print(f"wrong: fixed epochs > {100 * WRONG_M:.0f} cm from the reference (3D, horizontal), > {100 * NEAR_M:.0f} cm "
          "3D; pseudo: against demo5's combined forward/backward fixed solution, widest system set")
    rows: list[list[str]] = []
    notes: list[str] = []
    engine_ms: list[tuple[str, str, float, int, int, float]] = []
    for ds in chosen:
        sets = [s for s in ds.systems if (not args.quick or s == "G") and (not args.systems or s in args.systems)]
        pseudo = None
        if ds.pseudo_ref and sets:
            pseudo, n_fixed = pseudo_reference(ds, rtklib_args)
            notes.append(f"{ds.name}: pseudo-reference = demo5 combined {systems_label(ds.systems[-1])}, "
                         f"{n_fixed} fixed epochs")
        print(f"\n== {ds.name}\n   README (RTKLIB rnx2rtkp, GPS): {ds.readme}", flush=True)
        for systems in sets:
            new, us_per_epoch = run_set(ds, systems, engines, pseudo, rtklib_args, args.repeat)
            print(text_table(new), flush=True)
            rows += new
            if systems == "G" and ds.rtcm_stream is not None and "ours" in engines:
                r = rtcm_stream_run(ds)
                notes.append(f"{ds.name}: ours on the raw RTCM3 stream ({ds.rtcm_stream.name}, in process): "
                             f"{r['epochs']} epochs, fix {r['fix']:.1f} %, 1st fix {r['ttff']:.0f} s, h {r['h']:.1f} "
                             f"cm, v {r['v']:.1f} cm, >10 cm {r['wrong']}")
                print("   " + notes[-1])
            if "ours" in engines and not args.no_engine_alone:
                for bare in (False, True) if args.bare else (False,):
                    ms, n, fixed = engine_alone_ms(ds, systems, args.repeat, bare)
                    engine_ms.append((ds.name + (" [bare]" if bare else ""), systems, ms, n, fixed,
                                      us_per_epoch.get("demo5", 0.0) / 1e3))
    print("\nall sets:\n" + text_table(rows))
    for note in notes:
        print("  " + note)
    if engine_ms:
        print("\nengine alone (onboard.rtk forward filter, this process, reading excluded"
              + (f"; least of {args.repeat} runs" if args.repeat > 1 else "") + "), against demo5's whole-run CPU "
              "per epoch (issue 16's speed measure):")
    for name, systems, ms, n, fixed, demo5_ms in engine_ms:
        peer = f"demo5 {demo5_ms:5.2f} ms/epoch, ours/demo5 x{ms / demo5_ms:.2f}" if demo5_ms > 0 else "demo5 not run"
        print(f"  {name:47s} {systems:4s} {ms:7.2f} ms/epoch over {n} epochs ({fixed} fixed); {peer}  (Pi budget "
              f"{PI_BUDGET_MS:.0f} ms at 5 Hz; x86 figure, a Pi 4 is roughly 3-5x slower)")
    if args.markdown:
        from onboard.formats.atomic import write_atomic

        md = options_line + "\n\n" + markdown_table([h for h, _, _ in COLUMNS], rows) + "".join(f"\n- {n}" for n in notes) + "\n"
        write_atomic(args.markdown, md)
        print(f"written {args.markdown}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
