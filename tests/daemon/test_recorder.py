"""The recorder in-process over fake byte streams: every byte recorded whatever the receiver does."""

from __future__ import annotations

import errno
import json
from pathlib import Path
from types import MappingProxyType

import pytest

from onboard.errors import LinkLost
from onboard.hw.fake import FakeByteStream
from onboard.logger.journal import iter_journal_bytes, read_manifest
from onboard.receiver.ubx_tables import poll_frame
from onboard.recorder.daemon import EXIT_DISK_FULL, RecorderDeps
from onboard.recorder.status import read_status
from tests.daemon.helpers import RunningRecorder, make_settings, numbered_frame, status, tim_tm2, wait_until

pytestmark = pytest.mark.timeout(60)


def recorded(data_dir: Path) -> bytes:
    flights = sorted(data_dir.glob("flight-*"))
    return b"".join(b"".join(iter_journal_bytes(f)) for f in flights)


def test_silent_receiver_everything_recorded_and_status_names_the_problem(tmp_path: Path) -> None:
    """A receiver that never answers configuration: every byte it sends is recorded, status says MON-VER."""
    stream = FakeByteStream()
    settings = make_settings(tmp_path)
    run = RunningRecorder(settings, RecorderDeps(open_port=lambda: stream))
    sent = b""
    for n in range(200):
        chunk = numbered_frame(n) + (b"\x00garbage\xb5" if n % 17 == 0 else b"")
        stream.feed(chunk)
        sent += chunk
    wait_until(lambda: status(settings.status_path).get("config_state") == "failed", what="config failure")
    wait_until(lambda: status(settings.status_path).get("bytes_recorded") == len(sent), what="all bytes")
    assert run.stop() == 0
    assert recorded(settings.data_dir) == sent
    st = read_status(settings.status_path)
    assert st["state"] == "stopped"
    assert "MON-VER" in st["config_error"] and "no answer" in st["config_error"]
    assert st["frames"] == 200 and st["skipped_bytes"] > 0
    # the recorder did ask: MON-VER polls went out (then a baud probe, harmless on a fake port)
    assert poll_frame("MON-VER") in bytes(stream.written)
    m = read_manifest(next(settings.data_dir.glob("flight-*")))
    assert m is not None and m.closed and m.close_reason == "test stop"
    assert m.config_report is not None and m.config_report["ok"] is False


def test_port_disappears_and_returns_flight_continues_and_config_is_reapplied(tmp_path: Path) -> None:
    first, second = FakeByteStream(), FakeByteStream()
    opens = {"n": 0}

    def open_port() -> FakeByteStream:
        opens["n"] += 1
        if opens["n"] == 1:
            return first
        if opens["n"] < 5:
            raise LinkLost("no such device (unplugged)")
        return second

    settings = make_settings(tmp_path)
    run = RunningRecorder(settings, RecorderDeps(open_port=open_port))
    first.feed(b"".join(numbered_frame(n) for n in range(10)))
    wait_until(lambda: status(settings.status_path).get("frames") == 10, what="first frames")
    first.unplug()
    wait_until(lambda: status(settings.status_path).get("state") == "port_lost", what="port_lost state")
    st = read_status(settings.status_path)
    assert "unplugged" in st["port_error"] and not st["port_open"]
    wait_until(lambda: opens["n"] >= 5, what="reopen attempts")
    second.feed(b"".join(numbered_frame(n) for n in range(10, 20)))
    wait_until(lambda: status(settings.status_path).get("frames") == 20, what="frames after reconnect")
    st = read_status(settings.status_path)
    assert st["state"] == "recording" and st["port_open"] and st["port_reconnects"] == 1
    # configuration is attempted again on the new connection
    wait_until(lambda: poll_frame("MON-VER") in bytes(second.written), what="re-detection after reconnect")
    assert run.stop() == 0
    assert len(list(settings.data_dir.glob("flight-*"))) == 1  # one flight across the outage
    assert recorded(settings.data_dir) == b"".join(numbered_frame(n) for n in range(20))


@pytest.mark.slow
def test_time_mark_is_fsynced_at_once(tmp_path: Path) -> None:
    """A TIM-TM2 triggers an immediate fsync, well before the 1 s sync interval."""
    from onboard.logger.files import RecordingFileLayer

    files = RecordingFileLayer()
    stream = FakeByteStream()
    settings = make_settings(tmp_path, journal_sync_interval_s=1.0, receiver_configure=False)
    run = RunningRecorder(settings, RecorderDeps(open_port=lambda: stream, files=files))
    wait_until(lambda: run.recorder.journal is not None and run.recorder.journal.current_segment, what="journal")
    seg = run.recorder.journal.current_segment  # type: ignore[union-attr]
    first = numbered_frame(0)
    stream.feed(first)
    wait_until(lambda: files.synced_bytes.get(seg, 0) == len(first), timeout_s=3, what="interval sync")
    # just synced: the interval rule would wait ~1 s; the mark must not
    more = numbered_frame(1) + tim_tm2(7)
    stream.feed(more)
    wait_until(lambda: files.synced_bytes.get(seg, 0) == len(first) + len(more), timeout_s=0.5,
               what="fsync right after the time mark")
    st = wait_until(lambda: (s := status(settings.status_path)).get("time_marks") == 1 and s, what="mark count")
    assert st["last_mark_gpst"] is not None
    assert run.stop() == 0


def test_refuses_to_start_below_disk_floor(tmp_path: Path) -> None:
    settings = make_settings(tmp_path, disk_floor_mb=500.0)
    run = RunningRecorder(settings, RecorderDeps(open_port=FakeByteStream, disk_free=lambda _p: 100_000_000))
    assert run.join() == EXIT_DISK_FULL
    assert list(settings.data_dir.glob("flight-*")) == []  # nothing was started
    st = read_status(settings.status_path)
    assert st["state"] == "disk_full" and "refusing to start" in st["message"] and "500.0 MB" in st["message"]


def test_disk_fills_while_recording_flight_closed_cleanly(tmp_path: Path) -> None:
    free = {"bytes": 10**10}
    stream = FakeByteStream()
    settings = make_settings(tmp_path, disk_floor_mb=200.0)
    run = RunningRecorder(settings, RecorderDeps(open_port=lambda: stream, disk_free=lambda _p: free["bytes"]))
    stream.feed(b"".join(numbered_frame(n) for n in range(50)))
    wait_until(lambda: status(settings.status_path).get("frames") == 50, what="frames")
    free["bytes"] = 150_000_000
    assert run.join() == EXIT_DISK_FULL
    flight = next(settings.data_dir.glob("flight-*"))
    m = read_manifest(flight)
    assert m is not None and m.closed and m.close_reason == "disk full"
    assert m.segments[-1].bytes == 50 * len(numbered_frame(0))
    st = read_status(settings.status_path)
    assert st["state"] == "disk_full" and "disk full" in st["message"]
    assert recorded(settings.data_dir) == b"".join(numbered_frame(n) for n in range(50))


def test_enospc_from_the_file_system_stops_with_disk_full(tmp_path: Path) -> None:
    """The file system says ENOSPC before our floor check does: stop, exit 3, keep what was written."""
    from onboard.logger.files import OsFileLayer

    class FillingLayer(OsFileLayer):
        budget = 5000

        def create(self, path: Path):  # type: ignore[no-untyped-def]
            handle = super().create(path)
            layer = self
            orig = handle.append

            def append(data: bytes) -> None:
                if path.suffix == ".ubx":
                    layer.budget -= len(data)
                    if layer.budget < 0:
                        raise OSError(errno.ENOSPC, "No space left on device")
                orig(data)

            handle.append = append  # type: ignore[method-assign]
            return handle

    stream = FakeByteStream()
    settings = make_settings(tmp_path, receiver_configure=False)
    run = RunningRecorder(settings, RecorderDeps(open_port=lambda: stream, files=FillingLayer()))
    for n in range(400):
        stream.feed(numbered_frame(n))
    assert run.join() == EXIT_DISK_FULL
    st = read_status(settings.status_path)
    assert st["state"] == "disk_full" and "No space left" in st["message"]
    data = recorded(settings.data_dir)
    assert 0 < len(data) <= 5000 and b"".join(numbered_frame(n) for n in range(400)).startswith(data)


def test_status_snapshot_complete(tmp_path: Path) -> None:
    stream = FakeByteStream()
    settings = make_settings(tmp_path, receiver_configure=False)
    run = RunningRecorder(settings, RecorderDeps(open_port=lambda: stream))
    stream.feed(numbered_frame(0))
    wait_until(lambda: status(settings.status_path).get("frames") == 1, what="frame")
    st = json.loads(settings.status_path.read_bytes())
    for key in ("receiver_model", "receiver_sw_version", "config_state", "config_error", "bytes_recorded",
                "frames", "epochs", "last_epoch_gpst", "satellites", "time_marks", "disk_free_bytes",
                "flight", "segment", "state", "port_open"):
        assert key in st, key
    assert st["config_state"] == "disabled" and st["disk_free_bytes"] > 0 and st["segment"] == "000000.ubx"
    assert run.stop() == 0


def test_unwritable_data_dir_is_a_clear_error(tmp_path: Path) -> None:
    """The data directory cannot be written (read-only mount, wrong owner): exit 1, status says why."""
    from onboard.logger.files import OsFileLayer
    from onboard.recorder.daemon import EXIT_IO_ERROR

    class ReadOnlyLayer(OsFileLayer):
        def create(self, path: Path):  # type: ignore[no-untyped-def]
            raise OSError(errno.EROFS, "Read-only file system", str(path))

    settings = make_settings(tmp_path, receiver_configure=False)
    run = RunningRecorder(settings, RecorderDeps(open_port=FakeByteStream, files=ReadOnlyLayer()))
    assert run.join() == EXIT_IO_ERROR
    st = status(settings.status_path)
    assert st["state"] == "error" and "Read-only file system" in st["message"]


def test_aid_eph_backup_poll_after_the_first_fix_then_every_interval(tmp_path: Path) -> None:
    """After configuration is over (here: failed, the fake never answers) the first NAV-SOL with a 3D fix makes
    the recorder poll AID-EPH for all SVs once; further fixes do not, until `aid_eph_poll_s` has passed."""
    from hil_sim.ubx_encode import nav_sol
    from onboard.gnsstime import GpsTime
    from onboard.hw.fake import ManualClock

    clock = ManualClock()
    stream = FakeByteStream()
    settings = make_settings(tmp_path, receiver_options=MappingProxyType(
        {"ack_timeout_s": 0.1, "retries": 0, "aid_eph_poll_s": 60.0}))
    run = RunningRecorder(settings, RecorderDeps(open_port=lambda: stream, clock=clock))
    poll = poll_frame("AID-EPH")
    assert poll == bytes.fromhex("b5620b3100003cbf")
    t = GpsTime.from_week_tow_s(2300, 1000.0)

    def fix(dt_s: float, with_fix: bool = True) -> bytes:
        return nav_sol(t.add_s(dt_s), (3.9e6, 3.0e5, 5.0e6) if with_fix else None, (0.0, 0.0, 0.0), 8, 2.5, 1.6)

    try:
        stream.feed(fix(0.0, with_fix=False))  # a valid frame (no baud probe needed), no fix yet: no poll
        wait_until(lambda: status(settings.status_path).get("config_state") == "failed", timeout_s=20,
                   what="configuration over")
        assert status(settings.status_path)["frames"] == 1 and bytes(stream.written).count(poll) == 0
        stream.feed(fix(1.0))
        wait_until(lambda: bytes(stream.written).count(poll) == 1, what="first AID-EPH poll")
        stream.feed(fix(2.0) + fix(3.0))
        wait_until(lambda: status(settings.status_path).get("frames", 0) >= 4, what="more fixes")
        clock.advance_s(59.0)
        stream.feed(fix(4.0))
        wait_until(lambda: status(settings.status_path).get("frames", 0) >= 5, what="fix before the interval")
        assert bytes(stream.written).count(poll) == 1
        clock.advance_s(2.0)
        stream.feed(fix(5.0))
        wait_until(lambda: bytes(stream.written).count(poll) == 2, what="AID-EPH poll after the interval")
        wait_until(lambda: status(settings.status_path).get("aid_eph_polls") == 2, what="status counter")
    finally:
        assert run.stop() == 0
