"""`onboard base` over real ptys: the hil_sim base receiver emulator in, the RTCM3 radio stream out.

The base station (the recorder plus the correction sender) configures the emulated M8T, journals it, and
writes RTCM3 to a radio pty. What comes out of the radio must decode with pyrtcm to the observations the
base journal recorded, carry the base position and the ephemerides, and stay within the byte budget.
"""

from __future__ import annotations

import asyncio
import json
import os
import threading
import time
import tty
from pathlib import Path
from types import MappingProxyType

import numpy as np
import pytest
from pyrtcm import RTCMReader

from onboard.base.cli import base_recorder
from onboard.base.station import BaseOptions, BaseStationFeature
from onboard.hw.fake import FakeByteStream
from onboard.hw.serial_port import SerialByteStream
from onboard.receiver.decode import iter_journal
from onboard.receiver.framing import Protocol, StreamFramer
from onboard.receiver.rtcm import PRUNIT_GPS_M
from onboard.recorder.daemon import Recorder, RecorderDeps
from onboard.rtk.types import ObsEpoch
from tests.conftest import shared_file
from tests.daemon.helpers import make_settings, status, wait_until

pytestmark = [pytest.mark.timeout(120)]
SPEED = 4.0
BUDGET_B_S = 400.0
BURST_B = 600


def _read_all(fd: int, into: bytearray, stop: threading.Event) -> None:
    import select

    while not stop.is_set():
        r, _, _ = select.select([fd], [], [], 0.05)
        if r:
            try:
                into += os.read(fd, 65536)
            except (BlockingIOError, OSError):
                pass


@pytest.mark.slow
def test_base_station_sends_rtcm_matching_its_journal_within_budget(tmp_path: Path) -> None:
    shared_file("gnss/broadcast-nav-20100701/brdc1820.10n")
    from hil_sim.pty_server import ReceiverEmulator
    from hil_sim.receiver import ReceiverOptions
    from hil_sim.scenario import Scenario
    from hil_sim.world import World

    world = World(Scenario.default(model="m8t", duration_s=600.0))
    emu = ReceiverEmulator("m8t", ReceiverOptions(time_valid_after_s=1.0), world, speed=SPEED, receiver="base")
    port = emu.start()
    radio_master, radio_slave = os.openpty()
    tty.setraw(radio_slave)
    radio_path = os.ttyname(radio_slave)
    got = bytearray()
    stop = threading.Event()
    reader = threading.Thread(target=_read_all, args=(radio_master, got, stop), daemon=True)
    reader.start()
    settings = make_settings(tmp_path, port_device=port, port_baud=9600)
    deps = RecorderDeps(open_port=lambda: SerialByteStream(port, 9600, 0.05))
    options = BaseOptions(station_id=42, position_ecef_m=tuple(world.base_ecef_m), radio_budget_bytes_s=BUDGET_B_S,
                          radio_burst_bytes=BURST_B, obs_message="1004")
    station = base_recorder(settings, deps, options, lambda: SerialByteStream(radio_path, 57600, 0.05))
    (base,) = station.features
    assert isinstance(base, BaseStationFeature)
    result: dict[str, int] = {}
    thread = threading.Thread(target=lambda: result.setdefault("rc", asyncio.run(station.run())), daemon=True)
    thread.start()
    try:
        st = wait_until(lambda: (s := status(settings.status_path)).get("config_state") in ("verified", "failed")
                        and s, timeout_s=60, what="configuration")
        assert st["config_state"] == "verified", st.get("config_error")
        wait_until(lambda: base.core.scheduler.counts.sent.get("obs", 0) >= 40, timeout_s=40,
                   what="40 epochs of corrections")
    finally:
        loop = station._loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(station.request_stop, "test stop", 0)
        thread.join(20)
        time.sleep(0.2)
        stop.set()
        reader.join(5)
        emu.stop()
        os.close(radio_master)
        os.close(radio_slave)
    assert result.get("rc") == 0
    flight = Path(station.status.flight_dir or "")

    # What came out of the radio is exactly what the base logged as sent, frame for frame, CRC-valid.
    assert bytes(got) == (flight / "radio-tx.rtcm3").read_bytes()
    framer = StreamFramer()
    frames = framer.feed(bytes(got)) + framer.flush()
    assert frames and all(f.protocol is Protocol.RTCM3 for f in frames) and framer.skipped_bytes == 0
    msgs = [RTCMReader.parse(f.raw) for f in frames]
    numbers = [int(m.identity) for m in msgs]
    assert numbers.count(1004) >= 40 and 1006 in numbers and 1019 in numbers

    # Every 1004 is an epoch of the journal: same time tag and satellites, pseudorange to 2 cm, phase to 1 mm.
    journal = {e.time.tow_ns // 1_000_000: e.gps_only() for e in iter_journal(flight) if isinstance(e, ObsEpoch)}
    checked = 0
    for m in msgs:
        if m.identity != "1004":
            continue
        ep = journal[int(m.DF004)]
        assert int(m.DF003) == 42 and int(m.DF006) == len(ep)
        for k in range(1, int(m.DF006) + 1):
            prn = int(getattr(m, f"DF009_{k:02d}"))
            j = int(np.flatnonzero(ep.sv_id == prn)[0])
            pr = float(getattr(m, f"DF011_{k:02d}")) + int(getattr(m, f"DF014_{k:02d}")) * PRUNIT_GPS_M
            assert pr == pytest.approx(ep.pr_m[j], abs=0.02)
            ppr_m = float(getattr(m, f"DF012_{k:02d}"))
            lam = 299792458.0 / 1575.42e6
            wrapped = (ep.cp_cyc[j] - pr / lam) % 1500.0
            assert min(abs(ppr_m / lam % 1500.0 - wrapped), 1500.0 - abs(ppr_m / lam % 1500.0 - wrapped)) < 0.002
            checked += 1
    assert checked >= 40 * 5
    pos = next(m for m in msgs if m.identity == "1006")
    np.testing.assert_allclose([pos.DF025, pos.DF026, pos.DF027], world.base_ecef_m, atol=1e-3)

    # Byte budget: over any window of whole epochs, sent ≤ budget × span + burst (1004 alone fit easily).
    times = sorted({int(m.DF004) for m in msgs if m.identity == "1004"})
    span_s = (times[-1] - times[0]) / 1000.0 + 1.0
    assert len(got) <= BUDGET_B_S * span_s + BURST_B
    assert base.sender is not None and base.sender.frames_dropped == 0
    snap = json.loads(settings.status_path.with_name("base.json").read_text())
    assert snap["sent_bytes"] == len(got) and snap["sent"]["obs"] >= 40 and snap["queue_drops"] == 0
    np.testing.assert_allclose(snap["position_ecef_m"], world.base_ecef_m, atol=1e-3)


@pytest.mark.slow
def test_python_m_onboard_base_end_to_end_and_sigterm(tmp_path: Path) -> None:
    """The command itself (a subprocess): configures the emulated LEA-6T, sends 1004 + 1006, stops on SIGTERM."""
    import signal
    import subprocess
    import sys

    from tests.conftest import PROJECT_ROOT

    shared_file("gnss/broadcast-nav-20100701/brdc1820.10n")
    from hil_sim.pty_server import ReceiverEmulator
    from hil_sim.receiver import ReceiverOptions
    from hil_sim.scenario import Scenario
    from hil_sim.world import World

    world = World(Scenario.default(model="lea6t", duration_s=600.0))
    emu = ReceiverEmulator("lea6t", ReceiverOptions(time_valid_after_s=1.0), world, speed=SPEED, receiver="base")
    port = emu.start()
    radio_master, radio_slave = os.openpty()
    tty.setraw(radio_slave)
    got = bytearray()
    stop = threading.Event()
    reader = threading.Thread(target=_read_all, args=(radio_master, got, stop), daemon=True)
    reader.start()
    cfg = tmp_path / "base.toml"
    cfg.write_text("[receiver]\nmeas_rate_ms = 1000\n[journal]\ndisk_floor_mb = 1.0\n")
    x, y, z = world.base_ecef_m
    env = dict(os.environ, PYTHONPATH=str(PROJECT_ROOT))
    env.pop("NOTIFY_SOCKET", None)
    status_path = tmp_path / "run" / "status.json"
    proc = subprocess.Popen(
        [sys.executable, "-m", "onboard", "base", "--port", port, "--baud", "9600", "--radio",
         os.ttyname(radio_slave), f"--position={x},{y},{z}", "--message", "1002", "--station-id", "7",
         "--config", str(cfg), "--data-dir", str(tmp_path / "data"), "--status", str(status_path)],
        cwd=PROJECT_ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        st = wait_until(lambda: (s := status(status_path)).get("config_state") in ("verified", "failed") and s,
                        timeout_s=60, what="configuration")
        assert st["config_state"] == "verified", st.get("config_error")
        wait_until(lambda: got.count(b"\xd3") >= 12, timeout_s=40, what="corrections on the radio")
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
        stop.set()
        reader.join(5)
        emu.stop()
        os.close(radio_master)
        os.close(radio_slave)
    assert proc.returncode == 0, out.decode(errors="replace")[-2000:]
    framer = StreamFramer()
    msgs = [RTCMReader.parse(f.raw) for f in framer.feed(bytes(got)) + framer.flush()]
    numbers = [int(m.identity) for m in msgs]
    assert numbers.count(1002) >= 5 and 1006 in numbers
    assert all(int(m.DF003) == 7 for m in msgs if m.identity == "1002")
    flights = list((tmp_path / "data").glob("flight-*"))
    assert len(flights) == 1 and (flights[0] / "radio-tx.rtcm3").read_bytes() == bytes(got)


@pytest.mark.slow
def test_survey_in_over_the_emulated_base_gates_corrections_and_lands_near_the_antenna(tmp_path: Path) -> None:
    shared_file("gnss/broadcast-nav-20100701/brdc1820.10n")
    from hil_sim.pty_server import ReceiverEmulator
    from hil_sim.receiver import ReceiverOptions
    from hil_sim.scenario import Scenario
    from hil_sim.world import World

    world = World(Scenario.default(model="m8t", duration_s=600.0))
    emu = ReceiverEmulator("m8t", ReceiverOptions(time_valid_after_s=1.0), world, speed=8.0, receiver="base")
    port = emu.start()
    radio = FakeByteStream()
    settings = make_settings(tmp_path, port_device=port, port_baud=9600, receiver_options=MappingProxyType(
        {"ack_timeout_s": 0.5, "retries": 1, "meas_rate_ms": 1000}))
    base = BaseStationFeature(BaseOptions(survey_in_s=20.0), lambda: radio)
    station = Recorder(settings, RecorderDeps(open_port=lambda: SerialByteStream(port, 9600, 0.05)), features=[base])
    result: dict[str, int] = {}
    thread = threading.Thread(target=lambda: result.setdefault("rc", asyncio.run(station.run())), daemon=True)
    thread.start()
    try:
        wait_until(lambda: base.core.counts()["sent"].get("obs", 0) >= 5, timeout_s=60,
                   what="survey-in done and corrections flowing")
    finally:
        loop = station._loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(station.request_stop, "test stop", 0)
        thread.join(20)
        emu.stop()
    assert result.get("rc") == 0
    survey = base.core.survey
    assert survey is not None and survey.result_ecef_m is not None
    assert np.linalg.norm(survey.result_ecef_m - world.base_ecef_m) < 5.0  # mean of SPP over 20 s
    framer = StreamFramer()
    msgs = [RTCMReader.parse(f.raw) for f in framer.feed(bytes(radio.written))]
    pos = next(m for m in msgs if m.identity == "1006")
    np.testing.assert_allclose([pos.DF025, pos.DF026, pos.DF027], survey.result_ecef_m, atol=1e-3)
    first_obs_ms = min(int(m.DF004) for m in msgs if m.identity == "1074")  # the default MSM4 (GPS world)
    journal = [e.time for e in iter_journal(Path(station.status.flight_dir or "")) if isinstance(e, ObsEpoch)]
    # nothing was sent during the survey: the first MSM is at least 20 s after the first fix of the survey
    assert first_obs_ms / 1000.0 - journal[0].tow_s >= 20.0
