"""RINEX 2.11 / 3.0x observation files → header + `ObsEpoch` stream (single-frequency L1 C/A).

Keeps, per satellite, the L1 C/A pseudorange, carrier phase, Doppler and C/N0 (v3 codes C1C/L1C/D1C/S1C;
v2 C1/L1/D1/S1, with P1 as pseudorange fallback), the phase LLI bits, and nothing else. Every system of a
mixed file (GPS, GLONASS, Galileo, QZSS, BeiDou B1I, SBAS): each entry's `signal` is the attribute of the code
read (e.g. "1C", Galileo "1X", BeiDou "2I"), a GLONASS entry's `glo_fcn` the channel of its slot in the
`GLONASS SLOT / FRQ #` header lines (FCN_NONE when the header has none). Values keep RINEX's
sign conventions (the ones `ObsEpoch` documents). gzip-compressed files are accepted.
Special event records (flags 2–5, e.g. TIM-TM2 marks written by convbin) and cycle-slip records (flag 6)
are skipped; power-failure epochs (flag 1) are read with every phase flagged as slipped.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from onboard.errors import InputError
from onboard.formats.textfile import read_text_lines
from onboard.gnsstime import GpsTime, gpst_from_calendar
from onboard.rtk.geodesy import ecef_to_llh, enu_rotation
from onboard.rtk.types import (
    FCN_NONE,
    GNSS_BEIDOU,
    GNSS_GALILEO,
    GNSS_GLONASS,
    GNSS_GPS,
    GNSS_QZSS,
    GNSS_SBAS,
    LLI_SLIP,
    ObsEpoch,
)

log = logging.getLogger(__name__)

SYSTEM_GNSS_ID = {"G": GNSS_GPS, " ": GNSS_GPS, "R": GNSS_GLONASS, "E": GNSS_GALILEO, "C": GNSS_BEIDOU,
                  "J": GNSS_QZSS, "S": GNSS_SBAS}
"""RINEX system letter → u-blox gnssId."""

# Preferred observation codes for the L1 C/A signal, best first (per quantity).
_V3_CODES = {
    "pr": ("C1C",),
    "cp": ("L1C",),
    "dop": ("D1C",),
    "cn0": ("S1C",),
}
_V3_FALLBACK = {  # Galileo E1 / BeiDou B1 / QZSS use other attribute letters; harmless for GPS
    "pr": ("C1X", "C1Z", "C2I"),
    "cp": ("L1X", "L1Z", "L2I"),
    "dop": ("D1X", "D1Z", "D2I"),
    "cn0": ("S1X", "S1Z", "S2I"),
}
_V2_CODES = {"pr": ("C1", "P1"), "cp": ("L1",), "dop": ("D1",), "cn0": ("S1",)}


@dataclass
class RinexObsHeader:
    """What the RTK engine needs from an observation header.

    `approx_pos_ecef_m` APPROX POSITION XYZ (marker, m; None if absent or zero), `antenna_delta_hen_m`
    ANTENNA: DELTA H/E/N (m, antenna reference point above the marker), `interval_s` (None if absent).
    `obs_types` maps system letter → list of observation codes as written; `glo_fcn` GLONASS slot → frequency
    channel k from `GLONASS SLOT / FRQ #` (RINEX 3.02+).
    """

    version: float
    marker_name: str = ""
    approx_pos_ecef_m: np.ndarray | None = None
    antenna_delta_hen_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    antenna_type: str = ""
    receiver_type: str = ""
    interval_s: float | None = None
    obs_types: dict[str, list[str]] = field(default_factory=dict)
    glo_fcn: dict[int, int] = field(default_factory=dict)

    def antenna_position_ecef_m(self) -> np.ndarray | None:
        """APPROX POSITION plus the ANTENNA DELTA H/E/N rotated into ECEF (None without a position)."""
        if self.approx_pos_ecef_m is None:
            return None
        h, e, n = self.antenna_delta_hen_m
        lat, lon, _ = ecef_to_llh(self.approx_pos_ecef_m)
        return self.approx_pos_ecef_m + np.array([e, n, h]) @ enu_rotation(lat, lon)


@dataclass
class RinexObsFile:
    """A read observation file: header and epochs in file order."""

    header: RinexObsHeader
    epochs: list[ObsEpoch]


def _parse_header(path: Path, lines: list[str]) -> tuple[RinexObsHeader, int]:
    if not lines or "RINEX VERSION" not in lines[0]:
        raise InputError(f"{path}: not a RINEX file (no 'RINEX VERSION / TYPE' header line)")
    try:
        version = float(lines[0][:9])
    except ValueError as exc:
        raise InputError(f"{path}: unreadable RINEX version {lines[0][:9]!r}") from exc
    if lines[0][20:21] not in ("O", "o"):
        raise InputError(f"{path}: not an observation file (type {lines[0][20:21]!r})")
    hdr = RinexObsHeader(version=version)
    v2_types: list[str] = []
    v2_count = 0
    cur_sys = ""
    cur_count = 0
    for i, line in enumerate(lines[1:], start=1):
        label = line[60:].strip()
        try:
            if label == "END OF HEADER":
                if v2_types:
                    hdr.obs_types["G"] = v2_types[:v2_count] if v2_count else v2_types
                return hdr, i + 1
            if label == "MARKER NAME":
                hdr.marker_name = line[:60].strip()
            elif label == "APPROX POSITION XYZ":
                pos = np.array([float(line[k : k + 14]) for k in (0, 14, 28)])
                hdr.approx_pos_ecef_m = pos if np.any(pos != 0.0) else None
            elif label == "ANTENNA: DELTA H/E/N":
                hdr.antenna_delta_hen_m = tuple(float(line[k : k + 14]) for k in (0, 14, 28))  # type: ignore[assignment]
            elif label == "ANT # / TYPE":
                hdr.antenna_type = line[20:40].strip()
            elif label == "REC # / TYPE / VERS":
                hdr.receiver_type = line[20:40].strip()
            elif label == "INTERVAL":
                hdr.interval_s = float(line[:10])
            elif label == "# / TYPES OF OBSERV":
                if line[:6].strip():
                    v2_count = int(line[:6])
                v2_types += line[6:60].split()
            elif label == "GLONASS SLOT / FRQ #":
                for k in range(4, 60, 7):  # up to 8 "Rnn kk" pairs after the count (I3, 1X)
                    item = line[k : k + 7]
                    if item.strip():
                        hdr.glo_fcn[int(item[1:3])] = int(item[3:7])
            elif label == "SYS / # / OBS TYPES":
                if line[0] != " ":
                    cur_sys = line[0]
                    cur_count = int(line[3:6])
                    hdr.obs_types[cur_sys] = []
                hdr.obs_types[cur_sys] += line[7:60].split()
                hdr.obs_types[cur_sys] = hdr.obs_types[cur_sys][:cur_count]
        except ValueError as exc:
            raise InputError(f"{path}:{i + 1}: malformed header line {label!r}: {exc}") from exc
    raise InputError(f"{path}: no END OF HEADER")


def _column_indices(types: list[str], version: float) -> dict[str, int]:
    """Column index of each kept quantity (pr, cp, dop, cn0) in a system's observation list, −1 if absent."""
    out: dict[str, int] = {}
    for key in ("pr", "cp", "dop", "cn0"):
        codes = _V2_CODES[key] if version < 3.0 else _V3_CODES[key] + _V3_FALLBACK[key]
        out[key] = next((types.index(c) for c in codes if c in types), -1)
    return out


def _signal_code(types: list[str], cols: dict[str, int]) -> str:
    """The signal (band + attribute, e.g. "1C") of the code read as pseudorange (else as phase); "" if none."""
    k = cols["pr"] if cols["pr"] >= 0 else cols["cp"]
    if k < 0:
        return ""
    code = types[k]
    return code[1:3] if len(code) >= 3 else {"C1": "1C", "L1": "1C", "P1": "1P"}.get(code, "")


def _field_spans(cols: dict[str, int], offset: int) -> tuple[slice, slice, slice, slice, slice]:
    """Where a satellite's kept values are in its text, whose fixed 16-column fields (F14.3 + LLI + SSI) start at
    `offset`: the pr, cp, dop and cn0 values and the phase's LLI digit; an empty slice for an absent quantity
    (read as NaN, LLI 0). Computed once per system and file, not per satellite."""

    def span(key: str, start: int, stop: int) -> slice:
        k = cols[key]
        return slice(offset + 16 * k + start, offset + 16 * k + stop) if k >= 0 else slice(0, 0)

    return span("pr", 0, 14), span("cp", 0, 14), span("dop", 0, 14), span("cn0", 0, 14), span("cp", 14, 15)


class _EpochBuilder:
    """Accumulates one epoch's rows and turns them into an ObsEpoch."""

    def __init__(self, glo_fcn: dict[int, int]) -> None:
        self.rows: list[tuple[int, int, float, float, float, float, int, int, str]] = []
        """Per satellite: gnss id, PRN, pr (m), cp (cycles), Doppler (Hz), C/N0 (dB-Hz), LLI, GLONASS channel,
        signal (one append each)."""
        self.glo_fcn = glo_fcn

    def add_fields(self, sys_letter: str, prn: int, text: str, spans: tuple[slice, slice, slice, slice, slice],
                   force_slip: bool, signal: str) -> None:
        """Add one satellite from its fixed 16-column fields, at `spans` (_field_spans) of `text`.

        Only the kept quantities are parsed (a blank or missing field is NaN, its LLI 0), straight from the
        line: the reader's cost is per field, and most files carry more observation types than L1 C/A. Each
        value is float() of its stripped field, "nan" when blank: no call or exception per field (a third of
        the reading time went into them); a malformed field raises ValueError as float() does.
        """
        s_pr, s_cp, s_dop, s_cn0, s_lli = spans
        pr = float(text[s_pr].strip() or "nan")
        cp = float(text[s_cp].strip() or "nan")
        if math.isnan(pr) and math.isnan(cp):
            return
        lli_c = text[s_lli].strip()
        lli = int(lli_c) if lli_c.isdigit() else 0
        fcn = self.glo_fcn.get(prn, FCN_NONE) if sys_letter == "R" else FCN_NONE
        self.rows.append((SYSTEM_GNSS_ID.get(sys_letter, -1), prn, pr if pr != 0.0 else math.nan,
                          cp if cp != 0.0 else math.nan, float(text[s_dop].strip() or "nan"),
                          float(text[s_cn0].strip() or "nan"), (lli | LLI_SLIP) if force_slip else lli, fcn,
                          signal))

    def build(self, time: GpsTime) -> ObsEpoch:
        n = len(self.rows)
        gnss, sv, pr, cp, dop, cn0, lli, fcn, signal = zip(*self.rows) if n else ((),) * 9
        values = np.array((pr, cp, dop, cn0), float)  # one array, one row per quantity
        unknown = np.full((3, n), np.nan)  # RINEX has no lock time or precisions
        return ObsEpoch(
            time=time, gnss_id=np.array(gnss, np.int8), sv_id=np.array(sv, np.int16), pr_m=values[0],
            cp_cyc=values[1], dop_hz=values[2], cn0_dbhz=values[3], lock_ms=unknown[0], lli=np.array(lli, np.uint8),
            half_cyc_sub=np.zeros(n, np.uint8), pr_std_m=unknown[1], cp_std_cyc=unknown[2],
            glo_fcn=np.array(fcn, np.int8), signal=np.array(signal, "<U2"),
        )


def _iter_v3(path: Path, lines: list[str], start: int, hdr: RinexObsHeader,
             systems: str | None = None) -> Iterator[ObsEpoch]:
    cols = {s: _column_indices(t, hdr.version) for s, t in hdr.obs_types.items() if systems is None or s in systems}
    spans = {s: _field_spans(c, 3) for s, c in cols.items()}
    signals = {s: _signal_code(hdr.obs_types[s], c) for s, c in cols.items()}
    i = start
    while i < len(lines):
        line = lines[i]
        if not line.startswith(">"):
            i += 1
            continue
        try:
            year, mo, dd, hh, mi = (int(line[k : k + w]) for k, w in ((2, 4), (7, 2), (10, 2), (13, 2), (16, 2)))
            sec = float(line[18:29])
            flag = int(line[31:32] or 0)
            nsat = int(line[32:35])
        except ValueError as exc:
            raise InputError(f"{path}:{i + 1}: malformed epoch line: {exc}") from exc
        body = lines[i + 1 : i + 1 + nsat]
        i += 1 + nsat
        if flag > 1:
            continue
        if len(body) < nsat:
            log.warning("%s: truncated last epoch dropped", path)
            return
        b = _EpochBuilder(hdr.glo_fcn)
        for row in body:
            sys_letter = row[0:1]
            if sys_letter not in spans:
                continue
            try:
                prn = int(row[1:3])
            except ValueError as exc:
                raise InputError(f"{path}: malformed satellite id {row[:3]!r}") from exc
            try:
                b.add_fields(sys_letter, prn, row, spans[sys_letter], flag == 1, signals[sys_letter])
            except ValueError as exc:
                raise InputError(f"{path}: malformed observation for {row[:3]}: {exc}") from exc
        yield b.build(gpst_from_calendar(year, mo, dd, hh, mi, round(sec * 1e9)))


def _iter_v2(path: Path, lines: list[str], start: int, hdr: RinexObsHeader,
             systems: str | None = None) -> Iterator[ObsEpoch]:
    types = hdr.obs_types.get("G", [])
    ntypes = len(types)
    cols = _column_indices(types, hdr.version)
    spans = _field_spans(cols, 0)
    signal = _signal_code(types, cols)
    lines_per_sat = (ntypes + 4) // 5
    i = start
    while i < len(lines):
        line = lines[i]
        if not line.strip():
            i += 1
            continue
        try:
            flag = int(line[28:29] or 0)
            nsat = int(line[29:32])
        except ValueError as exc:
            raise InputError(f"{path}:{i + 1}: malformed epoch line: {exc}") from exc
        if flag > 1:  # special record: nsat = number of following header lines
            i += 1 + nsat
            continue
        try:
            yy, mo, dd, hh, mi = (int(line[k : k + 3]) for k in (0, 3, 6, 9, 12))
            sec = float(line[15:26])
        except ValueError as exc:
            raise InputError(f"{path}:{i + 1}: malformed epoch line: {exc}") from exc
        year = yy + (2000 if yy < 80 else 1900)
        sats_text = line[32:68].ljust(36)
        i += 1
        for _ in range((nsat - 1) // 12):  # continuation lines carry 12 satellites each
            sats_text = sats_text.ljust(36) + (lines[i][32:68] if i < len(lines) else "")
            i += 1
        sats = [sats_text[3 * k : 3 * k + 3] for k in range(nsat)]
        body = lines[i : i + nsat * lines_per_sat]
        i += nsat * lines_per_sat
        if len(body) < nsat * lines_per_sat:
            log.warning("%s: truncated last epoch dropped", path)
            return
        b = _EpochBuilder(hdr.glo_fcn)
        for k, sat in enumerate(sats):
            sys_letter = sat[0] if sat[0] != " " else "G"
            if systems is not None and sys_letter not in systems:
                continue
            try:
                prn = int(sat[1:3])
            except ValueError as exc:
                raise InputError(f"{path}: malformed satellite id {sat!r}") from exc
            text = "".join(ln.ljust(80)[:80] for ln in body[k * lines_per_sat : (k + 1) * lines_per_sat])
            try:
                b.add_fields(sys_letter, prn, text, spans, flag == 1, signal)
            except ValueError as exc:
                raise InputError(f"{path}: malformed observation for {sat}: {exc}") from exc
        yield b.build(gpst_from_calendar(year, mo, dd, hh, mi, round(sec * 1e9)))


def read_rinex_obs(path: str | Path, systems: str | None = None) -> RinexObsFile:
    """Read a RINEX 2.1x or 3.0x observation file (gzip accepted) into a header and a list of epochs.

    `systems`: the RINEX system letters whose satellites are kept (e.g. "G"), None for all; the others' fields
    are not parsed (an epoch of theirs alone stays, empty). Raises `InputError` naming the file and line for
    anything unreadable.
    """
    path = Path(path)
    lines = read_text_lines(path, "observation file")
    hdr, start = _parse_header(path, lines)
    if hdr.version >= 3.0:
        epochs = list(_iter_v3(path, lines, start, hdr, systems))
    else:
        if not hdr.obs_types.get("G"):
            raise InputError(f"{path}: no '# / TYPES OF OBSERV' in the header")
        epochs = list(_iter_v2(path, lines, start, hdr, systems))
    return RinexObsFile(header=hdr, epochs=epochs)
