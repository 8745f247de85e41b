"""Bench: simulated-world epochs and LNAV codec speed, each next to a peer doing comparable work.

- World.observe (rover + base, full physics) per epoch (the GPS world and the two multi-constellation worlds), next to onboard SPP (pntpos) solving that same epoch,
  and against the real-time budget of a 5 Hz two-receiver simulation (100 ms per epoch pair).
- LNAV: our encode→decode of subframes 1–3 per ephemeris, next to RTKLIB decode_frame (pyrtklib) decoding
  the same subframes.

Run: `.venv/bin/python bench/hil_world.py` (needs ../shared/data).
"""

from __future__ import annotations

import math
import time

from hil_sim.scenario import Scenario
from hil_sim.world import World
from onboard.formats.rinex_nav import read_rinex_nav
from onboard.rtk import lnav
from onboard.rtk.ephemeris import EphemerisStore, satellite_states
from onboard.rtk.pntpos import pntpos


def bench_world(n: int = 300, scenario: Scenario | None = None, label: str = "GPS") -> None:
    """World construction and observe() cost of `scenario` (default: the GPS world), next to onboard SPP."""
    print(f"-- world: {label}")
    t0 = time.perf_counter()
    world = World(scenario or Scenario.default())
    t_init = time.perf_counter() - t0
    epochs = []
    t0 = time.perf_counter()
    for k in range(n):
        t = world.start.add_s(0.2 * k)
        epochs.append(world.observe("rover", t))
        world.observe("base", t)
    t_obs = (time.perf_counter() - t0) / n
    store = EphemerisStore(world.ephemerides())
    t0 = time.perf_counter()
    for full in epochs:
        ep = full.select(full.gnss_id == 0)  # today's SPP is GPS-only
        sats = satellite_states(store, ep.sv_id, ep.time, ep.pr_m)
        pntpos(ep.pr_m, sats, ep.time.tow_s, math.radians(5), dop_hz=ep.dop_hz, iono=world.iono_params())
    t_spp = (time.perf_counter() - t0) / n
    print(f"World() construction                 {t_init * 1e3:8.1f} ms")
    print(f"World.observe rover+base per epoch   {t_obs * 1e3:8.2f} ms  ({len(epochs[0])} sats)")
    print(f"peer: onboard SPP on one epoch       {t_spp * 1e3:8.2f} ms")
    print(f"real-time margin at 5 Hz (100 ms/pair) {100e-3 / t_obs:6.1f} x")


def bench_lnav() -> None:
    nav = read_rinex_nav(Scenario().nav_path)
    ephs = nav.ephemerides
    t0 = time.perf_counter()
    encoded = [lnav.encode_subframes(e, 0.0) for e in ephs]
    t_enc = (time.perf_counter() - t0) / len(ephs)
    t0 = time.perf_counter()
    for e, sfs in zip(ephs, encoded):
        asm = lnav.LnavAssembler(1590)
        for sf in sfs:
            asm.add_subframe_words30(e.prn, sf)
    t_dec = (time.perf_counter() - t0) / len(ephs)
    print(f"lnav.encode_subframes per ephemeris  {t_enc * 1e6:8.1f} µs")
    print(f"LnavAssembler decode (parity+fields) {t_dec * 1e6:8.1f} µs")
    try:
        import pyrtklib as p
    except ImportError:
        print("peer: pyrtklib not installed")
        return
    buf_t = getattr(p, "Arr1Dunsigned char")
    bufs = []
    for e in ephs:
        buf = buf_t(150)
        for k, sf in enumerate(lnav.encode_subframes_transmitted(e, 0.0)):
            words24, _ = lnav.words24_from_words30(sf)
            for i, byte in enumerate(b"".join(w.to_bytes(3, "big") for w in words24)):
                buf[30 * k + i] = byte
        bufs.append(buf)
    t0 = time.perf_counter()
    for buf in bufs:
        p.decode_frame(buf, p.eph_t(), p.alm_t(), p.Arr1Ddouble(8), p.Arr1Ddouble(8))
    t_rtk = (time.perf_counter() - t0) / len(bufs)
    print(f"peer: RTKLIB decode_frame (no parity) {t_rtk * 1e6:7.1f} µs")


if __name__ == "__main__":
    bench_world()
    bench_world(scenario=Scenario.multi("gr-2012"), label="gr-2012 (GPS + GLONASS, 32 channels)")
    bench_world(scenario=Scenario.multi("gej-2021"), label="gej-2021 (GPS + Galileo + QZSS, 32 channels)")
    bench_lnav()
