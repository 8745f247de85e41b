"""Reassembled GPS_RTCM_DATA bytes handed from the autopilot link's thread to the real-time RTK service as a
base-correction `ByteStream` (`rtk.base_stream = "mavlink"`): the RTK service journals and decodes them exactly
as it does the telemetry radio's bytes."""

from __future__ import annotations

import collections
import threading


class CorrectionsPipe:
    """A bounded, thread-safe queue of RTCM blocks: `put` from the link thread, `open()` → the RTK side's stream.

    Full (`max_blocks` waiting, the RTK service stalled): the oldest block is dropped and counted, so the
    freshest corrections win and the link thread never blocks.
    """

    def __init__(self, max_blocks: int = 512) -> None:
        self._blocks: collections.deque[bytes] = collections.deque()
        self._max = max_blocks
        self._cond = threading.Condition()
        self.dropped_blocks = 0
        self.blocks_in = 0

    def put(self, block: bytes) -> None:
        """One complete RTCM3 block (never blocks)."""
        with self._cond:
            if len(self._blocks) >= self._max:
                self._blocks.popleft()
                self.dropped_blocks += 1
            self._blocks.append(block)
            self.blocks_in += 1
            self._cond.notify_all()

    def open(self, read_timeout_s: float = 0.1) -> CorrectionsStream:
        """The reading end, a ByteStream (the RTK service's `open_radio` factory)."""
        return CorrectionsStream(self, read_timeout_s)

    def take(self, max_bytes: int, timeout_s: float) -> bytes:
        """Up to `max_bytes` of whole blocks (at least one block if any arrives within `timeout_s`)."""
        with self._cond:
            if not self._blocks:
                self._cond.wait(timeout_s)
            out = bytearray()
            while self._blocks and (not out or len(out) + len(self._blocks[0]) <= max_bytes):
                out += self._blocks.popleft()
            return bytes(out)


class CorrectionsStream:
    """The RTK service's view of the pipe: `read` waits up to the timeout; nothing is ever written back
    (read-only toward the autopilot: we never inject corrections into it)."""

    def __init__(self, pipe: CorrectionsPipe, read_timeout_s: float) -> None:
        self._pipe = pipe
        self._timeout_s = read_timeout_s

    def read(self, max_bytes: int) -> bytes:
        """The next RTCM bytes, b"" when none arrived within the timeout."""
        return self._pipe.take(max_bytes, self._timeout_s)

    def write(self, data: bytes) -> int:
        """Refuses: corrections never go back to the autopilot (0 bytes written)."""
        return 0

    def close(self) -> None:
        """Nothing to release: the pipe belongs to the autopilot feature."""
