"""RTCM3 for the base link: decoding (through pyrtcm) to our types, and encoding of what a base sends.

Decoded: GPS observations from 1002/1004 (legacy L1), and MSM4/5/6/7 of GPS, GLONASS, Galileo, QZSS and BeiDou
(L1-band signals: MSM_L1_SIGNALS) → `ObsEpoch`; base antenna reference point from 1005/1006 → `BasePosition`;
GPS ephemerides from 1019 → `Ephemeris`; GLONASS code-phase biases 1230 → `GlonassCodePhaseBias`; the GLONASS
frequency channel of 1020 → `GlonassChannel`.
Encoded (for `python -m onboard base`): 1002, 1004, 1005, 1006, 1019, 1033, 1230 and MSM4/5/7 (`MsmEncoder`)
from declarative bit layouts below (the other ephemerides: onboard.receiver.rtcm_nav) —
pyrtcm 1.2.1 parses but cannot build messages, so we pack the bits here and tests parse them back with pyrtcm.

RTCM epochs carry no GPS week: the decoder resolves it from a reference time (the rover's, or the host clock).
Phase-minus-pseudorange fields (DF012) wrap every 1500 cycles; the decoder unwraps them per satellite, as any
RTCM 3 decoder must, so carrier phase stays continuous across a wrap.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from pyrtcm import RTCMMessage, RTCMReader, parse_msm
from pyrtcm.exceptions import RTCMMessageError, RTCMParseError, RTCMStreamError, RTCMTypeError

from onboard.gnsstime import GpsTime, gps_from_bdt_tow_ns, gps_from_glonass_tod, resolve_week
from onboard.receiver.framing import Frame, Protocol, crc24q
from onboard.rtk.consts import CLIGHT_M_S, GLO_FCN_MAX, GLO_FCN_MIN, LAMBDA_L1_M, l1_wavelength_m
from onboard.rtk.geodesy import enu_to_ecef
from onboard.rtk.types import (
    FCN_NONE,
    GNSS_BEIDOU,
    GNSS_GALILEO,
    GNSS_GLONASS,
    GNSS_GPS,
    GNSS_QZSS,
    LLI_HALF_CYCLE,
    LLI_SLIP,
    Ephemeris,
    ObsEpoch,
)

log = logging.getLogger(__name__)

PRUNIT_GPS_M = 299_792.458
"""RTCM pseudorange modulus (one light-millisecond), m."""
PPR_WRAP_CYC = 1500.0
"""The phase-minus-pseudorange field is defined modulo this many L1 cycles."""
SC2RAD = math.pi
"""Semicircles → radians."""

RTCM_GPS_OBS = frozenset({1002, 1004, 1074, 1075, 1076, 1077})


@dataclass(frozen=True)
class BasePosition:
    """Base antenna reference point (ECEF m) and antenna height above it (m; 0 for 1005)."""

    station_id: int
    arp_ecef_m: tuple[float, float, float]
    antenna_height_m: float = 0.0

    @property
    def phase_centre_ecef_m(self) -> np.ndarray:
        """ARP raised by the antenna height along the ellipsoidal normal (L1 PCO not modelled)."""
        arp = np.array(self.arp_ecef_m)
        if self.antenna_height_m == 0.0:
            return arp
        return enu_to_ecef(np.array([0.0, 0.0, self.antenna_height_m]), arp)


# --- lock-time indicators → minimum lock time (ms) ---------------------------------------------------------


def lock_ms_from_df013(indicator: int) -> float:
    """Legacy 1002/1004 L1 lock time indicator (DF013, 7 bits) → minimum lock time in ms."""
    i = int(indicator)
    if i < 24:
        s = i
    elif i < 48:
        s = 2 * i - 24
    elif i < 72:
        s = 4 * i - 120
    elif i < 96:
        s = 8 * i - 408
    elif i < 120:
        s = 16 * i - 1176
    elif i < 127:
        s = 32 * i - 3096
    else:
        s = 937
    return s * 1000.0


def df013_from_lock_ms(lock_ms: float) -> int:
    """Minimum lock time (ms) → legacy lock time indicator DF013 (largest indicator not exceeding it)."""
    best = 0
    for i in range(128):
        if lock_ms_from_df013(i) <= lock_ms:
            best = i
    return best


def lock_ms_from_df402(indicator: int) -> float:
    """MSM4 lock time indicator (DF402, 4 bits) → minimum lock time in ms."""
    i = int(indicator)
    return 0.0 if i == 0 else float(2 ** (i + 4))


def lock_ms_from_df407(indicator: int) -> float:
    """MSM7 extended lock time indicator (DF407, 10 bits) → minimum lock time in ms."""
    i = int(indicator)
    if i < 64:
        return float(i)
    if i >= 704:
        return 67_108_864.0
    k = (i - 64) // 32 + 1
    start_i = 64 + 32 * (k - 1)
    start_t = 64 + sum(2**j * 32 for j in range(1, k))
    return float(start_t + 2**k * (i - start_i))


# --- decoding ------------------------------------------------------------------------------------------


MSM_SYSTEMS: dict[int, int] = {1070: GNSS_GPS, 1080: GNSS_GLONASS, 1090: GNSS_GALILEO, 1110: GNSS_QZSS,
                               1120: GNSS_BEIDOU}
"""MSM message family (number rounded down to tens) → u-blox gnssId."""
MSM_L1_SIGNALS: dict[int, tuple[str, ...]] = {
    GNSS_GPS: ("1C",), GNSS_GLONASS: ("1C",), GNSS_GALILEO: ("1C", "1X", "1B"), GNSS_QZSS: ("1C",),
    GNSS_BEIDOU: ("2I",),
}
"""The L1-band signals kept from MSM cells per system, preferred first (one entry per satellite): GPS, GLONASS
and QZSS L1 C/A, Galileo E1 (C, B+C, B), BeiDou B1I."""
RTCM_MSM_OBS = frozenset(base + k for base in MSM_SYSTEMS for k in (4, 5, 6, 7))
"""MSM4–7 of GPS, GLONASS, Galileo, QZSS and BeiDou (1074–1077, 1084–1087, 1094–1097, 1114–1117, 1124–1127)."""
RTCM_DECODED = frozenset({1002, 1004, 1005, 1006, 1019, 1020, 1230}) | RTCM_MSM_OBS
QZSS_PRN_OFFSET = 192
"""QZSS PRN = satellite number + 192 (pyrtcm reports MSM QZSS satellites as PRN 193–202)."""
_MSM_PR_INVALID_MS = -(2.0**-10)
"""DF400 (MSM4/5) and DF405 (MSM6/7) invalid value (0x4000 / 0x80000): −2^-10 ms."""
_MSM_RATE_INVALID_M_S = -8192
"""DF399 rough phase-range rate invalid value (0x2000), m/s."""
_MSM_FINE_RATE_INVALID_M_S = -1.6384
"""DF404 fine phase-range rate invalid value (0x4000 × 0.0001 m/s)."""


@dataclass(frozen=True)
class ObsMessageInfo:
    """What an observation message said about its epoch beyond the observations (for the epoch reassembly).

    `number` message type, `gnss_id` its system, `station_id` DF003, `more_follow` True when the multiple
    message bit (MSM DF393) or the synchronous GNSS flag (1002/1004 DF005) says further observation messages
    of the same epoch follow. `time` the epoch in GPS time (GLONASS/BeiDou epoch times already converted).
    """

    number: int
    gnss_id: int
    station_id: int
    more_follow: bool
    time: GpsTime


@dataclass(frozen=True)
class GlonassCodePhaseBias:
    """RTCM 1230: the base receiver's GLONASS code−phase biases (m) per signal, None where not sent.

    `aligned` DF421: True when the base's GLONASS code and phase are already aligned (biases removed). The
    rover engine uses them to correct the base's GLONASS pseudoranges (demo5's `gloicb` practice).
    """

    station_id: int
    aligned: bool
    l1ca_m: float | None
    l1p_m: float | None
    l2ca_m: float | None
    l2p_m: float | None


@dataclass(frozen=True)
class GlonassChannel:
    """A GLONASS slot's frequency channel learned from RTCM 1020 (DF038 slot, DF040 − 7 = channel k)."""

    slot: int
    fcn: int


class RtcmDecoder:
    """Stateful RTCM3 decoder: resolves GPS weeks from a reference and unwraps DF012 per satellite.

    `decode(frame, reference)` returns an `ObsEpoch` (1002/1004 GPS; MSM4–7 of GPS, GLONASS, Galileo, QZSS,
    BeiDou: L1-band signals, MSM_L1_SIGNALS), `BasePosition` (1005/1006), `Ephemeris` (1019),
    `GlonassCodePhaseBias` (1230), `GlonassChannel` (1020: only the channel, the ephemeris is not decoded
    here), or None (other messages or undecodable payloads, counted in `errors`). Never raises on bad input.
    After each observation message `last_obs_info` tells its system, epoch and multiple-message bit.

    GLONASS phase: an MSM carries phase as a range (light-ms); cycles need the satellite's carrier, i.e. its
    frequency channel k. It comes, first found first used, from the MSM5/7 extended satellite info (DF419),
    else from `glo_fcn` (slot → k), which the caller may fill beforehand (a table, the rover's RXM-RAWX freqId)
    and which learns every channel seen in DF419 and in 1020. A GLONASS cell whose channel is still unknown
    keeps its pseudorange, but its phase and Doppler are NaN (counted in `glo_phase_without_fcn`): never a
    phase in the wrong cycles.
    """

    def __init__(self, glo_fcn: dict[int, int] | None = None) -> None:
        self._ppr_cyc: dict[int, float] = {}
        self._last_lock_ms: dict[tuple[int, int], float] = {}
        self.glo_fcn: dict[int, int] = dict(glo_fcn or {})
        """GLONASS slot → frequency channel number k (−7…+6)."""
        self.glo_phase_without_fcn = 0
        """GLONASS MSM cells whose phase was dropped for want of a frequency channel."""
        self.last_obs_info: ObsMessageInfo | None = None
        self.errors = 0
        self.decoded = 0

    def decode(self, frame: Frame, reference: GpsTime) -> (ObsEpoch | BasePosition | Ephemeris | GlonassCodePhaseBias
                                                          | GlonassChannel | None):
        """Decode one RTCM3 frame; `reference` is any GPS time within half a week of the message (12 h for a
        GLONASS MSM, whose epoch is a time of day)."""
        if frame.protocol is not Protocol.RTCM3:
            return None
        if frame.msg_id not in RTCM_DECODED:
            return None
        try:
            msg = RTCMReader.parse(frame.raw)
            out = self._decode_message(msg, frame.msg_id, reference)
        except (RTCMParseError, RTCMMessageError, RTCMTypeError, RTCMStreamError, ValueError, KeyError,
                AttributeError, TypeError, IndexError) as exc:
            self.errors += 1
            log.debug("undecodable RTCM %s: %s", frame.msg_id, exc)
            return None
        if out is not None:
            self.decoded += 1
        return out

    def _decode_message(
        self, msg: RTCMMessage, number: int, reference: GpsTime
    ) -> ObsEpoch | BasePosition | Ephemeris | GlonassCodePhaseBias | GlonassChannel | None:
        if number in (1005, 1006):
            return BasePosition(
                station_id=int(msg.DF003),
                arp_ecef_m=(float(msg.DF025), float(msg.DF026), float(msg.DF027)),
                antenna_height_m=float(getattr(msg, "DF028", 0.0)),
            )
        if number == 1019:
            return _ephemeris_from_1019(msg, reference)
        if number == 1020:
            slot, fcn = int(msg.DF038), int(msg.DF040) - 7
            if not 1 <= slot <= 24 or not GLO_FCN_MIN <= fcn <= GLO_FCN_MAX:
                raise ValueError(f"1020 with slot {slot}, channel {fcn}")
            self.glo_fcn[slot] = fcn
            return GlonassChannel(slot, fcn)
        if number == 1230:
            return _glonass_biases_from_1230(msg)
        if number in (1002, 1004):
            obs = self._legacy_obs(msg, reference)
            self.last_obs_info = ObsMessageInfo(number, GNSS_GPS, int(msg.DF003), bool(int(msg.DF005)), obs.time)
            return obs
        return self._msm_obs(msg, number, reference)

    def _unwrap(self, prn: int, ppr_cyc: float) -> float:
        prev = self._ppr_cyc.get(prn)
        if prev is not None:
            ppr_cyc += PPR_WRAP_CYC * round((prev - ppr_cyc) / PPR_WRAP_CYC)
        self._ppr_cyc[prn] = ppr_cyc
        return ppr_cyc

    def _slip_bits(self, key: tuple[int, int], lock_ms: float) -> int:
        prev = self._last_lock_ms.get(key)
        self._last_lock_ms[key] = lock_ms
        return LLI_SLIP if prev is not None and lock_ms < prev else 0

    def _legacy_obs(self, msg: RTCMMessage, reference: GpsTime) -> ObsEpoch:
        time = resolve_week(int(msg.DF004) / 1000.0, reference)
        n = int(msg.DF006)
        rows = []
        for k in range(1, n + 1):
            sfx = f"_{k:02d}"
            prn = int(getattr(msg, "DF009" + sfx))
            if not 1 <= prn <= 32:
                continue
            pr = float(getattr(msg, "DF011" + sfx)) + int(getattr(msg, "DF014" + sfx, 0)) * PRUNIT_GPS_M
            ppr_m = float(getattr(msg, "DF012" + sfx))
            lock_ms = lock_ms_from_df013(int(getattr(msg, "DF013" + sfx)))
            cp = math.nan
            if abs(ppr_m) < 262.0:  # 0x80000 (−262.144 m) marks an invalid phase
                cp = (pr + self._unwrap(prn, ppr_m / LAMBDA_L1_M) * LAMBDA_L1_M) / LAMBDA_L1_M
            cn0 = float(getattr(msg, "DF015" + sfx, 0.0))
            rows.append((GNSS_GPS, prn, pr, cp, math.nan, cn0, lock_ms, self._slip_bits((GNSS_GPS, prn), lock_ms),
                         FCN_NONE, "1C"))
        return _obs_epoch(time, rows)

    def _msm_time(self, msg: RTCMMessage, gnss: int, reference: GpsTime) -> GpsTime:
        """The MSM epoch in GPS time: GPS/QZSS/Galileo tow (GST = GPST to the second, Galileo's own week
        aside), BeiDou tow + 14 s, GLONASS time of day (Moscow) → UTC → GPS."""
        if gnss == GNSS_GLONASS:
            return gps_from_glonass_tod(int(msg.DF034) * 1_000_000, reference)
        if gnss == GNSS_BEIDOU:
            return gps_from_bdt_tow_ns(int(msg.DF427) * 1_000_000, reference)
        field_name = {GNSS_GPS: "DF004", GNSS_GALILEO: "DF248", GNSS_QZSS: "DF428"}[gnss]
        return resolve_week(int(getattr(msg, field_name)) / 1000.0, reference)

    def _msm_obs(self, msg: RTCMMessage, number: int, reference: GpsTime) -> ObsEpoch:
        gnss = MSM_SYSTEMS[number // 10 * 10]
        kind = number % 10  # 4 MSM4, 5 MSM5, 6 MSM6, 7 MSM7
        time = self._msm_time(msg, gnss, reference)
        self.last_obs_info = ObsMessageInfo(number, gnss, int(msg.DF003), bool(int(msg.DF393)), time)
        parsed = parse_msm(msg)
        if not parsed:
            raise ValueError("MSM message without cells")
        _meta, sats, cells = parsed
        rough = {int(s["PRN"]): s for s in sats}
        wanted = MSM_L1_SIGNALS[gnss]
        best: dict[int, dict] = {}  # PRN → its preferred L1 cell
        for cell in cells:
            sig = cell["CELLSIG"]
            if sig not in wanted:
                continue
            prn = int(cell["CELLPRN"])
            have = best.get(prn)
            if have is None or wanted.index(sig) < wanted.index(have["CELLSIG"]):
                best[prn] = cell
        rows = []
        for prn in sorted(best):
            cell = best[prn]
            sat = rough.get(prn)
            sv = prn - QZSS_PRN_OFFSET if gnss == GNSS_QZSS else prn
            if sat is None or not 1 <= sv <= (32 if gnss == GNSS_GPS else 63):
                continue
            fcn: int | None = None
            if gnss == GNSS_GLONASS:
                ext = sat.get("DF419")
                if ext is not None and 0 <= int(ext) <= 13:
                    self.glo_fcn[sv] = int(ext) - 7
                fcn = self.glo_fcn.get(sv)
            lam = l1_wavelength_m(gnss, fcn)
            rough_ms = float(sat["DF397"]) + float(sat.get("DF398", 0.0))
            dop = math.nan
            if kind >= 6:
                fine_pr, fine_cp = cell.get("DF405"), cell.get("DF406")
                lock_ms = lock_ms_from_df407(int(cell.get("DF407", 0)))
                cn0 = float(cell.get("DF408", 0.0))
            else:
                fine_pr, fine_cp = cell.get("DF400"), cell.get("DF401")
                lock_ms = lock_ms_from_df402(int(cell.get("DF402", 0)))
                cn0 = float(cell.get("DF403", 0.0))
            if kind in (5, 7) and lam is not None:
                rough_rate, fine_rate = sat.get("DF399"), cell.get("DF404")
                if (rough_rate is not None and fine_rate is not None and int(rough_rate) != _MSM_RATE_INVALID_M_S
                        and float(fine_rate) > _MSM_FINE_RATE_INVALID_M_S + 1e-9):
                    dop = -(float(rough_rate) + float(fine_rate)) / lam
            if fine_pr is None or sat["DF397"] == 255 or float(fine_pr) <= _MSM_PR_INVALID_MS + 1e-15:
                continue
            pr = (rough_ms + float(fine_pr)) * CLIGHT_M_S / 1000.0
            cp = math.nan
            if fine_cp is not None and abs(float(fine_cp)) < 1.0 / 512.0:  # invalid: −2^-9 ms (MSM4) / −2^-8 (MSM7)
                if lam is not None:
                    cp = (rough_ms + float(fine_cp)) * CLIGHT_M_S / 1000.0 / lam
                else:
                    self.glo_phase_without_fcn += 1
            lli = self._slip_bits((gnss, sv), lock_ms)
            if int(cell.get("DF420", 0)):
                lli |= LLI_HALF_CYCLE
            rows.append((gnss, sv, pr, cp, dop, cn0, lock_ms, lli, FCN_NONE if fcn is None else fcn,
                         cell["CELLSIG"]))
        return _obs_epoch(time, rows)


def _obs_epoch(time: GpsTime,
               rows: list[tuple[int, int, float, float, float, float, float, int, int, str]]) -> ObsEpoch:
    """Rows (gnssId, sv, pr m, cp cycles, Doppler Hz, C/N0 dB-Hz, lock ms, LLI, channel k, signal) → ObsEpoch,
    sorted by system and satellite."""
    rows.sort(key=lambda r: (r[0], r[1]))
    n = len(rows)
    col = list(zip(*rows)) if rows else [()] * 10
    return ObsEpoch(
        time=time,
        gnss_id=np.array(col[0], np.int8),
        sv_id=np.array(col[1], np.int16),
        pr_m=np.array(col[2], float),
        cp_cyc=np.array(col[3], float),
        dop_hz=np.array(col[4], float),
        cn0_dbhz=np.array(col[5], float),
        lock_ms=np.array(col[6], float),
        lli=np.array(col[7], np.uint8),
        half_cyc_sub=np.zeros(n, np.uint8),
        pr_std_m=np.full(n, math.nan),
        cp_std_cyc=np.full(n, math.nan),
        glo_fcn=np.array(col[8], np.int8),
        signal=np.array(col[9], "<U2"),
    )


def _glonass_biases_from_1230(msg: RTCMMessage) -> GlonassCodePhaseBias:
    # DF423–DF426 are present only where the DF422 mask bit (L1 C/A, L1 P, L2 C/A, L2 P) is set
    values = []
    for k, name in enumerate(("DF423", "DF424", "DF425", "DF426"), start=1):
        values.append(float(getattr(msg, name)) if int(getattr(msg, f"DF422_{k}", 0)) else None)
    return GlonassCodePhaseBias(int(msg.DF003), bool(int(msg.DF421)), *values)


def _ephemeris_from_1019(msg: RTCMMessage, reference: GpsTime) -> Ephemeris:
    # The 10-bit week is ambiguous; an ephemeris in use is at most hours from the reference time.
    toe = resolve_week(float(msg.DF093), reference)
    toc = resolve_week(float(msg.DF081), reference)
    return Ephemeris(
        prn=int(msg.DF009), week=toe.week, toe=toe, toc=toc, iode=int(msg.DF071), iodc=int(msg.DF085),
        sqrt_a=float(msg.DF092), e=float(msg.DF090), i0_rad=float(msg.DF097) * SC2RAD,
        omega0_rad=float(msg.DF095) * SC2RAD, omega_rad=float(msg.DF099) * SC2RAD,
        m0_rad=float(msg.DF088) * SC2RAD, delta_n_rad_s=float(msg.DF087) * SC2RAD,
        omega_dot_rad_s=float(msg.DF100) * SC2RAD, idot_rad_s=float(msg.DF079) * SC2RAD,
        cuc_rad=float(msg.DF089), cus_rad=float(msg.DF091), crc_m=float(msg.DF098), crs_m=float(msg.DF086),
        cic_rad=float(msg.DF094), cis_rad=float(msg.DF096), af0_s=float(msg.DF084), af1_s_s=float(msg.DF083),
        af2_s_s2=float(msg.DF082), tgd_s=float(msg.DF101), ura_index=int(msg.DF077), health=int(msg.DF102),
        fit_interval_h=6.0 if int(msg.DF137) else 4.0, code_on_l2=int(msg.DF078), l2p_flag=int(msg.DF103),
    )


# --- encoding ------------------------------------------------------------------------------------------

# (field, bits, signed, scale): value_in_units / scale is rounded to an integer of `bits` bits.
_HEADER_1002 = (("DF002", 12, False, 1), ("DF003", 12, False, 1), ("DF004", 30, False, 1),
                ("DF005", 1, False, 1), ("DF006", 5, False, 1), ("DF007", 1, False, 1), ("DF008", 3, False, 1))
_SAT_1002 = (("DF009", 6, False, 1), ("DF010", 1, False, 1), ("DF011", 24, False, 0.02),
             ("DF012", 20, True, 0.0005), ("DF013", 7, False, 1), ("DF014", 8, False, 1),
             ("DF015", 8, False, 0.25))
_SAT_1004_L2 = (("DF016", 2, False, 1), ("DF017", 14, True, 0.02), ("DF018", 20, True, 0.0005),
                ("DF019", 7, False, 1), ("DF020", 8, False, 0.25))
_BODY_1005 = (("DF002", 12, False, 1), ("DF003", 12, False, 1), ("DF021", 6, False, 1), ("DF022", 1, False, 1),
              ("DF023", 1, False, 1), ("DF024", 1, False, 1), ("DF141", 1, False, 1),
              ("DF025", 38, True, 0.0001), ("DF142", 1, False, 1), ("DF001", 1, False, 1),
              ("DF026", 38, True, 0.0001), ("DF364", 2, False, 1), ("DF027", 38, True, 0.0001))
_BODY_1019 = (("DF002", 12, False, 1), ("DF009", 6, False, 1), ("DF076", 10, False, 1), ("DF077", 4, False, 1),
              ("DF078", 2, False, 1), ("DF079", 14, True, 2**-43), ("DF071", 8, False, 1),
              ("DF081", 16, False, 2**4), ("DF082", 8, True, 2**-55), ("DF083", 16, True, 2**-43),
              ("DF084", 22, True, 2**-31), ("DF085", 10, False, 1), ("DF086", 16, True, 2**-5),
              ("DF087", 16, True, 2**-43), ("DF088", 32, True, 2**-31), ("DF089", 16, True, 2**-29),
              ("DF090", 32, False, 2**-33), ("DF091", 16, True, 2**-29), ("DF092", 32, False, 2**-19),
              ("DF093", 16, False, 2**4), ("DF094", 16, True, 2**-29), ("DF095", 32, True, 2**-31),
              ("DF096", 16, True, 2**-29), ("DF097", 32, True, 2**-31), ("DF098", 16, True, 2**-5),
              ("DF099", 32, True, 2**-31), ("DF100", 24, True, 2**-43), ("DF101", 8, True, 2**-31),
              ("DF102", 6, False, 1), ("DF103", 1, False, 1), ("DF137", 1, False, 1))

SIGN_MAGNITUDE = 2
"""Layout `signed` value of a sign-magnitude field (GLONASS DF111–DF135: sign bit, then the magnitude)."""

Layout = Sequence[tuple[str, int, int, float]]
"""(field, bits, signed: False/True two's complement or SIGN_MAGNITUDE, scale)."""


class BitWriter:
    """Big-endian bit packer for RTCM3 payloads."""

    def __init__(self) -> None:
        self._value = 0
        self.bits = 0

    def put(self, value: int, bits: int, signed: int = False) -> None:
        """Append `value` in `bits` bits (two's complement when `signed`, sign and magnitude when it is
        SIGN_MAGNITUDE); raises if it does not fit."""
        if signed == SIGN_MAGNITUDE:
            if abs(value) >= 1 << (bits - 1):
                raise ValueError(f"{value} does not fit in {bits} sign-magnitude bits")
            value = ((1 << (bits - 1)) | -value) if value < 0 else value
            signed = False
        lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
        if not lo <= value <= hi:
            raise ValueError(f"{value} does not fit in {bits} {'signed' if signed else 'unsigned'} bits")
        self._value = (self._value << bits) | (value & ((1 << bits) - 1))
        self.bits += bits

    def put_fields(self, layout: Layout, values: dict[str, float]) -> None:
        """Append each field of `layout` from `values` (in the field's physical units)."""
        for name, bits, signed, scale in layout:
            self.put(round(values[name] / scale), bits, signed)

    def to_bytes(self) -> bytes:
        """The payload, zero-padded to whole bytes."""
        pad = (-self.bits) % 8
        return (self._value << pad).to_bytes((self.bits + pad) // 8, "big")


def rtcm3_frame(payload: bytes) -> bytes:
    """A complete RTCM3 transport frame: preamble, 10-bit length, payload, CRC-24Q."""
    if len(payload) > 1023:
        raise ValueError("RTCM3 payload longer than 1023 bytes")
    head = bytes((0xD3, len(payload) >> 8, len(payload) & 0xFF)) + payload
    return head + crc24q(head).to_bytes(3, "big")


def encode_gps_observations(epoch: ObsEpoch, station_id: int, message: int = 1004, synchronous: bool = False) -> bytes:
    """RTCM 1002 or 1004 frame with the GPS L1 C/A observations of `epoch` (L2 fields marked invalid in 1004).

    `epoch.time` must be GPS time (the base's receiver time tag corrected to GPS, or the tag itself: the rover
    engine corrects for the age either way). Satellites without a valid pseudorange are left out.
    """
    if message not in (1002, 1004):
        raise ValueError("GPS observation message must be 1002 or 1004")
    gps = epoch.gps_only()
    keep = np.isfinite(gps.pr_m) & (gps.pr_m > 0)
    gps = gps.select(keep)
    w = BitWriter()
    w.put_fields(_HEADER_1002, {"DF002": message, "DF003": station_id, "DF004": (gps.time.tow_ns // 1_000_000),
                                "DF005": int(synchronous), "DF006": len(gps), "DF007": 0, "DF008": 0})
    for k in range(len(gps)):
        pr = float(gps.pr_m[k])
        amb = int(pr // PRUNIT_GPS_M)
        pr_mod = round((pr - amb * PRUNIT_GPS_M) / 0.02) * 0.02
        cp = float(gps.cp_cyc[k])
        if math.isfinite(cp):
            # Relative to the pseudorange as transmitted (DF011 rounded to 2 cm, as RTKLIB rtcm3e does):
            # relative to the unrounded one, the decoder's phase would be off by up to 1 cm.
            ppr_cyc = cp - (amb * PRUNIT_GPS_M + pr_mod) / LAMBDA_L1_M
            ppr_cyc -= PPR_WRAP_CYC * round(ppr_cyc / PPR_WRAP_CYC)
            ppr_m = ppr_cyc * LAMBDA_L1_M
        else:
            ppr_m = -262.144  # 0x80000: invalid
        lock = float(gps.lock_ms[k]) if math.isfinite(gps.lock_ms[k]) else 0.0
        cn0 = float(np.clip(gps.cn0_dbhz[k], 0.0, 63.75)) if math.isfinite(gps.cn0_dbhz[k]) else 0.0
        w.put_fields(_SAT_1002, {"DF009": int(gps.sv_id[k]), "DF010": 0, "DF011": pr_mod,
                                 "DF012": ppr_m, "DF013": df013_from_lock_ms(lock), "DF014": amb, "DF015": cn0})
        if message == 1004:
            w.put_fields(_SAT_1004_L2, {"DF016": 0, "DF017": -8192 * 0.02, "DF018": -262.144, "DF019": 0,
                                        "DF020": 0})
    return rtcm3_frame(w.to_bytes())


def encode_base_position(position: BasePosition, with_height: bool = True) -> bytes:
    """RTCM 1006 (with antenna height) or 1005 frame for the base antenna reference point."""
    w = BitWriter()
    x, y, z = position.arp_ecef_m
    w.put_fields(_BODY_1005, {"DF002": 1006 if with_height else 1005, "DF003": position.station_id, "DF021": 0,
                              "DF022": 1, "DF023": 0, "DF024": 0, "DF141": 0, "DF025": x, "DF142": 1,
                              "DF001": 0, "DF026": y, "DF364": 0, "DF027": z})
    if with_height:
        w.put(round(position.antenna_height_m / 0.0001), 16)
    return rtcm3_frame(w.to_bytes())


def encode_ephemeris(eph: Ephemeris) -> bytes:
    """RTCM 1019 frame for one GPS LNAV ephemeris."""
    w = BitWriter()
    w.put_fields(_BODY_1019, {
        "DF002": 1019, "DF009": eph.prn, "DF076": eph.toe.week % 1024, "DF077": eph.ura_index,
        "DF078": eph.code_on_l2, "DF079": eph.idot_rad_s / SC2RAD, "DF071": eph.iode, "DF081": eph.toc.tow_s,
        "DF082": eph.af2_s_s2, "DF083": eph.af1_s_s, "DF084": eph.af0_s, "DF085": eph.iodc, "DF086": eph.crs_m,
        "DF087": eph.delta_n_rad_s / SC2RAD, "DF088": eph.m0_rad / SC2RAD, "DF089": eph.cuc_rad, "DF090": eph.e,
        "DF091": eph.cus_rad, "DF092": eph.sqrt_a, "DF093": eph.toe.tow_s, "DF094": eph.cic_rad,
        "DF095": eph.omega0_rad / SC2RAD, "DF096": eph.cis_rad, "DF097": eph.i0_rad / SC2RAD, "DF098": eph.crc_m,
        "DF099": eph.omega_rad / SC2RAD, "DF100": eph.omega_dot_rad_s / SC2RAD, "DF101": eph.tgd_s,
        "DF102": eph.health, "DF103": eph.l2p_flag, "DF137": 1 if eph.fit_interval_h > 4.0 else 0,
    })
    return rtcm3_frame(w.to_bytes())



_BODY_1230 = (("DF002", 12, False, 1), ("DF003", 12, False, 1), ("DF421", 1, False, 1), ("DF001_3", 3, False, 1))


def encode_glonass_biases(bias: GlonassCodePhaseBias) -> bytes:
    """RTCM 1230 frame: the aligned indicator (DF421), the mask of the signals given (L1 C/A, L1 P, L2 C/A,
    L2 P: the non-None ones) and their code−phase biases (DF423–DF426, 2 cm)."""
    w = BitWriter()
    w.put_fields(_BODY_1230, {"DF002": 1230, "DF003": bias.station_id, "DF421": int(bias.aligned), "DF001_3": 0})
    values = (bias.l1ca_m, bias.l1p_m, bias.l2ca_m, bias.l2p_m)
    for v in values:
        w.put(int(v is not None), 1)
    for v in values:
        if v is not None:
            w.put(round(v / 0.02), 16, signed=True)
    return rtcm3_frame(w.to_bytes())


def encode_receiver_descriptor(station_id: int, receiver: str, firmware: str = "", antenna: str = "",
                               receiver_serial: str = "", antenna_serial: str = "", setup_id: int = 0) -> bytes:
    """RTCM 1033 frame: antenna and receiver descriptors (ASCII strings of at most 31 characters each)."""
    w = BitWriter()
    w.put(1033, 12)
    w.put(station_id, 12)

    def text(value: str) -> None:
        raw = value.encode("ascii")
        if len(raw) > 31:
            raise ValueError(f"RTCM 1033 descriptor longer than 31 characters: {value!r}")
        w.put(len(raw), 8)
        for ch in raw:
            w.put(ch, 8)

    text(antenna)
    w.put(setup_id, 8)
    for value in (antenna_serial, receiver, firmware, receiver_serial):
        text(value)
    return rtcm3_frame(w.to_bytes())

# --- MSM encoding ----------------------------------------------------------------------------------------

MSM_SIGNAL_IDS: dict[int, dict[str, int]] = {
    GNSS_GPS: {"1C": 2}, GNSS_GLONASS: {"1C": 2}, GNSS_GALILEO: {"1C": 2, "1B": 4, "1X": 5}, GNSS_QZSS: {"1C": 2},
    GNSS_BEIDOU: {"2I": 2},
}
"""MSM signal ids (DF395 mask bit, 1 = most significant) of the L1-band signals, RTCM 10403.3 tables 3.5-91…108."""
_MSM_BASE = {g: n for n, g in MSM_SYSTEMS.items()}
_DF407_LOCK_MS = [lock_ms_from_df407(i) for i in range(705)]


def _indicator_at_most(table: Sequence[float], lock_ms: float) -> int:
    """The largest indicator whose minimum lock time does not exceed `lock_ms` (tables increase)."""
    import bisect

    return max(0, bisect.bisect_right(table, lock_ms) - 1)


def _df402_from_lock_ms(lock_ms: float) -> int:
    return _indicator_at_most([0.0] + [lock_ms_from_df402(i) for i in range(1, 16)], lock_ms)


_DF393_BIT = 12 + 12 + 30
"""Offset in the payload of the MSM multiple-message bit (after DF002, DF003 and the 30-bit epoch time of every
system: GLONASS's DF416 + DF034 are 3 + 27 bits)."""


def msm_with_multiple_message_bit(frame: bytes, more_follow: bool) -> bytes:
    """An MSM frame with its multiple-message bit (DF393) set to `more_follow` (CRC recomputed)."""
    payload = bytearray(frame[3:-3])
    byte, mask = _DF393_BIT // 8, 0x80 >> (_DF393_BIT % 8)
    payload[byte] = (payload[byte] | mask) if more_follow else (payload[byte] & ~mask)
    return rtcm3_frame(bytes(payload))

class MsmEncoder:
    """`ObsEpoch` → RTCM3 MSM4, MSM5 or MSM7 frame of one system (the L1-band signal of each satellite).

    Stateful only where RTCM needs it: a carrier phase further than the fine-phase field's span (±2^-8 ms,
    ±1171 m) from the rough range is moved by whole cycles, the same shift kept for that satellite until its
    lock time falls (a slip). GLONASS needs each entry's `glo_fcn` (sent as DF419 in MSM5/7; a satellite
    without it is sent with its pseudorange only). Entries of other systems are ignored.
    """

    def __init__(self, station_id: int) -> None:
        self.station_id = station_id
        self._shift_cyc: dict[tuple[int, int], float] = {}
        self._lock_ms: dict[tuple[int, int], float] = {}

    def encode(self, epoch: ObsEpoch, gnss_id: int, kind: int = 4, more_follow: bool = False) -> bytes | None:
        """The MSM`kind` (4, 5 or 7) frame of `epoch`'s `gnss_id` satellites with a valid pseudorange (None when
        it has none); `more_follow` sets the multiple-message bit (further messages of this epoch follow)."""
        if kind not in (4, 5, 7):
            raise ValueError("MSM kind must be 4, 5 or 7")
        sig_ids = MSM_SIGNAL_IDS[gnss_id]
        rows = []
        for i in range(len(epoch)):
            sv = int(epoch.sv_id[i])
            sig = str(epoch.signal[i]) if epoch.signal.shape[0] == len(epoch) and epoch.signal[i] else ""
            sig = sig or next(iter(sig_ids))
            if int(epoch.gnss_id[i]) != gnss_id or sig not in sig_ids or not math.isfinite(epoch.pr_m[i]):
                continue
            if not 1 <= sv <= 64:
                continue
            rows.append((sv, i, sig))
        if not rows:
            return None
        rows.sort()
        sats = sorted({sv for sv, _, _ in rows})
        sigs = sorted({sig_ids[s] for _, _, s in rows})
        if len(sats) * len(sigs) > 64:
            raise ValueError(f"{len(sats)} satellites × {len(sigs)} signals exceed the 64-cell MSM mask")
        w = BitWriter()
        w.put(_MSM_BASE[gnss_id] + kind, 12)
        w.put(self.station_id, 12)
        self._put_epoch_time(w, epoch.time, gnss_id)
        for value, bits in ((int(more_follow), 1), (0, 3), (0, 7), (0, 2), (0, 2), (0, 1), (0, 3)):
            w.put(value, bits)  # DF393, IODS, reserved, clock steering, external clock, smoothing, interval
        w.put(sum(1 << (64 - sv) for sv in sats), 64)
        w.put(sum(1 << (32 - s) for s in sigs), 32)
        cells = {(sv, sig_ids[sig]): (i, sig) for sv, i, sig in rows}
        for sv in sats:
            for s in sigs:
                w.put(int((sv, s) in cells), 1)
        ms_m = CLIGHT_M_S / 1000.0
        rough: dict[int, float] = {}
        fcn_of: dict[int, int | None] = {}
        for sv in sats:
            i = next(i for (v, _), (i, _) in cells.items() if v == sv)
            rough[sv] = round(float(epoch.pr_m[i]) / ms_m * 1024.0) / 1024.0
            k = int(epoch.glo_fcn[i]) if gnss_id == GNSS_GLONASS and epoch.glo_fcn.shape[0] == len(epoch) else None
            fcn_of[sv] = k if k is not None and GLO_FCN_MIN <= k <= GLO_FCN_MAX else None
        rates = {sv: self._rate_m_s(epoch, cells, sv, fcn_of[sv]) for sv in sats}
        for sv in sats:
            w.put(int(rough[sv]), 8)
        if kind in (5, 7):
            for sv in sats:
                w.put(fcn_of[sv] + 7 if fcn_of[sv] is not None else (15 if gnss_id == GNSS_GLONASS else 0), 4)
        for sv in sats:
            w.put(round((rough[sv] - int(rough[sv])) * 1024.0), 10)
        if kind in (5, 7):
            for sv in sats:
                r = rates[sv]
                w.put(-8192 if r is None else round(r), 14, signed=True)
        order = [(sv, s) for sv in sats for s in sigs if (sv, s) in cells]
        fine = [self._fine(epoch, cells[c][0], c[0], rough[c[0]], fcn_of[c[0]], gnss_id) for c in order]
        pr_bits, pr_res, cp_bits, cp_res = (15, 2**-24, 22, 2**-29) if kind != 7 else (20, 2**-29, 24, 2**-31)
        for fpr, _, _ in fine:
            w.put(-(1 << (pr_bits - 1)) if fpr is None else round(fpr / pr_res), pr_bits, signed=True)
        for _, fcp, _ in fine:
            w.put(-(1 << (cp_bits - 1)) if fcp is None else round(fcp / cp_res), cp_bits, signed=True)
        for _, _, lock in fine:
            w.put(_df402_from_lock_ms(lock) if kind != 7 else _indicator_at_most(_DF407_LOCK_MS, lock),
                  4 if kind != 7 else 10)
        for c in order:
            w.put(int(bool(int(epoch.lli[cells[c][0]]) & LLI_HALF_CYCLE)), 1)
        for c in order:
            cn0 = float(epoch.cn0_dbhz[cells[c][0]])
            cn0 = 0.0 if not math.isfinite(cn0) else cn0
            if kind != 7:
                w.put(int(np.clip(round(cn0), 0, 63)), 6)
            else:
                w.put(int(np.clip(round(cn0 * 16), 0, 1023)), 10)
        if kind in (5, 7):
            for c in order:
                r = rates[c[0]]
                full = self._rate_m_s(epoch, {c: cells[c]}, c[0], fcn_of[c[0]], rounded=False)
                w.put(-16384 if r is None or full is None else round((full - round(r)) / 0.0001), 15, signed=True)
        return rtcm3_frame(w.to_bytes())

    @staticmethod
    def _put_epoch_time(w: BitWriter, t: GpsTime, gnss_id: int) -> None:
        if gnss_id == GNSS_GLONASS:
            import datetime as _dt

            moscow = t.to_utc() + _dt.timedelta(hours=3)
            tod_ms = round((moscow.hour * 3600 + moscow.minute * 60 + moscow.second) * 1000
                           + moscow.microsecond / 1000)
            w.put((moscow.weekday() + 1) % 7, 3)  # DF416: 0 Sunday
            w.put(tod_ms, 27)
            return
        tow_ms = round(t.tow_ns / 1e6)
        if gnss_id == GNSS_BEIDOU:
            tow_ms = (tow_ms - 14_000) % 604_800_000
        w.put(tow_ms, 30)

    @staticmethod
    def _rate_m_s(epoch: ObsEpoch, cells: dict, sv: int, fcn: int | None, rounded: bool = True) -> float | None:
        """Phase-range rate (m/s, −Doppler·λ) of the satellite's first cell; None without Doppler or carrier."""
        i = next(i for (v, _), (i, _) in cells.items() if v == sv)
        lam = l1_wavelength_m(int(epoch.gnss_id[i]), fcn)
        dop = float(epoch.dop_hz[i])
        if lam is None or not math.isfinite(dop):
            return None
        return -dop * lam

    def _fine(self, epoch: ObsEpoch, i: int, sv: int, rough_ms: float, fcn: int | None,
              gnss_id: int) -> tuple[float | None, float | None, float]:
        """Fine pseudorange and phase range (ms, relative to the rough range) and lock time (ms) of entry i."""
        ms_m = CLIGHT_M_S / 1000.0
        fpr = float(epoch.pr_m[i]) / ms_m - rough_ms
        if abs(fpr) >= 2**-10:
            fpr = None  # type: ignore[assignment]
        lock = float(epoch.lock_ms[i]) if math.isfinite(epoch.lock_ms[i]) else 0.0
        key = (gnss_id, sv)
        if lock < self._lock_ms.get(key, 0.0) or int(epoch.lli[i]) & LLI_SLIP:
            self._shift_cyc.pop(key, None)  # a new lock: a new whole-cycle shift may be chosen
        self._lock_ms[key] = lock
        lam = l1_wavelength_m(gnss_id, fcn)
        cp = float(epoch.cp_cyc[i])
        if lam is None or not math.isfinite(cp):
            return fpr, None, lock
        shift = self._shift_cyc.get(key, 0.0)
        fcp = (cp + shift) * lam / ms_m - rough_ms
        if abs(fcp) >= 2**-9:  # within the decoders' accepted span (±2^-9 ms), else whole cycles moved
            if key in self._shift_cyc or lock > 0.0:
                lock = 0.0  # a tracked phase moved: the receiving end must see a new lock (a slip)
            shift = float(round((rough_ms * ms_m - cp * lam) / lam))
            self._shift_cyc[key] = shift
            fcp = (cp + shift) * lam / ms_m - rough_ms
        return fpr, fcp, lock
