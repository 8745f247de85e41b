"""The emulator on A1's real World, in-process and as `python -m hil_sim receiver`, over real ptys."""

from __future__ import annotations

import dataclasses
import os
import select
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from pyubx2 import UBXReader

from hil_sim import ubx_encode as enc
from hil_sim.pty_server import ReceiverEmulator
from hil_sim.receiver import M8T_TP5_DEFAULTS, ReceiverOptions
from onboard.gnsstime import GpsTime
from tests.conftest import PROJECT_ROOT

pytestmark = pytest.mark.timeout(90)

VALID_AFTER_S = 4.0


def make_world(model: str):
    from hil_sim.scenario import Scenario
    from hil_sim.world import World

    sc = Scenario.default(model=model, duration_s=300.0)
    sc = dataclasses.replace(sc, camera=dataclasses.replace(sc.camera, valid_after_s=VALID_AFTER_S))
    return World(sc)


def cfg(client, name: str, head: dict) -> None:
    lay = enc.LAYOUTS[name]
    _, ack = client.request(lay.msg_class, lay.msg_id, enc.pack(lay, head))
    assert ack is not None and ack.msg_id == 0x01, f"{name} not ACKed"


@pytest.mark.slow
@pytest.mark.parametrize("model", ["lea6t", "m8t"])
def test_configured_receiver_on_the_world_streams_raw_subframes_and_marks(model: str, pty_client_factory) -> None:
    world = make_world(model)
    emu = ReceiverEmulator(model, ReceiverOptions(time_valid_after_s=VALID_AFTER_S, trigger_extint=True), world,
                           speed=10.0)
    path = emu.start()
    try:
        client = pty_client_factory(path, 9600)
        raw, sub = emu.core.model.raw_msg, emu.core.model.subframe_msg
        lay = enc.LAYOUTS["CFG-PRT"]
        client.send(lay.msg_class, lay.msg_id, enc.pack(lay, {"portID": 1, "mode": 0x8C0, "baudRate": 115200,
                                                               "inProtoMask": 1, "outProtoMask": 1}))
        time.sleep(0.2)
        client.set_baud(115200)
        cfg(client, "CFG-MSG", {"msgClass": raw[0], "msgID": raw[1], "rateUART1": 1})
        cfg(client, "CFG-MSG3", {"msgClass": sub[0], "msgID": sub[1], "rate": 1})
        cfg(client, "CFG-MSG3", {"msgClass": 0x0D, "msgID": 0x03, "rate": 1})
        cfg(client, "CFG-RATE", {"measRate": 200, "navRate": 1, "timeRef": 1})
        cfg(client, "CFG-TP5", {**M8T_TP5_DEFAULTS[1], "freqPeriod": 2_000_000, "freqPeriodLock": 2_000_000,
                                "pulseLenRatio": 0, "pulseLenRatioLock": 10_000, "flags": 0x77})
        start_sim = emu.sim_time()
        client.pump(2.5)  # ~25 s simulated
        end_sim = emu.sim_time()
    finally:
        emu.stop()
    assert emu.error is None
    epochs = [UBXReader.parse(f.raw) for f in client.ubx(*raw)]
    assert len(epochs) >= 100 and emu.core.stats.epochs_dropped_budget == 0
    n = [m.numSV if model == "lea6t" else m.numMeas for m in epochs]
    assert min(n) >= 5
    if model == "lea6t":
        assert all(m.iTOW % 1000 in (799, 798, 599, 598, 399, 398, 199, 198, 999, 998) for m in epochs)
    assert len(client.ubx(*sub)) >= 5  # subframes of every tracked satellite every 6 s
    # time marks: every flash the world's camera made after valid time, at its flash time
    flashes = [e.flash_time for e in world.camera_events(world.start, end_sim)
               if e.flash_time is not None and e.flash_time > start_sim and e.flash_time.add_s(1.0) < end_sim]
    marks = [UBXReader.parse(f.raw) for f in client.ubx(0x0D, 0x03)]
    ch0 = {GpsTime.from_ms_subms(m.wnF, m.towMsF, m.towSubMsF): m for m in marks if m.ch == 0 and m.newFallingEdge}
    assert len(flashes) >= 5
    for f in flashes:
        nearest = min(ch0, key=lambda t: abs(t.diff_ns(f)))
        assert abs(nearest.diff_ns(f)) < 100
    counts = [m.count for m in marks if m.ch == 0]
    assert np.all(np.diff(counts) == 1)
    trig = [m for m in marks if m.ch == 1 and m.newRisingEdge]
    assert trig and all(m.time == 1 for m in trig)


@pytest.mark.slow
def test_cli_prints_the_pty_path_answers_and_exits_cleanly_on_sigterm_and_sigint(pty_client_factory) -> None:
    for sig in (signal.SIGTERM, signal.SIGINT):
        proc = subprocess.Popen([sys.executable, "-m", "hil_sim", "receiver", "--model", "lea6t", "--speed", "5",
                                 "--duration", "120"], cwd=PROJECT_ROOT, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        try:
            assert proc.stdout is not None
            r, _, _ = select.select([proc.stdout], [], [], 30.0)
            assert r, "no pty path on stdout"
            path = proc.stdout.readline().strip()
            assert path.startswith("/dev/pts/") and os.path.exists(path)
            client = pty_client_factory(path, 9600)
            reply, _ = client.request(0x0A, 0x04, reply=(0x0A, 0x04), timeout_s=3.0)
            assert reply is not None and UBXReader.parse(reply.raw).swVersion.startswith(b"7.03")
            proc.send_signal(sig)
            assert proc.wait(timeout=10) == 0
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()


@pytest.mark.slow
def test_cli_reports_a_missing_navigation_file(tmp_path) -> None:
    proc = subprocess.run([sys.executable, "-m", "hil_sim", "receiver", "--model", "m8t", "--nav",
                           str(tmp_path / "missing.10n")], cwd=PROJECT_ROOT, capture_output=True, text=True,
                          timeout=60, check=False)
    assert proc.returncode == 2 and "missing.10n" in proc.stderr and proc.stdout == ""
