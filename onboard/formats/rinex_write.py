"""RINEX 3.04 writers: observation files (L1 code, phase, Doppler, C/N0 + time-mark event records) and GPS LNAV
navigation files.

Layout follows the RINEX 3.04 specification (IGS/RTCM, 2018) and, where the standard leaves a choice, what
RTKLIB's convbin writes for u-blox logs (so our files diff cleanly against it): epoch lines
`> yyyy mm dd hh mm ss.sssssss  0 nn` with the receiver time tag (not clock-corrected), values F14.3 followed by
the LLI digit (phase only; bits 0 slip, 1 half cycle) and a blank SSI, blank fields for missing values, and an
event record `> … 5  0` (epoch flag 5, external event) before the first epoch at or after each time mark.
Pure formatting: the callers open the files.
"""

from __future__ import annotations

import datetime as _dt
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import IO

import numpy as np

from onboard.gnsstime import GPS_EPOCH, NS_PER_S, GpsTime
from onboard.rtk.types import (
    GNSS_BEIDOU,
    GNSS_GALILEO,
    GNSS_GLONASS,
    GNSS_GPS,
    GNSS_QZSS,
    GNSS_SBAS,
    CameraMark,
    Ephemeris,
    ObsEpoch,
)

RINEX_VERSION = 3.04
LLI_RINEX_MASK = 0x07
"""LLI bits RINEX carries: 0 loss of lock, 1 half-cycle ambiguity, 2 BOC tracking (as RTKLIB masks them)."""

# System letter, RINEX observation codes (in column order) and the code whose phase is the reference signal
# (no phase shift needed, RINEX 3.04 table A23) per u-blox gnssId, for the L1 signals we decode.
SYSTEMS: dict[int, tuple[str, tuple[str, ...], bool]] = {
    GNSS_GPS: ("G", ("C1C", "L1C", "D1C", "S1C"), True),
    GNSS_GLONASS: ("R", ("C1C", "L1C", "D1C", "S1C"), True),
    GNSS_GALILEO: ("E", ("C1X", "L1X", "D1X", "S1X"), False),
    GNSS_QZSS: ("J", ("C1C", "L1C", "D1C", "S1C"), True),
    GNSS_SBAS: ("S", ("C1C", "L1C", "D1C", "S1C"), True),
    GNSS_BEIDOU: ("C", ("C2I", "L2I", "D2I", "S2I"), True),
}
SYSTEM_ORDER = "GREJSC"

# URA index -> metres (IS-GPS-200 table 20-I, upper bound of each range; RINEX stores metres).
URA_M = (2.4, 3.4, 4.85, 6.85, 9.65, 13.65, 24.0, 48.0, 96.0, 192.0, 384.0, 768.0, 1536.0, 3072.0, 6144.0)


def satellite_code(gnss_id: int, sv_id: int) -> str | None:
    """RINEX 3 satellite code (e.g. "G05", "S20" for SBAS PRN 120, "J01"), None when it has none."""
    sysinfo = SYSTEMS.get(int(gnss_id))
    if sysinfo is None:
        return None
    sv = int(sv_id)
    if gnss_id == GNSS_SBAS:
        return f"S{sv - 100:02d}" if 120 <= sv <= 158 else None
    if gnss_id == GNSS_QZSS:
        sv = sv - 192 if sv > 192 else sv
    if not 1 <= sv <= 99:
        return None
    return f"{sysinfo[0]}{sv:02d}"


def _label(text: str, label: str) -> str:
    return f"{text:<60.60s}{label:<20s}\n"


def _round_100ns(t: GpsTime) -> tuple[_dt.datetime, int]:
    """Calendar minute (GPS scale) and the seconds within it in units of 100 ns (RINEX carries 7 decimals)."""
    ticks = (t.total_ns + 50) // 100
    minute_ticks = 60 * NS_PER_S // 100
    minutes, rest = divmod(ticks, minute_ticks)
    return GPS_EPOCH + _dt.timedelta(minutes=minutes), rest


def _seconds_text(ticks_100ns: int) -> str:
    s, frac = divmod(ticks_100ns, 10_000_000)
    return f"{s}.{frac:07d}"


def epoch_line(t: GpsTime, flag: int, count: int) -> str:
    """`> yyyy mm dd hh mm ss.sssssss  f nnn` record line (observation epochs: trailing blank clock field)."""
    m, ticks = _round_100ns(t)
    head = f"> {m.year:04d} {m.month:02d} {m.day:02d} {m.hour:02d} {m.minute:02d}"
    if flag == 0:
        return f"{head} {_seconds_text(ticks):>010s}  {flag}{count:3d}{'':21s}\n"
    return f"{head}{_seconds_text(ticks):>11s}  {flag}{count:3d}\n"


def obs_field(value: float, lli: int = 0) -> str:
    """One observation: F14.3 (blank when missing or 0), LLI digit (blank when none), blank SSI."""
    text = " " * 14 if not math.isfinite(value) or value == 0.0 else f"{math.fmod(value, 1e9):14.3f}"
    bits = int(lli) & LLI_RINEX_MASK
    return text + (str(bits) if bits else " ") + " "


@dataclass(frozen=True)
class ObsHeaderInfo:
    """What the observation header says beyond the data: marker, receiver, antenna, approximate position.

    `approx_pos_ecef_m` ECEF metres (zeros when unknown); `antenna_delta_hen_m` height/east/north of the ARP
    over the marker (m); `glo_fcn` GLONASS slot -> frequency channel; `date_utc` text of the creation time.
    """

    marker_name: str = ""
    marker_type: str = "NON_GEODETIC"
    observer: str = ""
    agency: str = ""
    receiver_number: str = ""
    receiver_type: str = ""
    receiver_version: str = ""
    antenna_number: str = ""
    antenna_type: str = ""
    approx_pos_ecef_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    antenna_delta_hen_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    program: str = "directgeo"
    run_by: str = ""
    date_utc: str = ""
    comments: tuple[str, ...] = ()
    glo_fcn: dict[int, int] = field(default_factory=dict)


@dataclass
class ObsWriteSummary:
    """What an observation file holds: epochs, satellites per system letter, event records."""

    epochs: int = 0
    satellites: dict[str, set[str]] = field(default_factory=dict)
    events: int = 0
    first: GpsTime | None = None
    last: GpsTime | None = None
    interval_s: float | None = None

    @property
    def satellite_count(self) -> int:
        """Distinct satellites over all systems."""
        return sum(len(v) for v in self.satellites.values())


def regular_interval_s(times: Sequence[GpsTime]) -> float | None:
    """The epoch interval (s, ms resolution) when at least 90 % of the steps share it, else None."""
    if len(times) < 3:
        return None
    steps = np.diff(np.array([t.total_ns for t in times], dtype=np.int64))
    steps_ms = np.rint(steps / 1e6).astype(np.int64)
    values, counts = np.unique(steps_ms[steps_ms > 0], return_counts=True)
    if values.size == 0:
        return None
    best = int(np.argmax(counts))
    return float(values[best]) / 1e3 if counts[best] >= 0.9 * steps_ms.size else None


def system_codes(gnss_id: int, signals: set[str]) -> tuple[str, ...]:
    """The four observation codes (code, phase, Doppler, C/N0) written for a system: of its entries' one signal
    (`ObsEpoch.signal`, e.g. Galileo "1C" of a u-blox 9) when they all share one, else the SYSTEMS default."""
    signals = signals - {""}
    if len(signals) == 1:
        (sig,) = signals
        return tuple(q + sig for q in "CLDS")
    return SYSTEMS[gnss_id][1]


def _header(info: ObsHeaderInfo, systems: list[int], summary: ObsWriteSummary,
            codes_of: dict[int, tuple[str, ...]]) -> list[str]:
    letters = [SYSTEMS[g][0] for g in systems]
    kind = f"{letters[0]}: {_SYSTEM_NAMES[letters[0]]}" if len(letters) == 1 else "M: Mixed"
    out = [f"{RINEX_VERSION:9.2f}{'':11s}{'OBSERVATION DATA':<20s}{kind:<20s}RINEX VERSION / TYPE\n"]
    out.append(f"{info.program:<20.20s}{info.run_by:<20.20s}{info.date_utc:<20.20s}PGM / RUN BY / DATE \n")
    out += [_label(c, "COMMENT") for c in info.comments]
    out.append(_label(info.marker_name, "MARKER NAME"))
    out.append(_label(info.marker_type, "MARKER TYPE"))
    out.append(_label(f"{info.observer:<20.20s}{info.agency:<40.40s}", "OBSERVER / AGENCY"))
    out.append(_label(f"{info.receiver_number:<20.20s}{info.receiver_type:<20.20s}{info.receiver_version:<20.20s}",
                      "REC # / TYPE / VERS"))
    out.append(_label(f"{info.antenna_number:<20.20s}{info.antenna_type:<20.20s}", "ANT # / TYPE"))
    x, y, z = info.approx_pos_ecef_m
    out.append(_label(f"{x:14.4f}{y:14.4f}{z:14.4f}", "APPROX POSITION XYZ"))
    h, e, n = info.antenna_delta_hen_m
    out.append(_label(f"{h:14.4f}{e:14.4f}{n:14.4f}", "ANTENNA: DELTA H/E/N"))
    for g in systems:
        letter, codes = SYSTEMS[g][0], codes_of[g]
        out.append(_label(f"{letter}{len(codes):5d}" + "".join(f" {c}" for c in codes), "SYS / # / OBS TYPES"))
    if summary.interval_s is not None:
        out.append(_label(f"{summary.interval_s:10.3f}", "INTERVAL"))
    for t, label in ((summary.first, "TIME OF FIRST OBS"), (summary.last, "TIME OF LAST OBS")):
        if t is None:
            continue
        m, ticks = _round_100ns(t)
        out.append(_label(f"  {m.year:04d}    {m.month:02d}    {m.day:02d}    {m.hour:02d}    {m.minute:02d}"
                          f"   {_seconds_text(ticks):>010s}     GPS", label))
    for g in systems:
        letter, _codes, reference = SYSTEMS[g]
        phase = codes_of[g][1]
        # Reference signals need no shift; others get an explicit 0 (we apply none), as RTKLIB writes it.
        out.append(_label(f"{letter} {phase}" + ("" if reference else f" {0.0:8.5f}"), "SYS / PHASE SHIFT"))
    if GNSS_GLONASS in systems:
        slots = sorted(info.glo_fcn)
        lines = [slots[i : i + 8] for i in range(0, len(slots), 8)] or [[]]
        for k, chunk in enumerate(lines):
            lead = f"{len(slots):3d}" if k == 0 else "   "
            out.append(_label(lead + "".join(f" R{s:02d} {info.glo_fcn[s]:2d}" for s in chunk),
                              "GLONASS SLOT / FRQ #"))
        out.append(_label(" C1C    0.000 C1P    0.000 C2C    0.000 C2P    0.000", "GLONASS COD/PHS/BIS"))
    out.append(_label("", "END OF HEADER"))
    return out


_SYSTEM_NAMES = {"G": "GPS", "R": "GLONASS", "E": "Galileo", "J": "QZSS", "S": "SBAS Payload", "C": "BeiDou"}


def epoch_records(epoch: ObsEpoch) -> list[str]:
    """The satellite lines of one epoch (code, phase + LLI, Doppler, C/N0), in the epoch's order."""
    lines = []
    for i in range(len(epoch)):
        g = int(epoch.gnss_id[i])
        sat = satellite_code(g, int(epoch.sv_id[i]))
        if sat is None:
            continue
        lines.append(
            sat + obs_field(float(epoch.pr_m[i])) + obs_field(float(epoch.cp_cyc[i]), int(epoch.lli[i]))
            + obs_field(float(epoch.dop_hz[i])) + obs_field(float(epoch.cn0_dbhz[i])) + "\n"
        )
    return lines


def write_obs(fp: IO[str], epochs: Sequence[ObsEpoch], marks: Iterable[CameraMark] = (),
              info: ObsHeaderInfo = ObsHeaderInfo()) -> ObsWriteSummary:
    """Write a RINEX 3.04 observation file: header, epochs in the given order, an event record (flag 5) for
    each mark with a time, placed before the first epoch at or after it (marks after the last epoch at the end).

    Epochs must carry receiver time tags in increasing order; satellites without a RINEX code are skipped. Each
    system's observation codes follow its entries' signal (`system_codes`).
    Returns what was written.
    """
    summary = ObsWriteSummary()
    present: set[int] = set()
    signals: dict[int, set[str]] = {}
    for ep in epochs:
        sigs = ep.signal.tolist() if ep.signal.shape[0] == len(ep) else [""] * len(ep)
        for g, sv, sig in zip(ep.gnss_id.tolist(), ep.sv_id.tolist(), sigs):
            sat = satellite_code(g, sv)
            if sat is not None:
                present.add(g)
                summary.satellites.setdefault(sat[0], set()).add(sat)
                signals.setdefault(g, set()).add(sig)
    systems = [g for letter in SYSTEM_ORDER for g, s in SYSTEMS.items() if s[0] == letter and g in present]
    if not systems:
        systems = [GNSS_GPS]
    timed = sorted((m for m in marks if m.time is not None), key=lambda m: m.time.total_ns)  # type: ignore[union-attr]
    summary.first = epochs[0].time if epochs else None
    summary.last = epochs[-1].time if epochs else None
    summary.interval_s = regular_interval_s([e.time for e in epochs])
    fp.writelines(_header(info, systems, summary, {g: system_codes(g, signals.get(g, set())) for g in systems}))
    k = 0
    for ep in epochs:
        while k < len(timed) and timed[k].time <= ep.time:  # type: ignore[operator]
            fp.write(epoch_line(timed[k].time, 5, 0))  # type: ignore[arg-type]
            summary.events += 1
            k += 1
        lines = epoch_records(ep)
        if not lines:
            continue
        fp.write(epoch_line(ep.time, 0, len(lines)))
        fp.writelines(lines)
        summary.epochs += 1
    for mark in timed[k:]:
        fp.write(epoch_line(mark.time, 5, 0))  # type: ignore[arg-type]
        summary.events += 1
    return summary


# ---------------------------------------------------------------------------------------------------------
# Navigation
# ---------------------------------------------------------------------------------------------------------


def nav_value(value: float) -> str:
    """One D19.12 navigation field (exponent letter E, as RINEX 3 allows)."""
    return f"{float(value):19.12E}"


def _nav_line(values: Sequence[float], first: str = "    ") -> str:
    return first + "".join(nav_value(v) for v in values) + "\n"


def ura_m(index: int) -> float:
    """URA index -> metres (index ≥ 15 or < 0: 6144 m, "no accuracy prediction")."""
    return URA_M[index] if 0 <= index < len(URA_M) else 6144.0


def nav_record(eph: Ephemeris) -> str:
    """The 8-line RINEX 3.04 GPS LNAV record of one ephemeris (transmission time unknown: 0.999999999E+09)."""
    m, ticks = _round_100ns(eph.toc)
    sec = ticks // 10_000_000
    head = f"G{eph.prn:02d} {m.year:04d} {m.month:02d} {m.day:02d} {m.hour:02d} {m.minute:02d} {sec:02d}"
    return (
        _nav_line((eph.af0_s, eph.af1_s_s, eph.af2_s_s2), head)
        + _nav_line((eph.iode, eph.crs_m, eph.delta_n_rad_s, eph.m0_rad))
        + _nav_line((eph.cuc_rad, eph.e, eph.cus_rad, eph.sqrt_a))
        + _nav_line((eph.toe.tow_ns / NS_PER_S, eph.cic_rad, eph.omega0_rad, eph.cis_rad))
        + _nav_line((eph.i0_rad, eph.crc_m, eph.omega_rad, eph.omega_dot_rad_s))
        + _nav_line((eph.idot_rad_s, eph.code_on_l2, eph.toe.week, eph.l2p_flag))
        + _nav_line((ura_m(eph.ura_index), eph.health, eph.tgd_s, eph.iodc))
        + _nav_line((0.999999999e9, eph.fit_interval_h))
    )


def write_nav(fp: IO[str], ephemerides: Iterable[Ephemeris], program: str = "directgeo", run_by: str = "",
              date_utc: str = "", leap_s: int | None = None,
              iono_alpha: Sequence[float] | None = None, iono_beta: Sequence[float] | None = None) -> int:
    """Write a RINEX 3.04 GPS navigation file; ephemerides sorted by toc then PRN, exact repeats dropped.

    Returns the number of records written.
    """
    out = [f"{RINEX_VERSION:9.2f}{'':11s}{'N: GNSS NAV DATA':<20s}{'G: GPS':<20s}RINEX VERSION / TYPE\n",
           f"{program:<20.20s}{run_by:<20.20s}{date_utc:<20.20s}PGM / RUN BY / DATE \n"]
    for name, coeffs in (("GPSA", iono_alpha), ("GPSB", iono_beta)):
        if coeffs is not None:
            out.append(_label(f"{name} " + "".join(f"{float(c):12.4E}" for c in coeffs), "IONOSPHERIC CORR"))
    if leap_s is not None:
        out.append(_label(f"{leap_s:6d}", "LEAP SECONDS"))
    out.append(_label("", "END OF HEADER"))
    unique = {(e.toc.total_ns, e.prn, e.iode, e.iodc): e for e in ephemerides}
    records = [unique[k] for k in sorted(unique)]
    out += [nav_record(e) for e in records]
    fp.writelines(out)
    return len(records)
