"""The recorder's feature seam (onboard.recorder.feature) and its one-recorder-per-data-directory lock."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import pytest

from onboard.hw.fake import FakeByteStream
from onboard.logger.events import read_events
from onboard.logger.journal import iter_journal_bytes, read_manifest
from onboard.receiver.framing import Frame
from onboard.recorder.daemon import EXIT_IN_USE, LOCK_NAME, Recorder, RecorderDeps
from onboard.recorder.feature import FlightContext, RecorderFeature
from onboard.recorder.status import read_status
from tests.daemon.helpers import (
    RunningRecorder,
    make_settings,
    numbered_frame,
    reap,
    status,
    tim_tm2,
    wait_until,
)

pytestmark = pytest.mark.timeout(60)


class Probe(RecorderFeature):
    """Records every hook call, in order, with the thread it ran on."""

    status_name = "probe.json"

    def __init__(self, name: str = "probe") -> None:
        self.name = name
        self.calls: list[str] = []
        self.frames = 0
        self.byte_count = 0
        self.flight: FlightContext | None = None
        self.threads: set[str] = set()
        self.journal_open_at_start: bool | None = None
        self.posted: list[str] = []

    def _note(self, what: str) -> None:
        if not self.calls or self.calls[-1] != what:
            self.calls.append(what)
        self.threads.add(threading.current_thread().name)

    def on_flight_opened(self, flight: FlightContext) -> None:
        self._note("opened")
        self.flight = flight
        # a feature's own thread hands a result back to the loop through the recorder's post function
        threading.Thread(target=flight.post, args=(self.posted.append, "from my thread"), daemon=True).start()

    def on_bytes(self, data: bytes, rx_monotonic_ns: int) -> None:
        self._note("bytes")
        self.byte_count += len(data)

    def on_frame(self, frame: Frame) -> None:
        self._note("frame")
        self.frames += 1

    def on_decoded(self, item: Any) -> None:
        self._note("decoded")

    def status(self) -> dict[str, Any]:
        return {"frames": self.frames, "bytes": self.byte_count}

    def on_flight_closing(self, reason: str) -> None:
        self._note(f"closing:{reason}")
        assert self.flight is not None and self.flight.append_event is not None
        self.flight.append_event({"type": "probe", "event": "last words", "reason": reason})

    def on_flight_closed(self, reason: str) -> None:
        self._note(f"closed:{reason}")


class Broken(RecorderFeature):
    """A feature whose every hook raises."""

    name = "broken"
    status_name = "broken.json"

    def on_flight_opened(self, flight: FlightContext) -> None:
        raise RuntimeError("cannot open")

    def on_frame(self, frame: Frame) -> None:
        raise ZeroDivisionError("bug in on_frame")

    def status(self) -> dict[str, Any]:
        raise KeyError("bug in status")

    def on_flight_closed(self, reason: str) -> None:
        raise RuntimeError("cannot close")


def test_features_get_the_lifecycle_in_order_and_a_broken_one_never_stops_recording(tmp_path: Path) -> None:
    stream = FakeByteStream()
    settings = make_settings(tmp_path, receiver_configure=False)
    probe = Probe()
    run = RunningRecorder(settings, RecorderDeps(open_port=lambda: stream), [Broken(), probe])
    sent = b"".join(numbered_frame(n) for n in range(50)) + tim_tm2(1)  # 51 frames, the last one decodes
    stream.feed(sent)
    wait_until(lambda: status(settings.status_path).get("frames") == 51, what="51 frames")
    wait_until(lambda: probe.posted, what="the post from the feature's thread")
    wait_until(lambda: json.loads((settings.status_path.with_name("probe.json")).read_text()).get("frames") == 51
               if settings.status_path.with_name("probe.json").exists() else False, what="probe.json")
    assert run.stop() == 0
    flight = next(settings.data_dir.glob("flight-*"))
    assert b"".join(iter_journal_bytes(flight)) == sent  # every byte recorded, whatever the broken feature did
    assert probe.calls[0] == "opened" and probe.calls[-2:] == ["closing:test stop", "closed:test stop"]
    assert set(probe.calls[1:-2]) == {"bytes", "frame", "decoded"} and probe.frames == 51
    assert probe.calls[-3] == "decoded"  # the TIM-TM2: its frame, then its decoded item
    # the closing hook's record is in the flight's event log (still open then), before the flight's close
    records = read_events(flight / "events.jsonl").records
    assert {"type": "probe", "event": "last words", "reason": "test stop"} in records
    assert probe.byte_count == len(sent) and probe.posted == ["from my thread"]
    assert len(probe.threads) == 1 and "recorder-reader" not in probe.threads  # every hook on the loop
    assert probe.flight is not None and probe.flight.flight_dir == flight
    assert probe.flight.status_path == settings.status_path
    st = read_status(settings.status_path)
    # opened + 51 frames + every status snapshot + closed: all counted, under the feature's name
    assert st["feature_errors"]["broken"] >= 1 + 51 + 1 + 1 and "probe" not in st["feature_errors"]
    assert not settings.status_path.with_name("broken.json").exists()
    assert json.loads(settings.status_path.with_name("probe.json").read_text()) == {"frames": 51,
                                                                                   "bytes": len(sent)}
    m = read_manifest(flight)
    assert m is not None and m.closed


def test_feature_names_must_be_distinct(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="distinct names"):
        Recorder(make_settings(tmp_path), RecorderDeps(open_port=FakeByteStream), [Probe(), Probe()])


def test_a_second_recorder_on_the_same_data_dir_refuses_and_leaves_the_first_untouched(tmp_path: Path) -> None:
    stream = FakeByteStream()
    settings = make_settings(tmp_path, receiver_configure=False)
    first = RunningRecorder(settings, RecorderDeps(open_port=lambda: stream))
    stream.feed(numbered_frame(0))
    wait_until(lambda: status(settings.status_path).get("frames") == 1, what="the first recorder recording")
    flight = next(settings.data_dir.glob("flight-*"))
    manifest_before = (flight / "manifest.json").read_bytes()
    status_before = settings.status_path.read_bytes()
    other = tmp_path / "other-run"
    second_settings = make_settings(tmp_path, receiver_configure=False, status_path=other / "status.json")
    second = RunningRecorder(second_settings, RecorderDeps(open_port=FakeByteStream))
    assert second.join() == EXIT_IN_USE
    assert second.recorder.refused == f"{settings.data_dir} is in use by another recorder (pid {os.getpid()})"
    # the second one touched nothing: no flight of its own, no status, the first's manifest as it was
    assert sorted(settings.data_dir.glob("flight-*")) == [flight]
    assert (flight / "manifest.json").read_bytes() == manifest_before
    assert not other.exists() or not (other / "status.json").exists()
    stream.feed(numbered_frame(1))
    wait_until(lambda: status(settings.status_path).get("frames") == 2, what="the first recorder still recording")
    assert status_before != settings.status_path.read_bytes()
    assert first.stop() == 0
    assert b"".join(iter_journal_bytes(flight)) == numbered_frame(0) + numbered_frame(1)
    # once the first has stopped, the directory is free again
    stream2 = FakeByteStream()
    third = RunningRecorder(settings, RecorderDeps(open_port=lambda: stream2))
    wait_until(lambda: status(settings.status_path).get("state") == "recording", what="the third recorder")
    assert third.stop() == 0


@pytest.mark.slow
def test_two_recorder_processes_the_second_exits_2_with_one_error_line(tmp_path: Path) -> None:
    """Two `python -m onboard run` on one data directory (real processes; the port is a pty that stays silent)."""
    import pty

    master, slave = pty.openpty()
    data_dir = tmp_path / "data"

    def start(name: str) -> subprocess.Popen[bytes]:
        return subprocess.Popen([sys.executable, "-m", "onboard", "run", "--port", os.ttyname(slave),
                                 "--no-configure", "--data-dir", str(data_dir),
                                 "--status", str(tmp_path / name / "status.json")],
                                stderr=subprocess.PIPE, stdout=subprocess.DEVNULL)

    first = start("a")
    try:
        wait_until(lambda: status(tmp_path / "a" / "status.json").get("state") == "recording", timeout_s=30,
                   what="the first recorder recording")
        flight = next(data_dir.glob("flight-*"))
        manifest_before = (flight / "manifest.json").read_bytes()
        second = start("b")
        try:
            _, err = second.communicate(timeout=30)
        finally:
            reap(second)
        assert second.returncode == 2
        assert f"directgeo: run: error: {data_dir} is in use by another recorder (pid {first.pid})" in err.decode()
        assert "Traceback" not in err.decode()
        assert (flight / "manifest.json").read_bytes() == manifest_before
        assert sorted(data_dir.glob("flight-*")) == [flight] and first.poll() is None
        assert (data_dir / LOCK_NAME).read_text().strip() == str(first.pid)
    finally:
        first.terminate()
        first.wait(20)
        reap(first)
        os.close(master)
        os.close(slave)
    assert first.returncode == 0
    m = read_manifest(flight)
    assert m is not None and m.closed


def test_a_lock_file_that_cannot_be_opened_is_a_clear_error(tmp_path: Path) -> None:
    """`.lock` cannot be opened (here: a directory of that name; in the field a read-only data directory):
    exit 1, the status says why, and nothing is recorded."""
    from onboard.recorder.daemon import EXIT_IO_ERROR

    settings = make_settings(tmp_path, receiver_configure=False)
    (settings.data_dir / LOCK_NAME).mkdir(parents=True)
    run = RunningRecorder(settings, RecorderDeps(open_port=FakeByteStream))
    assert run.join() == EXIT_IO_ERROR
    st = status(settings.status_path)
    assert st["state"] == "error" and st["message"].startswith(f"cannot lock the data directory {settings.data_dir}")
    assert not list(settings.data_dir.glob("flight-*"))
