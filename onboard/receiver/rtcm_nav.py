"""RTCM 3 broadcast ephemerides of the other constellations → our types (parsed by pyrtcm 1.2.1).

1020 GLONASS → `GlonassEphemeris`; 1042 BeiDou, 1044 QZSS, 1045 Galileo F/NAV, 1046 Galileo I/NAV → `Ephemeris`
with their gnss_id (RTCM 10403.3, 3.5.12–3.5.17). GPS 1019 stays in onboard.receiver.rtcm. pyrtcm scales most
fields to their units (semicircles, s, km …); it leaves GLONASS γn, τn, Δτn (DF121, DF124, DF125) as signed
integers and tk (DF107) as its raw 12 bits, which we scale here. Angles go from semicircles to radians with the
ICD value of π (onboard.rtk.lnav.SC2RAD, as RTKLIB's RTCM decoder).

Times: RTCM carries weeks of 10 bits (QZSS) or the time of day only (GLONASS tb, tk): a `reference` GPS time
within half a week (GLONASS: half a day) resolves them; GLONASS also needs `leap_s` = GPST − UTC.
`decode_nav_message` returns None for other message numbers and raises RtcmNavError on undecodable frames.

Encoding (what `python -m onboard base` sends): `encode_nav_message` packs any ephemeris into its message —
1019 (onboard.receiver.rtcm), 1020, 1042, 1044, 1046 (I/NAV; F/NAV 1045 is not sent: the M8T tracks E1 only) —
from the declarative layouts below (field, bits, signed or SIGN_MAGNITUDE, scale in the decoded unit), the exact
inverse of the decoders above: decode(encode(eph)) re-encodes to the same bytes.
"""

from __future__ import annotations

import datetime as _dt

from pyrtcm import RTCMMessage, RTCMReader
from pyrtcm.exceptions import RTCMMessageError, RTCMParseError, RTCMStreamError, RTCMTypeError

from onboard.gnsstime import (
    GpsTime,
    bdt_week_tow_ns,
    glonass_datetime,
    gpst_from_bdt,
    gpst_from_glonass_tod,
    gpst_from_gst,
    gst_week_tow_ns,
    resolve_week,
)
from onboard.receiver.framing import Frame, Protocol
from onboard.receiver.rtcm import SIGN_MAGNITUDE, BitWriter, Layout, encode_ephemeris, rtcm3_frame
from onboard.rtk.galileo_inav import DATA_SOURCE_E1B
from onboard.rtk.lnav import SC2RAD, fit_interval_h, resolve_week10
from onboard.rtk.types import GNSS_BEIDOU, GNSS_GALILEO, GNSS_GPS, GNSS_QZSS, Ephemeris, GlonassEphemeris

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


# --- encoding ------------------------------------------------------------------------------------------

_SM = SIGN_MAGNITUDE
_KM = 1e3
_LAYOUT_1020: Layout = (
    ("DF002", 12, False, 1), ("DF038", 6, False, 1), ("DF040", 5, False, 1), ("DF104", 1, False, 1),
    ("DF105", 1, False, 1), ("DF106", 2, False, 1), ("DF107", 12, False, 1), ("DF108", 1, False, 1),
    ("DF109", 1, False, 1), ("DF110", 7, False, 1), ("DF111", 24, _SM, 2**-20), ("DF112", 27, _SM, 2**-11),
    ("DF113", 5, _SM, 2**-30), ("DF114", 24, _SM, 2**-20), ("DF115", 27, _SM, 2**-11), ("DF116", 5, _SM, 2**-30),
    ("DF117", 24, _SM, 2**-20), ("DF118", 27, _SM, 2**-11), ("DF119", 5, _SM, 2**-30), ("DF120", 1, False, 1),
    ("DF121", 11, _SM, 1), ("DF122", 2, False, 1), ("DF123", 1, False, 1), ("DF124", 22, _SM, 1),
    ("DF125", 5, _SM, 1), ("DF126", 5, False, 1), ("DF127", 1, False, 1), ("DF128", 4, False, 1),
    ("DF129", 11, False, 1), ("DF130", 2, False, 1), ("DF131", 1, False, 1), ("DF132", 11, False, 1),
    ("DF133", 32, _SM, 1), ("DF134", 5, False, 1), ("DF135", 22, _SM, 1), ("DF136", 1, False, 1),
    ("DF001_7", 7, False, 1))
"""RTCM 1020 (km, km/s, km/s² as pyrtcm scales them; γn, τn, Δτn as raw integers, scaled by the caller)."""
_LAYOUT_1042: Layout = (
    ("DF002", 12, False, 1), ("DF488", 6, False, 1), ("DF489", 13, False, 1), ("DF490", 4, False, 1),
    ("DF491", 14, True, 2**-43), ("DF492", 5, False, 1), ("DF493", 17, False, 8), ("DF494", 11, True, 2**-66),
    ("DF495", 22, True, 2**-50), ("DF496", 24, True, 2**-33), ("DF497", 5, False, 1), ("DF498", 18, True, 2**-6),
    ("DF499", 16, True, 2**-43), ("DF500", 32, True, 2**-31), ("DF501", 18, True, 2**-31),
    ("DF502", 32, False, 2**-33), ("DF503", 18, True, 2**-31), ("DF504", 32, False, 2**-19),
    ("DF505", 17, False, 8), ("DF506", 18, True, 2**-31), ("DF507", 32, True, 2**-31), ("DF508", 18, True, 2**-31),
    ("DF509", 32, True, 2**-31), ("DF510", 18, True, 2**-6), ("DF511", 32, True, 2**-31),
    ("DF512", 24, True, 2**-43), ("DF513", 10, True, 0.1), ("DF514", 10, True, 0.1), ("DF515", 1, False, 1))
"""RTCM 1042 BeiDou (TGD in ns)."""
_LAYOUT_1044: Layout = (
    ("DF002", 12, False, 1), ("DF429", 4, False, 1), ("DF430", 16, False, 16), ("DF431", 8, True, 2**-55),
    ("DF432", 16, True, 2**-43), ("DF433", 22, True, 2**-31), ("DF434", 8, False, 1), ("DF435", 16, True, 2**-5),
    ("DF436", 16, True, 2**-43), ("DF437", 32, True, 2**-31), ("DF438", 16, True, 2**-29),
    ("DF439", 32, False, 2**-33), ("DF440", 16, True, 2**-29), ("DF441", 32, False, 2**-19),
    ("DF442", 16, False, 16), ("DF443", 16, True, 2**-29), ("DF444", 32, True, 2**-31), ("DF445", 16, True, 2**-29),
    ("DF446", 32, True, 2**-31), ("DF447", 16, True, 2**-5), ("DF448", 32, True, 2**-31),
    ("DF449", 24, True, 2**-43), ("DF450", 14, True, 2**-43), ("DF451", 2, False, 1), ("DF452", 10, False, 1),
    ("DF453", 4, False, 1), ("DF454", 6, False, 1), ("DF455", 8, True, 2**-31), ("DF456", 10, False, 1),
    ("DF457", 1, False, 1))
"""RTCM 1044 QZSS."""
_LAYOUT_1046: Layout = (
    ("DF002", 12, False, 1), ("DF252", 6, False, 1), ("DF289", 12, False, 1), ("DF290", 10, False, 1),
    ("DF286", 8, False, 1), ("DF292", 14, True, 2**-43), ("DF293", 14, False, 60), ("DF294", 6, True, 2**-59),
    ("DF295", 21, True, 2**-46), ("DF296", 31, True, 2**-34), ("DF297", 16, True, 2**-5),
    ("DF298", 16, True, 2**-43), ("DF299", 32, True, 2**-31), ("DF300", 16, True, 2**-29),
    ("DF301", 32, False, 2**-33), ("DF302", 16, True, 2**-29), ("DF303", 32, False, 2**-19),
    ("DF304", 14, False, 60), ("DF305", 16, True, 2**-29), ("DF306", 32, True, 2**-31), ("DF307", 16, True, 2**-29),
    ("DF308", 32, True, 2**-31), ("DF309", 16, True, 2**-5), ("DF310", 32, True, 2**-31),
    ("DF311", 24, True, 2**-43), ("DF312", 10, True, 2**-32), ("DF313", 10, True, 2**-32), ("DF316", 2, False, 1),
    ("DF317", 1, False, 1), ("DF287", 2, False, 1), ("DF288", 1, False, 1), ("DF001_2", 2, False, 1))
"""RTCM 1046 Galileo I/NAV."""


def _frame(layout: Layout, values: dict[str, float]) -> bytes:
    w = BitWriter()
    w.put_fields(layout, values)
    return rtcm3_frame(w.to_bytes())


def _kepler_values(eph: Ephemeris, names: tuple[str, ...]) -> dict[str, float]:
    """The orbit and clock fields common to 1042/1044/1046, by the message's field names in this order:
    sqrt A, e, i0, Ω0, ω, M0, Δn, Ω̇, IDOT, Cuc, Cus, Crc, Crs, Cic, Cis, af0, af1, af2 (semicircles)."""
    values = (eph.sqrt_a, eph.e, eph.i0_rad / SC2RAD, eph.omega0_rad / SC2RAD, eph.omega_rad / SC2RAD,
              eph.m0_rad / SC2RAD, eph.delta_n_rad_s / SC2RAD, eph.omega_dot_rad_s / SC2RAD, eph.idot_rad_s / SC2RAD,
              eph.cuc_rad, eph.cus_rad, eph.crc_m, eph.crs_m, eph.cic_rad, eph.cis_rad, eph.af0_s, eph.af1_s_s,
              eph.af2_s_s2)
    return dict(zip(names, values, strict=True))


def encode_1042(eph: Ephemeris) -> bytes:
    """RTCM 1042 frame of a BeiDou ephemeris (GPST toe/toc → BDT)."""
    week, toe_ns = bdt_week_tow_ns(eph.toe)
    _, toc_ns = bdt_week_tow_ns(eph.toc)
    v = _kepler_values(eph, ("DF504", "DF502", "DF509", "DF507", "DF511", "DF500", "DF499", "DF512", "DF491",
                             "DF501", "DF503", "DF510", "DF498", "DF506", "DF508", "DF496", "DF495", "DF494"))
    v.update({"DF002": 1042, "DF488": eph.prn, "DF489": week, "DF490": eph.ura_index, "DF492": eph.iode,
              "DF493": toc_ns / 1e9, "DF497": eph.iodc, "DF505": toe_ns / 1e9, "DF513": eph.tgd_s * 1e9,
              "DF514": eph.tgd2_s * 1e9, "DF515": eph.health & 1})
    return _frame(_LAYOUT_1042, v)


def encode_1044(eph: Ephemeris) -> bytes:
    """RTCM 1044 frame of a QZSS ephemeris (fit flag 1 when the fit interval exceeds 2 h)."""
    v = _kepler_values(eph, ("DF441", "DF439", "DF446", "DF444", "DF448", "DF437", "DF436", "DF449", "DF450",
                             "DF438", "DF440", "DF447", "DF435", "DF443", "DF445", "DF433", "DF432", "DF431"))
    v.update({"DF002": 1044, "DF429": eph.prn, "DF430": eph.toc.tow_s, "DF434": eph.iode, "DF442": eph.toe.tow_s,
              "DF451": eph.code_on_l2, "DF452": eph.toe.week % 1024, "DF453": eph.ura_index,
              "DF454": eph.health, "DF455": eph.tgd_s, "DF456": eph.iodc,
              "DF457": int(eph.fit_interval_h > 2.0)})
    return _frame(_LAYOUT_1044, v)


def encode_1046(eph: Ephemeris) -> bytes:
    """RTCM 1046 frame of a Galileo I/NAV ephemeris (health word → E5b/E1-B HS and DVS)."""
    week, toe_ns = gst_week_tow_ns(eph.toe)
    _, toc_ns = gst_week_tow_ns(eph.toc)
    h = eph.health
    v = _kepler_values(eph, ("DF303", "DF301", "DF308", "DF306", "DF310", "DF299", "DF298", "DF311", "DF292",
                             "DF300", "DF302", "DF309", "DF297", "DF305", "DF307", "DF296", "DF295", "DF294"))
    v.update({"DF002": 1046, "DF252": eph.prn, "DF289": week % 4096, "DF290": eph.iode, "DF286": eph.ura_index,
              "DF293": toc_ns / 1e9, "DF304": toe_ns / 1e9, "DF312": eph.tgd_s, "DF313": eph.tgd2_s,
              "DF316": (h >> 7) & 3, "DF317": (h >> 6) & 1, "DF287": (h >> 1) & 3, "DF288": h & 1, "DF001_2": 0})
    return _frame(_LAYOUT_1046, v)


def _glonass_tod_s(t: GpsTime, leap_s: int) -> tuple[_dt.datetime, float]:
    g = glonass_datetime(t, leap_s)
    return g, g.hour * 3600 + g.minute * 60 + g.second + g.microsecond / 1e6


def encode_1020(eph: GlonassEphemeris, leap_s: int) -> bytes:
    """RTCM 1020 frame of a GLONASS ephemeris (m → km; tb and tk from toe/tof in GLONASS time, `leap_s` =
    GPST − UTC; NT the day of toe in its four-year interval; no almanac or additional data)."""
    tb_day, tb_s = _glonass_tod_s(eph.toe, leap_s)
    _, tk_s = _glonass_tod_s(eph.tof, leap_s)
    tk = int(tk_s)
    leap_year = tb_day.year - (tb_day.year - 1996) % 4
    nt = (tb_day.date() - _dt.date(leap_year, 1, 1)).days + 1
    v: dict[str, float] = {
        "DF002": 1020, "DF038": eph.slot, "DF040": eph.channel + 7, "DF104": 0, "DF105": 0, "DF106": 0,
        "DF107": (tk // 3600) << 7 | ((tk % 3600) // 60) << 1 | int(tk % 60 >= 30), "DF108": eph.health & 1,
        "DF109": 0, "DF110": round(tb_s / 900.0) % 96, "DF120": 0, "DF121": round(eph.gamma_n * 2.0**40),
        "DF122": 0, "DF123": (eph.health >> 1) & 1, "DF124": round(eph.tau_n_s * 2.0**30),
        "DF125": round(eph.delta_tau_n_s * 2.0**30), "DF126": eph.age_days, "DF127": 0, "DF128": eph.ft,
        "DF129": nt, "DF130": 1, "DF131": 0, "DF132": 0, "DF133": 0, "DF134": 0, "DF135": 0, "DF136": 0,
        "DF001_7": 0,
    }
    for axis, (p, vel, acc) in enumerate(zip(eph.pos_m, eph.vel_m_s, eph.acc_m_s2, strict=True)):
        v[f"DF{112 + 3 * axis}"] = p / _KM
        v[f"DF{111 + 3 * axis}"] = vel / _KM
        v[f"DF{113 + 3 * axis}"] = acc / _KM
    return _frame(_LAYOUT_1020, v)


def nav_message_number(eph: Ephemeris | GlonassEphemeris) -> int | None:
    """The RTCM message that carries `eph` (1019, 1020, 1042, 1044, 1046), None for an F/NAV or other one."""
    if isinstance(eph, GlonassEphemeris):
        return 1020
    if eph.gnss_id == GNSS_GALILEO:
        return 1046 if eph.code_on_l2 & DATA_SOURCE_E1B else None
    return {GNSS_GPS: 1019, GNSS_BEIDOU: 1042, GNSS_QZSS: 1044}.get(eph.gnss_id)


def encode_nav_message(eph: Ephemeris | GlonassEphemeris, leap_s: int) -> bytes:
    """The RTCM3 frame of one ephemeris (see `nav_message_number`; ValueError when none carries it or a value
    is outside its field). `leap_s` = GPST − UTC, used for GLONASS only."""
    number = nav_message_number(eph)
    if isinstance(eph, GlonassEphemeris):
        return encode_1020(eph, leap_s)
    if number == 1019:
        return encode_ephemeris(eph)
    if number == 1042:
        return encode_1042(eph)
    if number == 1044:
        return encode_1044(eph)
    if number == 1046:
        return encode_1046(eph)
    raise ValueError(f"no RTCM ephemeris message for gnssId {eph.gnss_id} (data source {eph.code_on_l2:#x})")
