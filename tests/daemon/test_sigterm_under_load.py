"""SIGTERM stops the real daemon cleanly even right after a burst that left its event loop behind.

A wake-up of the loop per serial read used to fill asyncio's self-pipe during a burst; CPython writes the
signal wake-up to the same socket, so the SIGTERM was lost and `systemctl stop` would end in a SIGKILL and an
unclosed flight. A pty is fed 8 MB of RXM-RAWX-sized frames in 512-byte writes as fast as it takes them
(an hour of 5 Hz data in a few seconds), then SIGTERM: the daemon must exit 0 within 15 s with every byte
journaled and the flight closed.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import tty
from pathlib import Path

import pytest

from onboard.logger.journal import iter_journal_bytes, read_manifest
from onboard.receiver.framing import ubx_frame
from tests.daemon.helpers import reap, status, wait_until

PROJECT = Path(__file__).resolve().parents[2]
pytestmark = [pytest.mark.timeout(120), pytest.mark.slow]


def test_sigterm_after_a_burst_stops_cleanly(tmp_path: Path) -> None:
    frame = ubx_frame(0x02, 0x15, bytes(range(256)) * 2)  # 520 B, the size of a 16-measurement RXM-RAWX
    stream = frame * (8_000_000 // len(frame))
    master, slave = os.openpty()
    tty.setraw(slave)
    data_dir, status_path = tmp_path / "data", tmp_path / "status.json"
    env = dict(os.environ, PYTHONPATH=str(PROJECT))
    env.pop("NOTIFY_SOCKET", None)
    proc = subprocess.Popen(
        [sys.executable, "-m", "onboard", "run", "--no-configure", "--port", os.ttyname(slave),
         "--data-dir", str(data_dir), "--status", str(status_path)],
        cwd=PROJECT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
    )
    try:
        wait_until(lambda: status(status_path).get("port_open"), timeout_s=30, what="daemon ready")
        view = memoryview(stream)
        while view:
            view = view[os.write(master, view[:512]):]
        flight = wait_until(lambda: next(data_dir.glob("flight-*"), None), what="flight directory")
        wait_until(lambda: sum(p.stat().st_size for p in flight.glob("*.ubx")) >= len(stream), timeout_s=60,
                   what="every byte journaled")
        proc.send_signal(signal.SIGTERM)
        t0 = time.monotonic()
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            pytest.fail("the daemon ignored SIGTERM after a burst (lost signal wake-up)")
        assert proc.returncode == 0, proc.stderr.read().decode(errors="replace")[-2000:]  # type: ignore[union-attr]
        assert time.monotonic() - t0 < 15
    finally:
        reap(proc)
        os.close(master)
        os.close(slave)
    manifest = read_manifest(flight)
    assert manifest is not None and manifest.closed
    assert b"".join(iter_journal_bytes(flight)) == stream
