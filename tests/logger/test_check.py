"""`check_flight` / `python -m onboard check`: clean, torn and tampered flights."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from onboard.hw.fake import ManualClock
from onboard.logger.check import check_flight
from onboard.logger.events import EventLog
from onboard.logger.files import RecordingFileLayer
from onboard.logger.journal import EVENTS_NAME, Journal, JournalOptions
from onboard.receiver.framing import ubx_frame

PROJECT = Path(__file__).resolve().parents[2]


def make_flight(path: Path, n: int = 20, segment_max_bytes: int = 0) -> None:
    """A closed flight as the recorder leaves it: journal segments, their indexes, an event log, the manifest."""
    clock = ManualClock()
    j = Journal(path, clock, JournalOptions(segment_max_bytes=segment_max_bytes))
    events = EventLog(path / EVENTS_NAME, clock)
    for k in range(n):
        j.append(ubx_frame(2, 0x10, bytes([k]) * 30), clock.monotonic_ns(), clock.wall_ns())
        if k % 5 == 0:
            events.append({"type": "mark", "k": k, "tow_ns": 123_000_000 * k})
        clock.advance_s(0.1)
    events.close()
    j.close()


def test_clean_flight_is_ok(tmp_path: Path) -> None:
    make_flight(tmp_path / "f")
    r = check_flight(tmp_path / "f")
    assert r.ok and r.closed and r.segments[0].frames == 20 and r.segments[0].hash_ok
    assert r.segments[0].torn_tail_bytes == 0 and r.segments[0].index_records == 20


def test_torn_flight_after_power_cut_is_ok_with_torn_tail(tmp_path: Path) -> None:
    clock = ManualClock()
    files = RecordingFileLayer()
    j = Journal(tmp_path / "f", clock, files=files)
    for k in range(10):
        j.append(ubx_frame(2, 0x10, bytes([k]) * 30), clock.monotonic_ns(), clock.wall_ns())
    j.sync_now()
    j.append(ubx_frame(2, 0x10, bytes(30))[:12], clock.monotonic_ns(), clock.wall_ns())
    j.sync_now()  # the torn half-frame reached the disk
    files.cut_to_sync_points()
    Journal(tmp_path / "f", clock).close()  # restart + recovery + clean stop
    (tmp_path / "f" / EVENTS_NAME).write_bytes(b'{"type":"mark","k":1}\n{"type":"ma\n{"type":"mark","k":2}\n')
    r = check_flight(tmp_path / "f")
    assert r.ok, r.problems
    assert r.segments[0].torn_tail_bytes == 12 and r.segments[0].frames == 10
    assert r.events == 2 and r.events_torn_lines == 1  # a record the power cut tore: noted, not a problem


def test_tampered_segment_is_a_problem_and_cli_exits_1(tmp_path: Path) -> None:
    make_flight(tmp_path / "f")
    seg = tmp_path / "f" / "000000.ubx"
    data = bytearray(seg.read_bytes())
    data[50] ^= 0xFF
    seg.write_bytes(bytes(data))
    r = check_flight(tmp_path / "f")
    assert not r.ok and "SHA-256" in r.problems[0]
    env = dict(os.environ, PYTHONPATH=str(PROJECT))
    out = subprocess.run([sys.executable, "-m", "onboard", "check", str(tmp_path / "f")], capture_output=True,
                         text=True, env=env, cwd=PROJECT, timeout=60, check=False)
    assert out.returncode == 1 and "PROBLEM" in out.stdout
    make_flight(tmp_path / "g")
    out = subprocess.run([sys.executable, "-m", "onboard", "check", str(tmp_path / "g")], capture_output=True,
                         text=True, env=env, cwd=PROJECT, timeout=60, check=False)
    assert out.returncode == 0 and "1 segments" in out.stdout and "closed" in out.stdout


def _check_cli(flight: Path) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, PYTHONPATH=str(PROJECT))
    return subprocess.run([sys.executable, "-m", "onboard", "check", str(flight)], capture_output=True, text=True,
                          env=env, cwd=PROJECT, timeout=60, check=False)


def test_deleted_event_log_is_a_problem(tmp_path: Path) -> None:
    make_flight(tmp_path / "f")
    (tmp_path / "f" / EVENTS_NAME).unlink()
    r = check_flight(tmp_path / "f")
    assert r.problems == ["events.jsonl: event log missing (the camera marks and configuration results are lost)"]
    out = _check_cli(tmp_path / "f")
    assert out.returncode == 1 and "PROBLEM: events.jsonl: event log missing" in out.stdout


def test_event_log_truncated_with_garbage_is_a_problem(tmp_path: Path) -> None:
    make_flight(tmp_path / "f")
    log = tmp_path / "f" / EVENTS_NAME
    data = log.read_bytes()
    cut = data.index(b"\n") + 10  # within the second record
    log.write_bytes(data[:cut] + bytes(range(128, 256)) + b"\n" + b"\x00\xff garbage\n")
    r = check_flight(tmp_path / "f")
    assert not r.ok
    second = data.index(b"\n") + 1
    assert r.problems == [f"events.jsonl: 2 lines of garbage (not event records) at byte {second}, {cut + 129}"]
    out = _check_cli(tmp_path / "f")
    assert out.returncode == 1 and "PROBLEM: events.jsonl: 2 lines of garbage" in out.stdout


def test_closed_flights_event_log_cut_short_is_a_problem(tmp_path: Path) -> None:
    make_flight(tmp_path / "f")
    log = tmp_path / "f" / EVENTS_NAME
    data = log.read_bytes()
    log.write_bytes(data[: data.rindex(b"\n") - 5])
    r = check_flight(tmp_path / "f")
    assert "events.jsonl: cut short (a closed flight's log ends within a line)" in r.problems


def test_missing_index_is_a_problem(tmp_path: Path) -> None:
    make_flight(tmp_path / "f")
    (tmp_path / "f" / "000000.idx").unlink()
    r = check_flight(tmp_path / "f")
    assert r.problems == ["000000.idx: index missing (the host times of 000000.ubx are lost)"]
    assert _check_cli(tmp_path / "f").returncode == 1


def test_deleted_middle_segment_is_named(tmp_path: Path) -> None:
    make_flight(tmp_path / "f", n=40, segment_max_bytes=300)
    (tmp_path / "f" / "000002.ubx").unlink()
    r = check_flight(tmp_path / "f")
    assert "segment 000002.ubx missing between 000001.ubx and 000003.ubx" in r.problems
    assert "000002.ubx: listed in the manifest but missing" in r.problems


def test_not_a_directory_is_a_usage_error(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("x")
    out = _check_cli(tmp_path / "file")
    assert out.returncode == 2 and out.stderr.strip() == f"directgeo: check: error: {tmp_path / 'file'}: not a flight directory"


def test_index_truncated_or_with_garbage_is_a_problem(tmp_path: Path) -> None:
    make_flight(tmp_path / "f")
    idx = tmp_path / "f" / "000000.idx"
    whole = idx.read_bytes()
    idx.write_bytes(whole[:-5])
    r = check_flight(tmp_path / "f")
    expected = (f"000000.idx: truncated or extended ({len(whole) - 5} bytes, not whole 24-byte records) in a "
                "cleanly closed segment")
    assert r.problems == [expected]
    idx.write_bytes(whole + b"\xff" * 24)  # one more record, of garbage: it points beyond the data
    assert check_flight(tmp_path / "f").problems == ["000000.idx: index points beyond the data or goes backwards"]
