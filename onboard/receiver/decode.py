"""UBX frames -> our types (`ObsEpoch`, `SubframeWords`, `Ephemeris`, `TimeMarks`, `Ack`, `MonVer`, `NavFix`,
`CfgReply`): the parsing boundary. Nothing downstream sees pyubx2 attribute names.

Decoding is best effort and never raises on a frame's content: `decode_frame` returns None for messages it
does not decode and for payloads that do not decode, and counts the latter in `DecodeStats`.

Representation
--------------
- RXM-RAW / RXM-RAWX -> `ObsEpoch` (L1 signals only; one entry per satellite, the first L1 signal reported;
  RXM-RAWX: every system, with `glo_fcn` from freqId − 7 and `signal` from (gnssId, sigId), L1_SIGNAL_CODES).
  The high-rate raw messages are unpacked here with declarative numpy record layouts (u-blox 6 Receiver
  Description §RXM-RAW, u-blox 8 §RXM-RAWX), not through pyubx2: the per-field Python objects pyubx2 builds
  cost 9–25x more per epoch than framer + this decoder (bench/bench_recorder.py), which matters at 5 Hz on a
  Pi; the tests check both agree on every raw epoch of the real captures.
  RXM-RAW: `cp_cyc` NaN when cpMes is 0 (RTKLIB writes such phase as blank); `lli` is the receiver's own
  RINEX LLI field; `lock_ms` NaN (RXM-RAW has none). Phase with mesQI < 5 is still passed on, as RTKLIB
  does: the receiver's `lli` carries its own loss-of-lock verdict.
  RXM-RAWX: `pr_m` NaN unless prValid, `cp_cyc` NaN unless cpValid (and cpMes != -0.5, RTKLIB's extra test),
  `lli` LLI_HALF_CYCLE where halfCyc (half-cycle ambiguity resolved) is clear, LLI_SLIP where locktime is 0,
  `half_cyc_sub` from subHalfCyc, `pr_std_m` 0.01·2^n, `cp_std_cyc` 0.004·n. The stateful slip rules
  (lock time decreasing, half-cycle-subtracted flag changing, slips carried to the next valid phase) need the
  previous epoch: `LockTracker` applies them exactly as RTKLIB ublox.c decode_rxmrawx().
- RXM-SFRB -> `SubframeWords(bits=24)`; RXM-SFRBX GPS L1 C/A -> `SubframeWords(bits=30)`;
  AID-EPH (104-byte reply) -> `Ephemeris` via `onboard.rtk.lnav.ephemeris_from_aid_eph`, 8-byte reply -> None.
- TIM-TM2 -> `TimeMarks` holding one `CameraMark` per edge whose "new" bit is set (a time without its new bit
  is stale and dropped); times on the UTC time base (the M8P's default) are moved to GPS time (+ leap s).
- ACK-ACK/NAK -> `Ack`; MON-VER -> `MonVer`; NAV-SOL/NAV-PVT/NAV-POSECEF -> `NavFix`;
  any CFG-* reply -> `CfgReply(name, fields)` (pyubx2's field dict; CFG-TP through our own table).
"""

from __future__ import annotations

import logging
import math
import struct
import zlib
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from pyubx2 import UBXReader
from pyubx2.exceptions import UBXMessageError, UBXParseError, UBXStreamError, UBXTypeError

from onboard.errors import InputError, OnboardError
from onboard.gnsstime import GpsTime, leap_seconds_at_utc
from onboard.receiver.framing import Frame, Protocol, StreamFramer
from onboard.rtk.geodesy import llh_to_ecef
from onboard.rtk.types import (
    FCN_NONE,
    GNSS_BEIDOU,
    GNSS_GALILEO,
    GNSS_GLONASS,
    GNSS_GPS,
    GNSS_QZSS,
    GNSS_SBAS,
    LLI_HALF_CYCLE,
    LLI_SLIP,
    CameraMark,
    Ephemeris,
    ObsEpoch,
)

if TYPE_CHECKING:
    from onboard.rtk.lnav import LnavAssembler

log = logging.getLogger(__name__)

# ---------------------------------------------------------------------------------------------------------
# Our decoded kinds
# ---------------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SubframeWords:
    """One navigation subframe: `words` 10 ints, `bits` 24 (RXM-SFRB: parity removed, data in bits 23..0) or
    30 (RXM-SFRBX GPS: transmitted words with parity in bits 29..0). `source` "rxm-sfrb" or "rxm-sfrbx"."""

    prn: int
    words: tuple[int, ...]
    bits: int
    source: str
    gnss_id: int = GNSS_GPS


@dataclass(frozen=True, slots=True)
class TimeMarks:
    """One TIM-TM2 report: `marks` the edges with their "new" bit set (0–2, in time order).

    `count` is the receiver's rising-edge counter (a jump > 1 means lost marks); `flags` the raw flag byte.
    """

    channel: int
    count: int
    marks: tuple[CameraMark, ...]
    flags: int


@dataclass(frozen=True, slots=True)
class Ack:
    """ACK-ACK (`ok` True) or ACK-NAK (`ok` False) for the CFG message (msg_class, msg_id)."""

    msg_class: int
    msg_id: int
    ok: bool


@dataclass(frozen=True, slots=True)
class MonVer:
    """MON-VER: software and hardware version strings and the extension strings (NULs stripped)."""

    sw: str
    hw: str
    extensions: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class NavFix:
    """The receiver's own navigation solution (for status only).

    `tow_ms` GPS time of week of the solution (ms), `week` None when the message has none (NAV-POSECEF),
    `pos_ecef_m` (3,) ECEF position, `fix_type` u-blox gpsFix/fixType (0 none … 3 3D, 4 GNSS+DR, 5 time only),
    `num_sv` satellites used (None for NAV-POSECEF), `p_acc_m` position accuracy estimate, `source` message.
    """

    tow_ms: int
    week: int | None
    pos_ecef_m: tuple[float, float, float]
    fix_type: int | None
    num_sv: int | None
    p_acc_m: float
    source: str

    @property
    def time(self) -> GpsTime | None:
        """GPS time of the solution when the message carried the week."""
        return None if self.week is None else GpsTime.from_week_tow_ns(self.week, self.tow_ms * 1_000_000)


@dataclass(frozen=True, slots=True)
class CfgReply:
    """A CFG-* message from the receiver (a poll reply): its name and its fields as plain Python values."""

    name: str
    msg_class: int
    msg_id: int
    fields: dict[str, Any]
    payload: bytes


Decoded = ObsEpoch | SubframeWords | Ephemeris | TimeMarks | Ack | MonVer | NavFix | CfgReply


@dataclass
class DecodeStats:
    """Counters of one decoding run, and facts learned on the way.

    `frames` UBX frames seen, `decoded` turned into one of our types, `ignored` UBX messages we do not decode,
    `failures` frames whose payload did not decode (wrong length, pyubx2 error …), `by_message` decoded
    count per message name, `glo_fcn` GLONASS slot -> frequency channel number (from RXM-RAWX freqId − 7),
    `reference_week` the last full GPS week seen (raw epochs, NAV-SOL), which resolves AID-EPH's 10-bit week.
    """

    frames: int = 0
    decoded: int = 0
    ignored: int = 0
    failures: int = 0
    by_message: dict[str, int] = field(default_factory=dict)
    glo_fcn: dict[int, int] = field(default_factory=dict)
    reference_week: int | None = None

    def count(self, name: str) -> None:
        """Count one decoded message of `name`."""
        self.decoded += 1
        self.by_message[name] = self.by_message.get(name, 0) + 1


class DecodeError(ValueError):
    """A payload that does not match its message layout (internal: decode_frame turns it into None)."""


# ---------------------------------------------------------------------------------------------------------
# Declarative payload layouts (little-endian, as every UBX payload)
# ---------------------------------------------------------------------------------------------------------

RXM_RAW_HEADER = struct.Struct("<iHBx")  # iTOW ms, week, numSV, reserved
RXM_RAW_SV = np.dtype(
    [("cpMes", "<f8"), ("prMes", "<f8"), ("doMes", "<f4"), ("sv", "u1"), ("mesQI", "i1"), ("cno", "i1"),
     ("lli", "u1")]
)
RXM_RAWX_HEADER = struct.Struct("<dHbBBB2x")  # rcvTow s, week, leapS, numMeas, recStat, version
RXM_RAWX_MEAS = np.dtype(
    [("prMes", "<f8"), ("cpMes", "<f8"), ("doMes", "<f4"), ("gnssId", "u1"), ("svId", "u1"), ("sigId", "u1"),
     ("freqId", "u1"), ("locktime", "<u2"), ("cno", "u1"), ("prStdev", "u1"), ("cpStdev", "u1"),
     ("doStdev", "u1"), ("trkStat", "u1"), ("reserved", "u1")]
)
TIM_TM2 = struct.Struct("<BBHHHIIIII")  # ch flags count wnR wnF towMsR towSubMsR towMsF towSubMsF accEst
RXM_SFRB = struct.Struct("<BB10I")  # chn, svid, 10 words
RXM_SFRBX_HEADER = struct.Struct("<BBBBBBBx")  # gnssId svId reserved/sigId freqId numWords chn version
AID_EPH_HEADER = struct.Struct("<II")  # svid, how

assert RXM_RAW_SV.itemsize == 24 and RXM_RAWX_MEAS.itemsize == 32 and TIM_TM2.size == 28

# trkStat bits (RXM-RAWX)
TRK_PR_VALID = 0x01
TRK_CP_VALID = 0x02
TRK_HALF_CYC = 0x04
TRK_SUB_HALF_CYC = 0x08

# TIM-TM2 flag bits
TM2_MODE_RUNNING = 0x01
TM2_RUN = 0x02
TM2_NEW_FALLING = 0x04
TM2_TIME_BASE_SHIFT = 3
TM2_UTC = 0x20
TM2_TIME_VALID = 0x40
TM2_NEW_RISING = 0x80

# L1 signals (sigId) per gnssId; RXM-RAWX version 0 (M8) leaves sigId 0 for every L1 signal.
L1_SIG_IDS: dict[int, frozenset[int]] = {
    GNSS_GPS: frozenset({0}), GNSS_SBAS: frozenset({0}), GNSS_GALILEO: frozenset({0, 1}),
    GNSS_BEIDOU: frozenset({0, 1}), GNSS_QZSS: frozenset({0, 1}), GNSS_GLONASS: frozenset({0}),
}

_L1_LOOKUP = np.zeros((256, 256), bool)
for _g, _sigs in L1_SIG_IDS.items():
    _L1_LOOKUP[_g, sorted(_sigs)] = True

L1_SIGNAL_CODES: dict[tuple[int, int], str] = {
    (GNSS_GPS, 0): "1C", (GNSS_SBAS, 0): "1C", (GNSS_GALILEO, 0): "1C", (GNSS_GALILEO, 1): "1B",
    (GNSS_BEIDOU, 0): "2I", (GNSS_BEIDOU, 1): "2I", (GNSS_QZSS, 0): "1C", (GNSS_QZSS, 1): "1Z",
    (GNSS_GLONASS, 0): "1C",
}
"""(gnssId, sigId) of the L1 signals we keep → RINEX 3 band + attribute (u-blox 8/9 Interface Description,
"Signal identifiers": GPS L1C/A, SBAS L1C/A, Galileo E1C/E1B, BeiDou B1I D1/D2, QZSS L1C/A and L1S, GLONASS L1OF)."""

_SIGNAL_LOOKUP = np.full((256, 256), "", "<U2")
for (_g, _s), _code in L1_SIGNAL_CODES.items():
    _SIGNAL_LOOKUP[_g, _s] = _code
_SIGNAL_LOOKUP_V0 = np.full(256, "", "<U2")
"""RXM-RAWX version 0 (u-blox M8: sigId always 0): Galileo E1 is B+C ("1X"), as RTKLIB writes it; the others as
L1_SIGNAL_CODES."""
for (_g, _s), _code in L1_SIGNAL_CODES.items():
    if _s == 0:
        _SIGNAL_LOOKUP_V0[_g] = "1X" if _g == GNSS_GALILEO else _code

CP_STD_CYC_PER_CODE = 0.004
"""RXM-RAWX cpStdev: n · 0.004 cycles."""
PR_STD_M_BASE = 0.01
"""RXM-RAWX prStdev: 0.01 · 2^n m."""

_ID_RXM_RAW = (0x02, 0x10)
_ID_RXM_SFRB = (0x02, 0x11)
_ID_RXM_SFRBX = (0x02, 0x13)
_ID_RXM_RAWX = (0x02, 0x15)
_ID_AID_EPH = (0x0B, 0x31)
_ID_TIM_TM2 = (0x0D, 0x03)
_ID_MON_VER = (0x0A, 0x04)
_ID_NAV_SOL = (0x01, 0x06)
_ID_NAV_PVT = (0x01, 0x07)
_ID_NAV_POSECEF = (0x01, 0x01)
_CLS_ACK = 0x05
# Payload lengths of the fixed-size messages we hand to pyubx2 (it silently pads short payloads with zeros).
_NAV_LENGTHS: dict[tuple[int, int], tuple[int, ...]] = {
    _ID_NAV_SOL: (52,), _ID_NAV_PVT: (84, 92), _ID_NAV_POSECEF: (20,),
}
_CLS_CFG = 0x06
_ID_CFG_TP = (0x06, 0x07)

# Every exception pyubx2 1.4.0 (and the struct/numpy unpacking here) is known to raise on bad payloads.
_PARSE_ERRORS: tuple[type[BaseException], ...] = (
    UBXParseError, UBXMessageError, UBXTypeError, UBXStreamError, DecodeError, OnboardError, struct.error,
    ValueError, IndexError, KeyError, TypeError, UnicodeDecodeError, OverflowError, AttributeError,
)


# ---------------------------------------------------------------------------------------------------------
# Raw measurements
# ---------------------------------------------------------------------------------------------------------


def decode_rxm_raw(payload: bytes) -> ObsEpoch | None:
    """RXM-RAW (u-blox 6) payload -> ObsEpoch with the receiver time tag (iTOW ms + week).

    Returns None when the week is 0 (time not yet known; RTKLIB drops such epochs). GPS PRN 1–32 get gnssId
    GPS, sv ≥ 120 SBAS. Raises DecodeError on a length that does not match numSV.
    """
    if len(payload) < RXM_RAW_HEADER.size:
        raise DecodeError(f"RXM-RAW payload of {len(payload)} bytes is shorter than its header")
    itow_ms, week, num_sv = RXM_RAW_HEADER.unpack_from(payload)
    need = RXM_RAW_HEADER.size + RXM_RAW_SV.itemsize * num_sv
    if len(payload) < need:
        raise DecodeError(f"RXM-RAW with numSV={num_sv} needs {need} bytes, got {len(payload)}")
    if week == 0:
        return None
    sv = np.frombuffer(payload, RXM_RAW_SV, num_sv, RXM_RAW_HEADER.size)
    prn = sv["sv"].astype(np.int16)
    gnss = np.where(prn >= 120, GNSS_SBAS, GNSS_GPS).astype(np.int8)
    cp = sv["cpMes"].astype(np.float64)
    cp[cp == 0.0] = np.nan
    pr = sv["prMes"].astype(np.float64)
    pr[pr == 0.0] = np.nan
    n = num_sv
    return ObsEpoch(
        time=GpsTime.from_week_tow_ns(week, itow_ms * 1_000_000),
        gnss_id=gnss, sv_id=prn, pr_m=pr, cp_cyc=cp, dop_hz=sv["doMes"].astype(np.float64),
        cn0_dbhz=sv["cno"].astype(np.float64), lock_ms=np.full(n, np.nan), lli=sv["lli"].astype(np.uint8),
        half_cyc_sub=np.zeros(n, np.uint8), pr_std_m=np.full(n, np.nan), cp_std_cyc=np.full(n, np.nan),
    )


def decode_rxm_rawx(payload: bytes, glo_fcn: dict[int, int] | None = None) -> ObsEpoch | None:
    """RXM-RAWX (u-blox 8/9) payload -> ObsEpoch of its L1 signals, receiver time tag rcvTow + week.

    Returns None when the week is 0. `glo_fcn`, when given, collects GLONASS slot -> FCN (freqId − 7).
    Raises DecodeError on a length that does not match numMeas.
    """
    if len(payload) < RXM_RAWX_HEADER.size:
        raise DecodeError(f"RXM-RAWX payload of {len(payload)} bytes is shorter than its header")
    rcv_tow_s, week, leap_s, num_meas, rec_stat, version = RXM_RAWX_HEADER.unpack_from(payload)
    need = RXM_RAWX_HEADER.size + RXM_RAWX_MEAS.itemsize * num_meas
    if len(payload) < need:
        raise DecodeError(f"RXM-RAWX with numMeas={num_meas} needs {need} bytes, got {len(payload)}")
    if not math.isfinite(rcv_tow_s) or not 0.0 <= rcv_tow_s < 604800.0:
        raise DecodeError(f"RXM-RAWX rcvTow {rcv_tow_s!r} s is not a time of week")
    if week == 0:
        return None
    m = np.frombuffer(payload, RXM_RAWX_MEAS, num_meas, RXM_RAWX_HEADER.size)
    gnss = m["gnssId"]
    sig = m["sigId"]
    svid = m["svId"]
    keep = _L1_LOOKUP[gnss, sig]  # L1 signals only (L1_SIG_IDS)
    glo = gnss == GNSS_GLONASS
    keep &= ~glo | ((svid >= 1) & (svid <= 24))  # GLONASS slot unknown (255): RTKLIB drops these too
    keys = gnss.astype(np.int32)[keep] * 256 + svid[keep]
    if np.unique(keys).size != keys.size:
        # Galileo E1C and E1B of one satellite: keep the first, as one RINEX row
        idx = np.flatnonzero(keep)
        _, first = np.unique(keys, return_index=True)
        keep = np.zeros(num_meas, bool)
        keep[idx[first]] = True
    if glo_fcn is not None and glo.any():
        for slot, freq in zip(svid[keep & glo].tolist(), m["freqId"][keep & glo].tolist()):
            glo_fcn.setdefault(slot, freq - 7)
    m = m[keep]
    trk = m["trkStat"]
    pr = m["prMes"].astype(np.float64)
    pr[(trk & TRK_PR_VALID) == 0] = np.nan
    cp = m["cpMes"].astype(np.float64)
    cp[((trk & TRK_CP_VALID) == 0) | (cp == -0.5)] = np.nan
    lock = m["locktime"].astype(np.float64)
    # Half-cycle resolved: trkStat bit 2, except SBAS where RTKLIB trusts it only after 8 s of lock.
    half_ok = np.where(m["gnssId"] == GNSS_SBAS, lock > 8000, (trk & TRK_HALF_CYC) != 0)
    lli = np.where(half_ok, 0, LLI_HALF_CYCLE) | np.where(lock == 0, LLI_SLIP, 0)
    # freqId is the GLONASS channel k + 7 (0–13); meaningless for the other systems
    fcn = m["freqId"].astype(np.int16) - 7
    glo_fcn = np.where((m["gnssId"] == GNSS_GLONASS) & (fcn >= -7) & (fcn <= 6), fcn, FCN_NONE).astype(np.int8)
    return ObsEpoch(
        time=GpsTime.from_week_tow_ns(week, round(rcv_tow_s * 1e9)),
        gnss_id=m["gnssId"].astype(np.int8), sv_id=m["svId"].astype(np.int16), pr_m=pr, cp_cyc=cp,
        dop_hz=m["doMes"].astype(np.float64), cn0_dbhz=m["cno"].astype(np.float64), lock_ms=lock,
        lli=lli.astype(np.uint8), half_cyc_sub=((trk & TRK_SUB_HALF_CYC) != 0).astype(np.uint8),
        pr_std_m=PR_STD_M_BASE * np.exp2((m["prStdev"] & 0x0F).astype(np.float64)),
        cp_std_cyc=CP_STD_CYC_PER_CODE * (m["cpStdev"] & 0x0F).astype(np.float64),
        clock_reset=bool(rec_stat & 0x02), leap_s=int(leap_s) if rec_stat & 0x01 else None,
        glo_fcn=glo_fcn,
        signal=_SIGNAL_LOOKUP[m["gnssId"], m["sigId"]] if version else _SIGNAL_LOOKUP_V0[m["gnssId"]],
    )


# ---------------------------------------------------------------------------------------------------------
# RTKLIB's slip rules (stateful across epochs)
# ---------------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class LockTrackerOptions:
    """Thresholds of RTKLIB ublox.c decode_rxmrawx() for u-blox 8 (Gen8) receivers.

    `max_cp_std_code` phase with cpStdev code above this is dropped (RTKLIB MAX_CPSTD_VALID_GEN8 = 5);
    `slip_cp_std_code` a code at or above this marks a slip (CPSTD_SLIP = 15).
    """

    max_cp_std_code: int = 5
    slip_cp_std_code: int = 15


class LockTracker:
    """Applies RTKLIB's RXM-RAWX carrier-phase validity and loss-of-lock rules to successive epochs.

    Follows RTKLIB ublox.c decode_rxmrawx(): phase with a cpStdev code > `max_cp_std_code` is invalid; a slip
    is lock time 0, lock time smaller than at the previous report, a change of the half-cycle-subtracted flag
    or cpStdev code ≥ `slip_cp_std_code`; a slip seen while the phase was invalid is carried forward to the
    next valid phase. LLI bit 0 = slip, bit 1 = half cycle unresolved (only on valid phase). The phase value is
    passed on as the receiver reported it (its half-cycle subtraction already applied), as RTKLIB writes it.
    Epochs without lock times (RXM-RAW) pass through unchanged: their LLI is the receiver's own.
    """

    def __init__(self, options: LockTrackerOptions = LockTrackerOptions()) -> None:
        self.options = options
        self._lock_s: dict[tuple[int, int], float] = {}
        self._half_sub: dict[tuple[int, int], int] = {}
        self._slip_pending: dict[tuple[int, int], bool] = {}

    def update(self, epoch: ObsEpoch) -> ObsEpoch:
        """The epoch with `cp_cyc` NaN where RTKLIB drops the phase and `lli` set by RTKLIB's rules."""
        n = len(epoch)
        if n == 0 or np.all(np.isnan(epoch.lock_ms)):
            return epoch
        cp = epoch.cp_cyc.copy()
        lli_out = np.zeros(n, np.uint8)
        std_code = np.rint(epoch.cp_std_cyc / CP_STD_CYC_PER_CODE)
        opts = self.options
        for i in range(n):
            key = (int(epoch.gnss_id[i]), int(epoch.sv_id[i]))
            code = std_code[i]
            if math.isfinite(code) and code > opts.max_cp_std_code:
                cp[i] = np.nan
            lock_s = float(epoch.lock_ms[i]) * 1e-3
            half_sub = int(epoch.half_cyc_sub[i]) if epoch.half_cyc_sub.shape[0] == n else 0
            prev_half = self._half_sub.get(key, 0)
            slip = lock_s == 0.0 or lock_s < self._lock_s.get(key, 0.0) or half_sub != prev_half
            if math.isfinite(code) and code >= opts.slip_cp_std_code:
                slip = True
            if slip:
                self._slip_pending[key] = True
            self._lock_s[key] = lock_s
            valid = not math.isnan(cp[i])
            if valid and key[0] == GNSS_BEIDOU and (key[1] <= 5 or key[1] >= 59):
                cp[i] += 0.5  # BDS GEO (D2) half-cycle shift, as RTKLIB
            lli = 0
            if valid and epoch.lli[i] & LLI_HALF_CYCLE:
                lli |= LLI_HALF_CYCLE
            if half_sub != prev_half:
                lli |= LLI_SLIP
            self._half_sub[key] = half_sub
            if valid:
                if self._slip_pending.get(key, False):
                    lli |= LLI_SLIP
                self._slip_pending[key] = False
            lli_out[i] = lli
        return ObsEpoch(
            time=epoch.time, gnss_id=epoch.gnss_id, sv_id=epoch.sv_id, pr_m=epoch.pr_m, cp_cyc=cp,
            dop_hz=epoch.dop_hz, cn0_dbhz=epoch.cn0_dbhz, lock_ms=epoch.lock_ms, lli=lli_out,
            half_cyc_sub=epoch.half_cyc_sub, pr_std_m=epoch.pr_std_m, cp_std_cyc=epoch.cp_std_cyc,
            clock_reset=epoch.clock_reset, leap_s=epoch.leap_s, glo_fcn=epoch.glo_fcn, signal=epoch.signal,
        )


# ---------------------------------------------------------------------------------------------------------
# Other messages
# ---------------------------------------------------------------------------------------------------------


def decode_tim_tm2(payload: bytes) -> TimeMarks:
    """TIM-TM2 -> TimeMarks with a CameraMark per edge whose "new" bit is set.

    Times in GPS time: time base 2 (UTC) is moved to GPS time with the leap-second table; an edge time is
    None when the receiver flags the time invalid. Falling edge = flash from a hot-shoe (pulls the line low).
    """
    if len(payload) != TIM_TM2.size:
        raise DecodeError(f"TIM-TM2 payload must be {TIM_TM2.size} bytes, got {len(payload)}")
    ch, flags, count, wn_r, wn_f, ms_r, sub_r, ms_f, sub_f, acc = TIM_TM2.unpack(payload)
    time_base = (flags >> TM2_TIME_BASE_SHIFT) & 0x03
    valid = bool(flags & TM2_TIME_VALID)

    def edge_time(week: int, tow_ms: int, sub_ns: int) -> GpsTime | None:
        if not valid:
            return None
        t = GpsTime.from_ms_subms(week, tow_ms, sub_ns)
        if time_base == 2:
            t = t.add_s(leap_seconds_at_utc(t.to_gpst_datetime()))
        return t

    marks = []
    for new_bit, edge, week, ms, sub in (
        (TM2_NEW_RISING, "rising", wn_r, ms_r, sub_r),
        (TM2_NEW_FALLING, "falling", wn_f, ms_f, sub_f),
    ):
        if flags & new_bit:
            marks.append(CameraMark(channel=ch, edge=edge, count=count, time=edge_time(week, ms, sub),
                                    acc_est_ns=acc, time_base=time_base, valid=valid))
    if len(marks) == 2 and marks[0].time is not None and marks[1].time is not None and marks[1].time < marks[0].time:
        marks.reverse()
    return TimeMarks(channel=ch, count=count, marks=tuple(marks), flags=flags)


def decode_rxm_sfrb(payload: bytes) -> SubframeWords | None:
    """RXM-SFRB -> SubframeWords (24 data bits per word) for GPS PRN 1–32; SBAS subframes -> None."""
    if len(payload) != RXM_SFRB.size:
        raise DecodeError(f"RXM-SFRB payload must be {RXM_SFRB.size} bytes, got {len(payload)}")
    _chn, svid, *words = RXM_SFRB.unpack(payload)
    if not 1 <= svid <= 32:
        return None
    return SubframeWords(prn=svid, words=tuple(w & 0xFFFFFF for w in words), bits=24, source="rxm-sfrb")


def decode_rxm_sfrbx(payload: bytes) -> SubframeWords | None:
    """RXM-SFRBX -> SubframeWords (30-bit words with parity) for GPS L1 C/A; other signals -> None."""
    if len(payload) < RXM_SFRBX_HEADER.size:
        raise DecodeError("RXM-SFRBX payload shorter than its header")
    gnss, svid, sig, _freq, num_words, _chn, _ver = RXM_SFRBX_HEADER.unpack_from(payload)
    if len(payload) != RXM_SFRBX_HEADER.size + 4 * num_words:
        raise DecodeError(f"RXM-SFRBX with numWords={num_words} has {len(payload)} bytes")
    if gnss != GNSS_GPS or sig != 0 or num_words != 10 or not 1 <= svid <= 32:
        return None
    words = struct.unpack_from("<10I", payload, RXM_SFRBX_HEADER.size)
    return SubframeWords(prn=svid, words=tuple(w & 0x3FFFFFFF for w in words), bits=30, source="rxm-sfrbx")


def decode_aid_eph(payload: bytes, reference_week: int | None = None) -> Ephemeris | None:
    """AID-EPH reply -> Ephemeris (104 bytes) or None (8 bytes: the receiver has no ephemeris for the SV)."""
    from onboard.rtk import lnav  # the LNAV bit layout lives with the RTK core

    if len(payload) == 8:
        return None
    if len(payload) != 104:
        raise DecodeError(f"AID-EPH payload must be 8 or 104 bytes, got {len(payload)}")
    svid, how = AID_EPH_HEADER.unpack_from(payload)
    words = struct.unpack_from("<24I", payload, 8)
    if not 1 <= svid <= 32:
        raise DecodeError(f"AID-EPH for svid {svid}")
    return lnav.ephemeris_from_aid_eph(svid, how, words, reference_week)


def _text(value: Any) -> str:
    if isinstance(value, (bytes, bytearray)):
        return bytes(value).split(b"\x00", 1)[0].decode("ascii", errors="replace").strip()
    return str(value)


def _plain(value: Any) -> Any:
    if isinstance(value, (bytes, bytearray)):
        return bytes(value)
    if isinstance(value, (int, float, str, bool)) or value is None:
        return value
    return str(value)


def _pyubx2_fields(raw: bytes) -> tuple[str, dict[str, Any]]:
    msg = UBXReader.parse(raw, validate=0)
    fields = {k: _plain(v) for k, v in vars(msg).items() if not k.startswith("_")}
    return str(msg.identity), fields


def _decode_mon_ver(raw: bytes) -> MonVer:
    _name, f = _pyubx2_fields(raw)
    ext = tuple(_text(f[k]) for k in sorted(f) if k.startswith("extension_"))
    return MonVer(sw=_text(f["swVersion"]), hw=_text(f["hwVersion"]), extensions=tuple(e for e in ext if e))


def _decode_nav(key: tuple[int, int], raw: bytes) -> NavFix:
    name, f = _pyubx2_fields(raw)
    if key == _ID_NAV_PVT:
        lat = math.radians(float(f["lat"]))
        lon = math.radians(float(f["lon"]))
        xyz = llh_to_ecef(lat, lon, float(f["height"]) * 1e-3)
        # NAV-PVT has no GPS week; iTOW is GPS time of week.
        return NavFix(tow_ms=int(f["iTOW"]), week=None, pos_ecef_m=(float(xyz[0]), float(xyz[1]), float(xyz[2])),
                      fix_type=int(f["fixType"]), num_sv=int(f["numSV"]), p_acc_m=float(f["hAcc"]) * 1e-3,
                      source=name)
    pos = (float(f["ecefX"]) * 0.01, float(f["ecefY"]) * 0.01, float(f["ecefZ"]) * 0.01)
    if key == _ID_NAV_SOL:
        return NavFix(tow_ms=int(f["iTOW"]), week=int(f["week"]) if f.get("wknSet", 1) else None, pos_ecef_m=pos,
                      fix_type=int(f["gpsFix"]), num_sv=int(f["numSV"]), p_acc_m=float(f["pAcc"]) * 0.01,
                      source=name)
    return NavFix(tow_ms=int(f["iTOW"]), week=None, pos_ecef_m=pos, fix_type=None, num_sv=None,
                  p_acc_m=float(f["pAcc"]) * 0.01, source=name)


def _decode_cfg(frame: Frame) -> CfgReply:
    key = (frame.msg_class, frame.msg_id)
    if key == _ID_CFG_TP:
        from onboard.receiver.ubx_tables import CFG_TP, unpack_payload

        return CfgReply("CFG-TP", frame.msg_class, frame.msg_id, dict(unpack_payload(CFG_TP, frame.payload)),
                        frame.payload)
    name, fields = _pyubx2_fields(frame.raw)
    return CfgReply(name, frame.msg_class, frame.msg_id, fields, frame.payload)


def _decode_ubx(frame: Frame, stats: DecodeStats) -> tuple[str, Decoded | None] | None:
    key = (frame.msg_class, frame.msg_id)
    payload = frame.payload
    if not payload or (frame.msg_class == _CLS_CFG and len(payload) <= 1 and key != _ID_CFG_TP):
        return None  # a poll request recorded on the way to the receiver (empty, or CFG-PRT/TP5 key byte)
    if key == _ID_RXM_RAWX:
        epoch = decode_rxm_rawx(payload, stats.glo_fcn)
        if epoch is not None:
            stats.reference_week = epoch.time.week
        return "RXM-RAWX", epoch
    if key == _ID_RXM_RAW:
        epoch = decode_rxm_raw(payload)
        if epoch is not None:
            stats.reference_week = epoch.time.week
        return "RXM-RAW", epoch
    if key == _ID_TIM_TM2:
        return "TIM-TM2", decode_tim_tm2(payload)
    if key == _ID_RXM_SFRBX:
        return "RXM-SFRBX", decode_rxm_sfrbx(payload)
    if key == _ID_RXM_SFRB:
        return "RXM-SFRB", decode_rxm_sfrb(payload)
    if key == _ID_AID_EPH:
        return "AID-EPH", decode_aid_eph(payload, stats.reference_week)
    if frame.msg_class == _CLS_ACK and frame.msg_id in (0, 1):
        if len(payload) != 2:
            raise DecodeError(f"ACK payload must be 2 bytes, got {len(payload)}")
        return ("ACK-ACK" if frame.msg_id else "ACK-NAK"), Ack(payload[0], payload[1], frame.msg_id == 1)
    if key == _ID_MON_VER:
        if len(payload) < 40 or (len(payload) - 40) % 30:
            raise DecodeError(f"MON-VER payload of {len(payload)} bytes is not 40 + 30·n")
        return "MON-VER", _decode_mon_ver(frame.raw)
    if key in _NAV_LENGTHS:
        if len(payload) not in _NAV_LENGTHS[key]:
            raise DecodeError(f"NAV 0x{frame.msg_id:02X} payload of {len(payload)} bytes, want {_NAV_LENGTHS[key]}")
        fix = _decode_nav(key, frame.raw)
        if fix.week is not None:
            stats.reference_week = fix.week
        return fix.source, fix
    if frame.msg_class == _CLS_CFG:
        reply = _decode_cfg(frame)
        return reply.name, reply
    return None


def decode_frame(frame: Frame, stats: DecodeStats | None = None) -> Decoded | None:
    """Decode one checksum-valid frame from `StreamFramer`; None for anything not decoded. Never raises on
    the frame's content: failures are logged at debug level and counted in `stats.failures`."""
    if stats is None:
        stats = DecodeStats()
    if frame.protocol is not Protocol.UBX:
        return None
    stats.frames += 1
    try:
        result = _decode_ubx(frame, stats)
    except _PARSE_ERRORS as exc:
        stats.failures += 1
        log.debug("UBX 0x%02X 0x%02X at byte %d does not decode: %s: %s", frame.msg_class, frame.msg_id,
                  frame.offset, type(exc).__name__, exc)
        return None
    if result is None:
        stats.ignored += 1
        return None
    name, item = result
    if item is None:
        stats.ignored += 1
        return None
    stats.count(name)
    return item


# ---------------------------------------------------------------------------------------------------------
# Logs
# ---------------------------------------------------------------------------------------------------------

CHUNK_BYTES = 1 << 20


GZIP_PIECE_BYTES = 16 * 1024
"""Compressed bytes fed to the decompressor at a time (a damaged piece is re-fed byte by byte to salvage it)."""


def iter_file_bytes(path: str | Path, chunk_bytes: int = CHUNK_BYTES,
                    warn: Callable[[str], None] | None = None) -> Iterator[bytes]:
    """The bytes of a UBX log, decompressing gzip (detected by its magic bytes, not the name).

    A gzip file damaged or cut short is salvaged: everything that decompresses before the damage is noticed is
    yielded, then `warn` (default: a logged warning) gets one message naming the compressed byte offset where
    it was noticed and the bytes recovered (deflate may notice only at the end, by the CRC: the frames' own
    checksums then sort the good bytes from the garbage). Raises InputError for an unreadable file, and for gzip data damaged before any
    byte decompressed.
    """
    path = Path(path)
    report = warn if warn is not None else log.warning
    try:
        f = open(path, "rb")  # noqa: SIM115  (closed by the `with` below; open errors need their own message)
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from exc
    with f:
        try:
            magic = f.read(2)
            f.seek(0)
            if magic == b"\x1f\x8b":
                yield from _iter_gzip(f, path, report)
            else:
                while chunk := f.read(chunk_bytes):
                    yield chunk
        except OSError as exc:
            raise InputError(f"cannot read {path}: {exc.strerror or exc}") from exc


def _iter_gzip(f: Any, path: Path, warn: Callable[[str], None]) -> Iterator[bytes]:
    """Decompress gzip members one after the other (RFC 1952 allows several), salvaging up to any damage."""
    d = zlib.decompressobj(wbits=31)
    consumed = 0  # compressed bytes fed so far
    produced = 0
    pending = b""
    started = False  # inside a member (some of its bytes fed)
    while True:
        piece = pending or f.read(GZIP_PIECE_BYTES)
        pending = b""
        if not piece:
            break
        saved = d.copy()
        try:
            out = d.decompress(piece)
        except zlib.error as exc:
            d = saved
            for i in range(len(piece)):  # again byte by byte: keep what decodes before the damaged byte
                try:
                    out = d.decompress(piece[i : i + 1])
                except zlib.error:
                    at = consumed + i
                    break
                if out:
                    produced += len(out)
                    yield out
            else:
                at = consumed + len(piece)
            if not produced:
                raise InputError(f"{path}: gzip data is corrupt from compressed byte {at} ({exc}); nothing "
                                 "decompressed") from None
            warn(f"{path}: gzip data is corrupt ({exc}), noticed at compressed byte {at}: kept the {produced} "
                 "bytes decompressed before it (those after a damaged spot are garbage: a frame counts only "
                 "when its checksum holds), the rest of the file is lost")
            return
        started = True
        if out:
            produced += len(out)
            yield out
        if d.eof:
            rest = d.unused_data
            consumed += len(piece) - len(rest)
            d = zlib.decompressobj(wbits=31)
            started = False
            if rest.strip(b"\x00"):
                pending = rest  # the next gzip member
            continue
        consumed += len(piece)
    if started:
        if not produced:
            raise InputError(f"{path}: gzip data is truncated at compressed byte {consumed}; nothing decompressed")
        warn(f"{path}: gzip data is cut short at compressed byte {consumed}: kept the {produced} bytes "
             "decompressed before the end")


def iter_decoded(chunks: Iterable[bytes], stats: DecodeStats | None = None,
                 on_frame: Callable[[Frame], None] | None = None) -> Iterator[Decoded]:
    """Frame and decode a byte stream given as chunks; a torn frame at the end is dropped."""
    if stats is None:
        stats = DecodeStats()
    framer = StreamFramer(frozenset({Protocol.UBX}))
    for chunk in chunks:
        for frame in framer.feed(chunk):
            if on_frame is not None:
                on_frame(frame)
            item = decode_frame(frame, stats)
            if item is not None:
                yield item
    for frame in framer.flush():  # frames a false sync near the end had hidden
        if on_frame is not None:
            on_frame(frame)
        item = decode_frame(frame, stats)
        if item is not None:
            yield item
    torn = getattr(framer, "torn_tail_bytes", 0)
    if torn:
        log.info("dropped a torn tail of %d bytes at the end of the stream", torn)


def iter_file(path: str | Path, stats: DecodeStats | None = None) -> Iterator[Decoded]:
    """Decoded items of a UBX log (plain or gzip; mixed UBX/NMEA/RTCM3 streams; torn tail tolerated)."""
    return iter_decoded(iter_file_bytes(path), stats)


def iter_journal(flight_dir: str | Path, stats: DecodeStats | None = None) -> Iterator[Decoded]:
    """Decoded items of a recorded flight (its journal segments in order; torn segment tails tolerated)."""
    from onboard.logger.journal import iter_journal_bytes

    flight_dir = Path(flight_dir)
    if not flight_dir.is_dir():
        raise InputError(f"{flight_dir} is not a flight directory")
    return iter_decoded(iter_journal_bytes(flight_dir), stats)


def observation_epochs(items: Iterable[Decoded], tracker: LockTracker | None = None) -> Iterator[ObsEpoch]:
    """The ObsEpochs among decoded items, with RTKLIB's slip rules applied by `tracker` (a new one if None)."""
    tracker = tracker or LockTracker()
    for item in items:
        if isinstance(item, ObsEpoch):
            yield tracker.update(item)


def ephemeris_from_subframe(assembler: LnavAssembler, item: SubframeWords,
                            reference_week: int | None) -> Ephemeris | None:
    """The one subframe → LNAV dispatch: a GPS subframe (24-bit RXM-SFRB data words or 30-bit RXM-SFRBX words)
    into `assembler`; returns the new Ephemeris when it completes a set, None otherwise (other systems too).
    `reference_week` (full GPS week, e.g. of the latest epoch) resolves the subframe's 10-bit week."""
    if item.gnss_id != GNSS_GPS:
        return None
    if item.bits == 30:
        return assembler.add_subframe_words30(item.prn, item.words, reference_week=reference_week)
    return assembler.add_subframe(item.prn, item.words, reference_week=reference_week)
