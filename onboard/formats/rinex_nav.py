"""RINEX 2.x / 3.x navigation files → `Ephemeris` / `GlonassEphemeris` objects and Klobuchar coefficients.

GPS records go to `NavFile.ephemerides` (what the engine reads: unchanged); RINEX 3 mixed files' Galileo,
BeiDou and QZSS records to `galileo`/`beidou`/`qzss` (Keplerian `Ephemeris` with their gnss_id, toe/toc moved
to the GPS time scale: BDT + 14 s) and GLONASS records to `glonass` (epoch in UTC → GPST with the leap seconds of
that date). RINEX 2 GLONASS (`G`) and QZSS (2.12 `J`) files are read too. SBAS and IRNSS records are skipped by
their line count.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

from onboard.errors import InputError
from onboard.formats.textfile import read_text_lines
from onboard.gnsstime import (
    BDT_MINUS_GPST_S,
    NS_PER_S,
    GpsTime,
    gpst_from_bdt,
    gpst_from_calendar,
    leap_seconds_at_utc,
)
from onboard.rtk.ephemeris import sisa_index_from_m
from onboard.rtk.gnss import QZSS_PRN_OFFSET
from onboard.rtk.types import GNSS_BEIDOU, GNSS_GALILEO, GNSS_QZSS, Ephemeris, GlonassEphemeris

# Lines per record after the first, by RINEX 3 system letter (GLONASS has a 4th line from RINEX 3.05).
_RECORD_LINES = {"G": 7, "E": 7, "C": 7, "J": 7, "I": 7, "R": 3, "S": 3}


@dataclass
class NavFile:
    """Contents of a navigation file: GPS ephemerides (`ephemerides`, the engine's), the other systems' (by
    system, empty when absent), the Klobuchar α/β (None when absent) and the header's leap seconds."""

    ephemerides: list[Ephemeris] = field(default_factory=list)
    iono_alpha: tuple[float, float, float, float] | None = None
    iono_beta: tuple[float, float, float, float] | None = None
    leap_s: int | None = None
    galileo: list[Ephemeris] = field(default_factory=list)
    beidou: list[Ephemeris] = field(default_factory=list)
    qzss: list[Ephemeris] = field(default_factory=list)
    glonass: list[GlonassEphemeris] = field(default_factory=list)


_FORTRAN_EXP = re.compile(r"(?<=[0-9.])([+-][0-9]{3})$")
"""A Fortran exponent of three digits written without its letter ("0.4990633144-269" = 0.499…e-269)."""


def _num(text: str) -> float:
    text = text.strip().replace("D", "E").replace("d", "e")
    if not text:
        return 0.0
    try:
        return float(text)
    except ValueError:
        fixed = _FORTRAN_EXP.sub(r"E\1", text)
        if fixed == text:
            raise
        return float(fixed)


def _fields(line: str, start: int, count: int = 4, width: int = 19) -> list[float]:
    return [_num(line[start + k * width : start + (k + 1) * width]) for k in range(count)]


def _ephemeris_from_values(prn: int, toc: GpsTime, v: list[float]) -> Ephemeris:
    """Build an Ephemeris from the 3 clock values + 28 broadcast-orbit values of a GPS record."""
    af0, af1, af2 = v[0:3]
    iode, crs, dn, m0 = v[3:7]
    cuc, e, cus, sqrt_a = v[7:11]
    toe_s, cic, omega0, cis = v[11:15]
    i0, crc, omega, omega_dot = v[15:19]
    idot, codes_l2, week, l2p = v[19:23]
    sva_m, svh, tgd, iodc = v[23:27]
    fit = v[28] if len(v) > 28 else 4.0
    toe = GpsTime.from_week_tow_s(int(week), toe_s)
    # The RINEX week is the toe's week; realign toc if it falls across the week rollover.
    if toe.diff_s(toc) > 302400:
        toc = toc.add_s(604800)
    elif toe.diff_s(toc) < -302400:
        toc = toc.add_s(-604800)
    return Ephemeris(
        prn=prn, week=int(week), toe=toe, toc=toc, iode=int(iode), iodc=int(iodc), sqrt_a=sqrt_a, e=e,
        i0_rad=i0, omega0_rad=omega0, omega_rad=omega, m0_rad=m0, delta_n_rad_s=dn,
        omega_dot_rad_s=omega_dot, idot_rad_s=idot, cuc_rad=cuc, cus_rad=cus, crc_m=crc, crs_m=crs,
        cic_rad=cic, cis_rad=cis, af0_s=af0, af1_s_s=af1, af2_s_s2=af2, tgd_s=tgd,
        ura_index=ura_index_from_m(sva_m), health=int(svh), fit_interval_h=fit or 4.0,
        code_on_l2=int(codes_l2), l2p_flag=int(l2p),
    )


def _near_week(t: GpsTime, ref: GpsTime) -> GpsTime:
    """`t` moved by whole weeks to within half a week of `ref`."""
    dt = t.diff_s(ref)
    if dt > 302400:
        return t.add_s(-604800)
    if dt < -302400:
        return t.add_s(604800)
    return t


def _galileo_from_values(prn: int, toc: GpsTime, v: list[float]) -> Ephemeris:
    """A Galileo record (RINEX 3 Table A8): GAL week = GPS week (continuous), toe in GST = GPST seconds."""
    e = _ephemeris_from_values(prn, toc, v)
    # v[20] data sources (bits 0/2/9 I/NAV, 1/8 F/NAV), v[23] SISA (m), v[24] health, v[25]/v[26] BGD E5a/E5b
    return dataclasses.replace(e, iodc=e.iode, ura_index=sisa_index_from_m(v[23]), code_on_l2=int(v[20]),
                               l2p_flag=0, tgd_s=v[25], tgd2_s=v[26], fit_interval_h=4.0, gnss_id=GNSS_GALILEO)


def _beidou_from_values(prn: int, toc_bdt: GpsTime, v: list[float]) -> Ephemeris:
    """A BeiDou record (RINEX 3 Table A14): epoch, toe and week in BDT (moved to GPST: + 14 s)."""
    toe = gpst_from_bdt(int(v[21]), round(v[11] * NS_PER_S))
    toc = _near_week(toc_bdt.add_ns(-BDT_MINUS_GPST_S * NS_PER_S), toe)
    e = _ephemeris_from_values(prn, toc, v)
    aodc = int(v[28]) if len(v) > 28 else 0
    return dataclasses.replace(e, toe=toe, toc=toc, week=toe.week, iode=int(v[3]), iodc=aodc,
                               ura_index=ura_index_from_m(v[23]), code_on_l2=0, l2p_flag=0, tgd_s=v[25],
                               tgd2_s=v[26], fit_interval_h=4.0, gnss_id=GNSS_BEIDOU)


def _qzss_from_values(prn: int, toc: GpsTime, v: list[float]) -> Ephemeris:
    """A QZSS LNAV record (as GPS; RINEX numbers J01 = PRN 193, we keep the u-blox svId 1–10). The fit field is
    a flag in RINEX 3 (0 → 2 h, 1 → more: 4 h taken) and hours in some RINEX 2.12 writers (2.0)."""
    e = _ephemeris_from_values(prn, toc, v)
    fit = v[28] if len(v) > 28 else 0.0
    hours = 2.0 if fit == 0.0 else 4.0 if fit == 1.0 else fit
    return dataclasses.replace(e, gnss_id=GNSS_QZSS, fit_interval_h=hours)


def _glonass_from_values(slot: int, toc_utc: GpsTime, v: list[float], v3: bool) -> GlonassEphemeris:
    """A GLONASS record: `toc_utc` the epoch tb read as a calendar instant on the UTC scale (RINEX), values
    −τn, γn, tk; x, ẋ, ẍ, health; y, ẏ, ÿ, channel; z, ż, z̈, age (km, km/s, km/s²)."""
    utc = toc_utc.to_gpst_datetime()
    leap = leap_seconds_at_utc(utc)
    toe = toc_utc.add_ns(leap * NS_PER_S)
    # frame time: seconds of the UTC week (RINEX 3) or of the UTC day (RINEX 2), as a time of day near tb
    day_start = toc_utc.add_ns(-(toc_utc.total_ns % (86_400 * NS_PER_S)))
    tof = day_start.add_s(math.fmod(v[2], 86_400.0) if v3 else v[2])
    if tof.diff_s(toc_utc) > 43_200:
        tof = tof.add_s(-86_400)
    elif tof.diff_s(toc_utc) < -43_200:
        tof = tof.add_s(86_400)
    tb_glo_s = (toc_utc.total_ns // NS_PER_S + 10_800) % 86_400  # tb in GLONASS time (UTC + 3 h) of day
    channel = int(v[10])
    if channel > 128:
        channel -= 256  # some writers store k as an unsigned byte (254 = −2), as RTKLIB also accepts
    return GlonassEphemeris(
        slot=slot, channel=channel, toe=toe, tof=tof.add_ns(leap * NS_PER_S),
        pos_m=(v[3] * 1e3, v[7] * 1e3, v[11] * 1e3), vel_m_s=(v[4] * 1e3, v[8] * 1e3, v[12] * 1e3),
        acc_m_s2=(v[5] * 1e3, v[9] * 1e3, v[13] * 1e3), tau_n_s=-v[0], gamma_n=v[1], health=int(v[6]),
        age_days=int(v[14]), iode=round(tb_glo_s / 900.0) & 0x7F,
    )


def ura_index_from_m(sva_m: float) -> int:
    """URA index for the accuracy (m) that RINEX stores (IS-GPS-200 table, smallest index that covers it)."""
    bounds = (2.4, 3.4, 4.85, 6.85, 9.65, 13.65, 24.0, 48.0, 96.0, 192.0, 384.0, 768.0, 1536.0, 3072.0, 6144.0)
    for i, b in enumerate(bounds):
        if sva_m <= b:
            return i
    return 15


def read_rinex_nav(path: str | Path) -> NavFile:
    """Read a RINEX 2.x (GPS `N`) or 3.x (any, GPS records kept) navigation file, gzip accepted."""
    path = Path(path)
    lines = read_text_lines(path, "navigation file")
    if not lines or "RINEX VERSION" not in lines[0]:
        raise InputError(f"{path}: not a RINEX file (no 'RINEX VERSION / TYPE' header line)")
    version = _num(lines[0][:9])
    nav = NavFile()
    i = 0
    while i < len(lines):
        line = lines[i]
        label = line[60:].strip()
        i += 1
        if label == "END OF HEADER":
            break
        if label == "ION ALPHA":
            nav.iono_alpha = tuple(_fields(line, 2, 4, 12))  # type: ignore[assignment]
        elif label == "ION BETA":
            nav.iono_beta = tuple(_fields(line, 2, 4, 12))  # type: ignore[assignment]
        elif label == "IONOSPHERIC CORR" and line[:4] in ("GPSA", "GPSB"):
            vals = tuple(_fields(line, 5, 4, 12))
            if line[:4] == "GPSA":
                nav.iono_alpha = vals  # type: ignore[assignment]
            else:
                nav.iono_beta = vals  # type: ignore[assignment]
        elif label == "LEAP SECONDS":
            nav.leap_s = int(line[:6])
    else:
        raise InputError(f"{path}: no END OF HEADER")
    is_v2 = version < 3.0
    sys_v2 = lines[0][20] if len(lines[0]) > 20 else "G"
    if is_v2 and sys_v2 not in ("N", "G", " ", "J", "Q"):
        return nav  # RINEX 2 SBAS / other navigation: no records we decode
    letter_v2 = {"N": "G", " ": "G", "G": "R", "J": "J", "Q": "J"}.get(sys_v2, "G")
    if is_v2 and sys_v2 == "N" and lines[0][40:41] == "J":
        letter_v2 = "J"  # RINEX 2.12 QZSS navigation: type N, system J
    while i < len(lines):
        head = lines[i]
        if not head.strip():
            i += 1
            continue
        try:
            if is_v2:
                system = letter_v2
                # RINEX 2.12 QZSS writes a 3-character satellite id ("J 1") and 4X before body fields
                w = 3 if system == "J" else 2
                prn = int(head[w - 2 : w])
                yy = int(head[w + 1 : w + 3])
                year = yy + (2000 if yy < 80 else 1900)
                mo, dd, hh, mi = (int(head[k + w - 2 : k + w + 1]) for k in (5, 8, 11, 14))
                sec = _num(head[17 + w - 2 : 22 + w - 2])
                values = _fields(head, 22 + w - 2, 3)
                start, nrec = (4 if system == "J" else 3), (3 if system == "R" else 7)
            else:
                system = head[0]
                prn = int(head[1:3])
                year, mo, dd, hh, mi = int(head[4:8]), int(head[9:11]), int(head[12:14]), int(head[15:17]), int(head[18:20])
                sec = _num(head[21:23])
                values = _fields(head, 23, 3)
                start, nrec = 4, _RECORD_LINES.get(system, 7)
                if system == "R" and version >= 3.05:
                    nrec = 4
        except ValueError as exc:
            raise InputError(f"{path}:{i + 1}: malformed navigation record: {exc}") from exc
        body = lines[i + 1 : i + 1 + nrec]
        i += 1 + nrec
        if system not in ("G", "E", "C", "J", "R"):
            continue
        if len(body) < nrec:
            break  # truncated last record
        try:
            for b in body:
                values += _fields(b.ljust(start + 76), start, 4)
        except ValueError as exc:
            raise InputError(f"{path}: malformed {system} record for satellite {prn}: {exc}") from exc
        if any(math.isnan(x) for x in values):
            continue
        toc = gpst_from_calendar(year, mo, dd, hh, mi, round(sec * 1e9))
        if system == "G":
            nav.ephemerides.append(_ephemeris_from_values(prn, toc, values))
        elif system == "E":
            nav.galileo.append(_galileo_from_values(prn, toc, values))
        elif system == "C":
            nav.beidou.append(_beidou_from_values(prn, toc, values))
        elif system == "J":
            sv = prn - QZSS_PRN_OFFSET if prn > QZSS_PRN_OFFSET else prn  # RINEX 2.12 may write the PRN itself
            nav.qzss.append(_qzss_from_values(sv, toc, values))
        else:
            nav.glonass.append(_glonass_from_values(prn, toc, values, not is_v2))
    return nav
