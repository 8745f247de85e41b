"""Configuration against the hil_sim receiver emulator over a real pseudo-terminal (lea6t and m8t).

The emulator models the line rate through the pty's termios (wrong rate = garbage both ways), so the CFG-PRT
baud change is exercised for real: the ACK only arrives once our side has reopened at the new rate.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Iterator
from contextlib import asynccontextmanager, contextmanager
from typing import Any

import pytest

from onboard.errors import ConfigRejected
from onboard.receiver.configure import apply_profile, detect_receiver
from onboard.receiver.framing import ubx_frame
from onboard.receiver.profiles import ReceiverOptions, build_profile
from tests.conftest import shared_file
from tests.receiver_config._pty_link import PtyLink

emu_mod = pytest.importorskip("hil_sim.pty_server", reason="hil_sim receiver emulator not available")
rx_mod = pytest.importorskip("hil_sim.receiver")
try:  # A2's stand-in World (real broadcast orbits, geometric ranges) unless A1's World has landed
    from tests.hil_sim_receiver.conftest import NAV, StandInWorld
except ImportError:  # pragma: no cover - depends on the other area's fixtures
    pytest.skip("hil_sim stand-in world not available", allow_module_level=True)

pytestmark = pytest.mark.timeout(60)


@contextmanager
def emulator(model: str, **options: Any) -> Iterator[Any]:
    from onboard.formats.rinex_nav import read_rinex_nav

    world = StandInWorld(read_rinex_nav(shared_file(NAV)).ephemerides)
    emu = emu_mod.ReceiverEmulator(model, rx_mod.ReceiverOptions(**options), world, speed=1.0)
    emu.start()
    try:
        yield emu
    finally:
        emu.stop()
    assert emu.error is None, emu.error


@asynccontextmanager
async def pty_link(path: str, baud: int = 9600) -> AsyncIterator[PtyLink]:
    link = PtyLink(path, baud)
    try:
        yield link
    finally:
        link.close()


def run(coro: Any) -> Any:
    return asyncio.run(coro)


@pytest.mark.parametrize("model", ["lea6t", "m8t"])
def test_profile_applied_and_verified_by_poll_back(model: str) -> None:
    opts = ReceiverOptions()

    async def scenario(path: str) -> Any:
        async with pty_link(path) as pl:
            info = await detect_receiver(pl.link)
            report = await apply_profile(pl.link, build_profile(info.model, opts), opts, receiver=info,
                                         current_baud=9600)
            return info, report

    with emulator(model) as emu:
        info, report = run(scenario(emu.path))
        assert emu.core.baud_rate == 115200
        tp5 = emu.core.config.tp5
        enabled = emu.core.config.gnss_enabled()
        restarts = emu.core.stats.gnss_restarts
    assert info.model == model
    assert report.ok, [str(e) for e in report.errors]
    assert report.baud == 115200
    assert all(m.polled_back for m in report.messages if m.name != "CFG-RST")
    if model == "m8t":  # GPS, Galileo, QZSS, GLONASS tracked (the dump's factory had BeiDou, SBAS, not GLONASS)
        assert enabled == {0, 2, 5, 6} and restarts == 1
        assert report.result("CFG-GNSS GPS+GLONASS+Galileo+QZSS").status == "ok"
    else:
        assert enabled is None and restarts == 0
    cam = report.result("CFG-TP5 TIMEPULSE2 camera")
    # The emulator (like a real receiver may) cleared alignToTow for the 3 s period: recorded, not an error.
    assert cam.status == "altered" and cam.applied["alignToTow"] == 0
    assert tp5[1]["freqPeriodLock"] == 3_000_000 and tp5[1]["pulseLenRatioLock"] == 100_000
    assert tp5[0]["freqPeriodLock"] == 1_000_000  # TIMEPULSE kept at 1 PPS


def test_lea6t_tp5_nak_falls_back_to_cfg_tp_on_the_emulator() -> None:
    opts = ReceiverOptions()

    async def scenario(path: str) -> Any:
        async with pty_link(path) as pl:
            return await apply_profile(pl.link, build_profile("lea6t", opts), opts, current_baud=9600)

    with emulator("lea6t", tp5_on_u6="nak") as emu:
        report = run(scenario(emu.path))
        tp = dict(emu.core.config.tp)
    assert report.ok, [str(e) for e in report.errors]
    assert report.camera_timepulse == "TIMEPULSE"
    assert report.result("CFG-TP TIMEPULSE camera").status == "ok"
    assert (tp["interval"], tp["length"], tp["status"], tp["timeRef"]) == (3_000_000, 100_000, 1, 1)


def test_m8t_table_on_a_lea6t_falls_back_to_rxm_raw() -> None:
    opts = ReceiverOptions()

    async def scenario(path: str) -> Any:
        async with pty_link(path) as pl:
            return await apply_profile(pl.link, build_profile("unknown", opts), opts, current_baud=9600)

    with emulator("lea6t") as emu:
        report = run(scenario(emu.path))
        raw_rate = emu.core.rate_of((0x02, 0x10))
    assert report.result("CFG-MSG RXM-RAWX every 1").status == "naked"
    assert report.result("CFG-MSG RXM-RAW every 1").status == "ok" and raw_rate == 1


def test_receiver_that_keeps_align_to_tow_is_verified_as_sent() -> None:
    """The other answer to the open question: a receiver that keeps alignToTow for a 3 s period. The poll-back
    shows the bit set, the camera pulse is "ok" (not "altered") and the applied flag is recorded as 1."""
    opts = ReceiverOptions()

    async def scenario(path: str) -> Any:
        async with pty_link(path) as pl:
            return await apply_profile(pl.link, build_profile("m8t", opts), opts, current_baud=9600)

    with emulator("m8t", align_to_tow="keep") as emu:
        report = run(scenario(emu.path))
    assert report.ok, [str(e) for e in report.errors]
    cam = report.result("CFG-TP5 TIMEPULSE2 camera")
    assert cam.status == "ok" and cam.applied["alignToTow"] == 1


def test_u6_that_acks_rxm_rawx_but_ignores_it_is_caught_by_poll_back() -> None:
    """The other answer to "NAK or ACK RXM-RAWX enabling on a u-blox 6": ACKed but never applied. The poll-back
    names the message and field (rateUART1 applied 0), and the RXM-RAW fallback is still enabled."""
    opts = ReceiverOptions()

    async def scenario(path: str) -> Any:
        async with pty_link(path) as pl:
            return await apply_profile(pl.link, build_profile("unknown", opts), opts, current_baud=9600)

    with emulator("lea6t", rawx_on_u6="ack-ignore") as emu:
        report = run(scenario(emu.path))
        raw_rate = emu.core.rate_of((0x02, 0x10))
    assert report.result("CFG-MSG RXM-RAWX every 1").status == "mismatch"
    assert any("RXM-RAWX" in str(e) and "rateUART1" in str(e) for e in report.errors)
    assert report.result("CFG-MSG RXM-RAW every 1").status == "ok" and raw_rate == 1


def test_emulator_factory_timepulse_is_the_real_neo_m8t_dump() -> None:
    dump = {}
    for line in shared_file("ubx/rtkbase_U-Blox_NEO-M8T_rtkbase.txt").read_text().splitlines():
        if line.startswith("CFG-TP5 - "):
            body = bytes.fromhex(line.split(" - ", 1)[1])
            dump[body[4]] = ubx_frame(body[0], body[1], body[4:])

    async def scenario(path: str) -> dict[int, bytes]:
        async with pty_link(path) as pl:
            got = {}
            for idx in (0, 1):
                await pl.link.send(ubx_frame(0x06, 0x31, bytes((idx,))))
                frame = await pl.link.wait_frame(
                    lambda f, i=idx: (f.msg_class, f.msg_id) == (0x06, 0x31) and f.payload[:1] == bytes((i,))
                    and len(f.payload) == 32, 1.0)
                assert frame is not None
                got[idx] = frame.raw
            return got

    with emulator("m8t") as emu:
        got = run(scenario(emu.path))
    assert got == dump
    assert got[0][6 + 28] == 0xF7


@pytest.mark.slow
def test_silent_receiver_named_in_the_report_and_its_bytes_still_arrive() -> None:
    """Nothing raised beyond MON-VER's ConfigRejected; every message named; NMEA kept flowing meanwhile."""
    opts = ReceiverOptions(ack_timeout_s=0.2, retries=0)

    async def scenario(path: str) -> Any:
        async with pty_link(path) as pl:
            with pytest.raises(ConfigRejected, match="MON-VER"):
                await detect_receiver(pl.link, timeout_s=0.2, retries=0)
            report = await apply_profile(pl.link, build_profile("m8t", opts), opts, current_baud=9600)
            return report, len(pl.raw), len(pl.frames)

    with emulator("m8t", silent=True) as emu:
        report, n_bytes, n_frames = run(scenario(emu.path))
    assert not report.ok
    assert [e.message for e in report.errors] == [e.label for e in build_profile("m8t", opts).entries
                                                  if e.expect_ack]
    assert report.errors[0].field == "baudRate"
    assert report.baud == 9600  # back at the rate the receiver still talks
    assert n_frames > 5 and n_bytes > 300  # factory NMEA received throughout
