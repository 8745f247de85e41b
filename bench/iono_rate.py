"""How fast the ionosphere changes between satellites: real dual-frequency data next to hil_sim's skies.

A rover differenced with a base epoch `lag` seconds old (a radio gap) carries in each double difference the
change of the two satellites' slant ionosphere over that lag; the engine carries an aged base forward along a
straight line fitted over the last 20 s of base data (onboard.rtk.rtkpos._extrapolated_base). This prints,
with `hil_sim.obs_stats.iono_change_stats`, the change between satellites at lags of 1-20 s and the miss of
that straight line 5-20 s ahead:

- real: the slant L1 ionosphere from the geometry-free carrier phase (λ₁φ₁ − λ₂φ₂)/(γ − 1), γ = (f₁/f₂)², of
  - GEONET 3034 (Trimble NetR9), 2021-09-22 06:30-06:36 GPST, Fujisawa: GPS L1C/L2W (L2X), Galileo E1/E5a,
    QZSS L1C/L2X (`../shared/data/gnss/geonet-3034-sept-20210922`, RINEX 3.04), the gej-2021 world's day,
    hour and place;
  - GMSD (Tanegashima) MSM7 stream, 2012-10-14 23:59:44 GPST (09:00 JST), GPS 1C/2W
    (`../shared/data/rtcm/rtklib_GMSD7_20121014.rtcm3`, 257 s): two weeks before the gr-2012 world's day,
    solar maximum, two hours earlier in the local morning, 5° further south;
  the phase noise of the geometry-free combination (a few mm at 1 s) is part of every real figure;
- hil_sim: the base's slant ionosphere (truth: Klobuchar × (1 + model error) + gradient) of each world,
  seeds 1-8, 360 s from the world's start.

Run: `.venv/bin/python bench/iono_rate.py` (about 1 min; the real rows need ../shared).
"""

from __future__ import annotations

import argparse
import gzip
import sys
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from hil_sim.obs_stats import iono_change_stats
from hil_sim.scenario import Scenario
from hil_sim.world import World
from onboard.rtk.consts import CLIGHT_M_S

SHARED = ROOT.parent / "shared" / "data"
GEONET_3034 = SHARED / "gnss" / "geonet-3034-sept-20210922" / "3034265G.21O.gz"
GMSD = SHARED / "rtcm" / "rtklib_GMSD7_20121014.rtcm3"
# system letter: (f1 Hz, f2 Hz, L1 phase code, L2 phase codes, best first)
DUAL = {"G": (1575.42e6, 1227.60e6, "L1C", ("L2W", "L2X")), "E": (1575.42e6, 1176.45e6, "L1X", ("L5X",)),
        "J": (1575.42e6, 1227.60e6, "L1C", ("L2X",))}
Series = dict[Any, dict[int, float]]


def rinex_geometry_free(path: Path) -> Series:
    """Slant L1 ionosphere + a constant (m) per satellite and second from a RINEX 3 file's two carrier phases.
    (onboard.formats.rinex_obs keeps the L1 signal only; this reads the two phase columns of DUAL.)"""
    types: dict[str, list[str]] = {}
    out: Series = {}
    t_s = 0
    with gzip.open(path, "rt") as f:
        last = ""
        for line in f:
            if "END OF HEADER" in line:
                break
            if "SYS / # / OBS TYPES" in line:
                if line[0] != " ":
                    last = line[0]
                    types[last] = []
                types[last] += line[7:58].split()
        for line in f:
            if line.startswith(">"):
                h, mi, sec = line[13:15], line[16:18], line[19:29]
                t_s = round(int(h) * 3600 + int(mi) * 60 + float(sec))
                continue
            sys_letter = line[0]
            if sys_letter not in DUAL:
                continue
            f1, f2, c1, c2s = DUAL[sys_letter]
            values = {}
            for i, code in enumerate(types[sys_letter]):
                field = line[3 + 16 * i: 3 + 16 * i + 14]
                if field.strip():
                    values[code] = float(field)
            c2 = next((c for c in c2s if c in values), None)
            if c1 not in values or c2 is None:
                continue
            gf_m = CLIGHT_M_S / f1 * values[c1] - CLIGHT_M_S / f2 * values[c2]
            out.setdefault(line[:3], {})[t_s] = gf_m / ((f1 / f2) ** 2 - 1.0)
    return out


def msm7_geometry_free(path: Path) -> Series:
    """The same from an RTCM3 stream's GPS MSM7 (1077) cells 1C and 2W: their fine phase ranges share the
    satellite's rough range, so it cancels."""
    from pyrtcm import RTCMReader, parse_msm

    g = (1575.42 / 1227.60) ** 2
    out: Series = {}
    with path.open("rb") as f:
        for _raw, msg in RTCMReader(f, quitonerror=0):
            if msg is None or msg.identity != "1077":
                continue
            meta, _sats, cells = parse_msm(msg)
            t_s = round(meta["epoch"] / 1000.0)
            t_s += 604800 if t_s < 302400 else 0  # the stream crosses the week's end
            by_sat: dict[str, dict[str, float]] = {}
            for c in cells:
                if c["DF406"] is not None:
                    by_sat.setdefault(c["CELLPRN"], {})[c["CELLSIG"]] = c["DF406"]
            for prn, sig in by_sat.items():
                if "1C" in sig and "2W" in sig:
                    out.setdefault("G" + prn, {})[t_s] = CLIGHT_M_S * 1e-3 * (sig["1C"] - sig["2W"]) / (g - 1.0)
    return out


def simulated(world: str, seed: int, duration_s: int = 360) -> Series:
    """hil_sim's slant ionosphere at the base (truth, on L1) per satellite and second."""
    w = World(Scenario.multi(world, "m8t", duration_s=duration_s + 40.0, seed=seed))
    out: Series = {}
    for k in range(duration_s):
        epoch, details = w.observe_detailed("base", w.start.add_s(k))
        for g, sv, iono_m in zip(epoch.gnss_id.tolist(), epoch.sv_id.tolist(), details["iono_m"].tolist()):
            out.setdefault((g, sv), {})[k] = iono_m
    return out


def row(label: str, series: Series) -> str:
    s = iono_change_stats(series)
    lags = "  ".join(f"{s['rms_mm'].get(lag, np.nan):5.1f} ({s['p95_mm'].get(lag, np.nan):5.1f})" for lag in (1, 5, 10, 20))
    ahead = "  ".join(f"{s['fit_rms_mm'].get(h, np.nan):4.1f}" for h in (5, 10, 20))
    return f"{label:44s} {len(series):4d}  {lags}   {ahead}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="1-8", help="hil_sim seeds, e.g. 1-8")
    args = ap.parse_args(argv)
    a, _, b = args.seeds.partition("-")
    seeds = range(int(a), int(b or a) + 1)
    print("between-satellite change of the slant L1 ionosphere, mm: RMS (p95) over lags of 1 / 5 / 10 / 20 s;")
    print("then the RMS miss of a 20-s straight line carried 5 / 10 / 20 s ahead")
    print(f"{'source':44s} {'sats':>4s}  {'1 s':>13s}  {'5 s':>13s}  {'10 s':>13s}  {'20 s':>13s}   fit 5 / 10 / 20 s")
    skies = (("gej-2021", "real GEONET 3034, 2021-09-22 06:30 GPST", GEONET_3034, rinex_geometry_free),
             ("gr-2012", "real GMSD MSM7, 2012-10-14 23:59 GPST (GPS)", GMSD, msm7_geometry_free))
    for world, label, path, read in skies:
        print(row(label, read(path)) if path.exists() else f"{label}: skipped, {path} not found")
        for seed in seeds:
            print(row(f"hil_sim {world}, seed {seed}", simulated(world, seed)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
