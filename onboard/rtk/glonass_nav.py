"""GLONASS L1 OF navigation strings (GLONASS ICD 5.1, 4.3–4.7) → :class:`GlonassEphemeris`.

Pure: no I/O. A string is 85 bits, bit 85 (always 0) sent first, data bits 84..9, Hamming check bits 8..1. The
u-blox RXM-SFRBX form (M8 Receiver Description, "GLONASS"): four 32-bit words, the string's 85 bits
left-aligned in words 1–3 (zero padded), word 4 the receiver's frame identifier (superframe number in bits
31..16, frame number 1–5 in bits 7..0). The immediate data (ephemeris) are strings 1–4 of one frame: they are
only combined when their frame identifiers agree, so strings of two different tb never mix. The date of tb
comes from string 4's day number NT and string 5's four-year interval N4 once a string 5 was seen (else from
the receiver's reference time: tb and tk are times of day).

Hamming code (ICD 4.7): check bit βk (k = 1..7) covers the data bits whose Hamming position has bit k−1 set, the
data bits b9..b85 taking the positions 3, 5, 6, 7, 9, … (powers of two skipped); C_Σ covers all 85 bits. A string
is accepted when every C is 0, or only C_Σ and one of C1..C7 are 1 (an error in a check bit); anything else
(including a single data-bit error the code could correct) is rejected: a guessed correction is not worth a
wrong orbit. RTKLIB rcvraw.c decode_glostr()/test_glostr() were read to check field positions; the code is ours.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

from onboard.gnsstime import GpsTime, gpst_from_glonass_day, gpst_from_glonass_tod
from onboard.rtk.navbits import BitField
from onboard.rtk.types import GlonassEphemeris

log = logging.getLogger(__name__)

STRING_BITS = 85


class GlonassNavError(ValueError):
    """A GLONASS string that cannot be used (wrong word count, Hamming failure, bad string number)."""


def _hamming_masks() -> tuple[list[int], int]:
    """Masks over the 85-bit string (as an int, bit 85 = MSB, bit 1 = LSB) for C1..C7, and the C_Σ mask."""
    positions: list[int] = []
    p = 3
    while len(positions) < STRING_BITS - 8:
        if p & (p - 1):  # not a power of two
            positions.append(p)
        p += 1
    masks = []
    for k in range(7):
        m = 1 << k  # βk+1 is string bit k+1
        for i, pos in enumerate(positions):
            if pos >> k & 1:
                m |= 1 << (i + 8)  # data bit b(9+i) is string bit 9+i
        masks.append(m)
    return masks, (1 << STRING_BITS) - 1


_MASKS, _MASK_SUM = _hamming_masks()


def string_bits(words: Sequence[int]) -> int:
    """The 85-bit string (bit 85 = MSB of the result) from RXM-SFRBX words 1–3 (word 4 is not part of it)."""
    if len(words) < 3:
        raise GlonassNavError(f"a GLONASS string needs 3 words, got {len(words)}")
    v = BitField.of_words(words[:3])
    return v.u(0, STRING_BITS)


def hamming_ok(string85: int) -> bool:
    """True when the string's Hamming code shows no error (or an error in a check bit only, ICD 4.7 a)."""
    c = [(string85 & m).bit_count() & 1 for m in _MASKS]
    c_sum = (string85 & _MASK_SUM).bit_count() & 1
    n = sum(c)
    return (n == 0 and c_sum == 0) or (n == 1 and c_sum == 1)


def string_number(string85: int) -> int:
    """String number m (bits 84..81)."""
    return (string85 >> 80) & 0xF


def _fields(strings: dict[int, int]) -> dict[str, float | int]:
    """Immediate-data fields of strings 1–4 (each an 85-bit int), in SI units (m, m/s, m/s², s)."""
    b = {m: BitField(s, STRING_BITS) for m, s in strings.items()}
    s1, s2, s3, s4 = b[1], b[2], b[3], b[4]
    # positions below are from bit 85 (= index 0): m at 1..4
    km = 1e3
    return {
        "tk_h": s1.u(9, 5), "tk_min": s1.u(14, 6), "tk_30s": s1.u(20, 1),
        "vx": s1.sm(21, 24) * 2.0**-20 * km, "ax": s1.sm(45, 5) * 2.0**-30 * km, "x": s1.sm(50, 27) * 2.0**-11 * km,
        "bn": s2.u(5, 3), "tb": s2.u(9, 7),
        "vy": s2.sm(21, 24) * 2.0**-20 * km, "ay": s2.sm(45, 5) * 2.0**-30 * km, "y": s2.sm(50, 27) * 2.0**-11 * km,
        "gamma_n": s3.sm(6, 11) * 2.0**-40, "ln3": s3.u(20, 1),
        "vz": s3.sm(21, 24) * 2.0**-20 * km, "az": s3.sm(45, 5) * 2.0**-30 * km, "z": s3.sm(50, 27) * 2.0**-11 * km,
        "tau_n": s4.sm(5, 22) * 2.0**-30, "dtau_n": s4.sm(27, 5) * 2.0**-30, "en": s4.u(32, 5),
        "ft": s4.u(52, 4), "nt": s4.u(59, 11), "slot": s4.u(70, 5), "m_type": s4.u(75, 2),
    }


def string5_n4(string85: int) -> int:
    """N4, the four-year interval number (1 = 1996–1999) of string 5 (bits 49–53 from bit 85)."""
    return BitField(string85, STRING_BITS).u(49, 5)


def ephemeris_from_strings(strings: dict[int, int], channel: int, reference: GpsTime,
                           leap_s: int, n4: int | None = None) -> GlonassEphemeris:
    """GlonassEphemeris from strings 1–4 of one frame (85-bit ints by string number).

    `channel` the frequency channel k (RXM-SFRBX freqId − 7), `reference` a GPS time within 12 h of the frame
    (e.g. the receiver time of the last string: tb and tk carry only the time of day), `leap_s` GPST − UTC (s).
    With `n4` (string 5's four-year interval, from any frame) and string 4's day number NT the date of tb is
    the broadcast one and the reference only places tk; a NT of 0 (not given) falls back to the reference.
    Raises GlonassNavError when a string is missing or the slot is 0.
    """
    missing = [m for m in (1, 2, 3, 4) if m not in strings]
    if missing:
        raise GlonassNavError(f"strings {missing} missing")
    f = _fields(strings)
    slot = int(f["slot"])
    if not 1 <= slot <= 24:
        raise GlonassNavError(f"slot number {slot} in string 4")
    tb = int(f["tb"])
    nt = int(f["nt"])
    if n4 and nt:
        toe = gpst_from_glonass_day(n4, nt, tb * 900.0, leap_s)  # tb counts within the day NT names
    else:
        toe = gpst_from_glonass_tod(tb * 900.0, reference, leap_s)
    tk_s = int(f["tk_h"]) * 3600 + int(f["tk_min"]) * 60 + int(f["tk_30s"]) * 30
    tof = gpst_from_glonass_tod(float(tk_s), toe, leap_s)  # the frame is sent within the interval around tb
    return GlonassEphemeris(
        slot=slot, channel=channel, toe=toe, tof=tof,
        pos_m=(float(f["x"]), float(f["y"]), float(f["z"])),
        vel_m_s=(float(f["vx"]), float(f["vy"]), float(f["vz"])),
        acc_m_s2=(float(f["ax"]), float(f["ay"]), float(f["az"])),
        tau_n_s=float(f["tau_n"]), gamma_n=float(f["gamma_n"]), delta_tau_n_s=float(f["dtau_n"]),
        # unhealthy: Bn's MSB (its other bits carry no health, ICD 4.4) or GLONASS-M's ln flag of string 3
        health=(int(f["bn"]) >> 2) | (int(f["ln3"]) << 1), age_days=int(f["en"]), iode=tb, ft=int(f["ft"]),
    )


class GlonassStringAssembler:
    """Collects strings 1–4 per satellite and frame and emits a GlonassEphemeris when a frame's set is
    complete and differs from the last one emitted for that satellite (repeats return None).

    Feed RXM-SFRBX GLONASS L1 OF words with :meth:`add_sfrbx`; a string failing the Hamming check is dropped
    and counted in `hamming_failures`. `leap_s` is GPST − UTC (s): GLONASS time follows UTC.
    """

    def __init__(self, leap_s: int) -> None:
        self.leap_s = leap_s
        self._frames: dict[int, tuple[int, dict[int, int]]] = {}
        self._last: dict[int, GlonassEphemeris] = {}
        self._n4: dict[int, int] = {}
        self.hamming_failures = 0
        self.rejected = 0

    def add_sfrbx(self, sv_id: int, freq_id: int, words: Sequence[int], reference: GpsTime) -> GlonassEphemeris | None:
        """Add one string (4 SFRBX words) of satellite `sv_id` (slot; 255 = unknown is ignored) on frequency
        `freq_id` (k + 7); `reference` the receiver's GPS time. Returns a new ephemeris or None."""
        if len(words) != 4:
            self.rejected += 1
            return None
        s = string_bits(words)
        if not hamming_ok(s):
            self.hamming_failures += 1
            log.debug("GLONASS slot %d: string fails its Hamming check", sv_id)
            return None
        m = string_number(s)
        if not 1 <= m <= 15 or not 1 <= sv_id <= 24:
            self.rejected += 1
            return None
        frame_id = int(words[3]) & 0xFFFFFFFF
        held = self._frames.get(sv_id)
        if held is None or held[0] != frame_id:
            held = (frame_id, {})
            self._frames[sv_id] = held
        held[1][m] = s
        if m == 5:
            self._n4[sv_id] = string5_n4(s)  # changes once in four years: any frame's will do
        if m > 4 or not all(k in held[1] for k in (1, 2, 3, 4)):
            return None
        try:
            eph = ephemeris_from_strings(held[1], freq_id - 7, reference, self.leap_s, self._n4.get(sv_id))
        except GlonassNavError as exc:
            self.rejected += 1
            log.debug("GLONASS slot %d: %s", sv_id, exc)
            return None
        if eph.slot != sv_id:
            self.rejected += 1
            log.debug("GLONASS svId %d carries slot %d in string 4", sv_id, eph.slot)
            return None
        last = self._last.get(sv_id)
        if last is not None and last.toe == eph.toe and last.iode == eph.iode and _same_data(last, eph):
            return None
        self._last[sv_id] = eph
        return eph


def _same_data(a: GlonassEphemeris, b: GlonassEphemeris) -> bool:
    """The same broadcast ephemeris (the frame time tk aside, which changes every frame)."""
    return (a.pos_m, a.vel_m_s, a.acc_m_s2, a.tau_n_s, a.gamma_n, a.health) == (
        b.pos_m, b.vel_m_s, b.acc_m_s2, b.tau_n_s, b.gamma_n, b.health)
