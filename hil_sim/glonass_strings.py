"""GLONASS L1 OF navigation strings 1–5 of a broadcast ephemeris, as a simulated receiver sends them.

Pure. The field layout, scales and Hamming code are those of GLONASS ICD 5.1 (4.3–4.7), the same ones
`onboard.rtk.glonass_nav` decodes (a string is 85 bits, bit 85 = 0 first, data bits 84..9, check bits 8..1).
A frame is 30 s of GLONASS time (UTC(SU) + 3 h), string m in its seconds [2(m − 1), 2m); strings 1–4 carry the
immediate data (ephemeris at tb, frame time tk), string 5 the four-year interval N4 (its other fields, the
non-immediate data, are zero here); strings 6–15 (almanac) are not produced. `sfrbx_words` packs a string as
u-blox RXM-SFRBX does: the 85 bits left-aligned in words 1–3, word 4 the superframe number (bits 31..16) and
the frame number 1–5 (bits 7..0).
"""

from __future__ import annotations

import datetime as _dt

from onboard.gnsstime import GpsTime, glonass_datetime
from onboard.rtk.glonass_nav import _MASKS, STRING_BITS
from onboard.rtk.types import GlonassEphemeris

FRAME_S = 30
STRING_S = 2
SUPERFRAME_S = 150


def _put(s: int, pos: int, length: int, value: int) -> int:
    """`s` with `value` (unsigned, `length` bits) at `pos` counted from bit 85 (index 0)."""
    if not 0 <= value < 1 << length:
        raise ValueError(f"value {value} does not fit {length} bits")
    return s | value << (STRING_BITS - pos - length)


def _sm(value: float, lsb: float, length: int) -> int:
    """Sign-magnitude code of `value` in units of `lsb` (the sign bit first)."""
    n = round(value / lsb)
    mag = abs(n)
    if mag >= 1 << (length - 1):
        raise ValueError(f"{value} exceeds a {length}-bit sign-magnitude field of LSB {lsb}")
    return (1 << (length - 1) if n < 0 else 0) | mag


def with_hamming(s: int) -> int:
    """The string with its check bits β1..β7 and the overall parity bit 8 set (ICD 4.7)."""
    s &= ~0xFF
    for k, mask in enumerate(_MASKS):
        s |= ((s & mask).bit_count() & 1) << k
    return s | ((s.bit_count() & 1) << 7)


def strings(eph: GlonassEphemeris, frame_start: GpsTime, leap_s: int) -> dict[int, int]:
    """Strings 1–5 (85-bit ints by string number) of the frame starting at `frame_start` (GPS time of a
    30-s boundary of GLONASS time); `leap_s` = GPST − UTC. Raises ValueError for a field out of range."""
    tk = glonass_datetime(frame_start, leap_s)
    toe = glonass_datetime(eph.toe, leap_s)
    tb_s = toe.hour * 3600 + toe.minute * 60 + toe.second
    if tb_s % 900:
        raise ValueError(f"slot {eph.slot}: tb {toe.time()} is not on a 15-min boundary")
    n4 = (toe.year - 1996) // 4 + 1
    nt = (toe.date() - _dt.date(1996 + 4 * (n4 - 1), 1, 1)).days + 1
    km = 1e3
    s1 = _put(0, 1, 4, 1)
    s1 = _put(s1, 9, 5, tk.hour)
    s1 = _put(s1, 14, 6, tk.minute)
    s1 = _put(s1, 20, 1, tk.second // 30)
    parts = [s1, _put(0, 1, 4, 2), _put(0, 1, 4, 3)]
    for axis in range(3):  # strings 1, 2, 3: velocity, luni-solar acceleration, position of x, y, z (PZ-90, km)
        v = _sm(eph.vel_m_s[axis] / km, 2.0**-20, 24)
        a = _sm(eph.acc_m_s2[axis] / km, 2.0**-30, 5)
        x = _sm(eph.pos_m[axis] / km, 2.0**-11, 27)
        parts[axis] = _put(_put(_put(parts[axis], 21, 24, v), 45, 5, a), 50, 27, x)
    s1, s2, s3 = parts
    s2 = _put(s2, 5, 3, (eph.health & 1) << 2)
    s2 = _put(s2, 9, 7, tb_s // 900)
    s3 = _put(s3, 6, 11, _sm(eph.gamma_n, 2.0**-40, 11))
    s3 = _put(s3, 20, 1, (eph.health >> 1) & 1)
    s4 = _put(0, 1, 4, 4)
    s4 = _put(s4, 5, 22, _sm(eph.tau_n_s, 2.0**-30, 22))
    s4 = _put(s4, 27, 5, _sm(eph.delta_tau_n_s, 2.0**-30, 5))
    s4 = _put(s4, 32, 5, eph.age_days)
    s4 = _put(s4, 52, 4, eph.ft)
    s4 = _put(s4, 59, 11, nt)
    s4 = _put(s4, 70, 5, eph.slot)
    s4 = _put(s4, 75, 2, 1)  # M = 01: GLONASS-M
    s5 = _put(_put(0, 1, 4, 5), 49, 5, n4)
    return {m: with_hamming(s) for m, s in enumerate((s1, s2, s3, s4, s5), start=1)}


def sfrbx_words(string85: int, frame_start: GpsTime, leap_s: int) -> tuple[int, int, int, int]:
    """The four RXM-SFRBX words of a string of the frame starting at `frame_start` (GPS time)."""
    v = string85 << (96 - STRING_BITS)
    t = glonass_datetime(frame_start, leap_s)
    tod = t.hour * 3600 + t.minute * 60 + t.second
    superframe = (tod // SUPERFRAME_S) & 0xFFFF
    frame = tod % SUPERFRAME_S // FRAME_S + 1
    return (v >> 64) & 0xFFFFFFFF, (v >> 32) & 0xFFFFFFFF, v & 0xFFFFFFFF, superframe << 16 | frame
