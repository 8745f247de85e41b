"""One contract suite over every ByteStream and EdgeSource implementation (fake, real pty, MockFactory GPIO)."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import pytest

from onboard.errors import LinkLost
from onboard.hw.fake import FakeByteStream, FakeEdgeSource, ManualClock
from onboard.hw.ports import ByteStream, Edge, EdgeSource

pytestmark = pytest.mark.timeout(30)


@dataclass
class StreamRig:
    """A ByteStream under test plus the device end: `send` bytes to it, `recv` what it wrote, `unplug`."""

    stream: ByteStream
    send: Callable[[bytes], None]
    recv: Callable[[int], bytes]
    unplug: Callable[[], None]


def _fake_rig() -> Iterator[StreamRig]:
    s = FakeByteStream(timeout_s=0.05)

    def recv(n: int) -> bytes:
        out = bytes(s.written[:n])
        del s.written[:n]
        return out

    yield StreamRig(s, s.feed, recv, s.unplug)
    s.close()


def _pty_rig() -> Iterator[StreamRig]:
    from onboard.hw.serial_port import SerialByteStream

    master, slave = os.openpty()
    path = os.ttyname(slave)
    os.close(slave)  # the stream opens the slave by path, as the daemon does
    stream = SerialByteStream(path, 115200, read_timeout_s=0.05)
    state = {"open": True}

    def recv(n: int) -> bytes:
        deadline = time.monotonic() + 2
        out = b""
        while len(out) < n and time.monotonic() < deadline:
            out += os.read(master, n - len(out))
        return out

    def unplug() -> None:
        os.close(master)
        state["open"] = False

    yield StreamRig(stream, lambda b: os.write(master, b) and None, recv, unplug)
    stream.close()
    if state["open"]:
        os.close(master)


@pytest.fixture(params=["fake", "pty"])
def rig(request: pytest.FixtureRequest) -> Iterator[StreamRig]:
    yield from (_fake_rig() if request.param == "fake" else _pty_rig())


def _read_all(stream: ByteStream, n: int, timeout_s: float = 2.0) -> bytes:
    out = b""
    deadline = time.monotonic() + timeout_s
    while len(out) < n and time.monotonic() < deadline:
        out += stream.read(n - len(out))
    return out


def test_bytes_arrive_in_order_and_complete(rig: StreamRig) -> None:
    data = bytes(range(256)) * 20
    rig.send(data)
    assert _read_all(rig.stream, len(data)) == data


def test_silence_returns_empty_within_timeout(rig: StreamRig) -> None:
    t0 = time.monotonic()
    assert rig.stream.read(100) == b""
    assert time.monotonic() - t0 < 1.0


def test_read_respects_max_bytes(rig: StreamRig) -> None:
    rig.send(b"x" * 100)
    time.sleep(0.05)
    first = rig.stream.read(10)
    assert 1 <= len(first) <= 10
    assert _read_all(rig.stream, 100 - len(first)) == b"x" * (100 - len(first))


def test_write_reaches_device(rig: StreamRig) -> None:
    assert rig.stream.write(b"\xb5\x62hello") == 7
    assert rig.recv(7) == b"\xb5\x62hello"


def test_unplug_raises_link_lost(rig: StreamRig) -> None:
    """Pulling the cable (closing the pty master) makes read raise LinkLost, never hang or return junk."""
    rig.unplug()
    with pytest.raises(LinkLost):
        for _ in range(50):
            rig.stream.read(10)


def test_serial_open_missing_device_is_link_lost(tmp_path: os.PathLike[str]) -> None:
    from onboard.hw.serial_port import SerialByteStream

    with pytest.raises(LinkLost, match="cannot open"):
        SerialByteStream(str(tmp_path) + "/no-such-tty")


def test_serial_reopen_at_new_baud() -> None:
    from onboard.hw.serial_port import SerialByteStream

    master, slave = os.openpty()
    try:
        s = SerialByteStream(os.ttyname(slave), 9600, read_timeout_s=0.05)
        s.reopen(115200)
        assert s.baud == 115200
        os.write(master, b"abc")
        assert _read_all(s, 3) == b"abc"
        s.close()
        with pytest.raises(LinkLost):
            s.read(1)
    finally:
        os.close(master)
        os.close(slave)


# -- EdgeSource contract ------------------------------------------------------------------------------------
@dataclass
class EdgeRig:
    source: EdgeSource
    toggle: Callable[[bool], None]  # drive the line to high (True) / low (False)


@pytest.fixture(params=["fake", "gpiozero-mock"])
def edge_rig(request: pytest.FixtureRequest) -> Iterator[EdgeRig]:
    if request.param == "fake":
        src = FakeEdgeSource()
        clock = ManualClock()

        def toggle(high: bool) -> None:
            clock.advance_ns(1000)
            src.push(Edge("trigger", high, clock.monotonic_ns()))

        yield EdgeRig(src, toggle)
        src.close()
    else:
        from gpiozero.pins.mock import MockFactory

        from onboard.hw.gpio_edges import GpioEdgeSource

        factory = MockFactory()
        gsrc = GpioEdgeSource(17, factory, line="trigger")
        pin = factory.pin(17)

        def toggle(high: bool) -> None:
            if high:
                pin.drive_high()
            else:
                pin.drive_low()

        yield EdgeRig(gsrc, toggle)
        gsrc.close()
        factory.reset()


def test_edges_in_order_with_increasing_times(edge_rig: EdgeRig) -> None:
    for _ in range(3):
        edge_rig.toggle(True)
        edge_rig.toggle(False)
    edges = [edge_rig.source.get(1.0) for _ in range(6)]
    assert all(e is not None for e in edges)
    assert [e.rising for e in edges if e] == [True, False] * 3
    times = [e.monotonic_ns for e in edges if e]
    assert times == sorted(times) and len(set(times)) == 6
    assert all(e.line == "trigger" for e in edges if e)


def test_no_edge_times_out(edge_rig: EdgeRig) -> None:
    t0 = time.monotonic()
    assert edge_rig.source.get(0.1) is None
    assert 0.05 < time.monotonic() - t0 < 1.0


def test_gpio_edge_time_is_the_change_tick_not_the_read_time() -> None:
    """The edge carries the pin factory's tick of the change, even when read much later."""
    from gpiozero.pins.mock import MockFactory

    from onboard.hw.gpio_edges import GpioEdgeSource

    factory = MockFactory()
    try:
        src = GpioEdgeSource(5, factory, line="trigger")
        before = time.monotonic_ns()
        factory.pin(5).drive_high()
        after = time.monotonic_ns()
        time.sleep(0.2)
        edge = src.get(1.0)
        assert edge is not None and edge.rising
        assert before <= edge.monotonic_ns <= after
        src.close()
    finally:
        factory.reset()
