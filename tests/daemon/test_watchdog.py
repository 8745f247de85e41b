"""sd_notify from the running recorder: READY, WATCHDOG while alive (even unplugged), none when the writer wedges."""

from __future__ import annotations

import os
import socket
import threading
import time
from pathlib import Path

import pytest

from onboard.errors import LinkLost
from onboard.hw.fake import FakeByteStream
from onboard.logger.files import AppendFile, OsFileLayer
from onboard.recorder.daemon import RecorderDeps
from onboard.recorder.sdnotify import SdNotifier
from tests.daemon.helpers import RunningRecorder, make_settings, numbered_frame, wait_until

pytestmark = pytest.mark.timeout(60)


class NotifySocket:
    """A service manager's notify socket: collects every datagram with its arrival time."""

    def __init__(self, path: Path) -> None:
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind(str(path))
        self.sock.settimeout(0.05)
        self.messages: list[tuple[float, str]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self.messages.append((time.monotonic(), self.sock.recv(4096).decode()))
            except TimeoutError:
                continue

    def pets_between(self, t0: float, t1: float) -> int:
        return sum(1 for t, m in list(self.messages) if t0 <= t <= t1 and "WATCHDOG=1" in m.split("\n"))

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        self.sock.close()


def notifier(path: Path) -> SdNotifier:
    return SdNotifier({"NOTIFY_SOCKET": str(path), "WATCHDOG_USEC": "400000", "WATCHDOG_PID": str(os.getpid())})


@pytest.mark.slow
def test_unplugged_receiver_keeps_petting(tmp_path: Path) -> None:
    """No receiver at all: the writer is idle but alive, so systemd must not restart us."""
    srv = NotifySocket(tmp_path / "notify")

    def never() -> FakeByteStream:
        raise LinkLost("no such device")

    settings = make_settings(tmp_path, watchdog_writer_stall_s=0.5, port_reopen_max_s=2.0)
    run = RunningRecorder(settings, RecorderDeps(open_port=never, notifier=notifier(tmp_path / "notify")))
    wait_until(lambda: any("READY=1" in m for _, m in srv.messages), what="READY=1")
    time.sleep(3.0)  # longer than the largest reopen backoff
    now = time.monotonic()
    assert srv.pets_between(now - 2.5, now) >= 8  # every 0.2 s
    assert any("port" in m and "no such device" in m for _, m in srv.messages)  # STATUS names the problem
    assert run.stop() == 0
    # the datagram is sent before stop() returns; this socket's reader thread may take it a moment later
    wait_until(lambda: any("STOPPING=1" in m for _, m in srv.messages), timeout_s=5.0, what="STOPPING=1")
    srv.close()


@pytest.mark.slow
def test_wedged_writer_stops_petting(tmp_path: Path) -> None:
    """An fsync that never returns (a dead SD card): the loop still runs, but no WATCHDOG=1 goes out."""
    release = threading.Event()
    wedge = threading.Event()

    class WedgingLayer(OsFileLayer):
        def create(self, path: Path) -> AppendFile:
            handle = super().create(path)
            orig = handle.fsync

            def fsync() -> None:
                if wedge.is_set():
                    release.wait()
                orig()

            handle.fsync = fsync  # type: ignore[method-assign]
            return handle

    srv = NotifySocket(tmp_path / "notify")
    stream = FakeByteStream()
    settings = make_settings(tmp_path, watchdog_writer_stall_s=0.5, receiver_configure=False)
    run = RunningRecorder(settings, RecorderDeps(open_port=lambda: stream, files=WedgingLayer(),
                                                 notifier=notifier(tmp_path / "notify")))
    wait_until(lambda: any("READY=1" in m for _, m in srv.messages), what="READY=1")
    time.sleep(1.0)
    now = time.monotonic()
    assert srv.pets_between(now - 1.0, now) >= 3
    wedge.set()
    stream.feed(numbered_frame(1))  # the next interval sync wedges the writer thread
    time.sleep(2.0)
    now = time.monotonic()
    assert srv.pets_between(now - 1.0, now) == 0
    release.set()
    time.sleep(0.6)
    now = time.monotonic()
    assert srv.pets_between(now - 0.4, now) >= 1  # alive again: petting resumes
    assert run.stop() == 0
    srv.close()
