"""RTCM 3 broadcast ephemerides of the other constellations → our types (parsed by pyrtcm 1.2.1).

1020 GLONASS → `GlonassEphemeris`; 1042 BeiDou, 1044 QZSS, 1045 Galileo F/NAV, 1046 Galileo I/NAV → `Ephemeris`
with their gnss_id (RTCM 10403.3, 3.5.12–3.5.17). GPS 1019 stays in onboard.receiver.rtcm. pyrtcm scales most
fields to their units (semicircles, s, km …); it leaves GLONASS γn, τn, Δτn (DF121, DF124, DF125) as signed
integers and tk (DF107) as its raw 12 bits, which we scale here. Angles go from semicircles to radians with the
ICD value of π (onboard.rtk.lnav.SC2RAD, as RTKLIB's RTCM decoder).

Times: RTCM carries weeks of 10 bits (QZSS) or the time of day only (GLONASS tb, tk): a `reference` GPS time
within half a week (GLONASS: half a day) resolves them; GLONASS also needs `leap_s` = GPST − UTC.
`decode_nav_message` returns None for other message numbers and raises RtcmNavError on undecodable frames.
"""

from __future__ import annotations

from pyrtcm import RTCMMessage, RTCMReader
from pyrtcm.exceptions import RTCMMessageError, RTCMParseError, RTCMStreamError, RTCMTypeError

from onboard.gnsstime import GpsTime, gpst_from_bdt, gpst_from_glonass_tod, gpst_from_gst, resolve_week
from onboard.receiver.framing import Frame, Protocol
from onboard.rtk.galileo_inav import DATA_SOURCE_E1B
from onboard.rtk.lnav import SC2RAD, fit_interval_h, resolve_week10
from onboard.rtk.types import GNSS_BEIDOU, GNSS_GALILEO, GNSS_QZSS, Ephemeris, GlonassEphemeris

RTCM_NAV_MESSAGES = frozenset({1020, 1042, 1044, 1045, 1046})
"""The ephemeris messages decoded here."""
DATA_SOURCE_FNAV = 0x102
"""RINEX data-source bits of an F/NAV ephemeris: bit 1 (F/NAV E5a-I) + bit 8 (clock for E5a,E1)."""


class RtcmNavError(ValueError):
    """An ephemeris frame that does not decode."""


def _f(msg: RTCMMessage, name: str) -> float:
    return float(getattr(msg, name))


def _i(msg: RTCMMessage, name: str) -> int:
    return int(getattr(msg, name))


def _near(t: GpsTime, ref: GpsTime) -> GpsTime:
    """`t` moved by whole weeks to within half a week of `ref`."""
    return resolve_week(t.tow_s, ref) if abs(t.diff_s(ref)) > 302_400 else t


def glonass_from_1020(msg: RTCMMessage, reference: GpsTime, leap_s: int) -> GlonassEphemeris:
    """RTCM 1020 → GlonassEphemeris (km → m; τn, γn, Δτn scaled; tb/tk placed nearest `reference`)."""
    km = 1e3
    tk = _i(msg, "DF107")
    tk_s = (tk >> 7) * 3600 + ((tk >> 1) & 0x3F) * 60 + (tk & 1) * 30
    tb = _i(msg, "DF110")
    return GlonassEphemeris(
        slot=_i(msg, "DF038"), channel=_i(msg, "DF040") - 7,
        toe=gpst_from_glonass_tod(tb * 900.0, reference, leap_s),
        tof=gpst_from_glonass_tod(float(tk_s), reference, leap_s),
        pos_m=(_f(msg, "DF112") * km, _f(msg, "DF115") * km, _f(msg, "DF118") * km),
        vel_m_s=(_f(msg, "DF111") * km, _f(msg, "DF114") * km, _f(msg, "DF117") * km),
        acc_m_s2=(_f(msg, "DF113") * km, _f(msg, "DF116") * km, _f(msg, "DF119") * km),
        tau_n_s=_i(msg, "DF124") * 2.0**-30, gamma_n=_i(msg, "DF121") * 2.0**-40,
        delta_tau_n_s=_i(msg, "DF125") * 2.0**-30,
        health=_i(msg, "DF108") | (_i(msg, "DF123") << 1),  # Bn MSB, ln (third string): as from the strings
        age_days=_i(msg, "DF126"), iode=tb, ft=_i(msg, "DF128"),
    )


def beidou_from_1042(msg: RTCMMessage) -> Ephemeris:
    """RTCM 1042 → BeiDou Ephemeris (BDT week/toe/toc → GPST; TGD ns → s)."""
    week = _i(msg, "DF489")
    toe = gpst_from_bdt(week, round(_f(msg, "DF505") * 1e9))
    toc = _near(gpst_from_bdt(week, round(_f(msg, "DF493") * 1e9)), toe)
    return Ephemeris(
        prn=_i(msg, "DF488"), week=toe.week, toe=toe, toc=toc, iode=_i(msg, "DF492"), iodc=_i(msg, "DF497"),
        sqrt_a=_f(msg, "DF504"), e=_f(msg, "DF502"), i0_rad=_f(msg, "DF509") * SC2RAD,
        omega0_rad=_f(msg, "DF507") * SC2RAD, omega_rad=_f(msg, "DF511") * SC2RAD, m0_rad=_f(msg, "DF500") * SC2RAD,
        delta_n_rad_s=_f(msg, "DF499") * SC2RAD, omega_dot_rad_s=_f(msg, "DF512") * SC2RAD,
        idot_rad_s=_f(msg, "DF491") * SC2RAD, cuc_rad=_f(msg, "DF501"), cus_rad=_f(msg, "DF503"),
        crc_m=_f(msg, "DF510"), crs_m=_f(msg, "DF498"), cic_rad=_f(msg, "DF506"), cis_rad=_f(msg, "DF508"),
        af0_s=_f(msg, "DF496"), af1_s_s=_f(msg, "DF495"), af2_s_s2=_f(msg, "DF494"),
        tgd_s=_f(msg, "DF513") * 1e-9, tgd2_s=_f(msg, "DF514") * 1e-9, ura_index=_i(msg, "DF490"),
        health=_i(msg, "DF515"), fit_interval_h=4.0, code_on_l2=0, l2p_flag=0, gnss_id=GNSS_BEIDOU,
    )


def qzss_from_1044(msg: RTCMMessage, reference: GpsTime) -> Ephemeris:
    """RTCM 1044 → QZSS Ephemeris (10-bit week resolved nearest `reference`)."""
    week = resolve_week10(_i(msg, "DF452"), reference.week)
    toe = _near(GpsTime.from_week_tow_s(week, _f(msg, "DF442")), reference)
    toc = _near(GpsTime.from_week_tow_s(toe.week, _f(msg, "DF430")), toe)
    iodc = _i(msg, "DF456")
    fit = fit_interval_h(_i(msg, "DF457"), iodc)
    return Ephemeris(
        prn=_i(msg, "DF429"), week=toe.week, toe=toe, toc=toc, iode=_i(msg, "DF434"), iodc=iodc,
        sqrt_a=_f(msg, "DF441"), e=_f(msg, "DF439"), i0_rad=_f(msg, "DF446") * SC2RAD,
        omega0_rad=_f(msg, "DF444") * SC2RAD, omega_rad=_f(msg, "DF448") * SC2RAD, m0_rad=_f(msg, "DF437") * SC2RAD,
        delta_n_rad_s=_f(msg, "DF436") * SC2RAD, omega_dot_rad_s=_f(msg, "DF449") * SC2RAD,
        idot_rad_s=_f(msg, "DF450") * SC2RAD, cuc_rad=_f(msg, "DF438"), cus_rad=_f(msg, "DF440"),
        crc_m=_f(msg, "DF447"), crs_m=_f(msg, "DF435"), cic_rad=_f(msg, "DF443"), cis_rad=_f(msg, "DF445"),
        af0_s=_f(msg, "DF433"), af1_s_s=_f(msg, "DF432"), af2_s_s2=_f(msg, "DF431"), tgd_s=_f(msg, "DF455"),
        ura_index=_i(msg, "DF453"), health=_i(msg, "DF454"), fit_interval_h=2.0 if fit == 4.0 else fit,
        code_on_l2=_i(msg, "DF451"), l2p_flag=0, gnss_id=GNSS_QZSS,
    )


def galileo_from_1045_1046(msg: RTCMMessage, number: int) -> Ephemeris:
    """RTCM 1045 (F/NAV) or 1046 (I/NAV) → Galileo Ephemeris (GST week → GPST; health as RINEX's SV health)."""
    week = _i(msg, "DF289")
    toe = gpst_from_gst(week, round(_f(msg, "DF304") * 1e9))
    toc = _near(gpst_from_gst(week, round(_f(msg, "DF293") * 1e9)), toe)
    if number == 1045:
        sisa, bgd2 = _i(msg, "DF291"), 0.0
        health = (_i(msg, "DF314") << 4) | (_i(msg, "DF315") << 3)  # E5a HS, DVS (RINEX bits 4–5, 3)
        source = DATA_SOURCE_FNAV
    else:
        sisa, bgd2 = _i(msg, "DF286"), _f(msg, "DF313")
        health = (_i(msg, "DF316") << 7) | (_i(msg, "DF317") << 6) | (_i(msg, "DF287") << 1) | _i(msg, "DF288")
        source = DATA_SOURCE_E1B
    iod = _i(msg, "DF290")
    return Ephemeris(
        prn=_i(msg, "DF252"), week=toe.week, toe=toe, toc=toc, iode=iod, iodc=iod,
        sqrt_a=_f(msg, "DF303"), e=_f(msg, "DF301"), i0_rad=_f(msg, "DF308") * SC2RAD,
        omega0_rad=_f(msg, "DF306") * SC2RAD, omega_rad=_f(msg, "DF310") * SC2RAD, m0_rad=_f(msg, "DF299") * SC2RAD,
        delta_n_rad_s=_f(msg, "DF298") * SC2RAD, omega_dot_rad_s=_f(msg, "DF311") * SC2RAD,
        idot_rad_s=_f(msg, "DF292") * SC2RAD, cuc_rad=_f(msg, "DF300"), cus_rad=_f(msg, "DF302"),
        crc_m=_f(msg, "DF309"), crs_m=_f(msg, "DF297"), cic_rad=_f(msg, "DF305"), cis_rad=_f(msg, "DF307"),
        af0_s=_f(msg, "DF296"), af1_s_s=_f(msg, "DF295"), af2_s_s2=_f(msg, "DF294"), tgd_s=_f(msg, "DF312"),
        tgd2_s=bgd2, ura_index=sisa, health=health, fit_interval_h=4.0, code_on_l2=source, l2p_flag=0,
        gnss_id=GNSS_GALILEO,
    )


def decode_nav_message(frame: Frame, reference: GpsTime, leap_s: int) -> Ephemeris | GlonassEphemeris | None:
    """One RTCM3 frame → the ephemeris it carries (1020/1042/1044/1045/1046), None for any other message.

    `reference` any GPS time within half a day of the message (GLONASS) or half a week (QZSS); `leap_s`
    GPST − UTC for GLONASS. Raises RtcmNavError when the frame does not decode.
    """
    if frame.protocol is not Protocol.RTCM3 or frame.msg_id not in RTCM_NAV_MESSAGES:
        return None
    try:
        msg = RTCMReader.parse(frame.raw)
        if frame.msg_id == 1020:
            return glonass_from_1020(msg, reference, leap_s)
        if frame.msg_id == 1042:
            return beidou_from_1042(msg)
        if frame.msg_id == 1044:
            return qzss_from_1044(msg, reference)
        return galileo_from_1045_1046(msg, frame.msg_id)
    except (RTCMParseError, RTCMMessageError, RTCMTypeError, RTCMStreamError, AttributeError, TypeError,
            ValueError) as exc:
        raise RtcmNavError(f"RTCM {frame.msg_id}: {exc}") from exc
