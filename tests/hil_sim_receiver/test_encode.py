"""Every frame the emulator builds decodes back with pyubx2 1.4.0 (CFG-TP with struct) to the intended fields."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from pyubx2 import GET, POLL, SET, UBXReader

from hil_sim import ubx_encode as enc
from hil_sim.receiver import M8T_TP5_DEFAULTS, MODELS
from onboard.gnsstime import GpsTime
from onboard.receiver.framing import iter_frames
from onboard.rtk import lnav
from onboard.rtk.types import LLI_HALF_CYCLE, LLI_SLIP, ObsEpoch
from tests.conftest import shared_file

T = GpsTime(1590, 352_799_999_000_000)


def parse(raw: bytes, msgmode: int = GET):
    return UBXReader.parse(raw, msgmode=msgmode)


def epoch(n: int = 3) -> ObsEpoch:
    return ObsEpoch(time=T, gnss_id=np.zeros(n, np.int8), sv_id=np.array([3, 17, 28][:n], np.int16),
                    pr_m=np.array([2.1e7, 2.2e7, 2.3e7][:n]), cp_cyc=np.array([1.1e8, np.nan, 1.2e8][:n]),
                    dop_hz=np.array([-1200.5, 300.25, 2000.0][:n]), cn0_dbhz=np.array([44.4, 38.6, 50.0][:n]),
                    lock_ms=np.array([70000.0, 0.0, 1234.0][:n]), lli=np.array([0, LLI_SLIP, LLI_HALF_CYCLE][:n], np.uint8),
                    half_cyc_sub=np.array([1, 0, 0][:n], np.uint8), pr_std_m=np.array([0.32, 0.64, 5.12][:n]),
                    cp_std_cyc=np.array([0.004, 0.02, 0.06][:n]))


def test_rxm_raw_decodes_with_pyubx2_fields_and_quality() -> None:
    msg = parse(enc.rxm_raw(epoch()))
    assert msg.identity == "RXM-RAW" and msg.iTOW == 352_799_999 and msg.week == 1590 and msg.numSV == 3
    assert msg.prMes_01 == 2.1e7 and msg.cpMes_01 == 1.1e8 and msg.doMes_01 == pytest.approx(-1200.5)
    assert msg.sv_02 == 17 and msg.cpMes_02 == 0.0 and msg.mesQI_02 == 4  # no phase: code+Doppler only
    assert msg.mesQI_01 == 7 and msg.cno_01 == 44 and msg.lli_02 == LLI_SLIP


def test_rxm_rawx_decodes_with_pyubx2_trkstat_std_codes_and_locktime_cap() -> None:
    msg = parse(enc.rxm_rawx(epoch()))
    assert msg.identity == "RXM-RAWX" and msg.week == 1590 and msg.numMeas == 3
    assert msg.rcvTow == pytest.approx(352_799.999) and msg.leapS == 15 and msg.leapSec == 1
    assert msg.svId_01 == 3 and msg.gnssId_01 == 0 and msg.locktime_01 == 64500
    assert msg.prValid_01 == 1 and msg.cpValid_01 == 1 and msg.halfCyc_01 == 1 and msg.subHalfCyc_01 == 1
    assert msg.cpValid_02 == 0 and msg.locktime_02 == 0
    assert msg.halfCyc_03 == 0  # LLI half-cycle → halfCyc not valid
    assert (msg.prStd_01, msg.prStd_02, msg.prStd_03) == (5, 6, 9)  # 0.01·2^n m
    assert (msg.cpStd_01, msg.cpStd_02) == (1, 5)  # 0.004·n cycles
    assert len(enc.rxm_rawx(epoch())) == 16 + 32 * 3 + 8


def test_subframe_messages_carry_lnav_words_that_decode_back_to_the_ephemeris(broadcast_ephemerides) -> None:
    eph = broadcast_ephemerides[0]
    tow0 = (eph.toe.tow_s - 7200) // 30 * 30
    sfs = lnav.encode_subframes_transmitted(eph, tow0)
    asm = lnav.LnavAssembler(reference_week=eph.week)
    got = None
    for sf in sfs:
        words24, ok = lnav.words24_from_words30(sf)
        assert all(ok)
        msg = parse(enc.rxm_sfrb(2, eph.prn, words24))
        assert msg.identity == "RXM-SFRB" and msg.svid == eph.prn and msg.chn == 2
        dec = [int.from_bytes(getattr(msg, f"dwrd_{i:02d}"), "little") for i in range(1, 11)]
        assert dec == words24
        got = asm.add_subframe(eph.prn, dec) or got
        bx = parse(enc.rxm_sfrbx(2, eph.prn, lnav.sfrbx_from_transmitted(sf)))
        assert bx.identity == "RXM-SFRBX" and bx.numWords == 10 and bx.svId == eph.prn
        dw = [getattr(bx, f"dwrd_{i:02d}") for i in range(1, 11)]
        assert lnav.sfrbx_words24(dw)[0] == words24 and all(lnav.sfrbx_words24(dw)[1])
    assert got is not None and got.iode == eph.iode and got.sqrt_a == pytest.approx(eph.sqrt_a, rel=1e-9)


def test_aid_eph_long_and_no_ephemeris_forms(broadcast_ephemerides) -> None:
    eph = broadcast_ephemerides[0]
    how, words = lnav.aid_eph_words(eph)
    raw = enc.aid_eph(eph.prn, how, words)
    assert len(raw) == 8 + 104
    msg = parse(raw)
    assert msg.identity == "AID-EPH" and msg.svid == eph.prn and msg.how == how and msg.sf3d8_01 == words[23] and msg.sf1d1_01 == words[0]
    back = lnav.ephemeris_from_aid_eph(msg.svid, msg.how, words, eph.week)
    assert back.iodc == eph.iodc and back.toe == eph.toe
    empty = enc.aid_eph(5)
    assert len(empty) == 16 and parse(empty).svid == 5


def test_tim_tm2_flags_count_and_split_times() -> None:
    fall = GpsTime(1590, 352_800_064_123_456)
    rep = enc.TimeMarkReport(0, 7, None, fall, False, True, True, 21)
    msg = parse(enc.tim_tm2(rep))
    assert msg.identity == "TIM-TM2" and msg.ch == 0 and msg.count == 7
    assert (msg.newFallingEdge, msg.newRisingEdge, msg.timeBase, msg.time, msg.run) == (1, 0, 1, 1, 1)
    assert (msg.wnF, msg.towMsF, msg.towSubMsF) == (1590, 352_800_064, 123_456) and msg.accEst == 21
    assert GpsTime.from_ms_subms(msg.wnF, msg.towMsF, msg.towSubMsF) == fall


def test_mon_ver_of_both_models() -> None:
    for spec in MODELS.values():
        msg = parse(enc.mon_ver(spec.sw_version, spec.hw_version, spec.extensions))
        assert msg.swVersion.rstrip(b"\0").decode() == spec.sw_version
        assert msg.hwVersion.rstrip(b"\0").decode() == spec.hw_version
        exts = [getattr(msg, f"extension_{i:02d}").rstrip(b"\0").decode() for i in range(1, len(spec.extensions) + 1)]
        assert exts == list(spec.extensions)


def test_m8t_mon_ver_matches_the_real_rtkbase_dump() -> None:
    text = shared_file("ubx/rtkbase_U-Blox_NEO-M8T_rtkbase.txt").read_text()
    line = next(ln for ln in text.splitlines() if ln.startswith("MON-VER"))
    body = bytes.fromhex(line.split(" - ")[1])
    spec = MODELS["m8t"]
    assert enc.mon_ver(spec.sw_version, spec.hw_version, spec.extensions)[2:-2] == body


def test_default_cfg_tp5_equals_the_real_neo_m8t_dump_bytes() -> None:
    text = shared_file("ubx/rtkbase_U-Blox_NEO-M8T_rtkbase.txt").read_text()
    dumps = [bytes.fromhex(ln.split(" - ")[1]) for ln in text.splitlines() if ln.startswith("CFG-TP5")]
    ours = [enc.frame("CFG-TP5", d)[2:-2] for d in M8T_TP5_DEFAULTS]
    assert ours == dumps
    assert ours[0][-4] == 0xF7


def test_cfg_prt_msg_rate_tp5_ack_decode_with_pyubx2() -> None:
    prt = parse(enc.frame("CFG-PRT", {"portID": 1, "mode": 0x8C0, "baudRate": 115200, "inProtoMask": 1,
                                      "outProtoMask": 1}), SET)
    assert (prt.portID, prt.baudRate, prt.charLen, prt.parity, prt.inUBX, prt.outNMEA) == (1, 115200, 3, 4, 1, 0)
    msg = parse(enc.frame("CFG-MSG", {"msgClass": 2, "msgID": 0x15, "rateUART1": 1}), SET)
    assert (msg.msgClass, msg.msgID, msg.rateUART1, msg.rateUSB) == (2, 0x15, 1, 0)
    rate = parse(enc.frame("CFG-RATE", {"measRate": 200, "navRate": 1, "timeRef": 1}), SET)
    assert (rate.measRate, rate.navRate, rate.timeRef) == (200, 1, 1)
    tp5 = parse(enc.frame("CFG-TP5", {**M8T_TP5_DEFAULTS[1], "flags": 0x77}), SET)
    assert tp5.tpIdx == 1 and tp5.active == 1 and tp5.gridUtcGnss == 0 and tp5.freqPeriod == 4
    assert parse(enc.ack(6, 0x31, True)).identity == "ACK-ACK"
    nak = parse(enc.ack(6, 0x31, False))
    assert nak.identity == "ACK-NAK" and (nak.clsID, nak.msgID) == (6, 0x31)


def test_cfg_tp_packed_by_hand_round_trips_with_struct() -> None:
    fields = {"interval": 2_000_000, "length": 50_000, "status": -1, "timeRef": 1, "flags": 0,
              "antennaCableDelay": 50, "rfGroupDelay": -3, "userDelay": 1200}
    payload = enc.pack(enc.LAYOUTS["CFG-TP"], fields)
    assert len(payload) == 20
    assert struct.unpack("<IIbBBBhhi", payload) == (2_000_000, 50_000, -1, 1, 0, 0, 50, -3, 1200)
    head, _ = enc.unpack(enc.LAYOUTS["CFG-TP"], payload)
    assert {k: head[k] for k in fields} == fields


def test_unpack_rejects_wrong_lengths_and_pack_rejects_out_of_range() -> None:
    with pytest.raises(enc.LayoutError, match="shorter"):
        enc.unpack(enc.LAYOUTS["CFG-TP5"], b"\x00" * 20)
    with pytest.raises(enc.LayoutError, match="unexpected"):
        enc.unpack(enc.LAYOUTS["CFG-RATE"], b"\x00" * 7)
    with pytest.raises(enc.LayoutError, match="repeated"):
        enc.unpack(enc.LAYOUTS["RXM-RAW"], enc.pack(enc.LAYOUTS["RXM-RAW"], {}, [{}])[:-3])
    with pytest.raises(enc.LayoutError):
        enc.pack(enc.LAYOUTS["CFG-RATE"], {"measRate": 70000})


def test_nav_sol_and_tim_tp_decode() -> None:
    pos = (-3_962_108.67, 3_381_309.41, 3_668_678.55)
    msg = parse(enc.nav_sol(GpsTime(1590, 352_800_000_000_000), pos, (1.0, -2.0, 0.5), 9, 2.5, 1.6))
    assert msg.gpsFix == 3 and msg.gpsfixOK == 1 and msg.numSV == 9 and msg.ecefX == round(pos[0] * 100)
    assert msg.iTOW == 352_800_000 and msg.ecefVY == -200
    nofix = parse(enc.nav_sol(GpsTime(1590, 0), None, None, 0, 0, 0))
    assert nofix.gpsFix == 0 and nofix.gpsfixOK == 0
    tp = parse(enc.tim_tp(GpsTime(1590, 352_801_000_000_000)))
    assert tp.towMS == 352_801_000 and tp.week == 1590


def test_frames_pass_our_own_framer() -> None:
    data = enc.rxm_rawx(epoch()) + enc.nmea_sentence("GPGGA,1,2") + enc.ack(6, 1, True)
    frames = iter_frames(data)
    assert [f.protocol.value for f in frames] == ["ubx", "nmea", "ubx"]
    assert parse(enc.frame("CFG-TP5", M8T_TP5_DEFAULTS[0]), POLL) is not None


def test_nav_pvt_decodes_with_pyubx2_to_the_position_and_velocity() -> None:
    from onboard.rtk.geodesy import enu_rotation, llh_to_ecef

    lat, lon, h = np.radians(47.4), np.radians(8.5), 512.25
    pos = llh_to_ecef(lat, lon, h)
    vel = enu_rotation(lat, lon).T @ np.array([3.0, 4.0, -0.5])  # 3 m/s east, 4 north, 0.5 down
    t = GpsTime(1590, 392_400_200_000_000)
    msg = parse(enc.nav_pvt(t, pos, vel, 9, 2.0, 1.6))
    assert len(enc.nav_pvt(t, pos, vel, 9, 2.0, 1.6)) == 8 + 92
    assert msg.fixType == 3 and msg.gnssFixOk == 1 and msg.numSV == 9 and msg.iTOW == 392_400_200
    assert msg.lat == pytest.approx(47.4, abs=1e-7) and msg.lon == pytest.approx(8.5, abs=1e-7)
    assert msg.height == round(h * 1000) and (msg.velN, msg.velE, msg.velD) == (4000, 3000, 500)
    assert msg.gSpeed == 5000 and msg.headMot == pytest.approx(36.87, abs=0.01)
    utc = t.to_utc()
    assert (msg.year, msg.month, msg.day, msg.hour, msg.min, msg.second) == (
        utc.year, utc.month, utc.day, utc.hour, utc.minute, utc.second)
    assert parse(enc.nav_pvt(t, None, None, 0, 0, 0)).fixType == 0
