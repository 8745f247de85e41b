"""The RTKLIB peer for the RTK benchmark: a Python driver calling RTKLIB through pyrtklib epoch by epoch.

`python bench/rtklib_driver.py --lib pyrtklib|pyrtklib5 ROVER.obs BASE.obs NAV [NAV...] -o OUT.pos`
reads RINEX with RTKLIB's own reader, pairs each rover epoch with the base epoch nearest in time (as RTKLIB
postpos does for post-processing), calls rtkpos() once per epoch and writes an RTKLIB-style .pos
(week tow x y z Q ns ...). Options: GPS only (or --systems, GLONASS AR on), L1, kinematic, fix-and-hold, ratio 3, 15° mask, broadcast
ionosphere, Saastamoinen troposphere, base position from the RINEX header (or --base-pos).

It exists so the benchmark measures both engines the same way: a whole Python process doing the same job.
Nothing in the product imports it.
"""

from __future__ import annotations

import argparse
import gzip
import importlib
import shutil
import sys
import tempfile
from pathlib import Path


def _plain(path: str, tmp: Path) -> str:
    """RTKLIB cannot read gzip: decompress to a temporary file when needed."""
    if not path.endswith(".gz"):
        return path
    out = tmp / Path(path).name[:-3]
    with gzip.open(path, "rb") as src, open(out, "wb") as dst:
        shutil.copyfileobj(src, dst)
    return str(out)


NAVSYS = {"G": "SYS_GPS", "R": "SYS_GLO", "E": "SYS_GAL", "J": "SYS_QZS", "C": "SYS_CMP"}
"""RINEX system letter → RTKLIB navsys flag name."""


def navsys_mask(mod, systems: str) -> int:  # type: ignore[no-untyped-def]
    """RTKLIB's navsys bit mask of `systems` (RINEX letters, e.g. "GR" → SYS_GPS|SYS_GLO)."""
    mask = 0
    for letter in systems:
        mask |= getattr(mod, NAVSYS[letter])
    return mask


def configure(mod, elmask_deg: float = 15.0, ratio: float = 3.0, systems: str = "G",  # type: ignore[no-untyped-def]
              dynamics: bool | None = None):
    """RTKLIB processing options matching the benchmark's common settings; GLONASS, when used, with its
    ambiguities fixed (glomodear=1, both receivers of one type). `dynamics` None keeps the binding's default
    receiver dynamics (pyrtklib 2.4.3: off, pyrtklib5 demo5: on), else sets it (RTKLIB pos1-dynamics)."""
    popt = mod.prcopt_default
    if dynamics is not None:
        popt.dynamics = int(dynamics)
    popt.mode = mod.PMODE_KINEMA
    popt.nf = 1
    popt.navsys = navsys_mask(mod, systems)
    popt.glomodear = 1 if "R" in systems else 0
    popt.elmin = elmask_deg * mod.D2R
    popt.modear = 3  # fix-and-hold
    popt.thresar[0] = ratio
    popt.ionoopt = mod.IONOOPT_BRDC
    popt.tropopt = mod.TROPOPT_SAAS
    return popt


def dynamics_flag(text: str | None) -> bool | None:
    """--dynamics on/off/absent → True/False/None."""
    return None if text is None else text == "on"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lib", default="pyrtklib", choices=("pyrtklib", "pyrtklib5"))
    parser.add_argument("rover")
    parser.add_argument("base")
    parser.add_argument("nav", nargs="+")
    parser.add_argument("--base-pos", help="X,Y,Z ECEF m (default: base RINEX header)")
    parser.add_argument("--elmask", type=float, default=15.0)
    parser.add_argument("--systems", default="G", help="RINEX system letters (default G)")
    parser.add_argument("--dynamics", choices=("on", "off"), help="receiver dynamics (default: the binding's)")
    parser.add_argument("-o", "--output", required=True)
    args = parser.parse_args(argv)
    mod = importlib.import_module(args.lib)
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        rover, base = _plain(args.rover, tmp), _plain(args.base, tmp)
        navs = [_plain(n, tmp) for n in args.nav]
        obs_r, obs_b, nav, sta = mod.obs_t(), mod.obs_t(), mod.nav_t(), mod.sta_t()
        sta_b = mod.sta_t()
        t0 = mod.gtime_t()
        if mod.readrnxt(rover, 1, t0, t0, 0.0, "", obs_r, nav, sta) <= 0:
            print(f"cannot read {rover}", file=sys.stderr)
            return 2
        if mod.readrnxt(base, 2, t0, t0, 0.0, "", obs_b, nav, sta_b) <= 0:
            print(f"cannot read {base}", file=sys.stderr)
            return 2
        for n in navs:
            mod.readrnxt(n, 0, t0, t0, 0.0, "", mod.obs_t(), nav, mod.sta_t())
        mod.sortobs(obs_r)
        mod.sortobs(obs_b)
        mod.uniqnav(nav)
    popt = configure(mod, args.elmask, systems=args.systems, dynamics=dynamics_flag(args.dynamics))
    if args.base_pos:
        rb = [float(v) for v in args.base_pos.split(",")]
    else:
        rb = [sta_b.pos[i] for i in range(3)]
    popt.refpos = 0
    for i in range(3):
        popt.rb[i] = rb[i]
    rtk = mod.rtk_t()
    mod.rtkinit(rtk, popt)
    for i in range(3):
        rtk.rb[i] = rb[i]

    def epochs(obs):  # type: ignore[no-untyped-def]
        out, i = [], 0
        while i < obs.n:
            j = i
            while j < obs.n and abs(mod.timediff(obs.data[j].time, obs.data[i].time)) < 1e-9:
                j += 1
            out.append((i, j))
            i = j
        return out

    ep_r, ep_b = epochs(obs_r), epochs(obs_b)
    kb = 0
    lines = []
    week = mod.Arr1Dint(1)
    for i0, i1 in ep_r:
        t = obs_r.data[i0].time
        while kb + 1 < len(ep_b) and abs(mod.timediff(obs_b.data[ep_b[kb + 1][0]].time, t)) <= abs(
            mod.timediff(obs_b.data[ep_b[kb][0]].time, t)
        ):
            kb += 1
        j0, j1 = ep_b[kb]
        n = (i1 - i0) + (j1 - j0)
        arr = mod.Arr1Dobsd_t(n)
        for k in range(i0, i1):
            arr[k - i0] = obs_r.data[k]
        for k in range(j0, j1):
            arr[(i1 - i0) + (k - j0)] = obs_b.data[k]
        mod.rtkpos(rtk, arr[0], n, nav)
        sol = rtk.sol
        if sol.stat == 0:
            continue
        tow = mod.time2gpst(sol.time, week)
        lines.append(
            f"{week[0]:4d} {tow:10.3f} {sol.rr[0]:14.4f} {sol.rr[1]:14.4f} {sol.rr[2]:14.4f} {sol.stat:3d} "
            f"{sol.ns:3d} {sol.age:6.2f} {sol.ratio:6.1f}"
        )
    Path(args.output).write_text("% week tow x y z Q ns age ratio (RTKLIB via " + args.lib + ")\n"
                                 + "\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
