"""apply_profile / detect_receiver / probe_baud against a scripted receiver (ACK, NAK, silence, tampering)."""

from __future__ import annotations

import asyncio
import json

import pytest

from onboard.errors import ConfigRejected
from onboard.receiver.configure import (
    FrameQueueLink,
    apply_profile,
    detect_receiver,
    parse_mon_ver,
    probe_baud,
)
from onboard.receiver.framing import iter_frames, ubx_frame
from onboard.receiver.profiles import ReceiverOptions, build_profile
from tests.conftest import shared_file
from tests.receiver_config._fake_ublox import (
    LEA6T_MON_VER,
    M8T_MON_VER,
    FakeUblox,
    ScriptedLink,
    mon_ver_payload,
)


def run(coro):  # type: ignore[no-untyped-def]
    return asyncio.run(coro)


def _configure(rx: FakeUblox, model: str = "m8t", link_baud: int = 115200, **opts: object):  # type: ignore[no-untyped-def]
    options = ReceiverOptions(**opts)  # type: ignore[arg-type]
    link = ScriptedLink(rx, baud=link_baud)
    report = run(apply_profile(link, build_profile(model, options), options, current_baud=link_baud))
    return report, link


def test_m8t_profile_applied_and_verified_alignment_clear_recorded() -> None:
    report, link = _configure(FakeUblox())
    assert report.ok, report.errors
    statuses = {m.label: m.status for m in report.messages}
    assert statuses.pop("CFG-RST GNSS restart (hot)") == "sent"  # never acknowledged, never polled
    assert all(s == "ok" for label, s in statuses.items() if label != "CFG-TP5 TIMEPULSE2 camera")
    cam = report.result("CFG-TP5 TIMEPULSE2 camera")
    # The receiver cleared alignToTow for the 3 s period: recorded as applied, a warning, not an error.
    assert cam.status == "altered" and cam.applied["alignToTow"] == 0 and cam.polled_back
    assert [d.field for d in cam.diff] == ["alignToTow"]
    assert any("alignToTow=0" in w for w in report.warnings)
    # One CFG at a time: every SET is followed by its own poll before the next SET goes out.
    sets = [f for f in link.sent if len(iter_frames(f)[0].payload) > 2]
    assert [s for s in sets] == build_profile("m8t", ReceiverOptions()).frames()
    assert len(link.sent) == 2 * len(sets) - 1  # CFG-RST is not polled
    assert set(link.timeouts) == {1.0}  # ACK and poll answers awaited for 1 s
    json.dumps(report.to_json())  # JSON-able for the status snapshot


def test_lea6t_profile_applied_and_verified() -> None:
    report, _ = _configure(FakeUblox(LEA6T_MON_VER), model="lea6t")
    assert report.ok and report.camera_timepulse == "TIMEPULSE2"
    assert report.result("CFG-MSG RXM-RAW every 1").status == "ok"


def test_baud_change_moves_the_link_and_is_confirmed_by_poll_back() -> None:
    rx = FakeUblox(baud=9600)
    report, link = _configure(rx, link_baud=9600)
    assert link.reopens == [115200] and report.baud == 115200 and rx.baud == 115200
    prt = report.result("CFG-PRT port 1")
    assert (prt.ack, prt.status, prt.applied["baudRate"]) == ("ack", "ok", 115200)
    assert report.ok


def test_baud_change_without_ack_still_confirmed_at_the_new_rate() -> None:
    rx = FakeUblox(baud=9600)
    rx.ack_after_baud_change = False
    report, _ = _configure(rx, link_baud=9600)
    prt = report.result("CFG-PRT port 1")
    assert (prt.ack, prt.status) == ("none", "ok") and "poll-back" in prt.detail
    assert report.ok and report.baud == 115200


def test_baud_change_refused_names_baudrate_and_carries_on_at_the_old_rate() -> None:
    rx = FakeUblox(baud=9600)
    rx.nak = lambda c, i, p: (c, i) == (0x06, 0x00) and len(p) > 1
    report, link = _configure(rx, link_baud=9600)
    assert link.baud == 9600 and report.baud == 9600
    assert {e.message for e in report.errors} == {"CFG-PRT port 1"}
    err = next(e for e in report.errors if e.field == "baudRate")
    assert err.detail == "receiver applied 9600, we sent 115200"
    assert report.result("CFG-PRT port 1").detail == "receiver stayed at 9600 baud"
    # Everything after the failed CFG-PRT still went through at 9600.
    assert report.result("CFG-MSG TIM-TM2 every 1").status == "ok"


def test_silent_receiver_every_message_reported_nothing_raised() -> None:
    rx = FakeUblox()
    rx.silent = True
    report, link = _configure(rx, retries=1)
    assert not report.ok and len(link.sent) >= len(report.messages)
    rst = report.result("CFG-RST GNSS restart (hot)")
    assert {m.status for m in report.messages if m is not rst} == {"silent"} and rst.status == "sent"
    assert all(m.attempts == 2 for m in report.messages if m.label != "CFG-PRT port 1" and m is not rst)
    names = [e.message for e in report.errors]
    assert names == [e.label for e in build_profile("m8t", ReceiverOptions()).entries if e.name != "CFG-RST"]
    assert "no ACK/NAK within 1.0 s" in str(report.errors[3])
    doc = report.to_json()
    assert doc["ok"] is False and doc["errors"][0]["message"] == "CFG-PRT port 1"
    json.dumps(doc)
    with pytest.raises(ConfigRejected, match="MON-VER: no answer to 3 polls"):
        run(detect_receiver(link))


def test_wrong_poll_back_is_an_error_naming_the_field() -> None:
    rx = FakeUblox()
    rx.tamper[(0x06, 0x08)] = lambda p: (1000).to_bytes(2, "little") + p[2:]  # measRate 1000 instead of 200
    report, _ = _configure(rx)
    [err] = report.errors
    assert (err.message, err.field) == ("CFG-RATE 200 ms", "measRate")
    assert "applied 1000, we sent 200" in err.detail
    assert report.result("CFG-RATE 200 ms").applied["measRate"] == 1000


def test_tp5_nak_on_u6_falls_back_to_legacy_cfg_tp() -> None:
    rx = FakeUblox(LEA6T_MON_VER)
    rx.nak = lambda c, i, p: (c, i) == (0x06, 0x31)
    report, _ = _configure(rx, model="lea6t")
    assert report.ok, report.errors
    assert report.result("CFG-TP5 TIMEPULSE 1 PPS").status == "naked"
    assert report.result("CFG-TP5 TIMEPULSE2 camera").status == "replaced"
    tp = report.result("CFG-TP TIMEPULSE camera")
    assert (tp.status, tp.fallback_for, tp.polled_back) == ("ok", "tp5", True)
    assert tp.applied["interval"] == 3_000_000 and tp.applied["length"] == 100_000
    assert report.camera_timepulse == "TIMEPULSE"
    assert any("CFG-TP5 TIMEPULSE 1 PPS: NAKed" in w for w in report.warnings)
    # The legacy frame really went out and the receiver stored it (our hand-packed bytes).
    assert rx.stored[(0x06, 0x07, b"")][:8] == (3_000_000).to_bytes(4, "little") + (100_000).to_bytes(4, "little")


def test_rawx_nak_on_u6_falls_back_to_rxm_raw() -> None:
    rx = FakeUblox(LEA6T_MON_VER)
    rx.nak = lambda c, i, p: (c, i) == (0x06, 0x01) and p[:2] in (b"\x02\x15", b"\x02\x13", b"\x01\x07")
    report, _ = _configure(rx, model="unknown")
    assert report.ok, report.errors
    assert report.result("CFG-MSG RXM-RAWX every 1").status == "naked"
    assert report.result("CFG-MSG RXM-SFRBX every 1").status == "replaced"
    assert report.result("CFG-MSG RXM-RAW every 1").status == "ok"
    assert report.result("CFG-MSG RXM-SFRB every 1").status == "ok"
    assert report.result("CFG-MSG NAV-SOL every 1").fallback_for == "nav"
    assert rx.stored[(0x06, 0x01, b"\x02\x10")][1 + 2] == 1  # RXM-RAW on UART1


def test_nak_without_fallback_is_an_error_and_the_rest_continues() -> None:
    rx = FakeUblox()
    rx.nak = lambda c, i, p: (c, i) == (0x06, 0x01) and p[:2] == b"\x0d\x03"
    report, _ = _configure(rx)
    [err] = report.errors
    assert err.message == "CFG-MSG TIM-TM2 every 1" and "NAKed" in err.detail
    assert report.result("CFG-MSG TIM-TM2 every 1").attempts == 1  # a NAK is final, no retry
    assert report.result("CFG-TP5 TIMEPULSE2 camera").status == "altered"


def test_unanswered_poll_back_is_a_warning_unverified() -> None:
    rx = FakeUblox()
    rx.answer_polls = False
    report, _ = _configure(rx, retries=0)
    assert report.ok and {m.status for m in report.messages if m.name != "CFG-RST"} == {"unverified"}
    assert len(report.warnings) == len(report.messages) - 1  # not CFG-RST


def test_lost_first_frame_is_retried() -> None:
    rx = FakeUblox()
    rx.drop_first = 1
    report, _ = _configure(rx)
    assert report.ok
    assert report.messages[0].attempts == 2 and report.messages[1].attempts == 1


def test_detect_m8t_from_the_real_mon_ver_dump() -> None:
    line = next(line for line in shared_file("ubx/rtkbase_U-Blox_NEO-M8T_rtkbase.txt").read_text().splitlines()
                if line.startswith("MON-VER"))
    body = bytes.fromhex(line.split(" - ", 1)[1])
    rx = FakeUblox(body[4:])
    info = run(detect_receiver(ScriptedLink(rx)))
    assert (info.model, info.family, info.hw_version) == ("m8t", "u-blox 8", "00080000")
    assert info.sw_version == "EXT CORE 3.01 (111141)"
    assert "FWVER=TIM 1.10" in info.extensions and "MOD=NEO-M8T-0" in info.extensions


@pytest.mark.parametrize(
    ("payload", "model"),
    [
        (M8T_MON_VER, "m8t"),
        (LEA6T_MON_VER, "lea6t"),
        (mon_ver_payload("ROM CORE 3.01 (107888)", "00080000", "FWVER=SPG 3.01", "MOD=NEO-M8N-0"), "unknown"),
        (mon_ver_payload("1.00 (59842)", "00070000"), "unknown"),
    ],
)
def test_parse_mon_ver_models(payload: bytes, model: str) -> None:
    assert parse_mon_ver(payload).model == model


def test_garbled_mon_ver_is_a_clear_error() -> None:
    rx = FakeUblox(b"\x01" * 45)  # not 40 + 30·n bytes
    with pytest.raises(ConfigRejected, match="MON-VER.*45 bytes"):
        run(detect_receiver(ScriptedLink(rx)))


def test_probe_baud_finds_the_rate_and_gives_up_cleanly() -> None:
    rx = FakeUblox(baud=57600)
    link = ScriptedLink(rx, baud=230400)
    assert run(probe_baud(link)) == 57600
    assert link.reopens == [9600, 38400, 57600]
    rx.silent = True
    assert run(probe_baud(link)) is None and link.reopens[-1] == 230400


# --- FrameQueueLink: the reference ConfigLink the daemon can feed from its reader loop ------------------------


def test_frame_queue_link_waits_drops_stale_and_times_out() -> None:
    async def scenario() -> None:
        written: list[bytes] = []

        async def write(raw: bytes) -> None:
            written.append(raw)

        link = FrameQueueLink(write)
        ack = iter_frames(ubx_frame(0x05, 0x01, b"\x06\x08"))[0]
        link.feed(ack)  # arrived before the send: stale, must not answer the next message
        await link.send(b"x")
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        assert await link.wait_frame(lambda f: True, 0.05) is None
        assert 0.045 <= loop.time() - t0 < 0.5
        loop.call_later(0.02, link.feed, ack)
        assert await link.wait_frame(lambda f: f.msg_class == 0x05, 1.0) == ack
        assert written == [b"x"]

    run(scenario())


def test_baud_change_with_no_answer_at_either_rate_names_baudrate() -> None:
    rx = FakeUblox(baud=9600)
    rx.silent = True
    report, link = _configure(rx, link_baud=9600, retries=1)
    err = report.errors[0]
    assert (err.message, err.field) == ("CFG-PRT port 1", "baudRate")
    assert err.detail == "no valid frames at 115200 baud after 2 attempt(s)"
    assert link.reopens == [115200, 9600, 115200, 9600] and report.baud == 9600


def test_camera_timepulse_record_reports_what_was_applied() -> None:
    from onboard.receiver.configure import camera_timepulse_record

    report, _ = _configure(FakeUblox())
    rec = camera_timepulse_record(report, build_profile("m8t", ReceiverOptions()))
    assert (rec["kind"], rec["camera_timepulse"], rec["period_us"], rec["length_us"]) == (
        "timepulse", "TIMEPULSE2", 3_000_000, 100_000)
    assert rec["align_to_tow"] == 0 and rec["trigger_measured"] is True  # as polled back: cleared

    rx = FakeUblox(LEA6T_MON_VER)
    rx.nak = lambda c, i, p: (c, i) == (0x06, 0x31)
    report, _ = _configure(rx, model="lea6t", trigger="none")
    rec = camera_timepulse_record(report, build_profile("lea6t", ReceiverOptions(trigger="none")))
    assert (rec["camera_timepulse"], rec["period_us"], rec["rising"], rec["align_to_tow"]) == (
        "TIMEPULSE", 3_000_000, True, None)
    assert rec["note"].startswith("no trigger measurement")

    rx = FakeUblox()
    rx.silent = True
    report, _ = _configure(rx, retries=0)
    rec = camera_timepulse_record(report, build_profile("m8t", ReceiverOptions()))
    assert rec["period_us"] == 0 and "not configured" in rec["note"] and "CFG-TP5 TIMEPULSE2 camera" in rec["note"]


def test_truncated_poll_answer_is_an_error_not_a_false_zero() -> None:
    rx = FakeUblox()
    rx.tamper[(0x06, 0x31)] = lambda p: p[:20]  # CFG-TP5 answers cut short
    report, _ = _configure(rx)
    assert [e.message for e in report.errors] == ["CFG-TP5 TIMEPULSE 1 PPS", "CFG-TP5 TIMEPULSE2 camera"]
    assert "payload is 20 bytes, expected 32" in report.errors[0].detail


def test_baud_change_acked_but_poll_unanswered_stays_at_the_new_rate() -> None:
    rx = FakeUblox(baud=9600)
    rx.answer_polls = False
    report, link = _configure(rx, link_baud=9600, retries=0)
    prt = report.result("CFG-PRT port 1")
    assert (prt.ack, prt.status) == ("ack", "unverified")
    assert link.baud == 115200 and report.baud == 115200
    assert report.result("CFG-RATE 200 ms").ack == "ack"  # the rest went through at the new rate


GNSS_LABEL = "CFG-GNSS GPS+GLONASS+Galileo+QZSS"


def test_cfg_gnss_nak_is_an_error_naming_it_and_the_rest_is_applied() -> None:
    rx = FakeUblox()
    rx.nak = lambda c, i, p: (c, i) == (0x06, 0x3E) and len(p) > 0
    report, _ = _configure(rx)
    [err] = report.errors
    assert err.message == GNSS_LABEL and "NAKed" in err.detail
    assert report.result("CFG-RATE 200 ms").status == "ok"


def test_cfg_gnss_poll_back_without_glonass_is_an_error_naming_the_system_field() -> None:
    def glonass_off(payload: bytes) -> bytes:  # the receiver answers with the GLONASS block disabled
        out = bytearray(payload)
        for k in range(payload[3]):
            if out[4 + 8 * k] == 6:
                out[4 + 8 * k + 4] &= 0xFE
        return bytes(out)

    rx = FakeUblox()
    rx.tamper[(0x06, 0x3E)] = glonass_off
    report, _ = _configure(rx)
    [err] = report.errors
    assert (err.message, err.field) == (GNSS_LABEL, "enable_GLONASS")
    assert "applied 0, we sent 1" in err.detail


def test_cfg_gnss_poll_back_in_another_block_order_and_reserved_bytes_is_ok() -> None:
    def reordered(payload: bytes) -> bytes:  # blocks reversed, flags' reserved high byte set as the real M8T
        blocks = [bytearray(payload[4 + 8 * k: 12 + 8 * k]) for k in range(payload[3])]
        for b in blocks:
            b[7] = 0x05
        return payload[:1] + b"\x20" + payload[2:4] + b"".join(reversed(blocks))

    rx = FakeUblox()
    rx.tamper[(0x06, 0x3E)] = reordered
    report, _ = _configure(rx)
    assert report.ok, report.errors
    assert report.result(GNSS_LABEL).status == "ok" and report.result(GNSS_LABEL).applied["enable_Galileo"] == 1
