"""The receiver state machine without a port: configuration, NAK rules, rates, budget, subframes, time marks."""

from __future__ import annotations

import numpy as np
import pytest
from pyubx2 import UBXReader

from hil_sim import ubx_encode as enc
from hil_sim.faults import FaultOptions, FaultState
from hil_sim.receiver import M8T_TP5_DEFAULTS, RXM_RAWX, ReceiverCore, ReceiverOptions
from onboard.gnsstime import GpsTime
from onboard.receiver.framing import Frame, Protocol, iter_frames
from onboard.rtk import lnav

CONFIGURED_PRT = {"portID": 1, "mode": 0x8C0, "baudRate": 115200, "inProtoMask": 0x1, "outProtoMask": 0x1}


def core_for(model: str, world, **opts) -> ReceiverCore:
    core = ReceiverCore(model, ReceiverOptions(**opts), world, world.start)
    core.advance(world.start)
    return core


def send(core: ReceiverCore, name: str, head: dict | None = None, raw_payload: bytes | None = None) -> list[Frame]:
    lay = enc.LAYOUTS[name]
    payload = raw_payload if raw_payload is not None else enc.pack(lay, head or {})
    frames = iter_frames(enc.ubx_frame(lay.msg_class, lay.msg_id, payload))
    return iter_frames(b"".join(core.handle_frame(frames[0])))


def acked(frames: list[Frame]) -> bool | None:
    acks = [f for f in frames if f.msg_class == 0x05]
    return None if not acks else acks[-1].msg_id == 0x01


def poll(core: ReceiverCore, name: str, payload: bytes = b"") -> dict:
    frames = send(core, name, raw_payload=payload)
    lay = enc.LAYOUTS[name]
    reply = next(f for f in frames if (f.msg_class, f.msg_id) == (lay.msg_class, lay.msg_id))
    return enc.unpack(lay, reply.payload)[0]


def run(core: ReceiverCore, seconds: float, step_s: float = 0.05) -> list[Frame]:
    t = core._t_last
    out = b""
    for _ in range(round(seconds / step_s)):
        t = t.add_s(step_s)
        out += b"".join(core.advance(t))
    return iter_frames(out)


def configure(core: ReceiverCore, meas_ms: int = 200) -> None:
    raw = core.model.raw_msg
    sub = core.model.subframe_msg
    assert acked(send(core, "CFG-PRT", CONFIGURED_PRT))
    assert acked(send(core, "CFG-MSG", {"msgClass": raw[0], "msgID": raw[1], "rateUART1": 1}))
    assert acked(send(core, "CFG-MSG3", {"msgClass": sub[0], "msgID": sub[1], "rate": 1}))
    assert acked(send(core, "CFG-MSG3", {"msgClass": 0x0D, "msgID": 0x03, "rate": 1}))
    assert acked(send(core, "CFG-RATE", {"measRate": meas_ms, "navRate": 1, "timeRef": 1}))


def ubx_of(frames: list[Frame], key: tuple[int, int]) -> list[Frame]:
    return [f for f in frames if f.protocol is Protocol.UBX and (f.msg_class, f.msg_id) == key]


@pytest.mark.parametrize("model", ["lea6t", "m8t"])
def test_factory_state_nmea_only_9600_and_mon_ver(model: str, standin_world) -> None:
    core = core_for(model, standin_world)
    prt = poll(core, "CFG-PRT")
    assert prt["baudRate"] == 9600 and prt["outProtoMask"] == 0x3
    assert poll(core, "CFG-MSG", bytes(core.model.raw_msg))["rateUART1"] == 0
    out = run(core, 3.0)
    assert {f.protocol for f in out} == {Protocol.NMEA}
    assert sum(f.raw.startswith(b"$GPGGA") for f in out) == 3
    ver = UBXReader.parse(send(core, "MON-VER", raw_payload=b"")[0].raw)
    assert ver.swVersion.rstrip(b"\0").decode() == core.model.sw_version


@pytest.mark.parametrize("model", ["lea6t", "m8t"])
def test_full_configuration_is_acked_and_polls_return_applied_values(model: str, standin_world) -> None:
    core = core_for(model, standin_world)
    configure(core)
    tp5 = {**M8T_TP5_DEFAULTS[1], "freqPeriod": 2_000_000, "freqPeriodLock": 2_000_000, "pulseLenRatio": 0,
           "pulseLenRatioLock": 10_000, "flags": 0x77}
    assert acked(send(core, "CFG-TP5", tp5))
    assert poll(core, "CFG-TP5", b"\x01")["freqPeriodLock"] == 2_000_000
    assert poll(core, "CFG-TP5", b"\x00")["flags"] == M8T_TP5_DEFAULTS[0]["flags"] & core.model.tp5_flags_mask
    assert poll(core, "CFG-PRT", b"\x01") == {**poll(core, "CFG-PRT"), **CONFIGURED_PRT}
    assert poll(core, "CFG-MSG", bytes(core.model.raw_msg))["rateUART1"] == 1
    assert poll(core, "CFG-RATE") == {"measRate": 200, "navRate": 1, "timeRef": 1}
    if model == "lea6t":
        tp = {"interval": 1_000_000, "length": 100_000, "status": 1, "timeRef": 1, "flags": 0,
              "reserved1": 0, "antennaCableDelay": 50, "rfGroupDelay": 0, "userDelay": 0}
        assert acked(send(core, "CFG-TP", tp))
        assert poll(core, "CFG-TP") == tp
        assert acked(send(core, "CFG-TP", {**tp, "length": 1_000_000})) is False  # length ≥ interval
    else:
        assert acked(send(core, "CFG-TP", {"interval": 1_000_000})) is False  # no legacy CFG-TP on M8


def test_rawx_on_lea6t_nak_or_ack_ignore(standin_world) -> None:
    nak = core_for("lea6t", standin_world)
    assert acked(send(nak, "CFG-MSG", {"msgClass": 2, "msgID": 0x15, "rateUART1": 1})) is False
    ign = core_for("lea6t", standin_world, rawx_on_u6="ack-ignore")
    assert acked(send(ign, "CFG-PRT", CONFIGURED_PRT))
    assert acked(send(ign, "CFG-MSG", {"msgClass": 2, "msgID": 0x15, "rateUART1": 1}))
    assert poll(ign, "CFG-MSG", bytes(RXM_RAWX))["rateUART1"] == 0
    assert not ubx_of(run(ign, 2.0), RXM_RAWX)
    tp5nak = core_for("lea6t", standin_world, tp5_on_u6="nak")
    assert acked(send(tp5nak, "CFG-TP5", M8T_TP5_DEFAULTS[0])) is False


def test_bad_inputs_are_naked_and_change_nothing(standin_world) -> None:
    core = core_for("m8t", standin_world)
    assert acked(send(core, "CFG-PRT", {**CONFIGURED_PRT, "mode": 0})) is False  # UART mode bits missing
    assert acked(send(core, "CFG-PRT", raw_payload=enc.pack(enc.LAYOUTS["CFG-PRT"], CONFIGURED_PRT)[:12])) is False
    assert acked(send(core, "CFG-PRT", {**CONFIGURED_PRT, "baudRate": 123456})) is False
    assert core.baud_rate == 9600
    assert acked(send(core, "CFG-MSG", raw_payload=b"\x02\x15\x01\x01")) is False  # 4 bytes: no such form
    assert acked(send(core, "CFG-TP5", {**M8T_TP5_DEFAULTS[0], "tpIdx": 2})) is False
    assert acked(send(core, "CFG-TP5", {**M8T_TP5_DEFAULTS[0], "pulseLenRatioLock": 1_000_000})) is False
    assert acked(send(core, "CFG-RATE", {"measRate": 50, "navRate": 1, "timeRef": 1})) is False
    assert acked(send(core, "CFG-RATE", {"measRate": 1000, "navRate": 1, "timeRef": 9})) is False
    assert poll(core, "CFG-RATE")["measRate"] == 1000
    unknown = iter_frames(b"".join(core.handle_frame(iter_frames(enc.ubx_frame(0x06, 0x99, b"\x01"))[0])))
    assert acked(unknown) is False and unknown[0].payload == b"\x06\x99"
    assert core.stats.naked == 9 and core.stats.acked == 1  # the one ACK: the poll


def test_ack_invalid_rates_applies_something_else_and_lea6t_navrate_is_fixed(standin_world) -> None:
    core = core_for("m8t", standin_world, ack_invalid_rates=True)
    assert acked(send(core, "CFG-RATE", {"measRate": 50, "navRate": 1, "timeRef": 1}))
    assert poll(core, "CFG-RATE")["measRate"] == 100  # the poll-back reveals the difference
    lea = core_for("lea6t", standin_world)
    assert acked(send(lea, "CFG-RATE", {"measRate": 1000, "navRate": 4, "timeRef": 1}))
    assert poll(lea, "CFG-RATE")["navRate"] == 1


@pytest.mark.parametrize(("policy", "period_us", "kept"), [
    ("clear", 2_000_000, False), ("clear", 3_000_000, False), ("clear", 500_000, True), ("keep", 2_000_000, True)])
def test_align_to_tow_for_non_divisor_periods(policy: str, period_us: int, kept: bool, standin_world) -> None:
    core = core_for("m8t", standin_world, align_to_tow=policy)
    tp5 = {**M8T_TP5_DEFAULTS[1], "freqPeriod": period_us, "freqPeriodLock": period_us, "pulseLenRatio": 0,
           "pulseLenRatioLock": 10_000, "flags": 0xF7}
    assert acked(send(core, "CFG-TP5", tp5))
    flags = poll(core, "CFG-TP5", b"\x01")["flags"]
    assert bool(flags & 0x20) is kept and flags & ~0x20 == 0xF7 & ~0x20


@pytest.mark.parametrize("model", ["lea6t", "m8t"])
def test_raw_epochs_at_the_configured_rate_decode_with_pyubx2(model: str, standin_world) -> None:
    core = core_for(model, standin_world)
    configure(core, meas_ms=200)
    raws = ubx_of(run(core, 2.0), core.model.raw_msg)
    assert len(raws) == 10
    msgs = [UBXReader.parse(f.raw) for f in raws]
    if model == "lea6t":
        tows = np.array([m.iTOW for m in msgs], float) / 1e3
        assert all(m.iTOW % 200 == 199 for m in msgs)  # receiver tags at …999 ms
        assert msgs[0].numSV == len(standin_world.observe("rover", standin_world.start))
    else:
        tows = np.array([m.rcvTow for m in msgs])
        assert msgs[0].numMeas >= 4 and msgs[0].prMes_01 > 2e7
    assert np.allclose(np.diff(tows), 0.2)


def test_byte_budget_at_9600_drops_whole_epochs(standin_world) -> None:
    core = core_for("m8t", standin_world)
    # raw at 10 Hz on the factory 9600 baud (960 B/s) with NMEA still on: over-subscribed
    assert acked(send(core, "CFG-MSG3", {"msgClass": 2, "msgID": 0x15, "rate": 1}))
    assert acked(send(core, "CFG-RATE", {"measRate": 100, "navRate": 1, "timeRef": 1}))
    out = run(core, 10.0)
    raws = ubx_of(out, RXM_RAWX)
    total = sum(len(f.raw) for f in out)
    assert core.stats.epochs_dropped_budget > 50 and len(raws) + core.stats.epochs_dropped_budget == 100
    assert total <= 960 * 10 + core.options.tx_buffer_bytes
    assert all(UBXReader.parse(f.raw).numMeas > 0 for f in raws)  # what arrives is whole


def test_subframes_every_6_s_and_aid_eph_after_three_subframes(standin_world) -> None:
    core = core_for("lea6t", standin_world)
    configure(core, meas_ms=1000)
    n_sv = len(standin_world.observe("rover", standin_world.start))
    before = [UBXReader.parse(f.raw) for f in send(core, "AID-EPH", raw_payload=b"")]
    assert len(before) == 32 and all(len(m.payload) == 8 for m in before)
    frames = run(core, 36.0, step_s=0.5)
    sfrb = ubx_of(frames, (0x02, 0x11))
    # 2 h 0 min start: subframes 1-3 end at 6, 12, 18 s and 36 s (next frame) → 4 rounds × visible SVs
    assert len(sfrb) == 4 * n_sv
    ids = {lnav.unpack_subframe([int.from_bytes(f.payload[2 + 4 * i:6 + 4 * i], "little") for i in range(10)])[0]
           for f in sfrb}
    assert ids == {1, 2, 3}
    prn = int(standin_world.observe("rover", standin_world.start).sv_id[0])
    reply = UBXReader.parse(send(core, "AID-EPH", raw_payload=bytes([prn]))[0].raw)
    words = [getattr(reply, f"sf{s}d{d}_01") for s in (1, 2, 3) for d in range(1, 9)]
    eph = lnav.ephemeris_from_aid_eph(reply.svid, reply.how, words, 1590)
    assert eph.prn == prn and eph.toe.week == 1590 and len(reply.payload) == 104


def flash_core(world, **opts) -> ReceiverCore:
    core = core_for("m8t", world, time_valid_after_s=1.0, **opts)
    configure(core, meas_ms=1000)
    tp5 = {**M8T_TP5_DEFAULTS[1], "freqPeriod": 2_000_000, "freqPeriodLock": 2_000_000, "pulseLenRatio": 0,
           "pulseLenRatioLock": 10_000, "flags": 0x77 | 0x04}
    assert acked(send(core, "CFG-TP5", tp5))
    return core


def tm2(frames: list[Frame], ch: int | None = None) -> list:
    msgs = [UBXReader.parse(f.raw) for f in ubx_of(frames, (0x0D, 0x03))]
    return [m for m in msgs if ch is None or m.ch == ch]


def test_one_tim_tm2_per_flash_with_count_and_edge_bits(standin_world) -> None:
    t0 = standin_world.start
    flashes = [t0.add_s(2.3 + 2 * k).add_s(0.064) for k in range(4)]
    for k, f in enumerate(flashes):
        standin_world.add_event(t0.add_s(2.3 + 2 * k), f)
    standin_world.add_event(t0.add_s(0.3), t0.add_s(0.364))  # before valid time: no pulse, no photo
    core = flash_core(standin_world, trigger_extint=True)
    out = run(core, 10.0)
    marks = tm2(out, 0)
    assert [m.count for m in marks] == [1, 2, 3, 4] and core.stats.pulses_suppressed == 1
    assert core.stats.edges_lost == 0
    for m, f in zip(marks, flashes, strict=True):
        assert m.newFallingEdge == 1 and m.newRisingEdge == 1 and m.time == 1 and m.timeBase == 1
        got = GpsTime.from_ms_subms(m.wnF, m.towMsF, m.towSubMsF)
        assert abs(got.diff_ns(f)) < 50 and 10 <= m.accEst <= 100
        rise = GpsTime.from_ms_subms(m.wnR, m.towMsR, m.towSubMsR)
        assert abs(rise.diff_s(f) - core.options.contact_closed_s) < 1e-6
    trig = tm2(out, 1)
    assert [m.count for m in trig] == [1, 2, 3, 4]
    assert abs(GpsTime.from_ms_subms(trig[0].wnR, trig[0].towMsR, trig[0].towSubMsR).diff_s(t0.add_s(2.3))) < 1e-7


def test_bounce_and_two_flashes_in_one_epoch_lose_marks_with_a_count_jump(standin_world) -> None:
    t0 = standin_world.start
    standin_world.add_event(t0.add_s(2.1), t0.add_s(2.164))
    standin_world.add_event(t0.add_s(4.1), t0.add_s(4.164), bounce_time=t0.add_s(4.1648))  # bounce
    standin_world.add_event(t0.add_s(6.1), t0.add_s(6.164))  # two photos within one epoch
    standin_world.add_event(t0.add_s(6.6), t0.add_s(6.664))
    core = flash_core(standin_world)
    marks = tm2(run(core, 8.0), 0)
    assert [m.count for m in marks] == [1, 3, 5]  # jumps of 2: the only sign of the lost marks
    assert core.stats.edges_lost == 4  # bounce: 1 rising + 1 falling overwritten; two photos: the same
    bounced = GpsTime.from_ms_subms(marks[1].wnF, marks[1].towMsF, marks[1].towSubMsF)
    assert abs(bounced.diff_s(t0.add_s(4.1648))) < 1e-7  # the bounce's edge, not the flash, is reported
    last = GpsTime.from_ms_subms(marks[2].wnF, marks[2].towMsF, marks[2].towSubMsF)
    assert abs(last.diff_s(t0.add_s(6.664))) < 1e-7


def test_bounce_fault_from_fault_options(standin_world) -> None:
    t0 = standin_world.start
    for k in range(3):
        standin_world.add_event(t0.add_s(2.1 + 2 * k), t0.add_s(2.164 + 2 * k))
    core = flash_core(standin_world, faults=FaultOptions(bounce_prob=1.0))
    assert [m.count for m in tm2(run(core, 8.0), 0)] == [2, 4, 6]


def test_lost_flash_report_fault_leaves_a_count_jump(standin_world) -> None:
    """`drop_flash_mark_rate` withholds whole EXTINT0 TIM-TM2 reports (flash and contact opening together):
    the trigger line (EXTINT1) still reports every pulse, and the next flash report's count jumps by 2."""
    t0 = standin_world.start
    for k in range(4):
        standin_world.add_event(t0.add_s(2.1 + 2 * k), t0.add_s(2.164 + 2 * k))
    core = flash_core(standin_world, trigger_extint=True,
                      faults=FaultOptions(seed=3, drop_flash_mark_rate=0.5))
    out = run(core, 10.0)
    flashes, pulses = tm2(out, 0), tm2(out, 1)
    dropped = core.dropped_flash_reports
    assert [m.count for m in pulses] == [1, 2, 3, 4]
    assert 0 < len(dropped) < 4 and core.stats.marks_dropped_fault == core.faults.flash_marks_dropped == len(dropped)
    assert len(flashes) + len(dropped) == 4
    assert sorted([m.count for m in flashes] + [r.count for r in dropped]) == [1, 2, 3, 4]
    assert core.stats.edges_lost == 0  # nothing overwritten inside the receiver: the reports were lost on the way


def test_camera_timepulse_inactive_means_no_photos(standin_world) -> None:
    t0 = standin_world.start
    standin_world.add_event(t0.add_s(3.1), t0.add_s(3.164))
    core = core_for("m8t", standin_world, time_valid_after_s=1.0)
    configure(core, meas_ms=1000)  # TIMEPULSE2 left at its factory flags 0xFE: inactive
    assert not tm2(run(core, 5.0)) and core.stats.pulses_suppressed == 1


def test_silent_receiver_answers_nothing_and_streams_factory_nmea(standin_world) -> None:
    core = core_for("m8t", standin_world, silent=True)
    assert send(core, "CFG-PRT", CONFIGURED_PRT) == []
    assert send(core, "MON-VER", raw_payload=b"") == []
    assert core.baud_rate == 9600
    out = run(core, 2.0)
    assert out and all(f.protocol is Protocol.NMEA for f in out)


def test_dropped_epoch_fault_leaves_gaps(standin_world) -> None:
    core = core_for("m8t", standin_world, faults=FaultOptions(seed=3, drop_epoch_rate=0.3))
    configure(core, meas_ms=200)
    raws = ubx_of(run(core, 10.0), RXM_RAWX)
    assert len(raws) + core.stats.epochs_dropped_fault == 50 and 5 <= core.stats.epochs_dropped_fault <= 25
    tows = np.array([UBXReader.parse(f.raw).rcvTow for f in raws])
    assert np.diff(tows).max() >= 0.4 - 1e-9


def test_corrupt_fault_flips_bytes_at_the_rate_and_is_reproducible() -> None:
    data = bytes(range(256)) * 40
    a = FaultState(FaultOptions(seed=5, corrupt_byte_rate=0.01)).corrupt(data)
    b = FaultState(FaultOptions(seed=5, corrupt_byte_rate=0.01)).corrupt(data)
    assert a == b and len(a) == len(data)
    diff = sum(x != y for x, y in zip(a, data, strict=True))
    assert 50 < diff < 160
    with pytest.raises(ValueError, match="probability"):
        FaultOptions(corrupt_byte_rate=1.5)


def test_cfg_cfg_save_load_and_clear(standin_world) -> None:
    core = core_for("m8t", standin_world)
    configure(core)
    assert acked(send(core, "CFG-CFG", raw_payload=enc.pack(enc.LAYOUTS["CFG-CFG"], {"saveMask": 0xFFFF}) + b"\x01"))
    assert acked(send(core, "CFG-RATE", {"measRate": 1000, "navRate": 1, "timeRef": 1}))
    assert acked(send(core, "CFG-CFG", {"loadMask": 0xFFFF}))
    assert poll(core, "CFG-RATE")["measRate"] == 200
    assert acked(send(core, "CFG-CFG", {"clearMask": 0xFFFF, "loadMask": 0xFFFF}))
    assert core.baud_rate == 9600 and poll(core, "CFG-RATE")["measRate"] == 1000
    assert acked(send(core, "CFG-CFG", raw_payload=b"\x00" * 5)) is False


def test_nav_sol_and_tim_tp_once_time_is_valid(standin_world) -> None:
    core = core_for("m8t", standin_world, time_valid_after_s=2.0, nav_noise_m=1.0)
    assert acked(send(core, "CFG-PRT", CONFIGURED_PRT))
    for msg in ((0x01, 0x06), (0x0D, 0x01)):
        assert acked(send(core, "CFG-MSG3", {"msgClass": msg[0], "msgID": msg[1], "rate": 1}))
    out = run(core, 5.0)
    sols = [UBXReader.parse(f.raw) for f in ubx_of(out, (0x01, 0x06))]
    assert [s.gpsFix for s in sols] == [0, 3, 3, 3, 3]  # epochs at 1..5 s: no fix before 2 s
    site = standin_world.site_ecef_m
    for s in sols[1:]:
        err = np.array([s.ecefX, s.ecefY, s.ecefZ]) / 100 - site
        assert np.linalg.norm(err) < 6.0 and s.numSV >= 4
    tps = [UBXReader.parse(f.raw) for f in ubx_of(out, (0x0D, 0x01))]
    # TIM-TP announces the next whole-second pulse at each epoch once time is valid
    assert [tp.towMS % 1000 for tp in tps] == [0] * 4 and len({tp.towMS for tp in tps}) == 4


def test_scenario_end_stops_measurements_but_configuration_still_answers(standin_world) -> None:
    core = core_for("m8t", standin_world)
    core.t_end = standin_world.start.add_s(2.0)
    configure(core, meas_ms=1000)
    assert len(ubx_of(run(core, 5.0), RXM_RAWX)) == 2
    assert poll(core, "CFG-RATE")["measRate"] == 1000


def test_u_blox_6_specifics_nav_pvt_naked_and_tp5_version_reads_zero(standin_world) -> None:
    lea = core_for("lea6t", standin_world)
    assert acked(send(lea, "CFG-MSG3", {"msgClass": 0x01, "msgID": 0x07, "rate": 1})) is False
    assert acked(send(lea, "CFG-MSG3", {"msgClass": 0x02, "msgID": 0x13, "rate": 1})) is False
    assert acked(send(lea, "CFG-TP5", {**M8T_TP5_DEFAULTS[1], "version": 1, "flags": 0x7FE}))
    back = poll(lea, "CFG-TP5", b"\x01")
    assert back["version"] == 0 and back["flags"] == 0xFE  # the M8 grid bits 8-10 do not exist on u-blox 6
    m8 = core_for("m8t", standin_world, time_valid_after_s=0.5)
    assert acked(send(m8, "CFG-PRT", CONFIGURED_PRT))
    assert acked(send(m8, "CFG-MSG3", {"msgClass": 0x01, "msgID": 0x07, "rate": 1}))
    pvts = [UBXReader.parse(f.raw) for f in ubx_of(run(m8, 3.0), (0x01, 0x07))]
    assert len(pvts) == 3 and all(p.fixType == 3 for p in pvts)


def _gnss_blocks(core: ReceiverCore) -> tuple[dict, list[dict]]:
    frames = send(core, "CFG-GNSS", raw_payload=b"")
    reply = next(f for f in frames if (f.msg_class, f.msg_id) == (0x06, 0x3E))
    return enc.unpack(enc.LAYOUTS["CFG-GNSS"], reply.payload)


def _gnss_set(enabled: dict[int, tuple[int, int]], use: int = 32) -> bytes:
    rows = [{"gnssId": g, "resTrkCh": (enabled.get(g) or (0, 8))[0], "maxTrkCh": (enabled.get(g) or (0, 8))[1],
             "flags": 0x00010001 if g in enabled else 0x00010000} for g in range(7)]
    return enc.pack(enc.LAYOUTS["CFG-GNSS"], {"msgVer": 0, "numTrkChUse": use}, rows)


def test_m8t_cfg_gnss_poll_is_the_real_dump_and_sets_follow_the_m8_rules(standin_world) -> None:
    from tests.conftest import shared_file

    core = core_for("m8t", standin_world)
    head, rows = _gnss_blocks(core)
    line = next(s for s in shared_file("ubx/rtkbase_U-Blox_NEO-M8T_rtkbase.txt").read_text().splitlines()
                if s.startswith("CFG-GNSS"))
    assert enc.pack(enc.LAYOUTS["CFG-GNSS"], head, rows) == bytes.fromhex(line.split(" - ", 1)[1])[4:]
    good = {0: (8, 16), 2: (4, 8), 5: (0, 3), 6: (8, 14)}
    four_majors = {**good, 3: (8, 16)}
    assert acked(send(core, "CFG-GNSS", raw_payload=_gnss_set(four_majors))) is False  # 3 major GNSS at most
    assert acked(send(core, "CFG-GNSS", raw_payload=_gnss_set({0: (8, 16), 6: (30, 30)}))) is False  # 38 reserved
    assert acked(send(core, "CFG-GNSS", raw_payload=_gnss_set({0: (8, 16), 6: (2, 3)}))) is False  # maxTrkCh < 4
    assert acked(send(core, "CFG-GNSS", raw_payload=_gnss_set({5: (0, 3)}))) is False  # no major GNSS
    assert acked(send(core, "CFG-GNSS", raw_payload=_gnss_set(good, use=33))) is False  # 32 channels
    assert core.config.gnss_enabled() == {0, 1, 2, 3, 5}  # NAKs changed nothing
    assert acked(send(core, "CFG-GNSS", raw_payload=_gnss_set(good)))
    _, rows = _gnss_blocks(core)
    by_id = {r["gnssId"]: r for r in rows}
    assert {g for g, r in by_id.items() if r["flags"] & 1} == {0, 2, 5, 6}
    assert by_id[5]["flags"] >> 24 == 0x05  # the receiver's reserved byte survives a SET
    lea = core_for("lea6t", standin_world)
    assert acked(send(lea, "CFG-GNSS", raw_payload=_gnss_set(good))) is False
    assert send(core, "CFG-RST", {"navBbrMask": 0, "resetMode": 2}) == [] and core.stats.gnss_restarts == 1


def test_m8t_rawx_carries_only_the_enabled_systems(standin_world) -> None:
    core = core_for("m8t", standin_world)
    configure(core)
    n_gps = len(standin_world.observe("rover", standin_world.start))
    first = [UBXReader.parse(f.raw) for f in run(core, 1.0) if (f.msg_class, f.msg_id) == RXM_RAWX]
    assert first and all(m.numMeas == n_gps for m in first)
    assert acked(send(core, "CFG-GNSS", raw_payload=_gnss_set({2: (4, 8), 6: (8, 14)})))  # GPS off
    later = [UBXReader.parse(f.raw) for f in run(core, 1.0) if (f.msg_class, f.msg_id) == RXM_RAWX]
    assert later and all(m.numMeas == 0 for m in later)
