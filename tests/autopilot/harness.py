"""The hil_sim autopilot core and the companion's `AutopilotLink` joined in memory (no pty, no socket): the
link's own thread against the stand-in stepped in simulated time, for fault tests that need no daemon."""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Self

from hil_sim.autopilot import AutopilotCore, AutopilotSimOptions
from onboard.autopilot.corrections import CorrectionsPipe
from onboard.autopilot.feature import AutopilotLink, AutopilotOptions


class _End:
    """The companion's side: a ByteStream over two queues."""

    def __init__(self, rx: queue.Queue[bytes], tx: queue.Queue[bytes]) -> None:
        self.rx, self.tx = rx, tx

    def read(self, max_bytes: int) -> bytes:
        try:
            return self.rx.get(timeout=0.05)
        except queue.Empty:
            return b""

    def write(self, data: bytes) -> int:
        self.tx.put(bytes(data))
        return len(data)

    def close(self) -> None:
        pass


class Joined:
    """Stand-in (simulated time at `speed`× real time) ↔ AutopilotLink; `run_until(predicate)`."""

    def __init__(self, tmp: Path, sim: AutopilotSimOptions, link: AutopilotOptions | None = None,
                 speed: float = 4.0, corrections: CorrectionsPipe | None = None, flight: Any = None) -> None:
        self.core = AutopilotCore(sim, flight)
        self.speed = speed
        self.to_link: queue.Queue[bytes] = queue.Queue()
        self.to_sim: queue.Queue[bytes] = queue.Queue()
        self.events: list[dict[str, Any]] = []
        self.link = AutopilotLink(link or AutopilotOptions(link_timeout_s=1.5, rerequest_s=1.5), self._open,
                                  corrections=corrections)
        self.tmp = tmp
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sim, daemon=True)
        self._t0 = 0.0

    def _open(self) -> _End:
        return _End(self.to_link, self.to_sim)

    def sim_time(self) -> float:
        return (time.monotonic() - self._t0) * self.speed

    def _sim(self) -> None:
        while not self._stop.is_set():
            t = self.sim_time()
            while not self.to_sim.empty():
                self.core.receive(self.to_sim.get(), t)
            for frame in self.core.step(t):
                self.to_link.put(frame)
            time.sleep(0.005)

    def __enter__(self) -> Self:
        self._t0 = time.monotonic()
        self.link.start(self.tmp, self.events.append)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self.link.stop()

    def run_until(self, predicate: Callable[[dict[str, Any]], bool], timeout_s: float, what: str) -> dict[str, Any]:
        """Poll the link's snapshot until `predicate` holds; AssertionError naming `what` after `timeout_s`."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            snap = self.link.snapshot()
            if predicate(snap):
                return snap
            time.sleep(0.05)
        raise AssertionError(f"{what}: not reached in {timeout_s} s; last snapshot {self.link.snapshot()}")
