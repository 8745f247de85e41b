"""The emulator over a real pseudo-terminal: factory state, baud change, configuration, streams, faults."""

from __future__ import annotations

import errno
import itertools
import os
import select
import time
from pathlib import Path

import pytest
from pyubx2 import UBXReader

from hil_sim import ubx_encode as enc
from hil_sim.faults import FaultOptions
from hil_sim.pty_server import ReceiverEmulator
from hil_sim.receiver import M8T_TP5_DEFAULTS, ReceiverOptions
from onboard.gnsstime import GpsTime
from onboard.receiver.framing import Protocol

pytestmark = pytest.mark.timeout(60)

PRT_115200 = {"portID": 1, "mode": 0x8C0, "baudRate": 115200, "inProtoMask": 0x1, "outProtoMask": 0x1}


@pytest.fixture
def emulator_factory():
    emus: list[ReceiverEmulator] = []

    def make(model: str, world, speed: float = 5.0, **kw) -> ReceiverEmulator:
        link = kw.pop("link", None)
        emu = ReceiverEmulator(model, ReceiverOptions(**kw), world, speed=speed, link=link)
        emus.append(emu)
        emu.start()
        return emu

    yield make
    for e in emus:
        e.stop()
        assert e.error is None


def payload(name: str, head: dict) -> tuple[int, int, bytes]:
    lay = enc.LAYOUTS[name]
    return lay.msg_class, lay.msg_id, enc.pack(lay, head)


def is_ack(frame) -> bool:
    return frame is not None and frame.msg_id == 0x01


@pytest.mark.slow
@pytest.mark.parametrize("model", ["lea6t", "m8t"])
def test_factory_state_answers_mon_ver_at_9600_and_streams_nmea(model, standin_world, emulator_factory,
                                                                 pty_client_factory) -> None:
    emu = emulator_factory(model, standin_world)
    client = pty_client_factory(emu.path, 9600)
    reply, _ = client.request(0x0A, 0x04, reply=(0x0A, 0x04))
    assert reply is not None
    ver = UBXReader.parse(reply.raw)
    assert ver.swVersion.rstrip(b"\0").decode() == emu.core.model.sw_version
    client.pump(0.5)
    assert any(f.protocol is Protocol.NMEA and f.raw.startswith(b"$GPGGA") for f in client.frames)
    assert not client.ubx(0x02, 0x15) and not client.ubx(0x02, 0x10)


@pytest.mark.slow
def test_client_at_the_wrong_rate_gets_only_garbage(standin_world, emulator_factory, pty_client_factory) -> None:
    emu = emulator_factory("m8t", standin_world)
    client = pty_client_factory(emu.path, 115200)  # receiver still at its factory 9600
    time.sleep(0.1)  # beyond the 20 ms in which input may still count as sent at the previous rate
    client.send(0x0A, 0x04)
    client.pump(1.0)
    assert client.frames == [] and len(client.raw) > 50  # bytes arrive, no frame can be formed
    assert emu.bytes_garbled_in > 0 and emu.core.stats.frames_in == 0


@pytest.mark.slow
@pytest.mark.parametrize("model", ["lea6t", "m8t"])
def test_configuration_sequence_with_baud_change_then_raw_epochs(model, standin_world, emulator_factory,
                                                                 pty_client_factory) -> None:
    emu = emulator_factory(model, standin_world, speed=5.0)
    client = pty_client_factory(emu.path, 9600)
    _, ack = client.request(*payload("CFG-PRT", PRT_115200), timeout_s=0.5)
    assert ack is None  # the ACK left at 115200 while we still listen at 9600
    assert emu.core.baud_rate == 115200
    client.set_baud(115200)
    prt, ack = client.request(0x06, 0x00, b"\x01", reply=(0x06, 0x00))
    assert is_ack(ack) and UBXReader.parse(prt.raw).baudRate == 115200
    raw = emu.core.model.raw_msg
    steps = [
        payload("CFG-MSG", {"msgClass": raw[0], "msgID": raw[1], "rateUART1": 1}),
        payload("CFG-MSG3", {"msgClass": 0x0D, "msgID": 0x03, "rate": 1}),
        payload("CFG-RATE", {"measRate": 200, "navRate": 1, "timeRef": 1}),
        payload("CFG-TP5", {**M8T_TP5_DEFAULTS[1], "freqPeriod": 2_000_000, "freqPeriodLock": 2_000_000,
                            "pulseLenRatio": 0, "pulseLenRatioLock": 10_000, "flags": 0x77}),
    ]
    if model == "lea6t":
        steps.append(payload("CFG-TP", {"interval": 1_000_000, "length": 100_000, "status": 1, "timeRef": 1,
                                        "antennaCableDelay": 50}))
    for cls, mid, pl in steps:
        t0 = time.monotonic()
        _, ack = client.request(cls, mid, pl)
        assert is_ack(ack) and time.monotonic() - t0 < 1.0, f"0x{cls:02X} 0x{mid:02X} not ACKed within 1 s"
    rate, _ = client.request(0x06, 0x08, reply=(0x06, 0x08))
    assert (UBXReader.parse(rate.raw).measRate, UBXReader.parse(rate.raw).navRate) == (200, 1)
    tp5, _ = client.request(0x06, 0x31, b"\x01", reply=(0x06, 0x31))
    assert UBXReader.parse(tp5.raw).freqPeriodLock == 2_000_000
    if model == "lea6t":
        tp, _ = client.request(0x06, 0x07, reply=(0x06, 0x07))
        assert enc.unpack(enc.LAYOUTS["CFG-TP"], tp.payload)[0]["timeRef"] == 1
        _, nak = client.request(*payload("CFG-MSG", {"msgClass": 2, "msgID": 0x15, "rateUART1": 1}))
        assert nak is not None and nak.msg_id == 0x00  # RXM-RAWX on u-blox 6
    start = len(client.frames)
    client.pump(1.2)  # 6 s simulated at 5 Hz
    epochs = [f for f in client.frames[start:] if (f.msg_class, f.msg_id) == raw]
    assert len(epochs) >= 20
    msgs = [UBXReader.parse(f.raw) for f in epochs]
    if model == "m8t":
        tows = [m.rcvTow for m in msgs]
    else:
        tows = [m.iTOW / 1e3 for m in msgs]
    assert all(abs((b - a) - 0.2) < 1e-6 for a, b in itertools.pairwise(tows))


def test_frame_written_just_before_the_client_switches_rate_is_still_received(standin_world, emulator_factory,
                                                                              pty_client_factory) -> None:
    emu = emulator_factory("m8t", standin_world)
    client = pty_client_factory(emu.path, 9600)
    time.sleep(0.1)
    cls, mid, pl = payload("CFG-PRT", PRT_115200)
    client.send(cls, mid, pl)
    client.set_baud(115200)  # at once, as a daemon reopening the port (a pty has no transmit delay)
    deadline = time.monotonic() + 1.0
    while emu.core.baud_rate != 115200 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert emu.core.baud_rate == 115200
    prt, ack = client.request(0x06, 0x00, b"\x01", reply=(0x06, 0x00))
    assert ack is not None and ack.msg_id == 1 and UBXReader.parse(prt.raw).baudRate == 115200


@pytest.mark.slow
def test_time_marks_arrive_over_the_pty(standin_world, emulator_factory, pty_client_factory) -> None:
    t0 = standin_world.start
    flashes = [t0.add_s(4.3 + 2 * k + 0.064) for k in range(3)]
    for k, f in enumerate(flashes):
        standin_world.add_event(t0.add_s(4.3 + 2 * k), f)
    emu = emulator_factory("m8t", standin_world, speed=4.0, time_valid_after_s=1.0)
    client = pty_client_factory(emu.path, 9600)
    for cls, mid, pl in (payload("CFG-MSG3", {"msgClass": 0x0D, "msgID": 0x03, "rate": 1}),
                         payload("CFG-TP5", {**M8T_TP5_DEFAULTS[1], "freqPeriod": 2_000_000,
                                             "freqPeriodLock": 2_000_000, "pulseLenRatio": 0,
                                             "pulseLenRatioLock": 10_000, "flags": 0x77})):
        assert is_ack(client.request(cls, mid, pl)[1])
    assert client.wait_for(lambda f: (f.msg_class, f.msg_id) == (0x0D, 0x03) and f.payload[2] == 3, 4.0, 0)
    marks = [UBXReader.parse(f.raw) for f in client.ubx(0x0D, 0x03)]
    assert [m.count for m in marks] == [1, 2, 3]
    for m, f in zip(marks, flashes, strict=True):
        assert m.newFallingEdge == 1 and abs(GpsTime.from_ms_subms(m.wnF, m.towMsF, m.towSubMsF).diff_ns(f)) < 50


@pytest.mark.slow
def test_corrupt_bytes_fault_breaks_checksums_but_frames_still_arrive(standin_world, emulator_factory,
                                                                      pty_client_factory) -> None:
    emu = emulator_factory("m8t", standin_world, speed=5.0, faults=FaultOptions(seed=2, corrupt_byte_rate=0.003))
    client = pty_client_factory(emu.path, 9600)
    client.pump(3.0)
    assert emu.core.faults.bytes_corrupted > 0
    assert client.framer.bad_checksums + client.framer.skipped_bytes > 0  # the reader had to resynchronise
    assert sum(f.protocol is Protocol.NMEA for f in client.frames) > 20


@pytest.mark.slow
def test_port_disappears_and_comes_back_at_the_link(tmp_path: Path, standin_world, emulator_factory,
                                                    pty_client_factory) -> None:
    link = tmp_path / "gnss0"
    emu = emulator_factory("m8t", standin_world, speed=4.0, link=link,
                           faults=FaultOptions(unplug_windows_s=((3.0, 4.0),)))
    assert link.is_symlink() and os.readlink(link) == emu.path
    client = pty_client_factory(str(link), 9600)
    assert client.request(0x0A, 0x04, reply=(0x0A, 0x04))[0] is not None
    # the port vanishes at 3 s simulated (0.75 s real): the open descriptor hangs up
    deadline = time.monotonic() + 3.0
    gone = False
    while time.monotonic() < deadline and not gone:
        r, _, x = select.select([client.fd], [], [client.fd], 0.1)
        if r or x:
            try:
                if os.read(client.fd, 4096) == b"":
                    gone = True
            except OSError as exc:
                gone = exc.errno == errno.EIO
    assert gone and not link.exists()
    deadline = time.monotonic() + 3.0
    while time.monotonic() < deadline and not link.exists():
        time.sleep(0.05)
    assert link.is_symlink() and emu.reopen_count == 1
    again = pty_client_factory(str(link), 9600)
    assert again.request(0x0A, 0x04, reply=(0x0A, 0x04))[0] is not None


@pytest.mark.slow
def test_silent_receiver_never_answers_over_the_pty(standin_world, emulator_factory, pty_client_factory) -> None:
    emu = emulator_factory("lea6t", standin_world, silent=True)
    client = pty_client_factory(emu.path, 9600)
    reply, ack = client.request(0x0A, 0x04, reply=(0x0A, 0x04), timeout_s=0.5)
    assert reply is None and ack is None
    _, ack = client.request(*payload("CFG-PRT", PRT_115200), timeout_s=0.5)
    assert ack is None and emu.core.baud_rate == 9600
    assert any(f.protocol is Protocol.NMEA for f in client.frames)
    assert all(f.protocol is Protocol.NMEA for f in client.frames)
