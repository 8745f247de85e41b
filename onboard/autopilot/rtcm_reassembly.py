"""GPS_RTCM_DATA (MAVLink 233) fragments → complete RTCM3 byte blocks (pure: no I/O, no clock).

A ground station injects RTCM3 as GPS_RTCM_DATA: `flags` bit 0 = fragmented, bits 1–2 = fragment id (0–3),
bits 3–7 = sequence id (0–31, one per RTCM message); `data` holds up to 180 bytes, `len` of them used. A message
of more than 180 bytes is split into at most 4 fragments of 180 bytes, the last shorter; one of exactly 180·k
bytes (k < 4) ends with an empty fragment (facts from common.xml and ArduPilot `handle_gps_rtcm_fragment`).

The rule here is "lose a message, never deliver a wrong one": a sequence that is not complete when another
sequence id (or an unfragmented message) arrives is dropped and counted, so is one with a repeated fragment or
a fragment past its last. Downstream, the RTCM3 framer checks each message's CRC-24Q as well.
"""

from __future__ import annotations

from dataclasses import dataclass

FRAGMENT_DATA_BYTES = 180
"""Payload capacity of one GPS_RTCM_DATA message (bytes)."""
MAX_FRAGMENTS = 4
"""Fragments per RTCM message at most (fragment id has 2 bits): 720 bytes."""


def split_flags(flags: int) -> tuple[bool, int, int]:
    """`flags` → (fragmented, fragment id 0–3, sequence id 0–31)."""
    return bool(flags & 1), (flags >> 1) & 0x3, (flags >> 3) & 0x1F


def make_flags(fragmented: bool, fragment_id: int, sequence_id: int) -> int:
    """The `flags` byte of one fragment (the inverse of `split_flags`)."""
    if not 0 <= fragment_id < MAX_FRAGMENTS or not 0 <= sequence_id < 32:
        raise ValueError(f"fragment id {fragment_id} / sequence id {sequence_id}: must be 0–3 / 0–31")
    return int(fragmented) | (fragment_id << 1) | (sequence_id << 3)


def fragment_rtcm(message: bytes, sequence_id: int) -> list[tuple[int, bytes]]:
    """One RTCM message → the (flags, data) of its GPS_RTCM_DATA messages, as a ground station sends them
    (MAVProxy's rule: a 180·k-byte message ends with an empty fragment). ValueError above 720 bytes."""
    n = len(message)
    if n > FRAGMENT_DATA_BYTES * MAX_FRAGMENTS:
        raise ValueError(f"RTCM message of {n} bytes: must be at most {FRAGMENT_DATA_BYTES * MAX_FRAGMENTS} bytes "
                         "to fit GPS_RTCM_DATA")
    if n < FRAGMENT_DATA_BYTES:
        return [(make_flags(False, 0, sequence_id % 32), message)]
    chunks = [message[i:i + FRAGMENT_DATA_BYTES] for i in range(0, n, FRAGMENT_DATA_BYTES)]
    if n % FRAGMENT_DATA_BYTES == 0 and len(chunks) < MAX_FRAGMENTS:
        chunks.append(b"")
    return [(make_flags(True, i, sequence_id % 32), c) for i, c in enumerate(chunks)]


@dataclass
class ReassemblyStats:
    """Counters: `fragments` received, `messages` delivered, `dropped` incomplete or inconsistent sequences,
    `bytes_out` RTCM bytes delivered."""

    fragments: int = 0
    messages: int = 0
    dropped: int = 0
    bytes_out: int = 0


class GpsRtcmReassembler:
    """Feed GPS_RTCM_DATA (`flags`, `data[:len]`) in arrival order; get complete RTCM3 blocks back."""

    def __init__(self) -> None:
        self.stats = ReassemblyStats()
        self._sequence: int | None = None
        self._parts: dict[int, bytes] = {}
        self._count: int | None = None  # fragments in the pending message, once its last one arrived

    def feed(self, flags: int, data: bytes) -> list[bytes]:
        """One GPS_RTCM_DATA message; returns the RTCM blocks it completes (0 or 1)."""
        fragmented, fragment_id, sequence_id = split_flags(flags)
        self.stats.fragments += 1
        if len(data) > FRAGMENT_DATA_BYTES:
            self._drop()
            self.stats.dropped += 1
            return []
        if not fragmented:
            self._drop()
            return self._deliver(bytes(data))
        if sequence_id != self._sequence:
            self._drop()
            self._sequence = sequence_id
        if fragment_id in self._parts:
            # a fragment seen twice: the message was sent again (or two messages share a sequence id); what is
            # held cannot be trusted, start again from this fragment (as ArduPilot does)
            self._drop()
            self._sequence = sequence_id
        if self._count is not None and fragment_id >= self._count:
            self._drop()  # a fragment past the last one: two messages mixed
            return []
        self._parts[fragment_id] = bytes(data)
        if len(data) < FRAGMENT_DATA_BYTES or fragment_id == MAX_FRAGMENTS - 1:
            if any(i > fragment_id for i in self._parts):
                self._drop()  # fragments after a short one: two messages mixed
                return []
            self._count = fragment_id + 1
        if self._count is None or len(self._parts) < self._count:
            return []
        if any(len(self._parts[i]) != FRAGMENT_DATA_BYTES for i in range(self._count - 1)):
            self._drop()  # a short fragment before the last: two messages mixed
            return []
        block = b"".join(self._parts[i] for i in range(self._count))
        self._reset()
        return self._deliver(block) if block else []

    def flush(self) -> None:
        """Drop (and count) a pending incomplete sequence, e.g. when the link was lost."""
        self._drop()

    @property
    def pending(self) -> bool:
        """Whether fragments of an incomplete message are held."""
        return bool(self._parts)

    def _deliver(self, block: bytes) -> list[bytes]:
        self.stats.messages += 1
        self.stats.bytes_out += len(block)
        return [block]

    def _drop(self) -> None:
        if self._parts:
            self.stats.dropped += 1
        self._reset()

    def _reset(self) -> None:
        self._sequence = None
        self._parts = {}
        self._count = None
