"""In-memory test doubles for the hardware seams: ByteStream, Clock, EdgeSource.

They ship in the package (not in tests) so every area and the simulator can pass them through constructors.
"""

from __future__ import annotations

import threading
import time

from onboard.errors import LinkLost
from onboard.hw.edge_queue import EdgeQueue
from onboard.hw.ports import Edge


class ManualClock:
    """A clock that moves only when told to (`advance_s`, `advance_ns`, `set_ns`)."""

    def __init__(self, monotonic_ns: int = 1_000_000_000, wall_ns: int = 1_700_000_000_000_000_000) -> None:
        self._mono_ns = monotonic_ns
        self._wall_offset_ns = wall_ns - monotonic_ns

    def monotonic_ns(self) -> int:
        """The current manual monotonic time in ns."""
        return self._mono_ns

    def wall_ns(self) -> int:
        """Wall time: the monotonic time plus a fixed offset (use `step_wall_s` to model a clock step)."""
        return self._mono_ns + self._wall_offset_ns

    def advance_ns(self, ns: int) -> None:
        """Move both clocks forward by `ns`."""
        if ns < 0:
            raise ValueError("a monotonic clock never goes back")
        self._mono_ns += ns

    def advance_s(self, seconds: float) -> None:
        """Move both clocks forward by `seconds`."""
        self.advance_ns(round(seconds * 1e9))

    def step_wall_s(self, seconds: float) -> None:
        """Step only the wall clock (as chrony does), leaving the monotonic clock alone."""
        self._wall_offset_ns += round(seconds * 1e9)


class FakeByteStream:
    """An in-memory ByteStream: `feed` queues bytes for `read`; `written` collects what was written.

    `read` waits up to `timeout_s` for data (returning b"" on silence), and raises `LinkLost` after `unplug`.
    Thread-safe, so a test thread can feed while a reader thread reads.
    """

    def __init__(self, timeout_s: float = 0.05) -> None:
        self.timeout_s = timeout_s
        self._rx = bytearray()
        self.written = bytearray()
        self._cond = threading.Condition()
        self._unplugged = False
        self.closed = False

    def feed(self, data: bytes) -> None:
        """Queue bytes the 'device' sends."""
        with self._cond:
            self._rx += data
            self._cond.notify_all()

    def unplug(self) -> None:
        """Make every later read/write raise LinkLost (the cable was pulled)."""
        with self._cond:
            self._unplugged = True
            self._cond.notify_all()

    def read(self, max_bytes: int) -> bytes:
        """Up to `max_bytes` queued bytes; b"" after `timeout_s` of silence; LinkLost when unplugged."""
        deadline = time.monotonic() + self.timeout_s
        with self._cond:
            while True:
                if self._unplugged or self.closed:
                    raise LinkLost("fake stream unplugged" if self._unplugged else "fake stream closed")
                if self._rx:
                    out = bytes(self._rx[:max_bytes])
                    del self._rx[:max_bytes]
                    return out
                left = deadline - time.monotonic()
                if left <= 0:
                    return b""
                self._cond.wait(left)

    def write(self, data: bytes) -> int:
        """Collect written bytes; LinkLost when unplugged."""
        with self._cond:
            if self._unplugged or self.closed:
                raise LinkLost("fake stream unplugged")
            self.written += data
            return len(data)

    def close(self) -> None:
        """Close; later reads raise LinkLost."""
        with self._cond:
            self.closed = True
            self._cond.notify_all()


class FakeEdgeSource:
    """An EdgeSource fed by the test (`push`)."""

    def __init__(self) -> None:
        self._queue = EdgeQueue()

    @property
    def closed(self) -> bool:
        """True after `close`."""
        return self._queue.closed

    def push(self, edge: Edge) -> None:
        """Queue an edge."""
        self._queue.put(edge)

    def get(self, timeout_s: float) -> Edge | None:
        """The next queued edge, waiting up to `timeout_s`; None on timeout or after close."""
        return self._queue.get(timeout_s)

    def close(self) -> None:
        """Stop delivering edges."""
        self._queue.close()
