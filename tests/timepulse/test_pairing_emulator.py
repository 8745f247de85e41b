"""Pairing end to end: the hil_sim emulator (configured by our profile over a real pty) fires camera pulses on
TIMEPULSE2 wired to EXTINT1 and flashes on EXTINT0; TIM-TM2 decoded by `onboard.receiver.decode`; every flash
paired with its pulse at the delay the simulator used (±1 µs), the missed flash and the bounce flagged.
"""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from onboard.receiver.configure import apply_profile
from onboard.receiver.profiles import ReceiverOptions, build_profile
from onboard.rtk.types import CameraMark
from onboard.timepulse.marks import BOUNCE, MISSED_FLASH, PULSE_WITHOUT_FLASH, pair_marks
from tests.conftest import shared_file

emu_mod = pytest.importorskip("hil_sim.pty_server", reason="hil_sim receiver emulator not available")
rx_mod = pytest.importorskip("hil_sim.receiver")
decode = pytest.importorskip("onboard.receiver.decode")
try:
    from tests.hil_sim_receiver.conftest import NAV, StandInWorld
    from tests.receiver_config._pty_link import PtyLink
except ImportError:  # pragma: no cover - depends on the other areas' fixtures
    pytest.skip("hil_sim stand-in world not available", allow_module_level=True)

pytestmark = pytest.mark.timeout(90)
SPEED = 4.0
DELAYS_NS = [61_234_567, 0, 63_999_001, 58_000_123, 60_500_000, 59_000_000]  # index 1: the camera did not flash
NO_FLASH = 1
BOUNCE_AT = 4  # event 4's flash bounces 3 ms later (same epoch: TIM-TM2 loses an edge, count jumps)


@pytest.mark.slow
def test_every_simulated_flash_paired_with_the_simulators_delay() -> None:
    from onboard.formats.rinex_nav import read_rinex_nav

    world = StandInWorld(read_rinex_nav(shared_file(NAV)).ephemerides)
    first_pulse = world.start.add_s(20.123456789)  # after configuration; an arbitrary phase of the GPS grid
    for k, delay in enumerate(DELAYS_NS):
        p = first_pulse.add_ns(k * 3_000_000_000)
        f = None if k == NO_FLASH else p.add_ns(delay)
        world.add_event(p, f, f.add_ns(3_000_000) if k == BOUNCE_AT and f is not None else None)
    end = first_pulse.add_s(3 * len(DELAYS_NS) + 1)
    opts = ReceiverOptions()

    async def scenario(emu: Any) -> list[Any]:
        pl = PtyLink(emu.path, 9600)
        try:
            report = await apply_profile(pl.link, build_profile("m8t", opts), opts, current_baud=9600)
            assert report.ok, [str(e) for e in report.errors]
            while emu.sim_time() < end:
                await asyncio.sleep(0.1)
            return list(pl.frames)
        finally:
            pl.close()

    emu = emu_mod.ReceiverEmulator("m8t", rx_mod.ReceiverOptions(trigger_extint=True, mark_noise_ns=7.0), world,
                                   speed=SPEED)
    emu.start()
    try:
        frames = asyncio.run(scenario(emu))
    finally:
        emu.stop()
    assert emu.error is None
    marks: list[CameraMark] = []
    for frame in frames:
        item = decode.decode_frame(frame)
        if isinstance(item, decode.TimeMarks):
            marks += item.marks
    pairs = pair_marks(marks)
    assert len(pairs) == len(DELAYS_NS)
    for k, (pair, delay) in enumerate(zip(pairs, DELAYS_NS, strict=True)):
        want_pulse = first_pulse.add_ns(k * 3_000_000_000)
        assert abs(pair.pulse_time.diff_ns(want_pulse)) < 1_000, k  # type: ignore[union-attr]
        if k == NO_FLASH:
            assert pair.flags == (PULSE_WITHOUT_FLASH,) and pair.flash_time is None
        elif k == BOUNCE_AT:
            assert BOUNCE in pair.flags and pair.lost_edges >= 1  # detected; its time is the bounce's
        else:
            assert pair.flags == (), (k, pair.flags)
            assert abs(pair.delay_ns - delay) <= 1_000, (k, pair.delay_ns, delay)  # type: ignore[operator]
    assert all(MISSED_FLASH not in p.flags for p in pairs)  # nothing lost but the bounce's edge
