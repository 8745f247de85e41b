"""A bounded, thread-safe queue of edges: what every EdgeSource hands to its reader."""

from __future__ import annotations

import collections
import threading
import time

from onboard.hw.ports import Edge


class EdgeQueue:
    """Edges in arrival order; the oldest is dropped (and counted in `dropped`) when `max_len` is reached."""

    def __init__(self, max_len: int | None = None) -> None:
        self._edges: collections.deque[Edge] = collections.deque()
        self._max_len = max_len
        self._cond = threading.Condition()
        self.dropped = 0
        self.closed = False

    def put(self, edge: Edge) -> None:
        """Queue an edge (from any thread, e.g. a GPIO callback)."""
        with self._cond:
            if self._max_len is not None and len(self._edges) >= self._max_len:
                self._edges.popleft()
                self.dropped += 1
            self._edges.append(edge)
            self._cond.notify_all()

    def get(self, timeout_s: float) -> Edge | None:
        """The next edge, waiting up to `timeout_s` (monotonic clock); None on timeout or after close."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while not self._edges:
                left = deadline - time.monotonic()
                if left <= 0 or self.closed:
                    return None
                self._cond.wait(left)
            return self._edges.popleft()

    def close(self) -> None:
        """Stop delivering edges and wake any waiting reader."""
        with self._cond:
            self.closed = True
            self._cond.notify_all()
