"""Decoding real captures to our types: known values, agreement with pyubx2, and the failure paths."""

from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np
import pytest
from pyubx2 import UBXReader

from onboard.errors import InputError
from onboard.gnsstime import GpsTime
from onboard.receiver.decode import (
    Ack,
    CfgReply,
    DecodeStats,
    MonVer,
    NavFix,
    SubframeWords,
    TimeMarks,
    decode_frame,
    iter_file,
    iter_journal,
)
from onboard.receiver.framing import Frame, Protocol, StreamFramer, iter_frames, ubx_frame
from onboard.rtk.ephemeris import eph_position, geometric_range
from onboard.rtk.types import GNSS_GLONASS, GNSS_GPS, GNSS_SBAS, LLI_HALF_CYCLE, Ephemeris, ObsEpoch
from tests.conftest import shared_file

M8P_ROVER = "gnss/ublox-m8p-galway-2018/raw/rover-20181004-1237.ubx.gz"


def _frame(msg_class: int, msg_id: int, payload: bytes) -> Frame:
    raw = ubx_frame(msg_class, msg_id, payload)
    (frame,) = iter_frames(raw)
    return frame


def test_first_rxm_raw_epoch_of_rtklib_capture() -> None:
    epochs = [i for i in iter_file(shared_file("ubx/rtklib_ubx_20080526.ubx")) if isinstance(i, ObsEpoch)]
    assert len(epochs) == 242  # every RXM-RAW epoch, although the file ends 18 bytes into a frame
    e = epochs[0]
    # iTOW 107964999 ms of week 1481: the receiver tags epochs at …999 ms, not on the second.
    assert e.time == GpsTime(1481, 107_964_999_000_000)
    assert e.sv_id.tolist() == [18, 9, 12, 5, 129, 30, 14, 15, 137, 22, 26]
    assert e.gnss_id.tolist() == [GNSS_GPS] * 4 + [GNSS_SBAS] + [GNSS_GPS] * 3 + [GNSS_SBAS] + [GNSS_GPS] * 2
    assert e.pr_m[0] == pytest.approx(20373182.790716607, abs=1e-6)
    assert e.cp_cyc[0] == pytest.approx(107061767.33946337, abs=1e-6)
    assert e.dop_hz[0] == pytest.approx(-954.693115234375, abs=1e-9)
    assert e.cn0_dbhz[:3].tolist() == [49.0, 48.0, 48.0]
    assert np.isnan(e.lock_ms).all()  # RXM-RAW has no lock time
    assert epochs[-1].time.diff_s(e.time) == pytest.approx(241.0, abs=0.01)


def test_first_rxm_rawx_epoch_of_neo_m8t() -> None:
    e = next(i for i in iter_file(shared_file("ubx/gpsd_ublox-neo-m8t.log")) if isinstance(i, ObsEpoch))
    assert e.time == GpsTime(2024, 420_963_992_000_000)  # rcvTow …992: receiver clock not steered
    assert len(e) == 13 and e.leap_s == 18 and not e.clock_reset
    assert e.sv_id[:3].tolist() == [32, 10, 14]
    assert e.gnss_id[7:10].tolist() == [GNSS_SBAS] * 3 and e.sv_id[7] == 131
    assert e.pr_m[0] == pytest.approx(18191129.764003463, abs=1e-6)
    assert e.cp_cyc[0] == pytest.approx(95595025.38180187, abs=1e-6)
    assert e.dop_hz[0] == pytest.approx(1130.42431640625, abs=1e-9)
    assert e.lock_ms[0] == 64500.0 and e.cn0_dbhz[0] == 50.0
    assert e.pr_std_m[0] == pytest.approx(0.32)  # code 5: 0.01·2^5 m
    assert e.cp_std_cyc[0] == pytest.approx(0.004)  # code 1: 0.004 cycles
    assert e.half_cyc_sub.tolist() == [1, 1, 0, 0, 0, 0, 1, 0, 1, 1, 0, 1, 1]
    # SBAS 131 (index 10) has 6.9 s of lock: RTKLIB trusts an SBAS half cycle only after 8 s.
    assert e.lock_ms[10] == 6920.0 and e.lli[10] == LLI_HALF_CYCLE
    assert int(np.count_nonzero(e.lli)) == 1


def test_raw_measurements_agree_with_pyubx2_on_every_epoch() -> None:
    """Our numpy layouts and pyubx2's field tables decode the same numbers from every real raw frame."""
    checked = 0
    for name in ("ubx/rtklib_ubx_20080526.ubx", "ubx/gpsd_ublox-neo-m8t.log", "ubx/pyublox_6P-raw-PPP.ubx"):
        for frame in iter_frames(shared_file(name).read_bytes(), frozenset({Protocol.UBX})):
            if (frame.msg_class, frame.msg_id) not in ((0x02, 0x10), (0x02, 0x15)):
                continue
            ours = decode_frame(frame)
            msg = UBXReader.parse(frame.raw)
            assert isinstance(ours, ObsEpoch)
            if frame.msg_id == 0x10:
                assert ours.time == GpsTime.from_week_tow_ns(msg.week, msg.iTOW * 1_000_000)
                for k in range(msg.numSV):
                    n = f"{k + 1:02d}"
                    assert ours.sv_id[k] == getattr(msg, f"sv_{n}")
                    assert ours.pr_m[k] == getattr(msg, f"prMes_{n}")
                    cp = getattr(msg, f"cpMes_{n}")
                    assert (ours.cp_cyc[k] == cp) or (cp == 0 and math.isnan(ours.cp_cyc[k]))
                    assert ours.lli[k] == getattr(msg, f"lli_{n}")
            else:
                assert ours.time == GpsTime.from_week_tow_s(msg.week, msg.rcvTow)
                for k in range(msg.numMeas):
                    n = f"{k + 1:02d}"
                    cp_valid = getattr(msg, f"cpValid_{n}")
                    assert ours.cp_cyc[k] == getattr(msg, f"cpMes_{n}") if cp_valid else math.isnan(ours.cp_cyc[k])
                    pr_valid = getattr(msg, f"prValid_{n}")
                    assert ours.pr_m[k] == getattr(msg, f"prMes_{n}") if pr_valid else math.isnan(ours.pr_m[k])
                    assert ours.lock_ms[k] == getattr(msg, f"locktime_{n}")
                    assert ours.half_cyc_sub[k] == getattr(msg, f"subHalfCyc_{n}")
            checked += 1
    assert checked == 242 + 39 + 259


def test_pyublox_capture_with_corrupt_frame_decodes_to_the_end() -> None:
    """pyubx2 1.4.0's reader raises UnicodeDecodeError on the corrupt frame near byte 40.9k; we skip it and
    decode every frame after it, up to the last byte of the file."""
    path = shared_file("ubx/pyublox_6P-raw-PPP.ubx")
    size = path.stat().st_size
    stats = DecodeStats()
    items = list(iter_file(path, stats))
    epochs = [i for i in items if isinstance(i, ObsEpoch)]
    ephs = [i for i in items if isinstance(i, Ephemeris)]
    # The framer finds 259 checksum-valid RXM-RAW frames (pyubx2's resync-on-error loop sees 246).
    assert len(epochs) == 259
    assert len(ephs) == 151  # the 24 eight-byte "no ephemeris" replies give nothing
    assert stats.by_message["AID-EPH"] == 151 and stats.failures == 0
    assert epochs[-1].time > epochs[0].time
    framer = StreamFramer()
    frames = framer.feed(path.read_bytes())
    # The capture ends 256 bytes into an RXM-RAW frame: everything before that torn frame is decoded.
    assert framer.pending == 256 and frames[-1].offset + len(frames[-1].raw) == size - 256
    assert path.read_bytes()[size - 256 : size - 252] == b"\xb5\x62\x02\x10"
    late = [f for f in frames if f.offset > 41_000 and (f.msg_class, f.msg_id) == (0x02, 0x10)]
    assert len(late) > 150
    assert decode_frame(late[-1]).time == epochs[-1].time  # type: ignore[union-attr]


def test_aid_eph_ephemerides_fit_the_pseudoranges() -> None:
    """Satellite positions from decoded AID-EPH explain the RXM-RAW pseudoranges from the receiver's own fix
    to within a common clock offset: the ephemeris words were unpacked correctly."""
    items = list(iter_file(shared_file("ubx/pyublox_6P-raw-PPP.ubx")))
    fix = next(i for i in items if isinstance(i, NavFix) and i.source == "NAV-SOL")
    ephs = {e.prn: e for e in items if isinstance(e, Ephemeris)}
    epoch = [e for e in items if isinstance(e, ObsEpoch)][-1]
    residuals = []
    for k in range(len(epoch)):
        prn = int(epoch.sv_id[k])
        if prn not in ephs:
            continue
        t_tx = epoch.time.add_s(-epoch.pr_m[k] / 299_792_458.0)
        pos, dts = eph_position(ephs[prn], t_tx)
        rng, _ = geometric_range(pos[None, :], np.array(fix.pos_ecef_m))
        residuals.append(epoch.pr_m[k] - rng[0] + 299_792_458.0 * dts)
    assert len(residuals) >= 6
    spread = np.array(residuals) - np.median(residuals)
    assert np.max(np.abs(spread)) < 100.0  # static receiver, metre-level fix: tens of metres at most


def test_tim_tm2_from_m8p_rover() -> None:
    marks = [i for i in iter_file(shared_file(M8P_ROVER)) if isinstance(i, TimeMarks)]
    assert len(marks) == 7
    first = marks[0]
    assert first.flags == 0x75 and first.channel == 1 and first.count == 0
    (mark,) = first.marks  # only the falling edge is new
    assert mark.edge == "falling" and mark.valid and mark.time_base == 2 and mark.acc_est_ns == 25
    # towMsF 391147141 ms + 535570 ns on the UTC time base: + 18 leap seconds to GPS time.
    assert mark.time == GpsTime(2021, 391_165_141_535_570)
    second = marks[1]
    assert second.flags == 0xF1 and [m.edge for m in second.marks] == ["rising"]
    assert second.marks[0].time == GpsTime(2021, 391_166_146_395_142)
    assert [t.count for t in marks] == [0, 1, 1, 2, 2, 3, 3]


def test_tim_tm2_both_edges_stale_and_invalid() -> None:
    # new rising + new falling, GPS time base (1), valid; falling earlier than rising -> sorted in time order
    flags = 0x80 | 0x04 | (1 << 3) | 0x40
    payload = struct.pack("<BBHHHIIIII", 0, flags, 5, 2021, 2021, 1000, 10, 900, 20, 30)
    tm = decode_frame(_frame(0x0D, 0x03, payload))
    assert isinstance(tm, TimeMarks)
    assert [m.edge for m in tm.marks] == ["falling", "rising"]
    assert tm.marks[1].time == GpsTime(2021, 1_000_000_010)
    # neither "new" bit: both times are stale -> no marks
    stale = decode_frame(_frame(0x0D, 0x03, struct.pack("<BBHHHIIIII", 0, 0x40 | 8, 5, 2021, 2021, 1, 2, 3, 4, 5)))
    assert isinstance(stale, TimeMarks) and stale.marks == ()
    # time not valid: the edge is reported with time None
    invalid = decode_frame(_frame(0x0D, 0x03, struct.pack("<BBHHHIIIII", 0, 0x04, 5, 0, 0, 0, 0, 0, 0, 0)))
    assert isinstance(invalid, TimeMarks) and invalid.marks[0].time is None and not invalid.marks[0].valid


def test_acks_nav_fix_and_mon_ver() -> None:
    items = list(iter_file(shared_file("ubx/pyublox_6P-raw-PPP.ubx")))
    acks = [i for i in items if isinstance(i, Ack)]
    assert len(acks) == 17 and [a for a in acks if not a.ok] == [Ack(0x06, 0x00, False)]  # NAK of CFG-PRT
    fix = next(i for i in items if isinstance(i, NavFix))
    assert fix.source == "NAV-SOL" and fix.week == 1729 and fix.fix_type == 3 and fix.num_sv == 13
    assert fix.pos_ecef_m == pytest.approx((-4471802.53, 2672935.10, -3668289.29), abs=1e-6)
    assert fix.time == GpsTime(1729, 249_838_000_000_000)
    ver = [i for i in iter_file(shared_file("ubx/pyubx2_pygpsdata-ALL.log")) if isinstance(i, MonVer)]
    assert ver == [MonVer("EXT CORE 4.04 (7f89f7)", "00190000",
                          ("ROM BASE 0x118B2060", "FWVER=SPG 4.04", "PROTVER=32.01", "MOD=NEO-M9N",
                           "GPS;GLO;GAL;BDS", "SBAS;QZSS"))]


def test_nav_pvt_gives_ecef() -> None:
    pvt = [i for i in iter_file(shared_file("ubx/pyubx2_pygpsdata-ALL.log"))
           if isinstance(i, NavFix) and i.source == "NAV-PVT"]
    assert len(pvt) == 1 and pvt[0].week is None and pvt[0].num_sv == 20
    r = math.dist(pvt[0].pos_ecef_m, (0.0, 0.0, 0.0))
    assert 6_360_000 < r < 6_400_000  # lat 53.45°, h 86 m: on the ellipsoid


def test_cfg_replies_and_hand_packed_cfg_tp() -> None:
    cfg = [i for i in iter_file(shared_file("ubx/pyubx2_pygpsdata-CFG.log")) if isinstance(i, CfgReply)]
    tp5 = next(c for c in cfg if c.name == "CFG-TP5")
    assert tp5.fields["tpIdx"] == 0 and tp5.fields["freqPeriod"] == 1_000_000
    assert tp5.fields["pulseLenRatioLock"] == 100_000 and tp5.fields["lockedOtherSet"] == 1
    rate = next(c for c in cfg if c.name == "CFG-RATE")
    assert (rate.fields["measRate"], rate.fields["navRate"], rate.fields["timeRef"]) == (1000, 1, 1)
    # CFG-TP (u-blox 6): pyubx2 cannot parse it, our table does
    payload = struct.pack("<IIbBBBhhi", 2_000_000, 100_000, -1, 1, 1, 0, 50, 0, 0)
    tp = decode_frame(_frame(0x06, 0x07, payload))
    assert isinstance(tp, CfgReply) and tp.name == "CFG-TP"
    assert tp.fields["interval"] == 2_000_000 and tp.fields["status"] == -1 and tp.fields["antennaCableDelay"] == 50


def test_subframes_sfrb_and_sfrbx() -> None:
    sfrb = [i for i in iter_file(shared_file("ubx/rtklib_ubx_20080526.ubx")) if isinstance(i, SubframeWords)]
    assert len(sfrb) == 360 and all(s.bits == 24 and 1 <= s.prn <= 32 for s in sfrb)  # 482 SBAS ones dropped
    assert all(w >> 24 == 0 for s in sfrb for w in s.words)
    assert all(s.words[0] >> 16 == 0x8B for s in sfrb)  # TLM preamble in the first data word
    sfrbx = [i for i in iter_file(shared_file("ubx/gpsd_ublox-ned-m8t-sbfrx3.log")) if isinstance(i, SubframeWords)]
    assert len(sfrbx) == 165 and {s.prn for s in sfrbx} == {3} and all(s.bits == 30 for s in sfrbx)


@pytest.mark.slow
def test_m8p_rawx_glonass_and_reference_week() -> None:
    stats = DecodeStats()
    epochs = [i for i in iter_file(shared_file(M8P_ROVER), stats) if isinstance(i, ObsEpoch)]
    assert len(epochs) == 1205 and stats.reference_week == 2021
    assert stats.glo_fcn == {22: -3, 7: 5, 6: -4, 23: 3, 21: 4, 8: 6, 14: -7, 15: 0}
    assert set(np.concatenate([e.gnss_id for e in epochs]).tolist()) == {GNSS_GPS, GNSS_GLONASS}


# ----------------------------------------------------------------------------------------------- failure paths

def test_bad_payloads_return_none_and_are_counted() -> None:
    """Every malformed payload (checksum-valid frame, wrong content) gives None and one counted failure."""
    good_rawx = next(f for f in iter_frames(shared_file("ubx/gpsd_ublox-neo-m8t.log").read_bytes())
                     if (f.msg_class, f.msg_id) == (0x02, 0x15))
    cases = [
        (0x02, 0x15, good_rawx.payload[:-32]),  # numMeas says 13, 12 present
        (0x02, 0x15, good_rawx.payload[:10]),  # shorter than the header
        (0x02, 0x10, struct.pack("<iHBx", 1000, 1500, 3) + bytes(24)),  # numSV 3, one SV present
        (0x0D, 0x03, bytes(27)),  # TIM-TM2 one byte short
        (0x0B, 0x31, bytes(50)),  # AID-EPH neither 8 nor 104 bytes
        (0x02, 0x11, bytes(41)),  # RXM-SFRB one byte short
        (0x05, 0x01, b"\x06"),  # ACK with one byte
        (0x01, 0x06, bytes(10)),  # NAV-SOL cut short (pyubx2 raises)
        (0x0A, 0x04, b"\xff" * 7),  # MON-VER garbage (pyubx2 raises)
    ]
    for msg_class, msg_id, payload in cases:
        stats = DecodeStats()
        assert decode_frame(_frame(msg_class, msg_id, payload), stats) is None, (msg_class, msg_id)
        assert stats.failures == 1 and stats.decoded == 0, (msg_class, msg_id)


def test_week_zero_polls_and_unknown_messages_are_ignored_not_failures() -> None:
    stats = DecodeStats()
    # RXM-RAW before the receiver knows the week: RTKLIB drops it, so do we
    assert decode_frame(_frame(0x02, 0x10, struct.pack("<iHBx", 1000, 0, 0)), stats) is None
    assert decode_frame(_frame(0x0A, 0x04, b""), stats) is None  # a MON-VER poll recorded on the way out
    assert decode_frame(_frame(0x06, 0x31, b"\x01"), stats) is None  # a CFG-TP5 poll for TIMEPULSE2
    assert decode_frame(_frame(0x27, 0x03, bytes(9)), stats) is None  # a message we do not decode
    assert decode_frame(_frame(0x0B, 0x31, bytes(8)), stats) is None  # AID-EPH "no ephemeris"
    assert stats.failures == 0 and stats.ignored == 5
    nmea = Frame(Protocol.NMEA, b"$GPGGA*56\r\n", 0)
    assert decode_frame(nmea, stats) is None and stats.frames == 5


def test_dual_frequency_rawx_keeps_one_l1_entry_per_satellite() -> None:
    """F9-class RXM-RAWX (L1+L2, Galileo E1C and E1B) -> one L1 entry per satellite, the first one reported."""
    frames = [f for f in iter_frames(shared_file("ubx/pygnssutils_pygpsdata_testobsnavdata.log").read_bytes(),
                                     frozenset({Protocol.UBX})) if (f.msg_class, f.msg_id) == (0x02, 0x15)]
    assert len(frames) == 75
    for frame in frames:
        ours = decode_frame(frame)
        assert isinstance(ours, ObsEpoch)
        msg = UBXReader.parse(frame.raw, parsebitfield=1)
        expect: dict[tuple[int, int], float] = {}
        payload = frame.payload
        for k in range(msg.numMeas):
            off = 16 + 32 * k
            gnss, sv, sig = payload[off + 20], payload[off + 21], payload[off + 22]
            l1 = sig == 0 or (sig == 1 and gnss in (2, 3, 5))
            if l1 and gnss != 4 and not (gnss == GNSS_GLONASS and sv == 255):
                expect.setdefault((gnss, sv), getattr(msg, f"prMes_{k + 1:02d}"))
        got = list(zip(ours.gnss_id.tolist(), ours.sv_id.tolist()))
        assert got == list(expect) and len(set(got)) == len(got)
        for pr, want in zip(ours.pr_m.tolist(), expect.values()):
            assert pr == want or math.isnan(pr)  # NaN where prValid is clear


def test_iter_journal_reads_segments_in_order_across_a_torn_segment(tmp_path: Path) -> None:
    """A flight whose first segment ends mid-frame (power cut, restart = new segment): every complete frame of
    both segments decodes, the torn frame is dropped and the framer resynchronises at the next segment."""
    data = shared_file("ubx/gpsd_ublox-neo-m8t.log").read_bytes()
    frames = [f for f in iter_frames(data, frozenset({Protocol.UBX})) if (f.msg_class, f.msg_id) == (0x02, 0x15)]
    tenth = frames[10]
    flight = tmp_path / "flight-20180101T000000Z"
    flight.mkdir()
    (flight / "000000.ubx").write_bytes(data[: tenth.offset + 100])  # torn inside the 11th RXM-RAWX
    (flight / "000001.ubx").write_bytes(data[tenth.offset + len(tenth.raw) :])
    epochs = [i for i in iter_journal(flight) if isinstance(i, ObsEpoch)]
    assert len(epochs) == 38
    assert epochs[9].time.diff_s(epochs[10].time) == pytest.approx(-2.0)  # the torn 11th epoch is missing
    with pytest.raises(InputError):
        list(iter_journal(tmp_path / "missing"))
