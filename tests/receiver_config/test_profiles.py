"""Configuration profiles: every frame pinned as golden bytes and decoded back (pyubx2 or our CFG-TP codec)."""

from __future__ import annotations

import struct

import pytest
from pyubx2 import SET, UBXMessage, UBXReader
from pyubx2.exceptions import UBXTypeError

from onboard.errors import ReceiverError
from onboard.receiver.framing import iter_frames, ubx_frame
from onboard.receiver.profiles import M8_GNSS_CHANNELS, ReceiverOptions, build_profile, decode_cfg
from onboard.receiver.ubx_tables import CFG_TP, pack_payload, poll_frame, unpack_payload
from tests.conftest import shared_file

# Frames shared by both models with default options (UART1 at 115200, 5 Hz).
COMMON_HEAD = [
    ("CFG-PRT port 1", "b5620600140001000000c008000000c201000100010000000000a842"),
    ("CFG-MSG NMEA-GGA off", "b56206010800f000000000000000ff23"),
    ("CFG-MSG NMEA-GLL off", "b56206010800f001000000000000002a"),
    ("CFG-MSG NMEA-GSA off", "b56206010800f0020000000000000131"),
    ("CFG-MSG NMEA-GSV off", "b56206010800f0030000000000000238"),
    ("CFG-MSG NMEA-RMC off", "b56206010800f004000000000000033f"),
    ("CFG-MSG NMEA-VTG off", "b56206010800f0050000000000000446"),
    ("CFG-RATE 200 ms", "b56206080600c80001000100de6a"),
]
# M8T only: CFG-GNSS (GPS 8/16, Galileo 4/8, QZSS 0/3, GLONASS 8/14 on; SBAS, BeiDou, IMES off) and the GNSS
# restart that applies it, right after the port.
M8T_GNSS = [
    ("CFG-GNSS GPS+GLONASS+Galileo+QZSS",
     ("b562063e3c000000200700081000010001000100030000000100020408000100010003001000000001000400080000000100050003"
      "000100010006080e00010001001fab")),
    ("CFG-RST GNSS restart (hot)", "b56206040400000002001068"),
]
M8T_HEAD = COMMON_HEAD[:1] + M8T_GNSS + COMMON_HEAD[1:]
GOLDEN = {
    ("lea6t", True): COMMON_HEAD + [
        ("CFG-MSG RXM-RAW every 1", "b5620601080002100001000000002228"),
        ("CFG-MSG RXM-SFRB every 1", "b562060108000211000100000000232f"),
        ("CFG-MSG TIM-TM2 every 1", "b562060108000d030001000000002025"),
        ("CFG-MSG NAV-SOL every 1", "b56206010800010600010000000017da"),
        ("CFG-TP5 TIMEPULSE 1 PPS",
         "b56206312000000000003200000040420f0040420f0000000000a086010000000000f7000000c997"),
        ("CFG-TP5 TIMEPULSE2 camera",
         "b562063120000100000032000000c0c62d00c0c62d0000000000a086010000000000f70000000e0f"),
    ],
    ("lea6t", False): COMMON_HEAD + [
        ("CFG-MSG RXM-RAW every 1", "b5620601080002100001000000002228"),
        ("CFG-MSG RXM-SFRB every 1", "b562060108000211000100000000232f"),
        ("CFG-MSG TIM-TM2 every 1", "b562060108000d030001000000002025"),
        ("CFG-MSG NAV-SOL every 1", "b56206010800010600010000000017da"),
        ("CFG-TP5 TIMEPULSE camera",
         "b562063120000000000032000000c0c62d00c0c62d0000000000a086010000000000f70000000def"),
    ],
    ("m8t", True): M8T_HEAD + [
        ("CFG-MSG RXM-RAWX every 1", "b562060108000215000100000000274b"),
        ("CFG-MSG RXM-SFRBX every 1", "b562060108000213000100000000253d"),
        ("CFG-MSG TIM-TM2 every 1", "b562060108000d030001000000002025"),
        ("CFG-MSG NAV-PVT every 1", "b56206010800010700010000000018e1"),
        ("CFG-TP5 TIMEPULSE 1 PPS",
         "b56206312000000100003200000040420f0040420f0000000000a086010000000000f7000000cab6"),
        ("CFG-TP5 TIMEPULSE2 camera",
         "b562063120000101000032000000c0c62d00c0c62d0000000000a086010000000000f70000000f2e"),
    ],
    ("m8t", False): M8T_HEAD + [
        ("CFG-MSG RXM-RAWX every 1", "b562060108000215000100000000274b"),
        ("CFG-MSG RXM-SFRBX every 1", "b562060108000213000100000000253d"),
        ("CFG-MSG TIM-TM2 every 1", "b562060108000d030001000000002025"),
        ("CFG-MSG NAV-PVT every 1", "b56206010800010700010000000018e1"),
        ("CFG-TP5 TIMEPULSE camera",
         "b562063120000001000032000000c0c62d00c0c62d0000000000a086010000000000f70000000e0e"),
    ],
}
GOLDEN_FALLBACKS = {
    "CFG-TP TIMEPULSE camera": "b56206071400c0c62d00a0860100010101003200000000000000305e",
    "CFG-MSG RXM-RAW every 1": "b5620601080002100001000000002228",
    "CFG-MSG RXM-SFRB every 1": "b562060108000211000100000000232f",
    "CFG-MSG NAV-SOL every 1": "b56206010800010600010000000017da",
}


@pytest.mark.parametrize(("model", "tp2"), sorted(GOLDEN))
def test_profile_frames_match_golden_bytes(model: str, tp2: bool) -> None:
    profile = build_profile(model, ReceiverOptions(use_timepulse2=tp2))
    assert [(e.label, e.raw.hex()) for e in profile.entries] == GOLDEN[(model, tp2)]
    assert profile.camera_timepulse == ("TIMEPULSE2" if tp2 else "TIMEPULSE")
    for entries in profile.fallbacks.values():
        for entry in entries:
            assert entry.raw.hex() == GOLDEN_FALLBACKS[entry.label]
    # Every frame is a checksum-valid UBX frame our framer accepts.
    assert len(iter_frames(b"".join(profile.frames()))) == len(profile.entries)


@pytest.mark.parametrize(("model", "tp2"), sorted(GOLDEN))
def test_every_pyubx2_frame_decodes_back_to_the_intended_fields(model: str, tp2: bool) -> None:
    profile = build_profile(model, ReceiverOptions(use_timepulse2=tp2))
    for entry in profile.entries:
        parsed = UBXReader.parse(entry.raw, msgmode=SET)
        assert parsed.identity == entry.name
        if entry.name == "CFG-RST":  # our layout (pyubx2 takes navBbrMask only bit by bit): hot start, GNSS only
            assert (parsed.resetMode, parsed.eph, parsed.alm, parsed.rtc) == (2, 0, 0, 0)
            continue
        if entry.name == "CFG-GNSS":  # pyubx2 numbers the blocks; ours are named by system
            by_system = {M8_GNSS_CHANNELS[g].gnss_id: g for g in M8_GNSS_CHANNELS}
            for n in range(1, parsed.numConfigBlocks + 1):
                g = by_system[getattr(parsed, f"gnssId_{n:02d}")]
                for f in ("enable", "resTrkCh", "maxTrkCh", "sigCfMask"):
                    assert getattr(parsed, f"{f}_{n:02d}") == entry.fields[f"{f}_{g}"], f"{entry.label}.{f}_{g}"
            assert parsed.numConfigBlocks == 7 and parsed.numTrkChUse == entry.fields["numTrkChUse"]
            continue
        for name, value in entry.fields.items():
            got = getattr(parsed, name)
            got = int.from_bytes(got, "little") if isinstance(got, bytes) else got
            assert got == value, f"{entry.label}.{name}"


def test_camera_pulse_fields_mean_what_the_issue_asks() -> None:
    """3 s period, 100 ms, rising, no pulses until locked, GPS grid, on TIMEPULSE2; TIMEPULSE at 1 PPS."""
    profile = build_profile("m8t", ReceiverOptions())
    by_label = {e.label: UBXReader.parse(e.raw, msgmode=SET) for e in profile.entries}
    cam = by_label["CFG-TP5 TIMEPULSE2 camera"]
    assert (cam.tpIdx, cam.freqPeriod, cam.freqPeriodLock) == (1, 3_000_000, 3_000_000)
    assert (cam.pulseLenRatio, cam.pulseLenRatioLock) == (0, 100_000)  # nothing until GPS time is valid
    assert (cam.active, cam.lockedOtherSet, cam.isFreq, cam.isLength) == (1, 1, 0, 1)
    assert (cam.polarity, cam.gridUtcGnss) == (1, 1)
    pps = by_label["CFG-TP5 TIMEPULSE 1 PPS"]
    assert (pps.tpIdx, pps.freqPeriodLock, pps.pulseLenRatioLock) == (0, 1_000_000, 100_000)


def test_options_change_the_frames() -> None:
    """Period, length, polarity, rate, baud and port reach the bytes (falling edge: polarity bit cleared)."""
    opts = ReceiverOptions(camera_period_s=2.0, pulse_len_ms=50, pulse_rising=False, meas_rate_ms=1000,
                           baud=230400, raw_every_n=2)
    profile = build_profile("m8t", opts)
    fields = {e.label: decode_cfg(e.raw, mode=SET) for e in profile.entries}
    cam = fields["CFG-TP5 TIMEPULSE2 camera"]
    assert (cam["freqPeriod"], cam["pulseLenRatioLock"], cam["polarity"]) == (2_000_000, 50_000, 0)
    assert fields["CFG-RATE 1000 ms"]["measRate"] == 1000
    assert fields["CFG-PRT port 1"]["baudRate"] == 230400
    assert fields["CFG-MSG RXM-RAWX every 2"]["rateUART1"] == 2
    usb = build_profile("m8t", ReceiverOptions(port_id=3))
    usb_msg = decode_cfg(usb.entries[-3].raw, mode=SET)  # TIM-TM2 on USB only
    assert (usb_msg["rateUSB"], usb_msg["rateUART1"]) == (1, 0)
    assert usb.entries[0].baud_change is None  # no baud on USB


def test_gpio_and_extint1_trigger_send_the_same_frames() -> None:
    """Trigger routing is wiring, not a receiver setting: TIM-TM2 reports EXTINT1 as channel 1 once enabled."""
    extint = build_profile("m8t", ReceiverOptions(trigger="extint1"))
    gpio = build_profile("m8t", ReceiverOptions(trigger="gpio"))
    assert extint.frames() == gpio.frames()
    assert (extint.trigger, gpio.trigger) == ("extint1", "gpio")


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"camera_period_s": 1.5}, "camera_period_s"),
        ({"camera_period_s": 3.5}, "camera_period_s"),
        ({"pulse_len_ms": 0}, "pulse_len_ms"),
        ({"baud": 12345}, "baud"),
        ({"trigger": "usb"}, "trigger"),
        ({"meas_rate_ms": 10}, "meas_rate_ms"),
        ({"raw_every_n": 300}, "raw_every_n"),
    ],
)
def test_bad_options_are_refused_naming_the_setting(kwargs: dict[str, object], name: str) -> None:
    with pytest.raises(ValueError, match=name):
        ReceiverOptions(**kwargs)  # type: ignore[arg-type]


def test_legacy_cfg_tp_codec_round_trip_and_pyubx2_cannot() -> None:
    fields = {"interval": 2_500_000, "length": 100_000, "status": -1, "timeRef": 1, "flags": 1,
              "antennaCableDelay": 50, "rfGroupDelay": 0, "userDelay": -20}
    payload = pack_payload(CFG_TP, fields)
    assert len(payload) == 20
    assert struct.unpack("<IIbBBBhhi", payload) == (2_500_000, 100_000, -1, 1, 1, 0, 50, 0, -20)
    assert unpack_payload(CFG_TP, payload) == fields | {"reserved1": 0}
    assert decode_cfg(ubx_frame(0x06, 0x07, payload)) == fields | {"reserved1": 0}
    with pytest.raises(UBXTypeError):  # the pyubx2 1.4.0 quirk this codec exists for (`length` field)
        UBXMessage("CFG", "CFG-TP", SET, **fields).serialize()


def test_cfg_tp_codec_refuses_bad_values_naming_the_field() -> None:
    with pytest.raises(ValueError, match="CFG-TP.interval"):
        pack_payload(CFG_TP, {"length": 1, "status": 1, "timeRef": 1, "flags": 0,
                              "antennaCableDelay": 0, "rfGroupDelay": 0, "userDelay": 0})
    with pytest.raises(ValueError, match="CFG-TP.status"):
        pack_payload(CFG_TP, {"interval": 1, "length": 1, "status": 200, "timeRef": 1, "flags": 0,
                              "antennaCableDelay": 0, "rfGroupDelay": 0, "userDelay": 0})
    with pytest.raises(ReceiverError, match="20"):
        unpack_payload(CFG_TP, b"\x00" * 19)  # truncated answer


def test_hand_built_polls() -> None:
    assert poll_frame("CFG-TP5", 1).hex() == "b562063101000139e6"
    assert poll_frame("MON-VER").hex() == "b5620a0400000e34"
    assert poll_frame("CFG-MSG", 0x02, 0x15).hex() == "b562060102000215204a"
    assert UBXReader.parse(poll_frame("CFG-PRT", 1), msgmode=2).portID == 1


def _rtkbase_frames() -> dict[str, list[bytes]]:
    out: dict[str, list[bytes]] = {}
    for line in shared_file("ubx/rtkbase_U-Blox_NEO-M8T_rtkbase.txt").read_text().splitlines():
        if " - " not in line:
            continue
        name, hexpart = line.split(" - ", 1)
        body = bytes.fromhex(hexpart)
        out.setdefault(name.strip(), []).append(ubx_frame(body[0], body[1], body[4:]))  # checksums added
    return out


def test_m8t_timepulse_matches_the_real_neo_m8t_dump() -> None:
    """Our TIMEPULSE (tpIdx 0) is the factory NEO-M8T one: 1 PPS, 100 ms locked, lockedOtherSet, GPS grid, 0xF7."""
    real = next(f for f in _rtkbase_frames()["CFG-TP5"] if f[6] == 0)
    real_fields = decode_cfg(real)
    assert real[6 + 28] == 0xF7
    assert (real_fields["freqPeriodLock"], real_fields["pulseLenRatio"], real_fields["pulseLenRatioLock"]) == (
        1_000_000, 0, 100_000)
    assert (real_fields["lockedOtherSet"], real_fields["alignToTow"], real_fields["gridUtcGnss"]) == (1, 1, 1)
    ours = next(e for e in build_profile("m8t", ReceiverOptions()).entries if e.label == "CFG-TP5 TIMEPULSE 1 PPS")
    assert ours.raw == real  # byte for byte
    assert {k: real_fields[k] for k in ours.fields} == dict(ours.fields)


def test_decode_cfg_refuses_garbage_with_the_message_name() -> None:
    with pytest.raises(ReceiverError, match="not a UBX frame"):
        decode_cfg(b"\x00\x01\x02")
    # pyubx2 would read a truncated answer as zeros (a false "applied 0"): the length is checked first.
    with pytest.raises(ReceiverError, match="CFG-TP5: payload is 7 bytes, expected 32"):
        decode_cfg(ubx_frame(0x06, 0x31, b"\x00" * 7))


def _m8t_dump_frame(line: str) -> bytes:
    """A frame of the real NEO-M8T dump (u-center text: "NAME - cls id len … payload")."""
    body = bytes.fromhex(line.split(" - ", 1)[1])
    return ubx_frame(body[0], body[1], body[4:])


def test_m8t_gnss_setting_is_the_m8_channel_budget_and_reads_the_real_dump() -> None:
    """Three major systems (GPS, GLONASS, Galileo) + QZSS within the 32 channels; BeiDou, SBAS, IMES off; the real
    NEO-M8T's CFG-GNSS answer (7 blocks, reserved flag bytes 0x01/0x03/0x05) decodes into the same per-system
    names our comparison uses."""
    entry = next(e for e in build_profile("m8t", ReceiverOptions()).entries if e.name == "CFG-GNSS")
    f = entry.fields
    on = [g for g in M8_GNSS_CHANNELS if f[f"enable_{g}"]]
    assert sorted(on) == ["GLONASS", "GPS", "Galileo", "QZSS"]
    assert sum(f[f"resTrkCh_{g}"] for g in M8_GNSS_CHANNELS) <= f["numTrkChUse"] == 32
    assert all(f[f"maxTrkCh_{g}"] >= 4 for g in ("GPS", "GLONASS", "Galileo"))
    assert entry.poll == b"" and entry.expect_ack
    lea = build_profile("lea6t", ReceiverOptions())
    assert not any(e.name in ("CFG-GNSS", "CFG-RST") for e in lea.entries)  # the LEA-6T stays GPS-only
    line = next(s for s in shared_file("ubx/rtkbase_U-Blox_NEO-M8T_rtkbase.txt").read_text().splitlines()
                if s.startswith("CFG-GNSS"))
    dump = decode_cfg(_m8t_dump_frame(line))
    assert dump["numTrkChHw"] == 32 and dump["numConfigBlocks"] == 7
    assert (dump["enable_BeiDou"], dump["enable_GLONASS"], dump["resTrkCh_GLONASS"], dump["maxTrkCh_GLONASS"]) \
        == (1, 0, 8, 14)
    assert {k for k in dump if k.endswith("_QZSS")} == {"enable_QZSS", "resTrkCh_QZSS", "maxTrkCh_QZSS",
                                                         "sigCfMask_QZSS"}


@pytest.mark.parametrize(("gnss", "fragment"), [
    ("GPS,GLONASS,Galileo,BeiDou,QZSS", "1 to 3 major"),
    ("QZSS", "1 to 3 major"),
    ("GPS,GLONASS", "GPS and QZSS together"),
    ("GPS,QZSS,Glonass", "unknown system"),
    ("GPS,QZSS,GPS", "named twice"),
])
def test_gnss_option_refuses_what_the_m8_cannot_do(gnss: str, fragment: str) -> None:
    with pytest.raises(ValueError, match=fragment):
        ReceiverOptions(gnss=gnss)


def test_gnss_option_changes_the_blocks() -> None:
    entry = next(e for e in build_profile("m8t", ReceiverOptions(gnss="GPS,QZSS,BeiDou")).entries
                 if e.name == "CFG-GNSS")
    assert entry.label == "CFG-GNSS GPS+QZSS+BeiDou"
    assert (entry.fields["enable_BeiDou"], entry.fields["resTrkCh_BeiDou"], entry.fields["enable_GLONASS"],
            entry.fields["resTrkCh_GLONASS"]) == (1, 8, 0, 0)


def test_cfg_gnss_answer_with_a_wrong_block_count_is_refused() -> None:
    entry = next(e for e in build_profile("m8t", ReceiverOptions()).entries if e.name == "CFG-GNSS")
    payload = bytearray(entry.raw[6:-2])
    payload[3] = 8  # announces 8 blocks, carries 7
    with pytest.raises(ReceiverError, match="numConfigBlocks"):
        decode_cfg(ubx_frame(0x06, 0x3E, bytes(payload)))
    with pytest.raises(ReceiverError, match="numConfigBlocks"):
        decode_cfg(ubx_frame(0x06, 0x3E, bytes(entry.raw[6:-2])[:-3]))
