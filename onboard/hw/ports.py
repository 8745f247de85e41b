"""The small interfaces every piece of hardware hides behind, and the real system clock."""

from __future__ import annotations

import time
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
