"""One dispatch from RXM-SFRBX navigation words of any constellation to ephemerides (pure: no I/O).

`NavMessageDecoder.add(gnss_id, sv_id, sig_id, freq_id, words, reference)` routes GPS and QZSS LNAV subframes
(onboard.rtk.lnav), GLONASS strings (onboard.rtk.glonass_nav), Galileo I/NAV page pairs
(onboard.rtk.galileo_inav) and BeiDou D1/D2 subframes (onboard.rtk.beidou_nav) to one assembler per system and
returns the new `Ephemeris` / `GlonassEphemeris` when one completes. SBAS and signals that are not the L1-band
navigation messages (GPS L2C/L5 CNAV, Galileo F/NAV, BeiDou B1C/B2a …) return None.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from onboard.gnsstime import GpsTime
from onboard.rtk.beidou_nav import BeidouNavAssembler
from onboard.rtk.galileo_inav import DATA_SOURCE_E1B, DATA_SOURCE_E5B, GalileoInavAssembler
from onboard.rtk.glonass_nav import GlonassStringAssembler
from onboard.rtk.lnav import LnavAssembler
from onboard.rtk.types import (
    GNSS_BEIDOU,
    GNSS_GALILEO,
    GNSS_GLONASS,
    GNSS_GPS,
    GNSS_QZSS,
    Ephemeris,
    GlonassEphemeris,
)

# u-blox sigId of the navigation messages decoded here (u-blox M8/F9 interface descriptions)
_SIG_GPS_L1CA = 0
_SIG_GAL_E1B, _SIG_GAL_E5BI = 1, 5
_SIG_BDS_B1I_D1, _SIG_BDS_B1I_D2 = 0, 1
_SIG_GLO_L1OF = 0


class NavMessageDecoder:
    """Per-system assemblers behind one `add`; `leap_s` = GPST − UTC (s) for GLONASS time (UTC(SU) + 3 h)."""

    def __init__(self, leap_s: int, reference_week: int | None = None) -> None:
        self.gps = LnavAssembler(reference_week)
        self.qzss = LnavAssembler(reference_week)
        self.glonass = GlonassStringAssembler(leap_s)
        self.galileo = GalileoInavAssembler()
        self.beidou = BeidouNavAssembler()

    @property
    def leap_s(self) -> int:
        """GPST − UTC used for GLONASS times (s)."""
        return self.glonass.leap_s

    @leap_s.setter
    def leap_s(self, value: int) -> None:
        self.glonass.leap_s = value

    def add(self, gnss_id: int, sv_id: int, sig_id: int, freq_id: int, words: Sequence[int],
            reference: GpsTime) -> Ephemeris | GlonassEphemeris | None:
        """One RXM-SFRBX message's words; `reference` the receiver's current GPS time (resolves the GPS/QZSS
        10-bit week and the GLONASS day). Returns a newly completed ephemeris, else None."""
        if gnss_id == GNSS_GPS and sig_id == _SIG_GPS_L1CA and len(words) == 10 and 1 <= sv_id <= 32:
            return self.gps.add_subframe_words30(sv_id, words, reference_week=reference.week)
        if gnss_id == GNSS_QZSS and sig_id == _SIG_GPS_L1CA and len(words) == 10 and 1 <= sv_id <= 10:
            eph = self.qzss.add_subframe_words30(sv_id, words, reference_week=reference.week)
            # IS-QZSS: the LNAV fit-interval flag 0 means 2 h
            return None if eph is None else dataclasses.replace(
                eph, gnss_id=GNSS_QZSS, fit_interval_h=2.0 if eph.fit_interval_h == 4.0 else eph.fit_interval_h)
        if gnss_id == GNSS_GLONASS and sig_id == _SIG_GLO_L1OF:
            return self.glonass.add_sfrbx(sv_id, freq_id, words, reference)
        if gnss_id == GNSS_GALILEO and sig_id in (_SIG_GAL_E1B, _SIG_GAL_E5BI) and 1 <= sv_id <= 36:
            source = DATA_SOURCE_E1B if sig_id == _SIG_GAL_E1B else DATA_SOURCE_E5B
            return self.galileo.add_sfrbx(sv_id, words, source)
        if gnss_id == GNSS_BEIDOU and sig_id in (_SIG_BDS_B1I_D1, _SIG_BDS_B1I_D2) and 1 <= sv_id <= 63:
            return self.beidou.add_sfrbx(sv_id, words)
        return None
