"""Bit-level helpers for navigation messages: big-endian bit fields of a byte string, two's complement and
sign-magnitude numbers, and the CRC-24Q (RTCM3 frames, Galileo I/NAV pages: polynomial 0x1864CFB)."""

from __future__ import annotations

from collections.abc import Sequence

_CRC24Q_TABLE: list[int] = []
for _i in range(256):
    _c = _i << 16
    for _ in range(8):
        _c <<= 1
        if _c & 0x1000000:
            _c ^= 0x1864CFB
    _CRC24Q_TABLE.append(_c & 0xFFFFFF)


def crc24q(data: bytes | bytearray) -> int:
    """CRC-24Q (RTCM3, Qualcomm polynomial 0x1864CFB) of `data`."""
    crc = 0
    for byte in data:
        crc = ((crc << 8) & 0xFFFFFF) ^ _CRC24Q_TABLE[(crc >> 16) ^ byte]
    return crc


class BitField:
    """A bit string read MSB first: bit 0 is the most significant bit of the first byte (or of `value`)."""

    def __init__(self, value: int, n_bits: int) -> None:
        self.value = value
        self.n_bits = n_bits

    @classmethod
    def of_bytes(cls, data: bytes | bytearray) -> BitField:
        """The bits of `data`, first byte first."""
        return cls(int.from_bytes(data, "big"), 8 * len(data))

    @classmethod
    def of_words(cls, words: Sequence[int], bits_per_word: int = 32) -> BitField:
        """The concatenation of `words` (each its `bits_per_word` low bits, MSB first)."""
        v = 0
        for w in words:
            v = (v << bits_per_word) | (int(w) & ((1 << bits_per_word) - 1))
        return cls(v, bits_per_word * len(words))

    def u(self, pos: int, length: int) -> int:
        """Unsigned field of `length` bits starting at bit `pos`."""
        if pos < 0 or length < 0 or pos + length > self.n_bits:
            raise IndexError(f"bits {pos}..{pos + length - 1} outside a {self.n_bits}-bit string")
        return (self.value >> (self.n_bits - pos - length)) & ((1 << length) - 1)

    def s(self, pos: int, length: int) -> int:
        """Two's complement field."""
        v = self.u(pos, length)
        return v - (1 << length) if v >> (length - 1) else v

    def sm(self, pos: int, length: int) -> int:
        """Sign-magnitude field (MSB = sign, 1 negative: GLONASS)."""
        v = self.u(pos + 1, length - 1)
        return -v if self.u(pos, 1) else v

    def u_parts(self, *parts: tuple[int, int]) -> int:
        """Unsigned value of fields split over several places ((pos, length), MSB part first)."""
        v = 0
        for pos, length in parts:
            v = (v << length) | self.u(pos, length)
        return v

    def s_parts(self, *parts: tuple[int, int]) -> int:
        """Two's complement value of a field split over several places (MSB part first)."""
        v = self.u_parts(*parts)
        n = sum(length for _, length in parts)
        return v - (1 << n) if v >> (n - 1) else v

    def bytes_from(self, pos: int, length: int) -> bytes:
        """`length` bits from `pos`, left-aligned and zero padded into bytes."""
        v = self.u(pos, length)
        pad = (-length) % 8
        return (v << pad).to_bytes((length + pad) // 8, "big")
