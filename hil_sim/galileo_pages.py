"""Galileo I/NAV (E1-B) word types 1–5 of a broadcast ephemeris as nominal page pairs, as a receiver sends them.

Pure. Field layout and scales of Galileo OS SIS ICD 2.0 (4.3), the ones `onboard.rtk.galileo_inav` decodes: a
128-bit word per page pair; the even part (even/odd 0, page type 0, word bits 0–111, 6 tail bits) and the odd
part (even/odd 1, page type 0, word bits 112–127, 64 reserved bits, CRC-24Q over 4 zero bits + even bits 0–113
+ odd bits 0–81, 8 reserved bits, 6 tail bits). u-blox RXM-SFRBX: 8 words, the even part left-aligned in words
1–4, the odd part in 5–8. `PAGE_OF_WORD` places each word type in its 2-s page of the 30-s E1-B subframe
(ICD nominal sequence: types 2, 4 in pages 1, 2 and 1, 3, 5 in pages 11–13; the other pages carry almanac and
spare words, not produced here).
"""

from __future__ import annotations

from onboard.gnsstime import gst_week_tow_ns
from onboard.rtk.lnav import SC2RAD
from onboard.rtk.navbits import crc24q
from onboard.rtk.types import Ephemeris

PAGE_S = 2
SUBFRAME_S = 30
PAGE_OF_WORD = {2: 0, 4: 1, 1: 10, 3: 11, 5: 12}
"""Page index (0–14) within the 30-s I/NAV subframe of each ephemeris word type."""


class _Word:
    """A 128-bit word filled MSB first."""

    def __init__(self, word_type: int) -> None:
        self.value = 0
        self.pos = 0
        self.put(word_type, 6)

    def put(self, v: int, length: int, signed: bool = False) -> None:
        if signed:
            if not -(1 << (length - 1)) <= v < 1 << (length - 1):
                raise ValueError(f"{v} does not fit a {length}-bit signed field")
            v &= (1 << length) - 1
        elif not 0 <= v < 1 << length:
            raise ValueError(f"{v} does not fit a {length}-bit field")
        self.value |= v << (128 - self.pos - length)
        self.pos += length


def _q(value: float, lsb: float) -> int:
    return round(value / lsb)


def words(eph: Ephemeris, t_tx_word5: float | None = None) -> dict[int, int]:
    """Word types 1–5 (128-bit ints by type) of a Galileo `eph`; word 5 carries GST week/TOW of `t_tx_word5`
    (s of the GPS week of toe; default toe). Raises ValueError for a value out of its field."""
    iod = eph.iode
    sc = SC2RAD * 2.0**-31
    w1 = _Word(1)
    w1.put(iod, 10)
    w1.put(round(eph.toe.tow_s / 60.0), 14)
    w1.put(_q(eph.m0_rad, sc), 32, True)
    w1.put(_q(eph.e, 2.0**-33), 32)
    w1.put(_q(eph.sqrt_a, 2.0**-19), 32)
    w2 = _Word(2)
    w2.put(iod, 10)
    for v in (eph.omega0_rad, eph.i0_rad, eph.omega_rad):
        w2.put(_q(v, sc), 32, True)
    w2.put(_q(eph.idot_rad_s, SC2RAD * 2.0**-43), 14, True)
    w3 = _Word(3)
    w3.put(iod, 10)
    w3.put(_q(eph.omega_dot_rad_s, SC2RAD * 2.0**-43), 24, True)
    w3.put(_q(eph.delta_n_rad_s, SC2RAD * 2.0**-43), 16, True)
    for v, lsb in ((eph.cuc_rad, 2.0**-29), (eph.cus_rad, 2.0**-29), (eph.crc_m, 2.0**-5), (eph.crs_m, 2.0**-5)):
        w3.put(_q(v, lsb), 16, True)
    w3.put(eph.ura_index, 8)
    w4 = _Word(4)
    w4.put(iod, 10)
    w4.put(eph.prn, 6)
    w4.put(_q(eph.cic_rad, 2.0**-29), 16, True)
    w4.put(_q(eph.cis_rad, 2.0**-29), 16, True)
    w4.put(round(eph.toc.tow_s / 60.0), 14)
    w4.put(_q(eph.af0_s, 2.0**-34), 31, True)
    w4.put(_q(eph.af1_s_s, 2.0**-46), 21, True)
    w4.put(_q(eph.af2_s_s2, 2.0**-59), 6, True)
    w5 = _Word(5)
    w5.put(0, 47 - 6)  # ionospheric (NeQuick) coefficients and disturbance flags: not simulated
    w5.put(_q(eph.tgd_s, 2.0**-32), 10, True)
    w5.put(_q(eph.tgd2_s, 2.0**-32), 10, True)
    h = eph.health
    w5.put((h >> 7) & 3, 2)  # E5b HS
    w5.put((h >> 1) & 3, 2)  # E1-B HS
    w5.put((h >> 6) & 1, 1)  # E5b DVS
    w5.put(h & 1, 1)  # E1-B DVS
    t5 = eph.toe if t_tx_word5 is None else eph.toe.add_s(t_tx_word5 - eph.toe.tow_s)
    wn, tow_ns = gst_week_tow_ns(t5)
    w5.put(wn & 0xFFF, 12)
    w5.put(tow_ns // 1_000_000_000, 20)
    return {t: w.value for t, w in ((1, w1), (2, w2), (3, w3), (4, w4), (5, w5))}


def sfrbx_words(word128: int) -> tuple[int, ...]:
    """The 8 RXM-SFRBX words of the nominal page pair carrying `word128` (CRC-24Q computed)."""
    even = (word128 >> 16) << 6  # 0, 0 (page type), 112 data bits, 6 tail bits: 120 bits
    odd_head = (1 << 81) | ((word128 & 0xFFFF) << 64)  # 1, 0, 16 data bits, 64 reserved bits: 82 bits
    crc = crc24q((((even >> 6) & ((1 << 114) - 1)) << 82 | odd_head).to_bytes(25, "big"))
    odd = ((odd_head << 24 | crc) << 14)  # + 8 reserved bits + 6 tail bits: 120 bits
    v_even, v_odd = even << 8, odd << 8  # left-aligned in 128 bits
    return tuple((v >> (96 - 32 * i)) & 0xFFFFFFFF for v in (v_even, v_odd) for i in range(4))
