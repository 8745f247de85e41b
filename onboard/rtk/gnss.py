"""Satellite systems and satellite ids: u-blox gnssId ↔ RINEX system letter ↔ satellite id ("G05", "R07", "E11").

One table (`SYSTEMS`) holds what differs between constellations: the u-blox gnssId (RXM-RAWX/SFRBX; also
`ObsEpoch.gnss_id`), the RINEX 3 letter, the time system its broadcast times are in, the satellite-number range,
the L1-band carrier the M8T tracks and the largest ephemeris age RTKLIB uses. Satellite numbers inside the
project are u-blox `svId`s: GPS PRN 1–32, SBAS PRN 120–158, Galileo 1–36, BeiDou 1–63, QZSS 1–10 (PRN 193–202),
GLONASS slot 1–24. RINEX numbers them the same except SBAS (S20 = PRN 120) and QZSS (J01 = PRN 193).
"""

from __future__ import annotations

from dataclasses import dataclass

from onboard.rtk.consts import (
    DFREQ_G1_HZ,
    FREQ_B1I_HZ,
    FREQ_G1_HZ,
    FREQ_L1_HZ,
    GLO_FCN_MAX,
    GLO_FCN_MIN,
)
from onboard.rtk.types import GNSS_BEIDOU, GNSS_GALILEO, GNSS_GLONASS, GNSS_GPS, GNSS_QZSS, GNSS_SBAS

GLONASS_CHANNEL_MIN, GLONASS_CHANNEL_MAX = GLO_FCN_MIN, GLO_FCN_MAX
"""Range of the GLONASS frequency channel number k (the carrier constants live in onboard.rtk.consts)."""

TIME_GPST, TIME_GST, TIME_BDT, TIME_GLONASST = "GPST", "GST", "BDT", "GLONASST"
"""Time systems (conversions in onboard.gnsstime): GST = GPST; BDT = GPST − 14 s; GLONASS time = UTC(SU) + 3 h."""


@dataclass(frozen=True)
class GnssSystem:
    """One satellite system: `gnss_id` (u-blox), `letter` (RINEX 3), `name`, `time_system` of its broadcast
    times, `sv_min`/`sv_max` the u-blox svId range, `rinex_offset` (RINEX number = svId − offset),
    `l1_freq_hz` the L1-band carrier the M8T tracks (None for GLONASS: one per channel, glonass_l1_freq_hz),
    `max_eph_age_s` the largest |t − toe| at which a broadcast ephemeris is used (RTKLIB MAXDTOE*)."""

    gnss_id: int
    letter: str
    name: str
    time_system: str
    sv_min: int
    sv_max: int
    rinex_offset: int
    l1_freq_hz: float | None
    max_eph_age_s: float


GPS = GnssSystem(GNSS_GPS, "G", "GPS", TIME_GPST, 1, 32, 0, FREQ_L1_HZ, 7200.0 + 60.0)
SBAS = GnssSystem(GNSS_SBAS, "S", "SBAS", TIME_GPST, 120, 158, 100, FREQ_L1_HZ, 360.0)
GALILEO = GnssSystem(GNSS_GALILEO, "E", "Galileo", TIME_GST, 1, 36, 0, FREQ_L1_HZ, 14400.0)
BEIDOU = GnssSystem(GNSS_BEIDOU, "C", "BeiDou", TIME_BDT, 1, 63, 0, FREQ_B1I_HZ, 21600.0)
QZSS = GnssSystem(GNSS_QZSS, "J", "QZSS", TIME_GPST, 1, 10, 0, FREQ_L1_HZ, 7200.0)
GLONASS = GnssSystem(GNSS_GLONASS, "R", "GLONASS", TIME_GLONASST, 1, 24, 0, None, 1800.0)

SYSTEMS: dict[int, GnssSystem] = {s.gnss_id: s for s in (GPS, SBAS, GALILEO, BEIDOU, QZSS, GLONASS)}
"""Every system by u-blox gnssId."""
SYSTEMS_BY_LETTER: dict[str, GnssSystem] = {s.letter: s for s in SYSTEMS.values()}
"""Every system by RINEX 3 letter."""

QZSS_PRN_OFFSET = 192
"""QZSS PRN = u-blox svId + 192 (PRN 193–202)."""
BEIDOU_GEO_PRNS = frozenset({1, 2, 3, 4, 5, 59, 60, 61, 62, 63})
"""BeiDou satellites in geostationary orbit (BeiDou ICD B1I 3.0, 5.2.4.12: PRN 1–5 and 59–63)."""


class SatIdError(ValueError):
    """A satellite id or number that no system defines."""


def system(gnss_id: int) -> GnssSystem:
    """The system of u-blox gnssId `gnss_id` (SatIdError when unknown, e.g. IMES = 4)."""
    try:
        return SYSTEMS[int(gnss_id)]
    except KeyError:
        raise SatIdError(f"unknown u-blox gnssId {gnss_id}") from None


def sat_id(gnss_id: int, sv_id: int) -> str:
    """RINEX 3 satellite id ("G05", "R07", "E11", "C14", "J01", "S20") of u-blox (gnssId, svId)."""
    s = system(gnss_id)
    if not s.sv_min <= sv_id <= s.sv_max:
        raise SatIdError(f"{s.name} svId {sv_id} outside {s.sv_min}–{s.sv_max}")
    return f"{s.letter}{sv_id - s.rinex_offset:02d}"


def parse_sat_id(text: str) -> tuple[int, int]:
    """u-blox (gnssId, svId) of a RINEX 3 satellite id ("R07" → (6, 7), "S20" → (1, 120); a blank letter is
    GPS, as RINEX 2 writes it)."""
    t = text.strip()
    if not t:
        raise SatIdError("empty satellite id")
    letter, number = (t[0], t[1:]) if t[0].isalpha() else ("G", t)
    s = SYSTEMS_BY_LETTER.get(letter.upper())
    if s is None or not number.strip().isdigit():
        raise SatIdError(f"not a satellite id: {text!r}")
    sv = int(number) + s.rinex_offset
    if not s.sv_min <= sv <= s.sv_max:
        raise SatIdError(f"{s.name} number {int(number)} outside its range: {text!r}")
    return s.gnss_id, sv


def is_beidou_geo(prn: int) -> bool:
    """True for the BeiDou PRNs in geostationary orbit (their ephemeris uses the GEO rotation)."""
    return prn in BEIDOU_GEO_PRNS


def glonass_l1_freq_hz(channel: int) -> float:
    """GLONASS L1 OF carrier frequency (Hz) of frequency channel `channel` (k = −7 … +6)."""
    if not GLONASS_CHANNEL_MIN <= channel <= GLONASS_CHANNEL_MAX:
        raise SatIdError(f"GLONASS frequency channel {channel} outside {GLONASS_CHANNEL_MIN}…{GLONASS_CHANNEL_MAX}")
    return FREQ_G1_HZ + channel * DFREQ_G1_HZ


