"""`check_flight` / `python -m onboard check`: clean, torn and tampered flights."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from onboard.hw.fake import ManualClock
from onboard.logger.check import check_flight
from onboard.logger.files import RecordingFileLayer
from onboard.logger.journal import Journal
from onboard.receiver.framing import ubx_frame

PROJECT = Path(__file__).resolve().parents[2]


def make_flight(path: Path, n: int = 20) -> None:
    clock = ManualClock()
    j = Journal(path, clock)
    for k in range(n):
        j.append(ubx_frame(2, 0x10, bytes([k]) * 30), clock.monotonic_ns(), clock.wall_ns())
        clock.advance_s(0.1)
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
    r = check_flight(tmp_path / "f")
    assert r.ok, r.problems
    assert r.segments[0].torn_tail_bytes == 12 and r.segments[0].frames == 10


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
