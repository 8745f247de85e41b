"""RINEX 2.x / 3.x GPS navigation files → `Ephemeris` objects and Klobuchar coefficients.

Only GPS records are decoded; other systems' records are skipped by their line count.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from onboard.errors import InputError
from onboard.formats.textfile import read_text_lines
from onboard.gnsstime import GpsTime, gpst_from_calendar
from onboard.rtk.types import Ephemeris

# Lines per record after the first, by RINEX 3 system letter.
_RECORD_LINES = {"G": 7, "E": 7, "C": 7, "J": 7, "I": 7, "R": 3, "S": 3}


@dataclass
class NavFile:
    """Contents of a navigation file: GPS ephemerides and the Klobuchar α/β (None when absent)."""

    ephemerides: list[Ephemeris] = field(default_factory=list)
    iono_alpha: tuple[float, float, float, float] | None = None
    iono_beta: tuple[float, float, float, float] | None = None
    leap_s: int | None = None


def _num(text: str) -> float:
    text = text.strip().replace("D", "E").replace("d", "e")
    return float(text) if text else 0.0


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
    while i < len(lines):
        head = lines[i]
        if not head.strip():
            i += 1
            continue
        try:
            if is_v2:
                if sys_v2 not in ("N", "G", " "):
                    break
                prn = int(head[0:2])
                yy = int(head[3:5])
                year = yy + (2000 if yy < 80 else 1900)
                mo, dd, hh, mi = (int(head[k : k + 3]) for k in (5, 8, 11, 14))
                sec = _num(head[17:22])
                values = _fields(head, 22, 3)
                start, nrec = 3, 7
                system = "G"
            else:
                system = head[0]
                prn = int(head[1:3])
                year, mo, dd, hh, mi = int(head[4:8]), int(head[9:11]), int(head[12:14]), int(head[15:17]), int(head[18:20])
                sec = _num(head[21:23])
                values = _fields(head, 23, 3)
                start, nrec = 4, _RECORD_LINES.get(system, 7)
        except ValueError as exc:
            raise InputError(f"{path}:{i + 1}: malformed navigation record: {exc}") from exc
        body = lines[i + 1 : i + 1 + nrec]
        i += 1 + nrec
        if system != "G":
            continue
        if len(body) < nrec:
            break  # truncated last record
        try:
            for b in body:
                values += _fields(b.ljust(start + 76), start, 4)
        except ValueError as exc:
            raise InputError(f"{path}: malformed GPS record for PRN {prn}: {exc}") from exc
        if any(math.isnan(x) for x in values):
            continue
        toc = gpst_from_calendar(year, mo, dd, hh, mi, round(sec * 1e9))
        nav.ephemerides.append(_ephemeris_from_values(prn, toc, values))
    return nav
