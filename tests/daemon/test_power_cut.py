"""Power-cut model: the real daemon (subprocess) records a pty we write numbered frames and TIM-TM2 marks into;
at random moments it is SIGKILLed and every journal, index and events file is cut back to its last fsync'd
length (the daemon runs with ONBOARD_TEST_SYNC_LOG, a file layer that logs each fsync), then it restarts.

A SIGKILL alone leaves the page cache intact and cannot catch a missing fsync; the cut does. Checked at the
end: every frame sent more than 1 s before a cut and every time mark sent more than 0.2 s before it survive,
intact and in order, and every reader accepts the torn tails.
"""

from __future__ import annotations

import os
import random
import subprocess
import sys
import time
from pathlib import Path

import pytest

from onboard.logger.events import read_events
from onboard.logger.files import cut_files, sync_points_from_log
from onboard.logger.journal import iter_journal_frames, list_segments, read_index, read_manifest
from onboard.receiver.decode import iter_journal
from tests.daemon.helpers import SEQ_CLASS_ID, frame_number, numbered_frame, reap, status, tim_tm2, wait_until

PROJECT = Path(__file__).resolve().parents[2]
CYCLES = 4
FRAME_PERIOD_S = 0.01
MARK_EVERY = 130  # frames between TIM-TM2 marks (~1.3 s: the interval sync must carry the frames between)
pytestmark = [pytest.mark.timeout(120), pytest.mark.slow]


def test_power_cuts_lose_nothing_older_than_a_second(tmp_path: Path) -> None:
    rng = random.Random(20261123)
    master, slave = os.openpty()  # the test keeps the slave open so the pty outlives each daemon
    port = os.ttyname(slave)
    os.set_blocking(master, False)
    data_dir, status_path, sync_log = tmp_path / "data", tmp_path / "status.json", tmp_path / "sync.log"
    cfg = tmp_path / "r.toml"
    cfg.write_text("[journal]\nsync_interval_s = 0.5\ndisk_floor_mb = 1.0\n[status]\ninterval_s = 0.1\n")
    env = dict(os.environ, PYTHONPATH=str(PROJECT), ONBOARD_TEST_SYNC_LOG=str(sync_log))
    cmd = [sys.executable, "-m", "onboard", "run", "--config", str(cfg), "--port", port, "--no-configure",
           "--data-dir", str(data_dir), "--status", str(status_path)]
    seq = 0
    mark_count = 0
    must_frames: set[int] = set()
    must_marks: set[int] = set()
    try:
        for cycle in range(CYCLES + 1):
            proc = subprocess.Popen(cmd, cwd=PROJECT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
            try:
                pid = proc.pid
                wait_until(lambda: (s := status(status_path)).get("pid") == pid and s.get("port_open"),  # noqa: B023
                           timeout_s=30, what="daemon ready")
                sent: list[tuple[int, float]] = []
                marks: list[tuple[int, float]] = []
                run_s = rng.uniform(2.0, 4.0)
                t_end = time.monotonic() + run_s
                while time.monotonic() < t_end:
                    data = numbered_frame(seq, size=40)
                    sent.append((seq, time.monotonic()))
                    seq += 1
                    if seq % MARK_EVERY == 0:
                        mark_count += 1
                        data += tim_tm2(mark_count, tow_ms=100_000 + 1300 * mark_count)
                        marks.append((mark_count, time.monotonic()))
                    os.write(master, data)
                    time.sleep(FRAME_PERIOD_S)
                if cycle == CYCLES:
                    proc.terminate()  # the last run ends cleanly: SIGTERM closes the flight
                    assert proc.wait(timeout=20) == 0
                    cut_at = time.monotonic()
                else:
                    time.sleep(rng.uniform(0.0, 0.3))
                    cut_at = time.monotonic()
                    proc.kill()
                    proc.wait(timeout=10)
                    cut = cut_files(sync_points_from_log(sync_log))  # the power loss
                    assert cut, "the sync log named no files"
            finally:
                reap(proc)
            must_frames |= {n for n, t in sent if t < cut_at - 1.0}
            must_marks |= {n for n, t in marks if t < cut_at - 0.2}
            # drain what the dead daemon never read (a real UART would have lost it as well)
            try:
                while os.read(master, 65536):
                    pass
            except BlockingIOError:
                pass
    finally:
        os.close(master)
        os.close(slave)

    flights = sorted(data_dir.glob("flight-*"))
    assert len(flights) == 1, "every restart resumes the unclosed flight"
    flight = flights[0]

    # every reader accepts the torn tails
    frames = list(iter_journal_frames(flight))
    numbers = [frame_number(f.payload) for f in frames if (f.msg_class, f.msg_id) == SEQ_CLASS_ID]
    mark_counts = [int.from_bytes(f.payload[2:4], "little") for f in frames if (f.msg_class, f.msg_id) == (0x0D, 3)]
    decoded = list(iter_journal(flight))
    for seg in list_segments(flight):
        read_index(seg.with_suffix(".idx"))
    events = read_events(flight / "events.jsonl")

    # intact and in order, nothing older than a second lost, every time mark kept
    assert numbers == sorted(set(numbers)), "frames duplicated or out of order"
    assert must_frames - set(numbers) == set(), f"lost {len(must_frames - set(numbers))} frames older than 1 s"
    assert mark_counts == sorted(set(mark_counts))
    assert must_marks - set(mark_counts) == set(), "time marks lost"
    event_counts = [r["count"] for r in events.records if r.get("kind") == "mark"]
    assert must_marks - set(event_counts) == set(), "time-mark events lost"
    # pairing continues across restarts: image indices never repeat or go back
    indices = [r["index"] for r in events.records if r.get("kind") == "pairing"]
    assert indices == sorted(set(indices)) and len(indices) >= len(must_marks) - 1
    assert len(decoded) >= len(mark_counts)  # the decoder also read through every torn tail
    assert len(must_frames) > 500 and len(must_marks) >= 4

    # the manifest lists every segment with its true size, the torn ones marked recovered
    manifest = read_manifest(flight)
    assert manifest is not None and manifest.closed and manifest.restarts == CYCLES
    segs = list_segments(flight)
    assert [s.name for s in manifest.segments] == [p.name for p in segs]
    assert all(s.bytes == p.stat().st_size for s, p in zip(manifest.segments, segs))
    assert sum(s.recovered for s in manifest.segments) >= 1
