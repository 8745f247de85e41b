"""Shared helpers for the daemon tests: numbered UBX frames, an in-process recorder runner, polling."""

from __future__ import annotations

import asyncio
import subprocess
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from types import MappingProxyType
from typing import Any

from onboard.receiver.framing import ubx_frame
from onboard.recorder.daemon import Recorder, RecorderDeps
from onboard.recorder.feature import RecorderFeature
from onboard.recorder.settings import Settings

SEQ_CLASS_ID = (0x02, 0x10)  # RXM-RAW class/id; a payload of the wrong length just fails to decode (counted)


def numbered_frame(n: int, size: int = 24) -> bytes:
    """A checksum-valid UBX frame whose payload starts with its sequence number."""
    return ubx_frame(*SEQ_CLASS_ID, n.to_bytes(4, "little") + bytes(size - 4))


def frame_number(payload: bytes) -> int:
    """The sequence number in a `numbered_frame` payload."""
    return int.from_bytes(payload[:4], "little")


def tim_tm2(count: int, week: int = 2200, tow_ms: int = 100_000, sub_ns: int = 0) -> bytes:
    """A TIM-TM2 frame with a new falling edge (flash) on channel 0, GNSS time base, time valid."""
    flags = 0x04 | (1 << 3) | 0x40  # newFallingEdge, timeBase GNSS, time valid
    payload = (
        bytes((0, flags))
        + count.to_bytes(2, "little")
        + week.to_bytes(2, "little") * 2
        + (tow_ms).to_bytes(4, "little") + (sub_ns).to_bytes(4, "little")
        + (tow_ms).to_bytes(4, "little") + (sub_ns).to_bytes(4, "little")
        + (20).to_bytes(4, "little")
    )
    return ubx_frame(0x0D, 0x03, payload)


def make_settings(tmp_path: Path, **kw: Any) -> Settings:
    """Settings for in-process runs: fast status, no disk floor, short configuration timeouts."""
    base: dict[str, Any] = {
        "port_device": "fake",
        "data_dir": tmp_path / "data",
        "status_path": tmp_path / "run" / "status.json",
        "status_interval_s": 0.05,
        "disk_floor_mb": 0.0,
        "disk_check_interval_s": 0.05,
        "port_reopen_min_s": 0.05,
        "port_reopen_max_s": 0.2,
        "receiver_options": MappingProxyType({"ack_timeout_s": 0.2, "retries": 0}),
    }
    base.update(kw)
    return Settings(**base)


class RunningRecorder:
    """A Recorder running `run()` in its own thread and event loop."""

    def __init__(self, settings: Settings, deps: RecorderDeps, features: Sequence[RecorderFeature] = ()) -> None:
        self.recorder = Recorder(settings, deps, features)
        self.exit_code: int | None = None
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._main, daemon=True)
        self.thread.start()

    def _main(self) -> None:
        try:
            self.exit_code = asyncio.run(self.recorder.run())
        except BaseException as exc:  # noqa: BLE001 — surfaced to the test by stop()
            self.error = exc

    def stop(self, timeout_s: float = 10.0) -> int:
        """Ask for a clean stop (as SIGTERM does) and return the exit code."""
        loop = self.recorder._loop
        if loop is not None and not loop.is_closed() and self.thread.is_alive():
            loop.call_soon_threadsafe(self.recorder.request_stop, "test stop", 0)
        return self.join(timeout_s)

    def join(self, timeout_s: float = 10.0) -> int:
        self.thread.join(timeout_s)
        assert not self.thread.is_alive(), "recorder did not stop"
        if self.error is not None:
            raise self.error
        assert self.exit_code is not None
        return self.exit_code


def wait_until(cond: Callable[[], Any], timeout_s: float = 10.0, what: str = "condition") -> Any:
    """Poll `cond` until truthy; AssertionError naming `what` on timeout."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = cond()
        if value:
            return value
        time.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")


def status(path: Path) -> dict[str, Any]:
    """The status snapshot, or {} before the recorder wrote its first one."""
    from onboard.recorder.status import read_status

    try:
        return read_status(path)
    except FileNotFoundError:
        return {}


def reap(proc: subprocess.Popen[bytes]) -> None:
    """After a daemon test, whatever happened: the process killed if it still runs, waited for, and its
    piped stderr closed."""
    if proc.poll() is None:
        proc.kill()
        proc.wait()
    if proc.stderr is not None:
        proc.stderr.close()
