"""The stream framer: valid frames out, everything else skipped, torn tails held back."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from onboard.receiver.framing import Protocol, StreamFramer, crc24q, iter_frames, ubx_frame
from tests.conftest import shared_file


def test_counts_on_real_capture_with_truncated_tail() -> None:
    data = shared_file("ubx/rtklib_ubx_20080526.ubx").read_bytes()
    framer = StreamFramer()
    frames = framer.feed(data)
    raw = [f for f in frames if (f.msg_class, f.msg_id) == (0x02, 0x10)]
    sfrb = [f for f in frames if (f.msg_class, f.msg_id) == (0x02, 0x11)]
    assert (len(raw), len(sfrb)) == (242, 842)
    assert sum(f.protocol is Protocol.NMEA for f in frames) == 2563
    assert framer.pending == 18  # the file is cut 18 bytes into its last frame
    assert framer.flush() == []
    assert framer.torn_tail_bytes == 18


def test_rtcm3_crc_and_message_numbers() -> None:
    data = shared_file("rtcm/rtklib_testglo.rtcm3").read_bytes()
    frames = iter_frames(data)
    numbers = [f.msg_id for f in frames]
    assert numbers.count(1004) == 186 and numbers.count(1019) == 19
    f = frames[0]
    assert crc24q(f.raw[:-3]) == int.from_bytes(f.raw[-3:], "big")


def test_resync_after_corrupt_frame() -> None:
    good = [ubx_frame(0x0D, 0x03, bytes(range(28))), ubx_frame(0x05, 0x01, b"\x06\x31")]
    broken = bytearray(good[0])
    broken[10] ^= 0xFF
    frames = iter_frames(bytes(broken) + good[1] + good[0])
    assert [f.raw for f in frames] == [good[1], good[0]]


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=400), st.integers(1, 50))
def test_random_bytes_between_frames_never_lose_a_frame(noise: bytes, chunk: int) -> None:
    frame = ubx_frame(0x02, 0x15, bytes(range(48)))
    stream = noise + frame + noise[::-1] + frame
    framer = StreamFramer()
    out = []
    for i in range(0, len(stream), chunk):
        out += framer.feed(stream[i : i + chunk])
    out += framer.flush()
    assert sum(f.raw == frame for f in out) >= 2
