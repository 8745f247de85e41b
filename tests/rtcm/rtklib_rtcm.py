"""RTKLIB's own RTCM3 decoder (pyrtklib `input_rtcm3`, what convbin runs) as the reference for our MSM decoding."""

from __future__ import annotations

import pytest

from onboard.gnsstime import NS_PER_S, GpsTime

GPS_EPOCH_POSIX_S = 315_964_800  # RTKLIB's gtime_t counts GPS time from 1970 without leap seconds
RTKLIB_SYSTEMS = {1: 0, 4: 6, 8: 2, 16: 5, 32: 3}
"""RTKLIB SYS_GPS/GLO/GAL/QZS/CMP → u-blox gnssId."""

Row = tuple[float, float, float, float, int, str]
"""pseudorange m, phase cycles, Doppler Hz, C/N0 dB-Hz, LLI, RINEX code of RTKLIB's first (L1-band) signal."""


def rtklib_msm_rows(data: bytes, reference: GpsTime) -> dict[tuple[int, int, int], Row]:
    """(GPS time ns, gnssId, sv) → the L1-band observation RTKLIB decodes from an RTCM3 byte stream."""
    rtk = pytest.importorskip("pyrtklib", reason="pyrtklib (RTKLIB bindings, x86_64 bench extra) is not installed")
    rtcm = rtk.rtcm_t()
    assert rtk.init_rtcm(rtcm) == 1
    t = rtcm.time
    t.time = GPS_EPOCH_POSIX_S + reference.week * 604_800 + reference.tow_ns // NS_PER_S
    t.sec = 0.0
    rtcm.time = t
    prn = rtk.Arr1Dint(1)
    out: dict[tuple[int, int, int], Row] = {}
    try:
        for byte in data:
            if rtk.input_rtcm3(rtcm, byte) != 1:
                continue
            for i in range(rtcm.obs.n):
                d = rtcm.obs.data[i]
                sys = rtk.satsys(d.sat, prn)
                if sys not in RTKLIB_SYSTEMS or not d.code[0]:
                    continue
                gnss, sv = RTKLIB_SYSTEMS[sys], prn[0] - (192 if sys == 16 else 0)
                t_ns = (d.time.time - GPS_EPOCH_POSIX_S) * NS_PER_S + round(d.time.sec * 1e9)
                out[(t_ns, gnss, sv)] = (d.P[0], d.L[0], float(d.D[0]), d.SNR[0] * 0.001, int(d.LLI[0]),
                                         rtk.code2obs(d.code[0]))
    finally:
        rtk.free_rtcm(rtcm)
    return out


def single_message_epochs(data: bytes, numbers: frozenset[int]) -> bytes:
    """The MSM frames of `numbers` alone, each with its multiple-message bit (DF393, payload bit 54) cleared and
    its CRC recomputed: RTKLIB then outputs every message as an epoch of its own (it discards a multi-message
    epoch whose parts carry different times, as in a stream whose BeiDou time tags are 14 s off)."""
    from onboard.receiver.framing import crc24q, iter_frames

    out = bytearray()
    for frame in iter_frames(data):
        if frame.msg_id not in numbers:
            continue
        raw = bytearray(frame.raw[:-3])
        raw[3 + 54 // 8] &= ~(0x80 >> (54 % 8)) & 0xFF
        out += raw + crc24q(bytes(raw)).to_bytes(3, "big")
    return bytes(out)
