"""UBX messages the receiver emulator sends and receives, as declarative layout tables, with pack/unpack.

Each `Layout` is the u-blox field list of one message (names as in the u-blox interface descriptions, which
are also pyubx2's names): a fixed head of `(name, struct code)` pairs and an optional repeated block. One
generic `pack`/`unpack` pair serves every message, so a layout fix is a one-line table edit. The encoders
below turn our own types (`ObsEpoch`, LNAV words, time marks) into complete frames.

Pure: no I/O, no clocks, no pyubx2 (tests decode the output with pyubx2 1.4.0 as an independent check).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from onboard.gnsstime import GpsTime, leap_seconds_at_utc
from onboard.receiver.framing import ubx_frame
from onboard.rtk.types import FCN_NONE, GNSS_GLONASS, LLI_HALF_CYCLE, LLI_SLIP, ObsEpoch

Field = tuple[str, str]
"""(u-blox field name, little-endian struct code)."""


@dataclass(frozen=True)
class Layout:
    """Payload layout of one UBX message: fixed head, then `block` repeated (count from `count_field` or
    from the payload length when `count_field` is None)."""

    name: str
    msg_class: int
    msg_id: int
    head: tuple[Field, ...]
    block: tuple[Field, ...] = ()
    count_field: str | None = None

    @property
    def head_struct(self) -> struct.Struct:
        return struct.Struct("<" + "".join(code for _, code in self.head))

    @property
    def block_struct(self) -> struct.Struct:
        return struct.Struct("<" + "".join(code for _, code in self.block))

    @property
    def head_size(self) -> int:
        return self.head_struct.size


def _L(name: str, cls: int, mid: int, head: str, block: str = "", count: str | None = None) -> Layout:
    """Build a layout from 'name:code name:code …' strings (compact table rows)."""

    def fields(spec: str) -> tuple[Field, ...]:
        return tuple(tuple(item.split(":")) for item in spec.split()) if spec else ()  # type: ignore[misc]

    return Layout(name, cls, mid, fields(head), fields(block), count)


# fmt: off
LAYOUTS: dict[str, Layout] = {lay.name: lay for lay in (
    _L("ACK-ACK", 0x05, 0x01, "clsID:B msgID:B"),
    _L("ACK-NAK", 0x05, 0x00, "clsID:B msgID:B"),
    _L("CFG-PRT", 0x06, 0x00, "portID:B reserved0:B txReady:H mode:I baudRate:I inProtoMask:H "
                              "outProtoMask:H flags:H reserved5:H"),
    _L("CFG-MSG", 0x06, 0x01, "msgClass:B msgID:B rateDDC:B rateUART1:B rateUART2:B rateUSB:B rateSPI:B "
                              "reserved:B"),
    _L("CFG-MSG3", 0x06, 0x01, "msgClass:B msgID:B rate:B"),
    _L("CFG-TP", 0x06, 0x07, "interval:I length:I status:b timeRef:B flags:B reserved1:B "
                             "antennaCableDelay:h rfGroupDelay:h userDelay:i"),
    _L("CFG-RATE", 0x06, 0x08, "measRate:H navRate:H timeRef:H"),
    _L("CFG-CFG", 0x06, 0x09, "clearMask:I saveMask:I loadMask:I"),
    _L("CFG-RST", 0x06, 0x04, "navBbrMask:H resetMode:B reserved1:B"),
    _L("CFG-GNSS", 0x06, 0x3E, "msgVer:B numTrkChHw:B numTrkChUse:B numConfigBlocks:B",
       "gnssId:B resTrkCh:B maxTrkCh:B reserved1:B flags:I", "numConfigBlocks"),
    _L("CFG-TP5", 0x06, 0x31, "tpIdx:B version:B reserved0:H antCableDelay:h rfGroupDelay:h freqPeriod:I "
                              "freqPeriodLock:I pulseLenRatio:I pulseLenRatioLock:I userConfigDelay:i flags:I"),
    _L("MON-VER", 0x0A, 0x04, "swVersion:30s hwVersion:10s", "extension:30s"),
    _L("RXM-RAW", 0x02, 0x10, "iTOW:i week:h numSV:B reserved1:B",
       "cpMes:d prMes:d doMes:f sv:B mesQI:b cno:b lli:B", "numSV"),
    _L("RXM-RAWX", 0x02, 0x15, "rcvTow:d week:H leapS:b numMeas:B recStat:B version:B reserved1:H",
       "prMes:d cpMes:d doMes:f gnssId:B svId:B sigId:B freqId:B locktime:H cno:B prStdev:B cpStdev:B "
       "doStdev:B trkStat:B reserved2:B", "numMeas"),
    _L("RXM-SFRB", 0x02, 0x11, "chn:B svid:B", "dwrd:I"),
    _L("RXM-SFRBX", 0x02, 0x13, "gnssId:B svId:B sigId:B freqId:B numWords:B chn:B version:B reserved0:B",
       "dwrd:I", "numWords"),
    _L("AID-EPH", 0x0B, 0x31, "svid:I how:I", "sfd:I"),
    _L("TIM-TM2", 0x0D, 0x03, "ch:B flags:B count:H wnR:H wnF:H towMsR:I towSubMsR:I towMsF:I towSubMsF:I "
                              "accEst:I"),
    _L("TIM-TP", 0x0D, 0x01, "towMS:I towSubMS:I qErr:i week:H flags:B refInfo:B"),
    _L("NAV-PVT", 0x01, 0x07, "iTOW:I year:H month:B day:B hour:B min:B second:B valid:B tAcc:I nano:i "
                              "fixType:B flags:B flags2:B numSV:B lon:i lat:i height:i hMSL:i hAcc:I vAcc:I "
                              "velN:i velE:i velD:i gSpeed:i headMot:i sAcc:I headAcc:I pDOP:H flags3:H "
                              "reserved0:I headVeh:i magDec:h magAcc:H"),
    _L("NAV-SOL", 0x01, 0x06, "iTOW:I fTOW:i week:h gpsFix:B flags:B ecefX:i ecefY:i ecefZ:i pAcc:I "
                              "ecefVX:i ecefVY:i ecefVZ:i sAcc:I pDOP:H reserved1:B numSV:B reserved2:I"),
)}
# fmt: on

BY_ID: dict[tuple[int, int], Layout] = {}
for _lay in LAYOUTS.values():
    BY_ID.setdefault((_lay.msg_class, _lay.msg_id), _lay)


class LayoutError(ValueError):
    """A payload does not fit the layout (wrong length) or a field value does not fit its type."""


def pack(layout: Layout, head: Mapping[str, Any], rows: Sequence[Mapping[str, Any]] = ()) -> bytes:
    """Payload bytes of `layout` from field values (missing fields are 0 / empty)."""

    def values(fields: tuple[Field, ...], src: Mapping[str, Any]) -> list[Any]:
        out: list[Any] = []
        for name, code in fields:
            v = src.get(name, b"" if code.endswith("s") else 0)
            if code.endswith("s") and isinstance(v, str):
                v = v.encode("ascii")
            out.append(v)
        return out

    h = dict(head)
    if layout.count_field is not None:
        h[layout.count_field] = len(rows)
    try:
        payload = layout.head_struct.pack(*values(layout.head, h))
        if layout.block:
            bs = layout.block_struct
            payload += b"".join(bs.pack(*values(layout.block, r)) for r in rows)
    except struct.error as exc:
        raise LayoutError(f"{layout.name}: {exc}") from exc
    return payload


def unpack(layout: Layout, payload: bytes) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Field values of a payload: (head, rows). Raises `LayoutError` when the length does not fit."""
    hs = layout.head_struct
    if len(payload) < hs.size:
        raise LayoutError(f"{layout.name}: payload {len(payload)} B shorter than its {hs.size} B head")
    head = dict(zip((n for n, _ in layout.head), hs.unpack_from(payload, 0), strict=True))
    rows: list[dict[str, Any]] = []
    rest = len(payload) - hs.size
    if not layout.block:
        if rest:
            raise LayoutError(f"{layout.name}: {rest} unexpected bytes after the {hs.size} B payload")
        return head, rows
    bs = layout.block_struct
    n = head[layout.count_field] if layout.count_field else rest // bs.size
    if rest != n * bs.size:
        raise LayoutError(f"{layout.name}: {rest} B of repeated blocks, expected {n} × {bs.size} B")
    names = [name for name, _ in layout.block]
    for i in range(n):
        rows.append(dict(zip(names, bs.unpack_from(payload, hs.size + i * bs.size), strict=True)))
    return head, rows


def frame(name: str, head: Mapping[str, Any], rows: Sequence[Mapping[str, Any]] = ()) -> bytes:
    """A complete UBX frame of message `name` (a LAYOUTS key)."""
    lay = LAYOUTS[name]
    return ubx_frame(lay.msg_class, lay.msg_id, pack(lay, head, rows))


# ---------------------------------------------------------------------------------------------------------
# encoders from our types

def ack(msg_class: int, msg_id: int, ok: bool) -> bytes:
    """ACK-ACK (ok) or ACK-NAK naming the message class/id it answers."""
    return frame("ACK-ACK" if ok else "ACK-NAK", {"clsID": msg_class, "msgID": msg_id})


def mon_ver(sw_version: str, hw_version: str, extensions: Sequence[str]) -> bytes:
    """MON-VER reply: NUL-padded 30-char software, 10-char hardware, 30-char extension strings."""
    return frame("MON-VER", {"swVersion": sw_version, "hwVersion": hw_version},
                 [{"extension": e} for e in extensions])


def _leap_s(t: GpsTime) -> int:
    return leap_seconds_at_utc(t.to_gpst_datetime())


def rxm_raw(epoch: ObsEpoch) -> bytes:
    """RXM-RAW (u-blox 6) of the GPS/SBAS entries of `epoch`; iTOW is the receiver tag in whole ms.

    mesQI: 7 with a valid phase, 4 code+Doppler only, 6 when the phase is valid but lock was lost (LLI).
    """
    rows = []
    for i in range(len(epoch)):
        cp = float(epoch.cp_cyc[i])
        lli = int(epoch.lli[i])
        phase_ok = math.isfinite(cp)
        qi = (6 if lli & LLI_SLIP else 7) if phase_ok else 4
        rows.append({"cpMes": cp if phase_ok else 0.0, "prMes": float(epoch.pr_m[i]),
                     "doMes": float(epoch.dop_hz[i]), "sv": int(epoch.sv_id[i]), "mesQI": qi,
                     "cno": round(float(epoch.cn0_dbhz[i])), "lli": lli})
    itow_ms = round(epoch.time.tow_ns / 1_000_000)
    return frame("RXM-RAW", {"iTOW": itow_ms, "week": epoch.time.week}, rows)


def _code(value: float, to_code: Any, default: int) -> int:
    if not math.isfinite(value) or value <= 0:
        return default
    return int(min(15, max(0, to_code(value))))


def rxm_rawx(epoch: ObsEpoch) -> bytes:
    """RXM-RAWX (u-blox 8, version 1) of `epoch`; rcvTow is the receiver tag in s.

    trkStat: bit0 prValid, bit1 cpValid, bit2 halfCyc valid (no LLI half-cycle flag), bit3 subHalfCyc.
    gnssId/svId as in the epoch; freqId the GLONASS channel k + 7 (0 for the other systems); sigId 0 (the L1
    C/A-class signal of every system: GPS/QZSS L1C/A, GLONASS L1OF, Galileo E1C, BeiDou B1I D1).
    Std-dev codes: pr 0.01·2^n m, cp 0.004·n cycles, Doppler 0.002·2^n Hz (n = 4 when unknown).
    """
    n = len(epoch)
    std_pr = epoch.pr_std_m if epoch.pr_std_m.shape[0] == n else np.full(n, np.nan)
    std_cp = epoch.cp_std_cyc if epoch.cp_std_cyc.shape[0] == n else np.full(n, np.nan)
    half = epoch.half_cyc_sub if epoch.half_cyc_sub.shape[0] == n else np.zeros(n, np.uint8)
    fcn = epoch.glo_fcn if epoch.glo_fcn.shape[0] == n else np.full(n, FCN_NONE, np.int8)
    rows = []
    for i in range(n):
        cp = float(epoch.cp_cyc[i])
        phase_ok = math.isfinite(cp)
        lock = float(epoch.lock_ms[i])
        lli = int(epoch.lli[i])
        trk = 0x01 | (0x02 if phase_ok else 0) | (0 if lli & LLI_HALF_CYCLE else 0x04) | (0x08 if half[i] else 0)
        rows.append({
            "prMes": float(epoch.pr_m[i]), "cpMes": cp if phase_ok else 0.0, "doMes": float(epoch.dop_hz[i]),
            "gnssId": int(epoch.gnss_id[i]), "svId": int(epoch.sv_id[i]), "sigId": 0,
            "freqId": int(fcn[i]) + 7 if int(epoch.gnss_id[i]) == GNSS_GLONASS and int(fcn[i]) != FCN_NONE else 0,
            "locktime": int(min(64500, max(0.0, lock))) if math.isfinite(lock) else 0,
            "cno": round(float(epoch.cn0_dbhz[i])),
            "prStdev": _code(float(std_pr[i]), lambda s: round(math.log2(s / 0.01)), 4),
            "cpStdev": _code(float(std_cp[i]), lambda s: round(s / 0.004), 4),
            "doStdev": 4, "trkStat": trk,
        })
    leap = epoch.leap_s if epoch.leap_s is not None else _leap_s(epoch.time)
    rec_stat = 0x01 | (0x02 if epoch.clock_reset else 0)
    return frame("RXM-RAWX", {"rcvTow": epoch.time.tow_ns / 1e9, "week": epoch.time.week, "leapS": leap,
                              "recStat": rec_stat, "version": 1}, rows)


def rxm_sfrb(chn: int, prn: int, words24: Sequence[int]) -> bytes:
    """RXM-SFRB (u-blox 6): 10 words, 24 parity-checked data bits each in bits 23..0."""
    if len(words24) != 10:
        raise LayoutError(f"RXM-SFRB needs 10 words, got {len(words24)}")
    return frame("RXM-SFRB", {"chn": chn, "svid": prn}, [{"dwrd": w & 0xFFFFFF} for w in words24])


def rxm_sfrbx(chn: int, prn: int, words30: Sequence[int], gnss_id: int = 0) -> bytes:
    """RXM-SFRBX (u-blox 8) for a GPS (or QZSS, `gnss_id` 5) L1 C/A LNAV subframe: 10 words of 30 bits."""
    if len(words30) != 10:
        raise LayoutError(f"RXM-SFRBX (GPS) needs 10 words, got {len(words30)}")
    return frame("RXM-SFRBX", {"gnssId": gnss_id, "svId": prn, "chn": chn, "version": 2},
                 [{"dwrd": w & 0x3FFFFFFF} for w in words30])


def rxm_sfrbx_glonass(chn: int, slot: int, channel_k: int, words: Sequence[int]) -> bytes:
    """RXM-SFRBX (u-blox 8) for a GLONASS L1 OF string: 4 words (hil_sim.glonass_strings.sfrbx_words),
    freqId = k + 7, sigId 0."""
    if len(words) != 4:
        raise LayoutError(f"RXM-SFRBX (GLONASS) needs 4 words, got {len(words)}")
    return frame("RXM-SFRBX", {"gnssId": GNSS_GLONASS, "svId": slot, "freqId": channel_k + 7, "chn": chn,
                               "version": 2}, [{"dwrd": w & 0xFFFFFFFF} for w in words])


def rxm_sfrbx_galileo(chn: int, sv: int, words: Sequence[int]) -> bytes:
    """RXM-SFRBX (u-blox 8) for a Galileo E1-B I/NAV page pair: 8 words (hil_sim.galileo_pages.sfrbx_words),
    sigId 1 (E1-B)."""
    if len(words) != 8:
        raise LayoutError(f"RXM-SFRBX (Galileo I/NAV) needs 8 words, got {len(words)}")
    return frame("RXM-SFRBX", {"gnssId": 2, "svId": sv, "sigId": 1, "chn": chn, "version": 2},
                 [{"dwrd": w & 0xFFFFFFFF} for w in words])


def aid_eph(prn: int, how: int | None = None, words24: Sequence[int] | None = None) -> bytes:
    """AID-EPH reply: 104 bytes with HOW and SF1D0..SF3D7, or the 8-byte 'no ephemeris' form."""
    if words24 is None:
        return frame("AID-EPH", {"svid": prn, "how": 0})
    if len(words24) != 24:
        raise LayoutError(f"AID-EPH needs 24 words, got {len(words24)}")
    return frame("AID-EPH", {"svid": prn, "how": (how or 0) & 0xFFFFFF}, [{"sfd": w & 0xFFFFFF} for w in words24])


@dataclass(frozen=True)
class TimeMarkReport:
    """One TIM-TM2 report: last rising/falling edge (GPS time, None = never seen) and their 'new' bits."""

    channel: int
    count: int
    rising: GpsTime | None
    falling: GpsTime | None
    new_rising: bool
    new_falling: bool
    time_valid: bool
    acc_est_ns: int
    utc_known: bool = True


TM2_MODE_RUNNING = 0x01
TM2_RUN = 0x02
TM2_NEW_FALLING = 0x04
TM2_TIMEBASE_GNSS = 0x08  # timeBase (bits 3-4) = 1
TM2_UTC = 0x20
TM2_TIME_VALID = 0x40
TM2_NEW_RISING = 0x80


def tim_tm2(report: TimeMarkReport) -> bytes:
    """TIM-TM2 frame (timeBase GNSS, running mode) from a `TimeMarkReport`."""
    flags = TM2_MODE_RUNNING | TM2_RUN | TM2_TIMEBASE_GNSS
    flags |= TM2_NEW_FALLING if report.new_falling else 0
    flags |= TM2_NEW_RISING if report.new_rising else 0
    flags |= TM2_TIME_VALID if report.time_valid else 0
    flags |= TM2_UTC if report.utc_known else 0

    def split(t: GpsTime | None) -> tuple[int, int, int]:
        if t is None:
            return 0, 0, 0
        ms, sub = divmod(t.tow_ns, 1_000_000)
        return t.week, ms, sub

    wr, msr, subr = split(report.rising)
    wf, msf, subf = split(report.falling)
    return frame("TIM-TM2", {"ch": report.channel, "flags": flags, "count": report.count & 0xFFFF,
                             "wnR": wr, "wnF": wf, "towMsR": msr, "towSubMsR": subr, "towMsF": msf,
                             "towSubMsF": subf, "accEst": report.acc_est_ns})


def tim_tp(pulse: GpsTime, q_err_ps: int = 0) -> bytes:
    """TIM-TP: time of the next TIMEPULSE (GPS time base, UTC available); towSubMS in 2^-32 ms."""
    ms, sub_ns = divmod(pulse.tow_ns, 1_000_000)
    return frame("TIM-TP", {"towMS": ms, "towSubMS": round(sub_ns / 1e6 * 2**32) & 0xFFFFFFFF,
                            "qErr": q_err_ps, "week": pulse.week, "flags": 0x03, "refInfo": 0})


def nav_sol(t: GpsTime, pos_ecef_m: Sequence[float] | np.ndarray | None,
            vel_ecef_m_s: Sequence[float] | np.ndarray | None,
            num_sv: int, p_acc_m: float, pdop: float) -> bytes:
    """NAV-SOL: 3D fix (gpsFix 3, flags fixOK|wknSet|towSet) or no fix when `pos_ecef_m` is None."""
    itow_ms, rem_ns = divmod(t.tow_ns, 1_000_000)
    if rem_ns >= 500_000:
        itow_ms += 1
        rem_ns -= 1_000_000
    head: dict[str, Any] = {"iTOW": itow_ms, "fTOW": rem_ns, "week": t.week, "numSV": num_sv}
    if pos_ecef_m is not None:
        vel = vel_ecef_m_s if vel_ecef_m_s is not None else (0.0, 0.0, 0.0)
        head.update(gpsFix=3, flags=0x0D, pAcc=round(p_acc_m * 100), sAcc=50, pDOP=round(pdop * 100),
                    ecefX=round(pos_ecef_m[0] * 100), ecefY=round(pos_ecef_m[1] * 100),
                    ecefZ=round(pos_ecef_m[2] * 100), ecefVX=round(vel[0] * 100),
                    ecefVY=round(vel[1] * 100), ecefVZ=round(vel[2] * 100))
    else:
        head.update(gpsFix=0, flags=0x00, pAcc=999_999_99, sAcc=999_99, pDOP=9999)
    return frame("NAV-SOL", head)


def nav_pvt(t: GpsTime, pos_ecef_m: Sequence[float] | np.ndarray | None,
            vel_ecef_m_s: Sequence[float] | np.ndarray | None, num_sv: int, h_acc_m: float, pdop: float) -> bytes:
    """NAV-PVT (u-blox 8, 92 bytes): UTC date/time of `t`, 3D fix with WGS 84 lat/lon/height (hMSL = height,
    no geoid model) and NED velocity, or fixType 0 when `pos_ecef_m` is None."""
    from onboard.rtk.geodesy import ecef_to_llh, enu_rotation

    utc = t.to_utc()
    itow_ms = round(t.tow_ns / 1e6)
    head: dict[str, Any] = {"iTOW": itow_ms, "year": utc.year, "month": utc.month, "day": utc.day,
                            "hour": utc.hour, "min": utc.minute, "second": utc.second, "numSV": num_sv,
                            "nano": utc.microsecond * 1000, "pDOP": round(pdop * 100)}
    if pos_ecef_m is None:
        head.update(valid=0x00, tAcc=0xFFFFFFFF, fixType=0, hAcc=0xFFFFFFFF, vAcc=0xFFFFFFFF, sAcc=0xFFFFFFFF,
                    headAcc=0xFFFFFFFF, pDOP=9999)
        return frame("NAV-PVT", head)
    lat, lon, h = (float(v) for v in ecef_to_llh(np.asarray(pos_ecef_m, float)))
    enu = enu_rotation(lat, lon) @ np.asarray(vel_ecef_m_s if vel_ecef_m_s is not None else np.zeros(3), float)
    g_speed = math.hypot(enu[0], enu[1])
    head.update(valid=0x07, tAcc=20, fixType=3, flags=0x01, flags2=0xE0, lon=round(math.degrees(lon) * 1e7),
                lat=round(math.degrees(lat) * 1e7), height=round(h * 1000), hMSL=round(h * 1000),
                hAcc=round(h_acc_m * 1000), vAcc=round(h_acc_m * 1500), velN=round(enu[1] * 1000),
                velE=round(enu[0] * 1000), velD=round(-enu[2] * 1000), gSpeed=round(g_speed * 1000),
                headMot=round(math.degrees(math.atan2(enu[0], enu[1])) % 360 * 1e5), sAcc=100, headAcc=5_000_000)
    return frame("NAV-PVT", head)


# ---------------------------------------------------------------------------------------------------------
# NMEA (factory output)

def nmea_sentence(body: str) -> bytes:
    """'$' + body + '*' + XOR checksum + CRLF."""
    ck = 0
    for ch in body.encode("ascii"):
        ck ^= ch
    return f"${body}*{ck:02X}\r\n".encode("ascii")
