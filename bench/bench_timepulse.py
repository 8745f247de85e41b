"""Camera-mark pairing and receiver configuration figures, each next to a peer run in the same process.

1. Pairing a 2-hour flight (2400 images at 3 s: pulse, flash, contact opening; some missed/bounced):
   `PairingRecorder` fed report by report (what the daemon does) vs one batch `pair_marks` over the whole
   flight (the peer: the least work that gives the same answer). Prints µs per report and the max window.
2. Configuration over a real pty against the hil_sim emulator (if importable), from the factory 9600 baud:
   `apply_profile` wall time and messages for lea6t and m8t, vs the bare round-trip time of one MON-VER poll
   on the same link (the peer: what one message costs at best).

Run: `.venv/bin/python bench/bench_timepulse.py`
"""

from __future__ import annotations

import asyncio
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from onboard.gnsstime import GpsTime
from onboard.rtk.types import CameraMark
from onboard.timepulse.marks import PairingRecorder, pair_marks

T0 = GpsTime(2345, 100_000_000_000_000)


def flight(n_images: int) -> list[list[CameraMark]]:
    reports: list[list[CameraMark]] = []
    count = 0
    for k in range(n_images):
        p = T0.add_ns(123_456_789 + k * 3_000_000_000)
        reports.append([CameraMark(1, "rising", k, p, 12, 1, True)])
        if k % 97 == 5:
            continue
        f = p.add_ns(60_000_000 + (k * 7919) % 3_000_000)
        count += 1 + (k % 113 == 7)
        reports.append([CameraMark(0, "falling", count, f, 15, 1, True),
                        CameraMark(0, "rising", count, f.add_ns(4_000_000), 15, 1, True)])
    return reports


def bench_pairing() -> None:
    reports = flight(2400)
    marks = [m for r in reports for m in r]
    t = time.perf_counter()
    batch = pair_marks(marks)
    batch_s = time.perf_counter() - t
    rec = PairingRecorder()
    window = 0
    n = 0
    t = time.perf_counter()
    for r in reports:
        n += sum(1 for x in rec.add(r) if x["kind"] == "pairing")
        window = max(window, rec.window)
    n += len(rec.flush())
    inc_s = time.perf_counter() - t
    print(f"pairing, 2 h flight: {len(reports)} reports, {len(marks)} marks, {len(batch)} images")
    print(f"  peer  batch pair_marks      : {batch_s * 1e3:8.1f} ms total")
    print(f"  ours  PairingRecorder.add   : {inc_s * 1e3:8.1f} ms total, {inc_s / len(reports) * 1e6:6.1f} µs/report, "
          f"max window {window} marks, {n} images")


def bench_configure() -> None:
    try:
        from hil_sim.pty_server import ReceiverEmulator
        from hil_sim.receiver import ReceiverOptions as EmuOptions
        from tests.hil_sim_receiver.conftest import NAV, StandInWorld
        from tests.receiver_config._pty_link import PtyLink
    except ImportError as exc:
        print(f"configuration: skipped ({exc})")
        return
    from onboard.formats.rinex_nav import read_rinex_nav
    from onboard.receiver.configure import apply_profile, detect_receiver
    from onboard.receiver.profiles import ReceiverOptions, build_profile
    from tests.conftest import SHARED_DATA

    nav = SHARED_DATA / NAV
    if not nav.exists():
        print("configuration: skipped (no broadcast file)")
        return
    ephs = read_rinex_nav(nav).ephemerides
    for model in ("lea6t", "m8t"):
        emu = ReceiverEmulator(model, EmuOptions(), StandInWorld(ephs), speed=1.0)
        emu.start()

        async def run(emu: ReceiverEmulator = emu, model: str = model) -> tuple[float, float, int, bool]:
            pl = PtyLink(emu.path, 9600)
            try:
                t = time.perf_counter()
                await detect_receiver(pl.link)
                rtt = time.perf_counter() - t
                opts = ReceiverOptions()
                t = time.perf_counter()
                report = await apply_profile(pl.link, build_profile(model, opts), opts, current_baud=9600)
                return rtt, time.perf_counter() - t, len(report.messages), report.ok
            finally:
                pl.close()

        try:
            rtt, total, n, ok = asyncio.run(run())
        finally:
            emu.stop()
        print(f"configuration {model}: peer MON-VER round trip {rtt * 1e3:6.1f} ms; ours apply_profile "
              f"{total:5.2f} s for {n} messages (each sent, ACKed, polled back; incl. 0.1 s baud settle), ok={ok}")


if __name__ == "__main__":
    bench_pairing()
    bench_configure()
