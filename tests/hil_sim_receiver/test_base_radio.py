"""Base receiver on a second pty, and the radio link pty pair with dropouts and an air byte budget."""

from __future__ import annotations

import dataclasses
import os
import time
import tty

import numpy as np
import pytest
from pyubx2 import UBXReader

from hil_sim import ubx_encode as enc
from hil_sim.pty_server import ReceiverEmulator
from hil_sim.radio import RadioChannel, RadioLink, RadioOptions
from hil_sim.receiver import ReceiverOptions

pytestmark = pytest.mark.timeout(60)


@pytest.mark.slow
def test_base_and_rover_emulators_run_side_by_side_on_their_own_ptys(pty_client_factory) -> None:
    from hil_sim.scenario import Scenario
    from hil_sim.world import World

    sc = Scenario.default(model="m8t", duration_s=120.0)
    world = World(dataclasses.replace(sc, camera=dataclasses.replace(sc.camera, valid_after_s=1.0)))
    opts = ReceiverOptions(time_valid_after_s=1.0, nav_noise_m=1.0)
    emus = {r: ReceiverEmulator("m8t", opts, world, speed=5.0, receiver=r) for r in ("rover", "base")}
    paths = {r: e.start() for r, e in emus.items()}
    try:
        assert paths["rover"] != paths["base"]
        sols = {}
        for r, path in paths.items():
            c = pty_client_factory(path, 9600)
            for cls, mid in ((0x01, 0x06), (0x02, 0x15)):
                lay = enc.LAYOUTS["CFG-MSG3"]
                _, ack = c.request(lay.msg_class, lay.msg_id, enc.pack(lay, {"msgClass": cls, "msgID": mid, "rate": 1}))
                assert ack is not None and ack.msg_id == 1
            c.pump(1.5)
            sols[r] = [UBXReader.parse(f.raw) for f in c.ubx(0x01, 0x06)]
            assert len(c.ubx(0x02, 0x15)) >= 3
    finally:
        for e in emus.values():
            e.stop()
    base_fix = [s for s in sols["base"] if s.gpsFix == 3]
    assert base_fix
    for s in base_fix:
        assert np.linalg.norm(np.array([s.ecefX, s.ecefY, s.ecefZ]) / 100 - world.base_ecef_m) < 6.0
    rover_fix = [s for s in sols["rover"] if s.gpsFix == 3]
    assert rover_fix and np.linalg.norm(
        np.array([rover_fix[0].ecefX, rover_fix[0].ecefY, rover_fix[0].ecefZ]) / 100 - world.base_ecef_m) > 500


def test_radio_channel_gaps_are_5_to_20_s_and_lose_everything_inside() -> None:
    ch = RadioChannel(RadioOptions(mean_interval_s=60.0, seed=4))
    gaps = ch.gaps_until(3600.0)
    lengths = np.array([b - a for a, b in gaps])
    assert len(gaps) > 20 and lengths.min() >= 5.0 and lengths.max() <= 20.0
    a, b = gaps[0]
    assert ch.pass_chunk((a + b) / 2, b"x" * 10) == b"" and ch.bytes_lost_dropout == 10
    assert ch.pass_chunk(b + 0.5, b"y" * 10) == b"y" * 10


def test_radio_channel_budget_drops_whole_chunks() -> None:
    ch = RadioChannel(RadioOptions(air_baud=9600, buffer_bytes=1000, mean_interval_s=1e9, seed=1))
    delivered = sum(len(ch.pass_chunk(k * 0.1, b"z" * 200)) for k in range(100))  # 2000 B/s offered for 10 s
    assert ch.bytes_lost_budget > 0 and delivered <= 960 * 10 + 1000 and delivered % 200 == 0
    assert delivered + ch.bytes_lost_budget == 200 * 100
    with pytest.raises(ValueError):
        RadioOptions(gap_min_s=30.0, gap_max_s=20.0)


@pytest.mark.slow
def test_radio_link_forwards_between_ptys_and_goes_silent_in_a_dropout() -> None:
    link = RadioLink(RadioOptions(mean_interval_s=3.0, gap_min_s=5.0, gap_max_s=5.0, seed=2), speed=10.0)
    tx, rx = link.start()
    try:
        ftx = os.open(tx, os.O_RDWR | os.O_NOCTTY)
        frx = os.open(rx, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        tty.setraw(ftx)
        tty.setraw(frx)
        got = bytearray()
        sent = 0
        t_end = time.monotonic() + 2.5  # 25 s simulated
        while time.monotonic() < t_end:
            os.write(ftx, b"R" * 50)
            sent += 50
            time.sleep(0.02)
            try:
                got += os.read(frx, 65536)
            except BlockingIOError:
                pass
        time.sleep(0.1)
        try:
            got += os.read(frx, 65536)
        except BlockingIOError:
            pass
        os.close(ftx)
        os.close(frx)
    finally:
        link.stop()
    ch = link.channel
    assert ch.bytes_lost_dropout > 0 and 0 < len(got) < sent
    assert len(got) == ch.bytes_out and set(got) == {ord("R")}


def test_radio_cli_prints_both_ptys_forwards_and_stops_on_sigterm() -> None:
    import select
    import signal
    import subprocess
    import sys

    from tests.conftest import PROJECT_ROOT

    proc = subprocess.Popen([sys.executable, "-m", "hil_sim", "radio", "--mean-interval", "1e9"], cwd=PROJECT_ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        assert select.select([proc.stdout], [], [], 20.0)[0]
        tx, rx = proc.stdout.readline().split()
        ftx = os.open(tx, os.O_RDWR | os.O_NOCTTY)
        frx = os.open(rx, os.O_RDWR | os.O_NOCTTY)
        tty.setraw(ftx)
        tty.setraw(frx)
        os.write(ftx, b"\xd3\x00\x13RTCM")
        assert select.select([frx], [], [], 5.0)[0]
        assert os.read(frx, 100) == b"\xd3\x00\x13RTCM"
        os.close(ftx)
        os.close(frx)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
