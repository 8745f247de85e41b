"""A telemetry radio link between the base station and the drone: two ptys, dropouts and an air byte budget.

Whatever the base side writes into `tx_path` comes out of `rx_path` (and the reverse is not modelled: a
one-way correction link), except:
- during a dropout (gaps of `gap_min_s`…`gap_max_s`, uniformly drawn, starting after exponentially
  distributed intervals of mean `mean_interval_s`; all in simulated time, reproducible from `seed`) every
  byte is lost;
- a chunk written when the air budget (air baud/10 B/s of simulated time, `buffer_bytes` burst) cannot take it
  is lost whole (radios send packets; an over-full packet buffer drops whole packets).

`RadioChannel` is the pure part (schedule, budget, counters); `RadioLink` the thread that moves the bytes.
"""

from __future__ import annotations

import logging
import os
import select
import threading
import tty
from dataclasses import dataclass

import numpy as np

from hil_sim.receiver import TxBudget
from onboard.hw.ports import Clock, SystemClock

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RadioOptions:
    """Air rate and dropout statistics of the link (simulated seconds)."""

    air_baud: int = 19200
    buffer_bytes: int = 2048
    mean_interval_s: float = 120.0
    gap_min_s: float = 5.0
    gap_max_s: float = 20.0
    seed: int = 0

    def __post_init__(self) -> None:
        if not 0 < self.gap_min_s <= self.gap_max_s:
            raise ValueError(f"need 0 < gap_min_s ≤ gap_max_s, got {self.gap_min_s}, {self.gap_max_s}")
        if self.mean_interval_s <= 0 or self.air_baud <= 0:
            raise ValueError("mean_interval_s and air_baud must be > 0")


class RadioChannel:
    """Which bytes get through, as a function of simulated time since the link started (s)."""

    def __init__(self, options: RadioOptions) -> None:
        self.options = options
        self._rng = np.random.default_rng(options.seed)
        self._gaps: list[tuple[float, float]] = []
        self._horizon_s = 0.0
        self.budget = TxBudget(options.air_baud, options.buffer_bytes)
        self._t_last_s = 0.0
        self.bytes_in = 0
        self.bytes_out = 0
        self.bytes_lost_dropout = 0
        self.bytes_lost_budget = 0

    def gaps_until(self, t_s: float) -> list[tuple[float, float]]:
        """Dropout windows (start_s, end_s) drawn so far, extended to cover `t_s`."""
        o = self.options
        while self._horizon_s <= t_s:
            start = self._horizon_s + float(self._rng.exponential(o.mean_interval_s))
            end = start + float(self._rng.uniform(o.gap_min_s, o.gap_max_s))
            self._gaps.append((start, end))
            self._horizon_s = end
        return list(self._gaps)

    def in_dropout(self, t_s: float) -> bool:
        """True while the link is down."""
        return any(a <= t_s < b for a, b in self.gaps_until(t_s))

    def pass_chunk(self, t_s: float, data: bytes) -> bytes:
        """The part of `data` (written at `t_s`) that reaches the far end: all of it or nothing."""
        self.budget.refill(t_s - self._t_last_s)
        self._t_last_s = max(self._t_last_s, t_s)
        self.bytes_in += len(data)
        if self.in_dropout(t_s):
            self.bytes_lost_dropout += len(data)
            return b""
        if not self.budget.take(len(data)):
            self.bytes_lost_budget += len(data)
            return b""
        self.bytes_out += len(data)
        return data


class RadioLink:
    """Two ptys: the base side writes to `tx_path`, the drone side reads `rx_path`; a thread forwards bytes."""

    def __init__(self, options: RadioOptions | None = None, speed: float = 1.0, clock: Clock | None = None) -> None:
        self.channel = RadioChannel(options or RadioOptions())
        self.speed = speed
        self.clock = clock or SystemClock()
        self._fds: list[int] = []
        self.tx_path = ""
        self.rx_path = ""
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._mono0 = 0

    def _pty(self) -> tuple[int, int, str]:
        m, s = os.openpty()
        tty.setraw(s)
        os.set_blocking(m, False)
        self._fds += [m, s]
        return m, s, os.ttyname(s)

    def start(self) -> tuple[str, str]:
        """Create both ptys and start forwarding; returns (tx_path, rx_path)."""
        self._tx_master, _, self.tx_path = self._pty()
        self._rx_master, _, self.rx_path = self._pty()
        self._mono0 = self.clock.monotonic_ns()
        self._thread = threading.Thread(target=self._run, name="hil-radio", daemon=True)
        self._thread.start()
        return self.tx_path, self.rx_path

    def elapsed_s(self) -> float:
        """Simulated seconds since start."""
        return (self.clock.monotonic_ns() - self._mono0) * self.speed / 1e9

    def _run(self) -> None:
        while not self._stop.is_set():
            r, _, _ = select.select([self._tx_master], [], [], 0.05)
            if not r:
                continue
            try:
                data = os.read(self._tx_master, 4096)
            except BlockingIOError:
                continue
            out = self.channel.pass_chunk(self.elapsed_s(), data)
            if out:
                try:
                    os.write(self._rx_master, out)
                except BlockingIOError:
                    self.channel.bytes_lost_budget += len(out)  # nobody reads the drone side

    def stop(self) -> None:
        """Stop forwarding and close both ptys."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        for fd in self._fds:
            os.close(fd)
        self._fds.clear()
