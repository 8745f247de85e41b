"""Synthetic, CRC-valid RTCM3 frames of chosen total lengths (for GPS_RTCM_DATA tests)."""

from __future__ import annotations

import random

from onboard.receiver.framing import crc24q

HEADER_CRC_BYTES = 6


def rtcm_frame(total_bytes: int, seed: int, msg_type: int = 4001) -> bytes:
    """A CRC-valid RTCM3 frame of exactly `total_bytes` (preamble, 10-bit length, payload starting with a
    12-bit message number, CRC-24Q); the payload's other bytes are seeded noise."""
    payload_len = total_bytes - HEADER_CRC_BYTES
    rng = random.Random(seed)
    payload = bytes([msg_type >> 4, ((msg_type & 0xF) << 4) | rng.randrange(16)]) + rng.randbytes(payload_len - 2)
    head = bytes([0xD3, (payload_len >> 8) & 0x03, payload_len & 0xFF]) + payload
    return head + crc24q(head).to_bytes(3, "big")
