"""BeiDou B1I navigation messages D1 (MEO/IGSO: subframes 1–3) and D2 (GEO: subframe 1, pages 1–10) → BeiDou
:class:`Ephemeris` (B1I ICD 3.0, 5.2 and 5.3).

Pure: no I/O. A subframe is 10 words of 30 bits. The u-blox RXM-SFRBX form: the 30 bits of each word in bits
29..0, de-interleaved: word 1 = 26 information bits (preamble, FraID, SOW MSBs …) + 4 BCH parity bits over its
last 11 information bits; words 2–10 = 22 information bits + the 4 parity bits of the first 11 + the 4 of the
second 11 (BCH(15,11), g(x) = x⁴ + x + 1). A subframe with any parity failure is dropped. Field positions are
bit offsets in the 300-bit subframe (bit 0 = word 1's first bit), as the ICD's figures give them; RTKLIB
rcvraw.c decode_bds_d1()/decode_bds_d2() were read to check them; the code is ours.

Times: SOW, toe, toc and the week are BDT; the Ephemeris holds GPST instants (BDT + 14 s, onboard.gnsstime).
GEO satellites (PRN 1–5, 59–63: onboard.rtk.gnss.is_beidou_geo) broadcast D2, the others D1.
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Sequence

from onboard.gnsstime import NS_PER_S, SECONDS_PER_WEEK, GpsTime, gpst_from_bdt
from onboard.rtk.gnss import is_beidou_geo
from onboard.rtk.lnav import SC2RAD
from onboard.rtk.navbits import BitField
from onboard.rtk.types import GNSS_BEIDOU, Ephemeris

log = logging.getLogger(__name__)


class BeidouNavError(ValueError):
    """A subframe or page set that cannot be used (word count, parity, inconsistent ids/SOW/toe)."""


def _bch_parity(info11: int) -> int:
    """The 4 BCH(15,11) parity bits of 11 information bits (MSB first), g(x) = x⁴ + x + 1."""
    r = info11 << 4
    for bit in range(14, 3, -1):
        if r >> bit & 1:
            r ^= 0b10011 << (bit - 4)
    return r & 0xF


def word_parity_ok(word30: int, first: bool) -> bool:
    """BCH check of one de-interleaved 30-bit word (`first`: word 1, whose first 15 bits are not coded)."""
    w = word30 & 0x3FFFFFFF
    if first:
        return _bch_parity((w >> 4) & 0x7FF) == w & 0xF
    return _bch_parity(w >> 19) == (w >> 4) & 0xF and _bch_parity((w >> 8) & 0x7FF) == w & 0xF


def subframe_bits(words: Sequence[int]) -> BitField:
    """The 300-bit subframe of 10 RXM-SFRBX words after the parity check (BeidouNavError on a failure)."""
    if len(words) != 10:
        raise BeidouNavError(f"a BeiDou subframe has 10 words, got {len(words)}")
    bad = [i + 1 for i, w in enumerate(words) if not word_parity_ok(int(w), i == 0)]
    if bad:
        raise BeidouNavError(f"BCH parity failure in words {bad}")
    return BitField.of_words([int(w) & 0x3FFFFFFF for w in words], 30)


def subframe_id(sf: BitField) -> int:
    """FraID (bits 15–17)."""
    return sf.u(15, 3)


def sow_s(sf: BitField) -> int:
    """Seconds of BDT week at the subframe start (bits 18–25 and 30–41)."""
    return sf.u_parts((18, 8), (30, 12))


def d2_page_number(sf: BitField) -> int:
    """Page number of a D2 subframe 1 (bits 42–45)."""
    return sf.u(42, 4)


def _times(week_bdt: int, sow: int, toe_bdt_s: float, toc_bdt_s: float) -> tuple[GpsTime, GpsTime]:
    """toe and toc on the GPS time scale, the week moved so toe lies within half a week of the SOW."""
    if toe_bdt_s > sow + SECONDS_PER_WEEK / 2:
        week_bdt -= 1
    elif toe_bdt_s < sow - SECONDS_PER_WEEK / 2:
        week_bdt += 1
    return (gpst_from_bdt(week_bdt, round(toe_bdt_s * NS_PER_S)),
            gpst_from_bdt(week_bdt, round(toc_bdt_s * NS_PER_S)))


def _ephemeris(prn: int, f: dict[str, float | int], toe: GpsTime, toc: GpsTime) -> Ephemeris:
    return Ephemeris(
        prn=prn, week=toe.week, toe=toe, toc=toc, iode=int(f["aode"]), iodc=int(f["aodc"]),
        sqrt_a=float(f["sqrt_a"]), e=float(f["e"]), i0_rad=float(f["i0_rad"]), omega0_rad=float(f["omega0_rad"]),
        omega_rad=float(f["omega_rad"]), m0_rad=float(f["m0_rad"]), delta_n_rad_s=float(f["delta_n_rad_s"]),
        omega_dot_rad_s=float(f["omega_dot_rad_s"]), idot_rad_s=float(f["idot_rad_s"]),
        cuc_rad=float(f["cuc_rad"]), cus_rad=float(f["cus_rad"]), crc_m=float(f["crc_m"]), crs_m=float(f["crs_m"]),
        cic_rad=float(f["cic_rad"]), cis_rad=float(f["cis_rad"]), af0_s=float(f["af0_s"]),
        af1_s_s=float(f["af1_s_s"]), af2_s_s2=float(f["af2_s_s2"]), tgd_s=float(f["tgd1_s"]),
        tgd2_s=float(f["tgd2_s"]), ura_index=int(f["urai"]), health=int(f["sath1"]), fit_interval_h=4.0,
        code_on_l2=0, l2p_flag=0, gnss_id=GNSS_BEIDOU,
    )


def ephemeris_from_d1(prn: int, sf1: BitField, sf2: BitField, sf3: BitField) -> Ephemeris:
    """D1 ephemeris from subframes 1–3 (checked: FraIDs 1, 2, 3, SOW steps of 6 s, toc = toe)."""
    if (subframe_id(sf1), subframe_id(sf2), subframe_id(sf3)) != (1, 2, 3):
        raise BeidouNavError("subframes are not 1, 2, 3")
    sow1, sow2, sow3 = sow_s(sf1), sow_s(sf2), sow_s(sf3)
    if sow2 != sow1 + 6 or sow3 != sow2 + 6:
        raise BeidouNavError(f"SOW {sow1}, {sow2}, {sow3} not consecutive")
    f: dict[str, float | int] = {
        "sath1": sf1.u(42, 1), "aodc": sf1.u(43, 5), "urai": sf1.u(48, 4), "week": sf1.u(60, 13),
        "toc_s": sf1.u_parts((73, 9), (90, 8)) * 8.0, "tgd1_s": sf1.s(98, 10) * 0.1e-9,
        "tgd2_s": sf1.s_parts((108, 4), (120, 6)) * 0.1e-9, "af2_s_s2": sf1.s(214, 11) * 2.0**-66,
        "af0_s": sf1.s_parts((225, 7), (240, 17)) * 2.0**-33, "af1_s_s": sf1.s_parts((257, 5), (270, 17)) * 2.0**-50,
        "aode": sf1.u(287, 5),
        "delta_n_rad_s": sf2.s_parts((42, 10), (60, 6)) * 2.0**-43 * SC2RAD,
        "cuc_rad": sf2.s_parts((66, 16), (90, 2)) * 2.0**-31,
        "m0_rad": sf2.s_parts((92, 20), (120, 12)) * 2.0**-31 * SC2RAD,
        "e": sf2.u_parts((132, 10), (150, 22)) * 2.0**-33, "cus_rad": sf2.s(180, 18) * 2.0**-31,
        "crc_m": sf2.s_parts((198, 4), (210, 14)) * 2.0**-6, "crs_m": sf2.s_parts((224, 8), (240, 10)) * 2.0**-6,
        "sqrt_a": sf2.u_parts((250, 12), (270, 20)) * 2.0**-19,
        "toe_s": sf2.u_parts((290, 2)) * 2.0**15 * 8.0 + sf3.u_parts((42, 10), (60, 5)) * 8.0,
        "i0_rad": sf3.s_parts((65, 17), (90, 15)) * 2.0**-31 * SC2RAD,
        "cic_rad": sf3.s_parts((105, 7), (120, 11)) * 2.0**-31,
        "omega_dot_rad_s": sf3.s_parts((131, 11), (150, 13)) * 2.0**-43 * SC2RAD,
        "cis_rad": sf3.s_parts((163, 9), (180, 9)) * 2.0**-31,
        "idot_rad_s": sf3.s_parts((189, 13), (210, 1)) * 2.0**-43 * SC2RAD,
        "omega0_rad": sf3.s_parts((211, 21), (240, 11)) * 2.0**-31 * SC2RAD,
        "omega_rad": sf3.s_parts((251, 11), (270, 21)) * 2.0**-31 * SC2RAD,
    }
    if f["toc_s"] != f["toe_s"]:
        raise BeidouNavError(f"toc {f['toc_s']} ≠ toe {f['toe_s']}")
    toe, toc = _times(int(f["week"]), sow1, float(f["toe_s"]), float(f["toc_s"]))
    return _ephemeris(prn, f, toe, toc)


def ephemeris_from_d2(prn: int, pages: dict[int, BitField]) -> Ephemeris:
    """D2 ephemeris from subframe 1 pages 1 and 3–10 (checked: page numbers, SOW 6 s from page 1 to 3 then 3 s
    steps, toc = toe)."""
    missing = [k for k in (1, 3, 4, 5, 6, 7, 8, 9, 10) if k not in pages]
    if missing:
        raise BeidouNavError(f"D2 pages {missing} missing")
    p = pages
    if any(d2_page_number(p[k]) != k for k in p):
        raise BeidouNavError("D2 page numbers do not match their slots")
    sows = [sow_s(p[k]) for k in (1, 3, 4, 5, 6, 7, 8, 9, 10)]
    if sows[1] != sows[0] + 6 or any(b != a + 3 for a, b in itertools.pairwise(sows[1:])):
        raise BeidouNavError(f"D2 page SOWs {sows} not consecutive")

    def join(msb: int, lsb: int, lsb_bits: int) -> int:
        return msb * (1 << lsb_bits) + lsb  # MSB part signed, LSB part unsigned

    f: dict[str, float | int] = {
        "sath1": p[1].u(46, 1), "aodc": p[1].u(47, 5), "urai": p[1].u(60, 4), "week": p[1].u(64, 13),
        "toc_s": p[1].u_parts((77, 5), (90, 12)) * 8.0, "tgd1_s": p[1].s(102, 10) * 0.1e-9,
        "tgd2_s": p[1].s(120, 10) * 0.1e-9,
        "af0_s": p[3].s_parts((100, 12), (120, 12)) * 2.0**-33,
        "af1_s_s": join(p[3].s(132, 4), p[4].u_parts((46, 6), (60, 12)), 18) * 2.0**-50,
        "af2_s_s2": p[4].s_parts((72, 10), (90, 1)) * 2.0**-66, "aode": p[4].u(91, 5),
        "delta_n_rad_s": p[4].s(96, 16) * 2.0**-43 * SC2RAD,
        "cuc_rad": join(p[4].s(120, 14), p[5].u(46, 4), 4) * 2.0**-31,
        "m0_rad": p[5].s_parts((50, 2), (60, 22), (90, 8)) * 2.0**-31 * SC2RAD,
        "cus_rad": p[5].s_parts((98, 14), (120, 4)) * 2.0**-31,
        "e": join(p[5].u(124, 10), p[6].u_parts((46, 6), (60, 16)), 22) * 2.0**-33,
        "sqrt_a": p[6].u_parts((76, 6), (90, 22), (120, 4)) * 2.0**-19,
        "cic_rad": join(p[6].s(124, 10), p[7].u_parts((46, 6), (60, 2)), 8) * 2.0**-31,
        "cis_rad": p[7].s(62, 18) * 2.0**-31, "toe_s": p[7].u_parts((80, 2), (90, 15)) * 8.0,
        "i0_rad": join(p[7].s_parts((105, 7), (120, 14)), p[8].u_parts((46, 6), (60, 5)), 11) * 2.0**-31 * SC2RAD,
        "crc_m": p[8].s_parts((65, 17), (90, 1)) * 2.0**-6, "crs_m": p[8].s(91, 18) * 2.0**-6,
        "omega_dot_rad_s": join(p[8].s_parts((109, 3), (120, 16)), p[9].u(46, 5), 5) * 2.0**-43 * SC2RAD,
        "omega0_rad": p[9].s_parts((51, 1), (60, 22), (90, 9)) * 2.0**-31 * SC2RAD,
        "omega_rad": join(p[9].s_parts((99, 13), (120, 14)), p[10].u(46, 5), 5) * 2.0**-31 * SC2RAD,
        "idot_rad_s": p[10].s_parts((51, 1), (60, 13)) * 2.0**-43 * SC2RAD,
    }
    if f["toc_s"] != f["toe_s"]:
        raise BeidouNavError(f"toc {f['toc_s']} ≠ toe {f['toe_s']}")
    toe, toc = _times(int(f["week"]), sows[0], float(f["toe_s"]), float(f["toc_s"]))
    return _ephemeris(prn, f, toe, toc)


class BeidouNavAssembler:
    """Collects D1 subframes 1–3 (MEO/IGSO) or D2 subframe-1 pages (GEO) per PRN and emits a BeiDou Ephemeris
    when a consistent set is complete and differs from the last one emitted (repeats return None).

    Feed RXM-SFRBX B1I subframes with :meth:`add_sfrbx`; parity failures are dropped and counted in
    `parity_failures`, inconsistent sets in `rejected`.
    """

    def __init__(self) -> None:
        self._d1: dict[int, dict[int, BitField]] = {}
        self._d2: dict[int, dict[int, BitField]] = {}
        self._last: dict[int, Ephemeris] = {}
        self.parity_failures = 0
        self.rejected = 0

    def add_sfrbx(self, prn: int, words: Sequence[int]) -> Ephemeris | None:
        """Add one subframe (10 words) of PRN `prn`; returns a new ephemeris or None."""
        try:
            sf = subframe_bits(words)
        except BeidouNavError as exc:
            self.parity_failures += 1
            log.debug("BeiDou C%02d: %s", prn, exc)
            return None
        fid = subframe_id(sf)
        try:
            if is_beidou_geo(prn):
                if fid != 1:
                    return None
                page = d2_page_number(sf)
                if not 1 <= page <= 10:
                    self.rejected += 1
                    return None
                pages = self._d2.setdefault(prn, {})
                if page == 1:
                    pages.clear()  # a new page cycle: never mix pages of two cycles
                pages[page] = sf
                if page != 10:
                    return None
                eph = ephemeris_from_d2(prn, pages)
            else:
                if not 1 <= fid <= 5:
                    self.rejected += 1
                    return None
                held = self._d1.setdefault(prn, {})
                held[fid] = sf
                if fid != 3 or 1 not in held or 2 not in held:
                    return None
                eph = ephemeris_from_d1(prn, held[1], held[2], held[3])
        except BeidouNavError as exc:
            self.rejected += 1
            log.debug("BeiDou C%02d: %s", prn, exc)
            return None
        if self._last.get(prn) == eph:
            return None
        self._last[prn] = eph
        return eph
