"""GPS LNAV navigation message (L1 C/A) subframes 1–3 ↔ :class:`onboard.rtk.types.Ephemeris`.

Pure: no I/O. Follows IS-GPS-200 20.3.2 (message structure), 20.3.3.3/20.3.3.4 (subframe 1–3 fields,
Tables 20-I, 20-III) and 20.3.5.2 (parity, Table 20-XIV). RTKLIB rcvraw.c decode_frame() was read to check
bit positions; the code here is our own.

Word forms handled:

- 30-bit words as transmitted (bits 29..0 = D1..D30, D1 first). Data bits D1..D24 go on air inverted when
  D30 of the previous word (D30*) is 1; :func:`data_bits` removes the inversion, :func:`parity_ok` checks
  D25..D30 against the previous word's D29*, D30*.
- u-blox RXM-SFRBX dwords for GPS L1 C/A (M8T): the 30-bit word in bits 29..0 with the D30* inversion
  already undone over all 30 bits (data *and* parity), so the parity then checks with D30* = 0 and
  D29* = D29 ⊕ D30 of the previous transmitted word; u-blox puts that effective D29* in bit 31 (bit 30 is
  0). Verified on every one of the 1 650 words of the real NED-M8T capture `gpsd_ublox-ned-m8t-sbfrx3.log`.
  :func:`sfrbx_from_transmitted` / :func:`sfrbx_words24` convert and check this form.
- 24 data bits (bits 23..0, parity stripped, inversion removed): u-blox 6 RXM-SFRB words, and AID-EPH's
  SF1D0..SF3D7 (words 3..10 of each subframe, no TLM/HOW).

Bit numbering in the field table follows the ICD: word 1..10 of the subframe, data bit 1..24 of the word
(bit 1 = most significant). Fields split over two words list the MSB part first.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

from onboard.gnsstime import SECONDS_PER_WEEK, GpsTime
from onboard.rtk.types import Ephemeris

log = logging.getLogger(__name__)

SC2RAD = 3.1415926535898
"""Semicircles → radians with the value of π that IS-GPS-200 20.3.3.4.3 mandates."""
PREAMBLE = 0x8B
"""TLM preamble 10001011 (IS-GPS-200 20.3.3.1)."""
TOW_COUNT_MAX = 100_800
"""Number of 6-s TOW counts in a week (HOW bits 1–17 range 0..100799)."""
DEFAULT_WEEK_ROLLOVERS = 2
"""Rollovers of the 10-bit week assumed when no reference week is given (weeks 2048–3071, 2019–2038)."""


class LnavError(ValueError):
    """A subframe or ephemeris cannot be encoded/decoded (field out of range, bad word count, wrong id)."""


@dataclass(frozen=True)
class LnavField:
    """One LNAV field: where it sits, how it is scaled.

    `parts` are (word 1..10, first data bit 1..24, length) in ICD order, MSB part first; the value is
    raw × 2**`scale_pow2` (× π when `semicircles`, giving radians or rad/s).
    """

    name: str
    subframe: int
    parts: tuple[tuple[int, int, int], ...]
    signed: bool = False
    scale_pow2: int = 0
    semicircles: bool = False

    @property
    def n_bits(self) -> int:
        """Total length in bits."""
        return sum(p[2] for p in self.parts)

    @property
    def lsb(self) -> float:
        """Value of one least significant bit in the field's output unit (s, m, rad, rad/s or count)."""
        return 2.0**self.scale_pow2 * (SC2RAD if self.semicircles else 1.0)


# IS-GPS-200 Figure 20-1 / Tables 20-I and 20-III. Names ending in a unit are Ephemeris attributes.
LNAV_FIELDS: tuple[LnavField, ...] = (
    # subframe 1: clock, health, accuracy
    LnavField("week10", 1, ((3, 1, 10),)),
    LnavField("code_on_l2", 1, ((3, 11, 2),)),
    LnavField("ura_index", 1, ((3, 13, 4),)),
    LnavField("health", 1, ((3, 17, 6),)),
    LnavField("iodc", 1, ((3, 23, 2), (8, 1, 8))),
    LnavField("l2p_flag", 1, ((4, 1, 1),)),
    LnavField("tgd_s", 1, ((7, 17, 8),), True, -31),
    LnavField("toc_s", 1, ((8, 9, 16),), False, 4),
    LnavField("af2_s_s2", 1, ((9, 1, 8),), True, -55),
    LnavField("af1_s_s", 1, ((9, 9, 16),), True, -43),
    LnavField("af0_s", 1, ((10, 1, 22),), True, -31),
    # subframe 2: ephemeris I
    LnavField("iode", 2, ((3, 1, 8),)),
    LnavField("crs_m", 2, ((3, 9, 16),), True, -5),
    LnavField("delta_n_rad_s", 2, ((4, 1, 16),), True, -43, True),
    LnavField("m0_rad", 2, ((4, 17, 8), (5, 1, 24)), True, -31, True),
    LnavField("cuc_rad", 2, ((6, 1, 16),), True, -29),
    LnavField("e", 2, ((6, 17, 8), (7, 1, 24)), False, -33),
    LnavField("cus_rad", 2, ((8, 1, 16),), True, -29),
    LnavField("sqrt_a", 2, ((8, 17, 8), (9, 1, 24)), False, -19),
    LnavField("toe_s", 2, ((10, 1, 16),), False, 4),
    LnavField("fit_flag", 2, ((10, 17, 1),)),
    LnavField("aodo", 2, ((10, 18, 5),)),
    # subframe 3: ephemeris II
    LnavField("cic_rad", 3, ((3, 1, 16),), True, -29),
    LnavField("omega0_rad", 3, ((3, 17, 8), (4, 1, 24)), True, -31, True),
    LnavField("cis_rad", 3, ((5, 1, 16),), True, -29),
    LnavField("i0_rad", 3, ((5, 17, 8), (6, 1, 24)), True, -31, True),
    LnavField("crc_m", 3, ((7, 1, 16),), True, -5),
    LnavField("omega_rad", 3, ((7, 17, 8), (8, 1, 24)), True, -31, True),
    LnavField("omega_dot_rad_s", 3, ((9, 1, 24),), True, -43, True),
    LnavField("iode_sf3", 3, ((10, 1, 8),)),
    LnavField("idot_rad_s", 3, ((10, 9, 14),), True, -43, True),
)
FIELDS_BY_NAME: dict[str, LnavField] = {f.name: f for f in LNAV_FIELDS}

# Fields whose raw value is an integer count kept as int (no scaling).
_INT_FIELDS = frozenset(
    {"week10", "code_on_l2", "ura_index", "health", "iodc", "l2p_flag", "iode", "fit_flag", "aodo", "iode_sf3"}
)

# Parity equations, IS-GPS-200 Table 20-XIV: for D25..D30, (uses D29* (else D30*), data bits d1..d24).
_PARITY_EQ: tuple[tuple[bool, tuple[int, ...]], ...] = (
    (True, (1, 2, 3, 5, 6, 10, 11, 12, 13, 14, 17, 18, 20, 23)),
    (False, (2, 3, 4, 6, 7, 11, 12, 13, 14, 15, 18, 19, 21, 24)),
    (True, (1, 3, 4, 5, 7, 8, 12, 13, 14, 15, 16, 19, 20, 22)),
    (False, (2, 4, 5, 6, 8, 9, 13, 14, 15, 16, 17, 20, 21, 23)),
    (False, (1, 3, 5, 6, 7, 9, 10, 14, 15, 16, 17, 18, 21, 22, 24)),
    (True, (3, 5, 6, 8, 9, 10, 11, 13, 15, 19, 22, 23, 24)),
)
# Same equations as 24-bit masks over the data word (d1 = bit 23).
_PARITY_MASKS: tuple[tuple[bool, int], ...] = tuple(
    (use29, sum(1 << (24 - b) for b in bits)) for use29, bits in _PARITY_EQ
)

# IS-GPS-200 Table 20-XII: fit interval (h) when the fit interval flag is 1, by IODC range.
_FIT_BY_IODC: tuple[tuple[int, int, float], ...] = (
    (240, 247, 8.0), (248, 255, 14.0), (496, 496, 14.0), (497, 503, 26.0), (1021, 1023, 26.0),
    (504, 510, 50.0), (511, 511, 74.0), (752, 756, 74.0), (757, 763, 98.0),
)


# --------------------------------------------------------------------------------------------- parity


def parity_bits(data24: int, prev_word30: int) -> int:
    """The 6 parity bits D25..D30 (as an int, D30 = bit 0) of 24 source data bits after `prev_word30`."""
    d29s = (prev_word30 >> 1) & 1
    d30s = prev_word30 & 1
    out = 0
    for use29, mask in _PARITY_MASKS:
        bit = (d29s if use29 else d30s) ^ ((data24 & mask).bit_count() & 1)
        out = (out << 1) | bit
    return out


def encode_word(data24: int, prev_word30: int) -> int:
    """30-bit transmitted word (bits 29..0 = D1..D30) from 24 source data bits, chained on `prev_word30`."""
    data24 &= 0xFFFFFF
    tx = data24 ^ (0xFFFFFF if prev_word30 & 1 else 0)  # D1..D24 inverted when D30* = 1
    return (tx << 6) | parity_bits(data24, prev_word30)


def data_bits(word30: int, prev_word30: int) -> int:
    """The 24 source data bits of a transmitted 30-bit word, the D30* inversion removed (parity not checked)."""
    data = (word30 >> 6) & 0xFFFFFF
    return data ^ 0xFFFFFF if prev_word30 & 1 else data


def parity_ok(word30: int, prev_word30: int) -> bool:
    """True when the parity bits D25..D30 of `word30` match its data given the previous word's D29*, D30*."""
    return parity_bits(data_bits(word30, prev_word30), prev_word30) == (word30 & 0x3F)


def sfrbx_from_transmitted(words30: Sequence[int], prev_word30: int = 0) -> list[int]:
    """u-blox RXM-SFRBX dwords of consecutive transmitted words (inversion undone, effective D29* in bit 31)."""
    out: list[int] = []
    prev = prev_word30
    for w in words30:
        w &= 0x3FFFFFFF
        d29_eff = ((prev >> 1) ^ prev) & 1
        out.append((w ^ 0x3FFFFFFF if prev & 1 else w) | (d29_eff << 31))
        prev = w
    return out


def sfrbx_words24(dwords: Sequence[int], prev_dword: int = 0) -> tuple[list[int], list[bool]]:
    """Data bits and per-word parity results of RXM-SFRBX GPS dwords (one subframe, 10 dwords).

    The effective D29* of each word is taken from the previous reported word (D29 ⊕ D30), not from bit 31,
    so a receiver that leaves bits 31..30 zero is handled the same. `prev_dword` precedes the first word
    (0 at a subframe start).
    """
    out: list[int] = []
    ok: list[bool] = []
    prev = prev_dword
    for w in dwords:
        w &= 0x3FFFFFFF
        eff_prev = (((prev >> 1) ^ prev) & 1) << 1
        data = (w >> 6) & 0xFFFFFF
        out.append(data)
        ok.append(parity_bits(data, eff_prev) == (w & 0x3F))
        prev = w
    return out, ok


def _solve_t_bits(data24: int, prev_word30: int) -> int:
    """Set data bits 23–24 (the non-information 't' bits) so that D29 = D30 = 0 (IS-GPS-200 20.3.5.2)."""
    base = data24 & ~0x3
    for t in range(4):
        if encode_word(base | t, prev_word30) & 0x3 == 0:
            return base | t
    raise AssertionError("no t bits zero D29/D30")  # cannot happen: the two equations are independent


def words24_from_words30(words30: Sequence[int], prev_word30: int = 0) -> tuple[list[int], list[bool]]:
    """Data bits and per-word parity results of consecutive transmitted words (e.g. one RXM-SFRBX subframe).

    `prev_word30` is the word transmitted before the first one (0 at a subframe start: every word 10 ends
    with D29 = D30 = 0).
    """
    out: list[int] = []
    ok: list[bool] = []
    prev = prev_word30
    for w in words30:
        w &= 0x3FFFFFFF
        out.append(data_bits(w, prev))
        ok.append(parity_ok(w, prev))
        prev = w
    return out, ok


# ----------------------------------------------------------------------------------- field packing


def _get_raw(words24: Sequence[int], fld: LnavField) -> int:
    raw = 0
    for word, start, length in fld.parts:
        raw = (raw << length) | ((words24[word - 1] >> (24 - start - length + 1)) & ((1 << length) - 1))
    if fld.signed and raw >> (fld.n_bits - 1):
        raw -= 1 << fld.n_bits
    return raw


def _set_raw(words24: list[int], fld: LnavField, raw: int) -> None:
    n = fld.n_bits
    lo, hi = (-(1 << (n - 1)), (1 << (n - 1)) - 1) if fld.signed else (0, (1 << n) - 1)
    if not lo <= raw <= hi:
        raise LnavError(f"LNAV field {fld.name}: value {raw} × LSB out of its {n}-bit range [{lo}, {hi}]")
    raw &= (1 << n) - 1
    shift_total = n
    for word, start, length in fld.parts:
        shift_total -= length
        part = (raw >> shift_total) & ((1 << length) - 1)
        pos = 24 - start - length + 1
        words24[word - 1] = (words24[word - 1] & ~(((1 << length) - 1) << pos)) | (part << pos)


def _to_raw(fld: LnavField, value: float) -> int:
    return int(value) if fld.name in _INT_FIELDS else round(value / fld.lsb)


def _from_raw(fld: LnavField, raw: int) -> float | int:
    return raw if fld.name in _INT_FIELDS else raw * fld.lsb


def unpack_subframe(words24: Sequence[int]) -> tuple[int, dict[str, float | int]]:
    """Subframe id and the fields of a 10-word subframe given as 24-bit data words (TLM, HOW first).

    Raises LnavError on a wrong word count or preamble; returns (id, {}) for subframes 4 and 5.
    """
    if len(words24) != 10:
        raise LnavError(f"an LNAV subframe has 10 words, got {len(words24)}")
    if (words24[0] >> 16) & 0xFF != PREAMBLE:
        raise LnavError(f"TLM word without preamble 0x8B (got 0x{(words24[0] >> 16) & 0xFF:02X})")
    how = words24[1] & 0xFFFFFF
    sfid = (how >> 2) & 0x7
    values: dict[str, float | int] = {"tow_count": how >> 7}
    if sfid in (1, 2, 3):
        values.update(_unpack_fields(sfid, words24))
    return sfid, values


def _unpack_fields(subframe: int, words24: Sequence[int]) -> dict[str, float | int]:
    return {f.name: _from_raw(f, _get_raw(words24, f)) for f in LNAV_FIELDS if f.subframe == subframe}


def fit_interval_h(fit_flag: int, iodc: int) -> float:
    """Curve-fit interval (h) from the subframe 2 fit flag and the IODC (IS-GPS-200 Table 20-XII)."""
    if not fit_flag:
        return 4.0
    for lo, hi, hours in _FIT_BY_IODC:
        if lo <= iodc <= hi:
            return hours
    return 6.0


def _field_values(eph: Ephemeris) -> dict[str, float | int]:
    vals: dict[str, float | int] = {
        f.name: getattr(eph, f.name) for f in LNAV_FIELDS if hasattr(eph, f.name) and f.name not in ("iode",)
    }
    vals.update(
        week10=eph.week % 1024, iode=eph.iode, iode_sf3=eph.iode, toc_s=eph.toc.tow_s, toe_s=eph.toe.tow_s,
        fit_flag=0 if eph.fit_interval_h <= 4.0 else 1, aodo=0,
    )
    if eph.iode != eph.iodc & 0xFF:
        raise LnavError(f"PRN {eph.prn}: IODE {eph.iode} is not the 8 LSBs of IODC {eph.iodc}")
    return vals


def _pack_fields(eph: Ephemeris) -> list[list[int]]:
    """Words 3..10 (24 data bits, t bits zero) of subframes 1, 2, 3; index [sf-1][word-1] with words 1–2 zero."""
    vals = _field_values(eph)
    frames = [[0] * 10 for _ in range(3)]
    for f in LNAV_FIELDS:
        _set_raw(frames[f.subframe - 1], f, _to_raw(f, vals[f.name]))
    return frames


# ------------------------------------------------------------------------------------------ encode


def how_word24(tow_count_next: int, subframe_id: int, alert: bool = False, anti_spoof: bool = True) -> int:
    """HOW data bits: TOW count of the *next* subframe start (6-s units), flags, subframe id, t bits zero."""
    return ((tow_count_next % TOW_COUNT_MAX) << 7) | (int(alert) << 6) | (int(anti_spoof) << 5) | (subframe_id << 2)


def tlm_word24(tlm_message: int = 0, integrity: bool = False) -> int:
    """TLM data bits: preamble, 14-bit TLM message, integrity status flag, reserved bit."""
    return (PREAMBLE << 16) | ((tlm_message & 0x3FFF) << 2) | (int(integrity) << 1)


def encode_subframes(eph: Ephemeris, tow_s: float, anti_spoof: bool = True) -> list[list[int]]:
    """Subframes 1, 2, 3 of `eph` as an M8T reports them in RXM-SFRBX: 3 × 10 dwords (see module doc).

    The on-air words of :func:`encode_subframes_transmitted` with the D30* inversion undone and the
    effective D29* in bit 31, exactly as in real captures; a 32-bit dword each.
    """
    return [sfrbx_from_transmitted(sf) for sf in encode_subframes_transmitted(eph, tow_s, anti_spoof)]


def encode_subframes_transmitted(eph: Ephemeris, tow_s: float, anti_spoof: bool = True) -> list[list[int]]:
    """Subframes 1, 2, 3 of `eph` as 3 × 10 transmitted 30-bit words with parity (D30* chained).

    `tow_s` is the GPS time of week (s) at which subframe 1 starts (a multiple of 6 s; a frame starts on
    multiples of 30 s). Each HOW carries the TOW count of the following subframe. Bits 23–24 of the HOW and
    of word 10 are solved so that every subframe ends with D29 = D30 = 0, so the first TLM chains on 0.
    Raises LnavError when a value does
    not fit its field or `tow_s` is off the 6-s grid.
    """
    if round(tow_s * 1000) % 6000 != 0 or not 0 <= tow_s < SECONDS_PER_WEEK:
        raise LnavError(f"subframe start tow_s={tow_s} is not on the 6-s grid within the week")
    count0 = round(tow_s) // 6
    data = _pack_fields(eph)
    out: list[list[int]] = []
    prev = 0
    for k in range(3):
        words24 = data[k]
        words24[0] = tlm_word24()
        words24[1] = how_word24(count0 + k + 1, k + 1, anti_spoof=anti_spoof)
        words30: list[int] = []
        for i in range(10):
            d = words24[i]
            if i in (1, 9):
                d = _solve_t_bits(d, prev)
            w = encode_word(d, prev)
            words30.append(w)
            prev = w
        out.append(words30)
    return out


def aid_eph_words(eph: Ephemeris, tow_s: float | None = None) -> tuple[int, list[int]]:
    """AID-EPH content of `eph`: (HOW data bits, 24 words SF1D0..SF3D7 = words 3..10 of subframes 1–3).

    `tow_s` is the transmission time of subframe 1 used for the HOW (default: toe − 2 h rounded down to
    a 30-s frame start, as for an ephemeris in use). The 't' bits of word 10 are solved as broadcast.
    """
    if tow_s is None:
        tow_s = ((eph.toe.tow_s - 7200.0) % SECONDS_PER_WEEK) // 30 * 30
    sfs = encode_subframes_transmitted(eph, tow_s)
    words: list[int] = []
    how = 0
    for k, sf in enumerate(sfs):
        w24, _ = words24_from_words30(sf)
        if k == 0:
            how = w24[1]
        words.extend(w24[2:])
    return how, words


# ------------------------------------------------------------------------------------------ decode


def resolve_week10(week10: int, reference_week: int | None) -> int:
    """Full GPS week from the broadcast 10-bit week: the one nearest `reference_week` (or the default era)."""
    if reference_week is None:
        return week10 + 1024 * DEFAULT_WEEK_ROLLOVERS
    full = reference_week - ((reference_week - week10) % 1024)
    if reference_week - full > 512:
        full += 1024
    return full


def _near(t: GpsTime, ref: GpsTime) -> GpsTime:
    """`t` moved by whole weeks to lie within half a week of `ref`."""
    dt = t.diff_s(ref)
    if dt > SECONDS_PER_WEEK / 2:
        return t.add_s(-SECONDS_PER_WEEK)
    if dt < -SECONDS_PER_WEEK / 2:
        return t.add_s(SECONDS_PER_WEEK)
    return t


def ephemeris_from_fields(
    prn: int,
    sf1: dict[str, float | int],
    sf2: dict[str, float | int],
    sf3: dict[str, float | int],
    week: int,
    t_tx: GpsTime | None = None,
) -> Ephemeris:
    """Ephemeris from decoded subframe fields; `week` is the full week of subframe 1.

    When the transmission time `t_tx` is known, toe/toc are placed within half a week of it (the broadcast
    week is the transmission week; toe may fall in the next week near a rollover); else in `week`.
    """
    iodc = int(sf1["iodc"])
    if not int(sf2["iode"]) == int(sf3["iode_sf3"]) == iodc & 0xFF:
        raise LnavError(f"PRN {prn}: IODC {iodc} / IODE {sf2['iode']} / {sf3['iode_sf3']} do not match")
    toe = GpsTime.from_week_tow_s(week, float(sf2["toe_s"]))
    if t_tx is not None:
        toe = _near(toe, t_tx)
    toc = _near(GpsTime.from_week_tow_s(toe.week, float(sf1["toc_s"])), toe)
    return Ephemeris(
        prn=prn, week=toe.week, toe=toe, toc=toc, iode=int(sf2["iode"]), iodc=iodc,
        sqrt_a=float(sf2["sqrt_a"]), e=float(sf2["e"]), i0_rad=float(sf3["i0_rad"]),
        omega0_rad=float(sf3["omega0_rad"]), omega_rad=float(sf3["omega_rad"]), m0_rad=float(sf2["m0_rad"]),
        delta_n_rad_s=float(sf2["delta_n_rad_s"]), omega_dot_rad_s=float(sf3["omega_dot_rad_s"]),
        idot_rad_s=float(sf3["idot_rad_s"]), cuc_rad=float(sf2["cuc_rad"]), cus_rad=float(sf2["cus_rad"]),
        crc_m=float(sf3["crc_m"]), crs_m=float(sf2["crs_m"]), cic_rad=float(sf3["cic_rad"]),
        cis_rad=float(sf3["cis_rad"]), af0_s=float(sf1["af0_s"]), af1_s_s=float(sf1["af1_s_s"]),
        af2_s_s2=float(sf1["af2_s_s2"]), tgd_s=float(sf1["tgd_s"]), ura_index=int(sf1["ura_index"]),
        health=int(sf1["health"]), fit_interval_h=fit_interval_h(int(sf2["fit_flag"]), iodc),
        code_on_l2=int(sf1["code_on_l2"]), l2p_flag=int(sf1["l2p_flag"]),
    )


def ephemeris_from_aid_eph(svid: int, how: int, words24: Sequence[int], reference_week: int | None) -> Ephemeris:
    """Ephemeris from an AID-EPH reply: `how` (unused beyond logging; may be 0), 24 words SF1D0..SF3D7.

    u-blox adjusts the subframe 1 week to the toe, so toe is placed in that (resolved) week.
    Raises LnavError on a wrong word count or mismatching IODC/IODE.
    """
    if len(words24) != 24:
        raise LnavError(f"AID-EPH carries 24 data words, got {len(words24)}")
    sfs = []
    for k in range(3):
        full = [0, 0] + [int(w) & 0xFFFFFF for w in words24[8 * k : 8 * k + 8]]
        sfs.append(_unpack_fields(k + 1, full))
    week = resolve_week10(int(sfs[0]["week10"]), reference_week)
    log.debug("AID-EPH SV %d HOW 0x%06X week %d", svid, how, week)
    return ephemeris_from_fields(svid, sfs[0], sfs[1], sfs[2], week)


class LnavAssembler:
    """Collects subframes 1–3 per PRN and emits an Ephemeris once a consistent set is complete.

    Feed 10 data words per subframe (24 bits each, TLM and HOW first: RXM-SFRB) with :meth:`add_subframe`,
    or 30-bit words (RXM-SFRBX dwords, or on-air words) with :meth:`add_subframe_words30` (parity-checked; a failed subframe is dropped
    and counted in `parity_failures`). An Ephemeris is returned when subframes 1, 2 and 3 agree on IODC/IODE
    and the set differs from the last one returned for that PRN (repeats return None). Subframes 4/5 are
    ignored. `reference_week` resolves the 10-bit week (nearest full week).
    """

    def __init__(self, reference_week: int | None = None) -> None:
        self.reference_week = reference_week
        self._parts: dict[int, dict[int, dict[str, float | int]]] = {}
        self._last: dict[int, Ephemeris] = {}
        self.parity_failures = 0
        self.rejected = 0

    def add_subframe(
        self, prn: int, words24: Sequence[int], reference_week: int | None = None
    ) -> Ephemeris | None:
        """Add one subframe of 24-bit data words; returns a new Ephemeris when a set completes."""
        try:
            sfid, vals = unpack_subframe([int(w) & 0xFFFFFF for w in words24])
        except LnavError as exc:
            self.rejected += 1
            log.debug("PRN %d: subframe rejected: %s", prn, exc)
            return None
        if sfid not in (1, 2, 3):
            return None
        parts = self._parts.setdefault(prn, {})
        parts[sfid] = vals
        if len(parts) < 3:
            return None
        sf1, sf2, sf3 = parts[1], parts[2], parts[3]
        iodc = int(sf1["iodc"])
        if not int(sf2["iode"]) == int(sf3["iode_sf3"]) == iodc & 0xFF:
            return None  # an ephemeris cut-over in progress: wait for the matching subframes
        ref = reference_week if reference_week is not None else self.reference_week
        week = resolve_week10(int(sf1["week10"]), ref)
        # HOW of subframe 1 holds the count of the next subframe's start.
        t_tx = GpsTime.from_week_tow_s(week, (int(sf1["tow_count"]) * 6 - 6) % SECONDS_PER_WEEK)
        eph = ephemeris_from_fields(prn, sf1, sf2, sf3, week, t_tx)
        if self._last.get(prn) == eph:
            return None
        self._last[prn] = eph
        return eph

    def add(self, prn: int, words: Sequence[int], reference_week: int | None = None) -> Ephemeris | None:
        """Add one subframe in either form (the ARCHITECTURE contract): 24-bit data words (RXM-SFRB) or
        RXM-SFRBX dwords. Told apart by the TLM word: 24-bit form keeps it below 2**24, while the SFRBX form
        has the preamble in bits 29..22 (≥ 2**29)."""
        if len(words) and int(words[0]) >> 24:
            return self.add_subframe_words30(prn, words, reference_week=reference_week)
        return self.add_subframe(prn, words, reference_week)

    def add_subframe_words30(
        self, prn: int, words30: Sequence[int], transmitted: bool = False, reference_week: int | None = None
    ) -> Ephemeris | None:
        """Add one subframe of 30-bit words: RXM-SFRBX dwords (default) or on-air words (`transmitted`).

        Parity is checked on every word; a subframe with any failure is dropped and counted.
        """
        words24, ok = words24_from_words30(words30) if transmitted else sfrbx_words24(words30)
        if not all(ok):
            self.parity_failures += 1
            log.debug("PRN %d: parity failure in words %s", prn, [i + 1 for i, good in enumerate(ok) if not good])
            return None
        return self.add_subframe(prn, words24, reference_week)
