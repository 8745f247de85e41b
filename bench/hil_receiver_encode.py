"""Bench: the emulator's RXM-RAWX / TIM-TM2 encoders against pyubx2 1.4.0 building the same frames.

Prints frames per second for each and checks that both produce identical bytes, so the figure compares like
with like. Run: `.venv/bin/python bench/hil_receiver_encode.py`.
"""

from __future__ import annotations

import time

import numpy as np
from pyubx2 import GET, UBXMessage

from hil_sim import ubx_encode as enc
from onboard.gnsstime import GpsTime
from onboard.rtk.types import ObsEpoch


def _epoch(n: int) -> ObsEpoch:
    rng = np.random.default_rng(1)
    return ObsEpoch(time=GpsTime(1590, 392_399_992_000_000), gnss_id=np.zeros(n, np.int8),
                    sv_id=np.arange(1, n + 1, dtype=np.int16), pr_m=2e7 + rng.random(n) * 5e6,
                    cp_cyc=1.1e8 + rng.random(n) * 2e7, dop_hz=rng.normal(0, 2000, n).astype(np.float32).astype(float),
                    cn0_dbhz=np.full(n, 44.0), lock_ms=np.full(n, 20000.0), lli=np.zeros(n, np.uint8),
                    half_cyc_sub=np.zeros(n, np.uint8), pr_std_m=np.full(n, 0.32), cp_std_cyc=np.full(n, 0.004))


def _pyubx2_rawx(ep: ObsEpoch) -> bytes:
    kw: dict[str, object] = {"rcvTow": ep.time.tow_ns / 1e9, "week": ep.time.week, "leapS": 15,
                             "numMeas": len(ep), "leapSec": 1, "reserved1": 1}
    for i in range(len(ep)):
        s = f"_{i + 1:02d}"
        kw |= {"prMes" + s: float(ep.pr_m[i]), "cpMes" + s: float(ep.cp_cyc[i]), "doMes" + s: float(ep.dop_hz[i]),
               "svId" + s: int(ep.sv_id[i]), "locktime" + s: 20000, "cno" + s: 44, "prStd" + s: 5,
               "cpStd" + s: 1, "doStd" + s: 4, "prValid" + s: 1, "cpValid" + s: 1, "halfCyc" + s: 1}
    return UBXMessage("RXM", "RXM-RAWX", GET, **kw).serialize()


def _rate(fn, n: int) -> float:
    t0 = time.perf_counter()
    for _ in range(n):
        fn()
    return n / (time.perf_counter() - t0)


def main() -> None:
    for n_meas in (12, 24):
        ep = _epoch(n_meas)
        ours, theirs = enc.rxm_rawx(ep), _pyubx2_rawx(ep)
        same = ours == theirs
        r_ours = _rate(lambda: enc.rxm_rawx(ep), 2000)  # noqa: B023
        r_py = _rate(lambda: _pyubx2_rawx(ep), 300)  # noqa: B023
        print(f"RXM-RAWX {n_meas:2d} meas ({len(ours)} B): hil_sim {r_ours:8.0f} frames/s   "
              f"pyubx2 {r_py:8.0f} frames/s   ratio {r_ours / r_py:5.1f}x   identical bytes: {same}")
    rep = enc.TimeMarkReport(0, 7, GpsTime(1590, 5), GpsTime(1590, 9), True, True, True, 21)
    ours = enc.tim_tm2(rep)
    theirs = UBXMessage("TIM", "TIM-TM2", GET, ch=0, mode=1, run=1, newFallingEdge=1, timeBase=1, utc=1, time=1,
                        newRisingEdge=1, count=7, wnR=1590, wnF=1590, towMsR=0, towSubMsR=5, towMsF=0,
                        towSubMsF=9, accEst=21).serialize()
    r_ours = _rate(lambda: enc.tim_tm2(rep), 20000)
    r_py = _rate(lambda: UBXMessage("TIM", "TIM-TM2", GET, ch=0, count=7).serialize(), 5000)
    print(f"TIM-TM2 (36 B): hil_sim {r_ours:8.0f} frames/s   pyubx2 {r_py:8.0f} frames/s   "
          f"identical bytes: {ours == theirs}")


if __name__ == "__main__":
    main()
