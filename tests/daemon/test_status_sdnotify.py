"""Status snapshot atomicity and completeness; sd_notify over a real datagram socket; the watchdog gate."""

from __future__ import annotations

import os
import socket
import threading
from pathlib import Path

import pytest

from onboard.recorder.sdnotify import SdNotifier, WatchdogGate
from onboard.recorder.status import STATUS_SCHEMA, SatelliteStatus, StatusSnapshot, read_status, write_status


def test_status_roundtrip_and_schema(tmp_path: Path) -> None:
    snap = StatusSnapshot(pid=1, state="recording", satellites=[SatelliteStatus(0, 5, 43.0)], epochs=3)
    write_status(tmp_path / "s.json", snap)
    got = read_status(tmp_path / "s.json")
    assert got["schema"] == STATUS_SCHEMA and got["epochs"] == 3
    assert got["satellites"] == [{"gnss_id": 0, "sv_id": 5, "cn0_dbhz": 43.0}]
    (tmp_path / "x.json").write_text('{"schema": "other"}')
    with pytest.raises(ValueError):
        read_status(tmp_path / "x.json")


@pytest.mark.slow
def test_status_readers_never_see_a_partial_file(tmp_path: Path) -> None:
    """A reader polling while the writer rewrites 500 times always parses a complete snapshot."""
    path = tmp_path / "s.json"
    write_status(path, StatusSnapshot())
    stop = threading.Event()
    bad: list[str] = []

    def reader() -> None:
        while not stop.is_set():
            try:
                read_status(path)
            except ValueError as exc:
                bad.append(str(exc))

    t = threading.Thread(target=reader)
    t.start()
    for i in range(500):
        write_status(path, StatusSnapshot(bytes_recorded=i, satellites=[SatelliteStatus(0, k, 40.0) for k in range(30)]))
    stop.set()
    t.join()
    assert bad == []
    assert read_status(path)["bytes_recorded"] == 499
    assert [p.name for p in tmp_path.iterdir()] == ["s.json"]  # no temp files left behind


@pytest.mark.parametrize("abstract", [False, True])
def test_sd_notify_reaches_a_real_socket(tmp_path: Path, abstract: bool) -> None:
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    if abstract:
        name = f"directgeo-test-{os.getpid()}"
        srv.bind(b"\0" + name.encode())
        env = {"NOTIFY_SOCKET": "@" + name}
    else:
        srv.bind(str(tmp_path / "notify"))
        env = {"NOTIFY_SOCKET": str(tmp_path / "notify")}
    srv.settimeout(2)
    n = SdNotifier(env)
    assert n.enabled
    assert n.notify(READY=1, STATUS="recording")
    assert srv.recv(4096) == b"READY=1\nSTATUS=recording"
    assert n.notify(WATCHDOG=1)
    assert srv.recv(4096) == b"WATCHDOG=1"
    n.close()
    srv.close()


def test_sd_notify_disabled_and_broken() -> None:
    assert not SdNotifier({}).notify(READY=1)
    n = SdNotifier({"NOTIFY_SOCKET": "/nonexistent/dir/sock"})
    assert not n.notify(READY=1)  # a vanished manager socket is logged, never raised
    assert n.errors == 1


def test_watchdog_usec_only_for_our_pid() -> None:
    assert SdNotifier({"WATCHDOG_USEC": "20000000"}).watchdog_usec == 20_000_000
    assert SdNotifier({"WATCHDOG_USEC": "20000000", "WATCHDOG_PID": str(os.getpid())}).watchdog_usec == 20_000_000
    assert SdNotifier({"WATCHDOG_USEC": "20000000", "WATCHDOG_PID": "1"}).watchdog_usec is None


def test_watchdog_gate_idle_writer_pets_wedged_writer_does_not() -> None:
    g = WatchdogGate(stale_ns=5_000_000_000)
    assert not g.should_pet(0)  # nothing has run yet
    g.loop_beat(1_000)
    g.writer_beat(1_000)
    assert g.should_pet(2_000_000_000)
    # loop keeps running, writer stuck in fsync for 6 s: no pet
    g.loop_beat(7_000_000_000)
    assert not g.should_pet(7_000_000_000)
    # writer goes round again (e.g. an idle read timeout on an unplugged port): pet again
    g.writer_beat(7_100_000_000)
    assert g.should_pet(7_200_000_000)
    # a wedged loop stops petting too
    assert not g.should_pet(13_000_000_000)
