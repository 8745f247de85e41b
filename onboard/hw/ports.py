"""The small interfaces every piece of hardware hides behind, and the real system clock."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Protocol, runtime_checkable


@runtime_checkable
class ByteStream(Protocol):
    """A bidirectional byte stream (serial port, pseudo-terminal, socket).

    `read` returns up to `max_bytes` bytes, b"" when nothing arrived within the stream's timeout, and raises
    `onboard.errors.LinkLost` when the device has gone away. `write` returns the count written.
    """

    def read(self, max_bytes: int) -> bytes: ...

    def write(self, data: bytes) -> int: ...

    def close(self) -> None: ...


@runtime_checkable
class Clock(Protocol):
    """Host clocks in integer nanoseconds: monotonic for timeouts and ordering, wall for humans only."""

    def monotonic_ns(self) -> int: ...

    def wall_ns(self) -> int: ...


class SystemClock:
    """The host's real clocks."""

    def monotonic_ns(self) -> int:
        """CLOCK_MONOTONIC in ns."""
        return time.monotonic_ns()

    def wall_ns(self) -> int:
        """CLOCK_REALTIME in ns (jumps when chrony steps it: never use for timeouts)."""
        return time.time_ns()


@dataclass(frozen=True, slots=True)
class Edge:
    """One logic-level change on an input line.

    `line` names the input (e.g. "trigger", a BCM pin number as text); `rising` True for low→high;
    `monotonic_ns` when it happened on the host monotonic clock (kernel line-event timestamp on a Pi).
    """

    line: str
    rising: bool
    monotonic_ns: int


@runtime_checkable
class EdgeSource(Protocol):
    """Timestamped edges from an input line (GPIO or a test double).

    `get` returns the next edge in order, waiting up to `timeout_s`, or None when none arrived.
    """

    def get(self, timeout_s: float) -> Edge | None: ...

    def close(self) -> None: ...
