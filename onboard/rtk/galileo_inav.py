"""Galileo I/NAV (E1-B, also E5b-I) word types 1–5 (OS SIS ICD 2.0, 4.3) → Galileo :class:`Ephemeris`.

Pure: no I/O. One nominal page pair carries one 128-bit word: the even part (even/odd = 0, page type, 112 data
bits, tail) and the odd part (even/odd = 1, page type, 16 data bits, reserved, CRC-24Q, …). The CRC covers 4
zero bits + the even part's first 114 bits + the odd part's first 82 bits and sits in odd bits 82–105. The
u-blox RXM-SFRBX form: 8 words, the even part left-aligned in words 1–4, the odd part in words 5–8.
Word types 1–4 carry the orbit and clock under one IODnav, type 5 the BGDs, health and GST week/TOW (used to
place toe in the right week). RTKLIB rcvraw.c decode_gal_inav() and ublox.c decode_enav() were read to check
positions; the code is ours.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

from onboard.gnsstime import SECONDS_PER_WEEK, GpsTime, gpst_from_gst
from onboard.rtk.lnav import SC2RAD
from onboard.rtk.navbits import BitField, crc24q
from onboard.rtk.types import GNSS_GALILEO, Ephemeris

log = logging.getLogger(__name__)

DATA_SOURCE_E1B = 0x201
"""RINEX data-source bits of an I/NAV E1-B ephemeris: bit 0 (I/NAV E1-B) + bit 9 (clock for E5b,E1)."""
DATA_SOURCE_E5B = 0x204
"""RINEX data-source bits of an I/NAV E5b-I ephemeris: bit 2 + bit 9."""


class GalileoNavError(ValueError):
    """A page pair that cannot be used (wrong word count, parts out of order, CRC failure, alert page)."""


def inav_word(words: Sequence[int]) -> BitField:
    """The 128-bit I/NAV word of one RXM-SFRBX page pair (8 words); raises GalileoNavError on a bad CRC, parts
    in the wrong order or an alert page."""
    if len(words) != 8:
        raise GalileoNavError(f"an I/NAV page pair has 8 words, got {len(words)}")
    even = BitField.of_words(words[:4])
    odd = BitField.of_words(words[4:])
    if even.u(0, 1) != 0 or odd.u(0, 1) != 1:
        raise GalileoNavError("page parts not even then odd")
    if even.u(1, 1) or odd.u(1, 1):
        raise GalileoNavError("alert page")
    crc_input = (even.u(0, 114) << 82) | odd.u(0, 82)  # 196 bits, 4 zero bits in front make 25 bytes
    if crc24q(crc_input.to_bytes(25, "big")) != odd.u(82, 24):
        raise GalileoNavError("CRC-24Q failure")
    return BitField((even.u(2, 112) << 16) | odd.u(2, 16), 128)


def word_type(word: BitField) -> int:
    """Word type (bits 0–5) of a 128-bit I/NAV word."""
    return word.u(0, 6)


def _fields(w: dict[int, BitField]) -> dict[str, float | int]:
    w1, w2, w3, w4, w5 = w[1], w[2], w[3], w[4], w[5]
    return {
        "iod1": w1.u(6, 10), "toe_s": w1.u(16, 14) * 60.0, "m0_rad": w1.s(30, 32) * 2.0**-31 * SC2RAD,
        "e": w1.u(62, 32) * 2.0**-33, "sqrt_a": w1.u(94, 32) * 2.0**-19,
        "iod2": w2.u(6, 10), "omega0_rad": w2.s(16, 32) * 2.0**-31 * SC2RAD,
        "i0_rad": w2.s(48, 32) * 2.0**-31 * SC2RAD, "omega_rad": w2.s(80, 32) * 2.0**-31 * SC2RAD,
        "idot_rad_s": w2.s(112, 14) * 2.0**-43 * SC2RAD,
        "iod3": w3.u(6, 10), "omega_dot_rad_s": w3.s(16, 24) * 2.0**-43 * SC2RAD,
        "delta_n_rad_s": w3.s(40, 16) * 2.0**-43 * SC2RAD, "cuc_rad": w3.s(56, 16) * 2.0**-29,
        "cus_rad": w3.s(72, 16) * 2.0**-29, "crc_m": w3.s(88, 16) * 2.0**-5, "crs_m": w3.s(104, 16) * 2.0**-5,
        "sisa": w3.u(120, 8),
        "iod4": w4.u(6, 10), "svid": w4.u(16, 6), "cic_rad": w4.s(22, 16) * 2.0**-29,
        "cis_rad": w4.s(38, 16) * 2.0**-29, "toc_s": w4.u(54, 14) * 60.0, "af0_s": w4.s(68, 31) * 2.0**-34,
        "af1_s_s": w4.s(99, 21) * 2.0**-46, "af2_s_s2": w4.s(120, 6) * 2.0**-59,
        "bgd_e5a_s": w5.s(47, 10) * 2.0**-32, "bgd_e5b_s": w5.s(57, 10) * 2.0**-32,
        "e5b_hs": w5.u(67, 2), "e1b_hs": w5.u(69, 2), "e5b_dvs": w5.u(71, 1), "e1b_dvs": w5.u(72, 1),
        "wn": w5.u(73, 12), "tow_s": w5.u(85, 20),
    }


def ephemeris_from_words(words: dict[int, BitField], data_source: int = DATA_SOURCE_E1B) -> Ephemeris:
    """Galileo Ephemeris from I/NAV word types 1–5 (128-bit words by type). Raises GalileoNavError when a type is
    missing or types 1–4 disagree on IODnav. toe/toc are placed in the GST week that puts toe within half a
    week of word 5's transmission time; `health` is the RINEX/RTKLIB SV health word (E5b HS<<7 | E5b DVS<<6 |
    E1-B HS<<1 | E1-B DVS)."""
    missing = [t for t in (1, 2, 3, 4, 5) if t not in words]
    if missing:
        raise GalileoNavError(f"word types {missing} missing")
    f = _fields(words)
    iods = {int(f[k]) for k in ("iod1", "iod2", "iod3", "iod4")}
    if len(iods) != 1:
        raise GalileoNavError(f"IODnav differs between word types 1–4: {sorted(iods)}")
    t_tx = gpst_from_gst(int(f["wn"]), int(f["tow_s"]) * 1_000_000_000)
    toe = GpsTime.from_week_tow_s(t_tx.week, float(f["toe_s"]))
    if toe.diff_s(t_tx) > SECONDS_PER_WEEK / 2:
        toe = toe.add_s(-SECONDS_PER_WEEK)
    elif toe.diff_s(t_tx) < -SECONDS_PER_WEEK / 2:
        toe = toe.add_s(SECONDS_PER_WEEK)
    toc = GpsTime.from_week_tow_s(toe.week, float(f["toc_s"]))
    if toc.diff_s(toe) > SECONDS_PER_WEEK / 2:  # toc and toe on either side of a week start
        toc = toc.add_s(-SECONDS_PER_WEEK)
    elif toc.diff_s(toe) < -SECONDS_PER_WEEK / 2:
        toc = toc.add_s(SECONDS_PER_WEEK)
    iod = iods.pop()
    health = (int(f["e5b_hs"]) << 7) | (int(f["e5b_dvs"]) << 6) | (int(f["e1b_hs"]) << 1) | int(f["e1b_dvs"])
    return Ephemeris(
        prn=int(f["svid"]), week=toe.week, toe=toe, toc=toc, iode=iod, iodc=iod, sqrt_a=float(f["sqrt_a"]),
        e=float(f["e"]), i0_rad=float(f["i0_rad"]), omega0_rad=float(f["omega0_rad"]),
        omega_rad=float(f["omega_rad"]), m0_rad=float(f["m0_rad"]), delta_n_rad_s=float(f["delta_n_rad_s"]),
        omega_dot_rad_s=float(f["omega_dot_rad_s"]), idot_rad_s=float(f["idot_rad_s"]),
        cuc_rad=float(f["cuc_rad"]), cus_rad=float(f["cus_rad"]), crc_m=float(f["crc_m"]),
        crs_m=float(f["crs_m"]), cic_rad=float(f["cic_rad"]), cis_rad=float(f["cis_rad"]),
        af0_s=float(f["af0_s"]), af1_s_s=float(f["af1_s_s"]), af2_s_s2=float(f["af2_s_s2"]),
        tgd_s=float(f["bgd_e5a_s"]), tgd2_s=float(f["bgd_e5b_s"]), ura_index=int(f["sisa"]), health=health,
        fit_interval_h=4.0, code_on_l2=data_source, l2p_flag=0, gnss_id=GNSS_GALILEO,
    )


class GalileoInavAssembler:
    """Collects I/NAV word types 1–5 per satellite and emits a Galileo Ephemeris when types 1–4 share an
    IODnav (type 5 being present) and the set differs from the last one emitted (repeats return None).

    Feed RXM-SFRBX page pairs with :meth:`add_sfrbx`; CRC failures are dropped and counted in `crc_failures`,
    alert pages and other word types are ignored.
    """

    def __init__(self) -> None:
        self._words: dict[int, dict[int, BitField]] = {}
        self._last: dict[int, Ephemeris] = {}
        self.crc_failures = 0
        self.rejected = 0

    def add_sfrbx(self, sv_id: int, words: Sequence[int], data_source: int = DATA_SOURCE_E1B) -> Ephemeris | None:
        """Add one page pair (8 RXM-SFRBX words) of satellite `sv_id`; returns a new ephemeris or None."""
        try:
            word = inav_word(words)
        except GalileoNavError as exc:
            if "CRC" in str(exc):
                self.crc_failures += 1
            log.debug("Galileo E%02d: %s", sv_id, exc)
            return None
        wt = word_type(word)
        if not 1 <= wt <= 5:
            return None
        held = self._words.setdefault(sv_id, {})
        held[wt] = word
        if len(held) < 5 or wt == 5:
            return None  # a set completes on its orbit/clock words (type 5 is sent between ephemeris batches)
        try:
            eph = ephemeris_from_words(held, data_source)
        except GalileoNavError:
            return None  # an IODnav change in progress: wait for the other words of the new batch
        if eph.prn != sv_id:
            self.rejected += 1
            log.debug("Galileo svId %d carries SVID %d in word type 4", sv_id, eph.prn)
            return None
        if self._last.get(sv_id) == eph:
            return None
        self._last[sv_id] = eph
        return eph
