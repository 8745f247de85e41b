"""Byte-level framing of mixed UBX / RTCM3 / NMEA streams with checksum checks and resynchronisation.

Pure and fast: no pyubx2. The framer never raises on bad input: corrupt or unknown bytes are skipped and
counted, and a torn frame at the end waits in the buffer for more bytes (or is reported by `flush`).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

# RTCM3 frames and Galileo I/NAV pages share the CRC-24Q: one implementation, in the core (re-exported here)
from onboard.rtk.navbits import crc24q

UBX_SYNC = b"\xb5\x62"
RTCM3_PREAMBLE = 0xD3
MAX_UBX_PAYLOAD = 8192
MAX_NMEA_LEN = 200


class Protocol(Enum):
    """Which protocol a frame belongs to."""

    UBX = "ubx"
    RTCM3 = "rtcm3"
    NMEA = "nmea"


@dataclass(frozen=True, slots=True)
class Frame:
    """One checksum-valid frame: its bytes and its byte offset in the stream fed to the framer.

    For UBX, `msg_class`/`msg_id` are set; for RTCM3, `msg_id` is the message number; NMEA has neither.
    """

    protocol: Protocol
    raw: bytes
    offset: int
    msg_class: int = -1
    msg_id: int = -1

    @property
    def payload(self) -> bytes:
        """The payload without header and checksum (UBX and RTCM3); the sentence for NMEA."""
        if self.protocol is Protocol.UBX:
            return self.raw[6:-2]
        if self.protocol is Protocol.RTCM3:
            return self.raw[3:-3]
        return self.raw


def ubx_checksum(body: bytes | bytearray) -> bytes:
    """The 8-bit Fletcher checksum (CK_A, CK_B) of class, id, length and payload."""
    a = b = 0
    for byte in body:
        a = (a + byte) & 0xFF
        b = (b + a) & 0xFF
    return bytes((a, b))


def ubx_frame(msg_class: int, msg_id: int, payload: bytes) -> bytes:
    """A complete UBX frame (sync, class, id, little-endian length, payload, checksum)."""
    body = bytes((msg_class, msg_id)) + len(payload).to_bytes(2, "little") + payload
    return UBX_SYNC + body + ubx_checksum(body)


class StreamFramer:
    """Incremental framer: `feed(bytes)` returns the complete valid frames found so far, in order.

    Statistics: `bytes_in`, `frames`, `skipped_bytes` (bytes that belonged to no valid frame),
    `bad_checksums`.
    """

    def __init__(self, protocols: frozenset[Protocol] = frozenset(Protocol)) -> None:
        self._buf = bytearray()
        self._base = 0  # stream offset of self._buf[0]
        self.protocols = protocols
        self.bytes_in = 0
        self.frames = 0
        self.skipped_bytes = 0
        self.bad_checksums = 0
        self.torn_tail_bytes = 0

    def feed(self, data: bytes) -> list[Frame]:
        """Append `data` and return every complete, checksum-valid frame now available."""
        self._buf += data
        self.bytes_in += len(data)
        out: list[Frame] = []
        buf = self._buf
        pos = 0
        n = len(buf)
        while pos < n:
            byte = buf[pos]
            if byte == 0xB5 and Protocol.UBX in self.protocols:
                if n - pos < 6:
                    break
                if buf[pos + 1] != 0x62:
                    pos += 1
                    self.skipped_bytes += 1
                    continue
                length = buf[pos + 4] | (buf[pos + 5] << 8)
                if length > MAX_UBX_PAYLOAD:
                    pos += 1
                    self.skipped_bytes += 1
                    continue
                end = pos + 8 + length
                if end > n:
                    break
                if ubx_checksum(buf[pos + 2 : end - 2]) != bytes(buf[end - 2 : end]):
                    self.bad_checksums += 1
                    pos += 1
                    self.skipped_bytes += 1
                    continue
                out.append(Frame(Protocol.UBX, bytes(buf[pos:end]), self._base + pos, buf[pos + 2], buf[pos + 3]))
                pos = end
            elif byte == RTCM3_PREAMBLE and Protocol.RTCM3 in self.protocols:
                if n - pos < 3:
                    break
                if buf[pos + 1] & 0xFC:
                    pos += 1
                    self.skipped_bytes += 1
                    continue
                length = ((buf[pos + 1] & 0x03) << 8) | buf[pos + 2]
                end = pos + 3 + length + 3
                if end > n:
                    break
                if crc24q(buf[pos : end - 3]) != int.from_bytes(buf[end - 3 : end], "big"):
                    self.bad_checksums += 1
                    pos += 1
                    self.skipped_bytes += 1
                    continue
                msg_no = (buf[pos + 3] << 4) | (buf[pos + 4] >> 4) if length >= 2 else -1
                out.append(Frame(Protocol.RTCM3, bytes(buf[pos:end]), self._base + pos, -1, msg_no))
                pos = end
            elif byte == 0x24 and Protocol.NMEA in self.protocols:  # '$'
                nl = buf.find(b"\n", pos, pos + MAX_NMEA_LEN)
                if nl < 0:
                    if n - pos < MAX_NMEA_LEN:
                        break
                    pos += 1
                    self.skipped_bytes += 1
                    continue
                sentence = bytes(buf[pos : nl + 1])
                if _nmea_valid(sentence):
                    out.append(Frame(Protocol.NMEA, sentence, self._base + pos))
                    pos = nl + 1
                else:
                    self.bad_checksums += 1
                    pos += 1
                    self.skipped_bytes += 1
            else:
                pos += 1
                self.skipped_bytes += 1
        del buf[:pos]
        self._base += pos
        self.frames += len(out)
        return out

    @property
    def pending(self) -> int:
        """Bytes held back waiting for the rest of a frame (a torn tail if the stream has ended)."""
        return len(self._buf)

    def flush(self) -> list[Frame]:
        """End of stream: recover any complete frames hidden behind a false sync, drop the torn tail.

        A stray sync pattern with a plausible length makes the framer wait for bytes that will never come;
        at the end of the stream we skip it one byte at a time and re-scan. Returns the frames recovered;
        the unrecoverable bytes are counted in `skipped_bytes` and `torn_tail_bytes`.
        """
        out: list[Frame] = []
        held = len(self._buf)
        while self._buf:
            del self._buf[:1]
            self._base += 1
            self.skipped_bytes += 1
            out += self.feed(b"")
        self.torn_tail_bytes = held - sum(len(f.raw) for f in out)
        return out

def _nmea_valid(sentence: bytes) -> bool:
    star = sentence.rfind(b"*")
    if star < 1 or star + 3 > len(sentence):
        return False
    try:
        want = int(sentence[star + 1 : star + 3], 16)
    except ValueError:
        return False
    got = 0
    for byte in sentence[1:star]:
        got ^= byte
    return got == want and all(32 <= c < 127 for c in sentence[1:star])


def iter_frames(data: bytes, protocols: frozenset[Protocol] = frozenset(Protocol)) -> list[Frame]:
    """Every valid frame in a complete byte string (a torn tail is ignored)."""
    framer = StreamFramer(protocols)
    return framer.feed(data) + framer.flush()
