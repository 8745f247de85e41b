"""The recorder's roll-over (in process, fake receiver): a feature asks to close the flight while bytes stream
in; the flight closes (segments hashed, final manifest, close record), the next opens, and not one byte is lost
or doubled between them. Features see on_flight_closed(rollover) then on_flight_opened(next)."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from onboard.hw.fake import FakeByteStream
from onboard.logger.events import read_events
from onboard.logger.journal import iter_journal_bytes, read_manifest
from onboard.recorder.daemon import RecorderDeps, new_flight_dir
from onboard.recorder.feature import FlightContext, RecorderFeature, is_rollover
from onboard.upload.queue import UploadQueue
from tests.daemon.helpers import RunningRecorder, make_settings, numbered_frame, wait_until


class Spy(RecorderFeature):
    """Records its hooks; `close()` asks the recorder to roll over (from a thread, as the autopilot link does)."""

    name = "spy"

    def __init__(self) -> None:
        self.calls: list[tuple[str, Any]] = []
        self.context: FlightContext | None = None

    def on_flight_opened(self, flight: FlightContext) -> None:
        self.calls.append(("opened", (flight.flight_dir.name, flight.previous_flight_dir, flight.resumed)))
        self.context = flight

    def on_flight_closed(self, reason: str) -> None:
        self.calls.append(("closed", reason))

    def close(self, why: str) -> None:
        assert self.context is not None and self.context.close_flight is not None
        self.context.post(self.context.close_flight, why)


@pytest.mark.slow
def test_rollover_loses_no_byte(tmp_path: Path) -> None:
    port = FakeByteStream()
    settings = make_settings(tmp_path, upload_url="http://127.0.0.1:9", upload_token_file=str(tmp_path / "t"))
    spy = Spy()
    rec = RunningRecorder(settings, RecorderDeps(open_port=lambda: port), [spy])
    sent = bytearray()
    stop = threading.Event()

    def stream() -> None:  # a frame every ms, written in odd pieces so frames straddle the switch
        n = 0
        while not stop.is_set():
            frame = numbered_frame(n, 40)
            for i in range(0, len(frame), 17):
                port.feed(frame[i:i + 17])
                sent.extend(frame[i:i + 17])
            n += 1
            time.sleep(0.001)

    feeder = threading.Thread(target=stream, daemon=True)
    try:
        wait_until(lambda: spy.context is not None, 10, "flight opened")
        feeder.start()
        time.sleep(0.5)
        spy.close("landed")
        wait_until(lambda: len(spy.calls) >= 3, 10, "roll-over")
        time.sleep(0.5)
        stop.set()
        feeder.join()
        wait_until(lambda: rec.recorder.status.bytes_recorded == len(sent), 10, "every byte read")
    finally:
        stop.set()
        assert rec.stop() == 0
    flights = sorted((tmp_path / "data").glob("flight-*"))
    assert len(flights) == 2
    first, second = flights
    recorded = [b"".join(iter_journal_bytes(f)) for f in flights]
    assert len(recorded[0]) > 1000 and len(recorded[1]) > 1000
    assert recorded[0] + recorded[1] == bytes(sent)  # no gap, no byte twice
    m1, m2 = read_manifest(first), read_manifest(second)
    assert m1 is not None and m2 is not None
    assert m1.closed and is_rollover(m1.close_reason or "") and "landed" in (m1.close_reason or "")
    assert m2.closed and m2.close_reason == "test stop"
    assert sum(s.bytes for s in m1.segments) == len(recorded[0]) and all(s.sha256 for s in m1.segments)
    assert spy.calls == [("opened", (first.name, None, False)), ("closed", m1.close_reason),
                         ("opened", (second.name, first, False)), ("closed", "test stop")]
    closing = [r for r in read_events(first / "events.jsonl").records if r.get("type") == "flight"]
    assert closing[-1]["event"] == "closed" and closing[-1]["next_flight"] == second.name
    opening = [r for r in read_events(second / "events.jsonl").records if r.get("type") == "flight"]
    assert opening[0]["event"] == "opened" and opening[0]["previous_flight"] == first.name
    queue = UploadQueue(tmp_path / "data")
    assert [(e.flight, e.ready) for e in queue.entries()] == [(first.name, True), (second.name, True)]
    status = json.loads(settings.status_path.read_text())
    assert status["flight"] == second.name


def test_a_crash_between_queueing_and_closing_is_promoted_at_the_next_start(tmp_path: Path) -> None:
    """A marker left not ready (power cut after the journal closed) becomes ready once the flight is closed."""
    data = tmp_path / "data"
    settings = make_settings(tmp_path, upload_url="http://127.0.0.1:9", upload_token_file=str(tmp_path / "t"))
    port = FakeByteStream()
    rec = RunningRecorder(settings, RecorderDeps(open_port=lambda: port))
    port.feed(numbered_frame(1))
    wait_until(lambda: rec.recorder.status.bytes_recorded > 0, 10, "bytes")
    assert rec.stop() == 0
    (flight,) = data.glob("flight-*")
    queue = UploadQueue(data)
    queue.enqueue(flight.name, False, 0)  # as if the power went between the marker and the ready rewrite
    assert queue.next_ready() is None
    rec = RunningRecorder(settings, RecorderDeps(open_port=lambda: FakeByteStream()))
    wait_until(lambda: queue.next_ready() is not None, 10, "promoted")
    assert rec.stop() == 0
    assert queue.entries()[0].flight == flight.name


def test_new_flight_names_sort_after_the_newest(tmp_path: Path) -> None:
    (tmp_path / "flight-20300101T000000Z").mkdir()
    d = new_flight_dir(tmp_path, 0)  # a wall clock back in 1970 (a Pi without RTC before NTP)
    assert d.name > "flight-20300101T000000Z"
    d.mkdir()
    assert new_flight_dir(tmp_path, 0).name > d.name


@pytest.mark.slow
def test_real_time_rtk_starts_again_in_the_next_flight(tmp_path: Path) -> None:
    """RtkFeature's service cannot start twice: after a roll-over a fresh one runs in the new flight."""
    from onboard.realtime.service import RtkFeature, RtkServiceOptions

    rtk = RtkFeature(RtkServiceOptions(), None)
    spy = Spy()
    rec = RunningRecorder(make_settings(tmp_path), RecorderDeps(open_port=lambda: FakeByteStream()), [spy, rtk])
    try:
        wait_until(lambda: spy.context is not None, 10, "flight opened")
        first = rtk.rtk
        spy.close("landed")
        wait_until(lambda: len(spy.calls) >= 3, 10, "roll-over")

        def fresh_service_running() -> bool:
            # the spy sees the new flight before the RTK feature (features run in order): wait for the latter
            svc = rtk.rtk
            return (svc is not first and svc.flight_dir is not None and bool(svc._threads)
                    and all(t.is_alive() for t in svc._threads))

        wait_until(fresh_service_running, 10, "the next flight's RTK service running")
        assert rtk.rtk.flight_dir.name == spy.calls[2][1][0]
    finally:
        assert rec.stop() == 0
    flights = sorted((tmp_path / "data").glob("flight-*"))
    assert [(f / "solution.pos").is_file() for f in flights] == [True, True]
