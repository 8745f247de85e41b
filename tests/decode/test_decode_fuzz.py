"""Property tests: decoding never raises on random or damaged input, and resynchronises after the damage."""

from __future__ import annotations

from functools import cache

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from onboard.receiver.decode import DecodeStats, decode_frame, iter_decoded
from onboard.receiver.framing import Frame, Protocol, StreamFramer, iter_frames, ubx_frame
from tests.conftest import shared_file

# Every message decode_frame handles, plus a few it ignores.
KNOWN_IDS = [(0x02, 0x10), (0x02, 0x15), (0x02, 0x11), (0x02, 0x13), (0x0B, 0x31), (0x0D, 0x03), (0x05, 0x00),
             (0x05, 0x01), (0x0A, 0x04), (0x01, 0x06), (0x01, 0x07), (0x01, 0x01), (0x06, 0x31), (0x06, 0x07),
             (0x06, 0x00), (0x06, 0x08), (0x06, 0x01), (0x01, 0x22), (0x27, 0x03)]


@cache
def _capture(name: str) -> bytes:
    return shared_file(name).read_bytes()


@cache
def _real_frames() -> tuple[Frame, ...]:
    names = ["ubx/gpsd_ublox-neo-m8t.log", "ubx/pyublox_6P-raw-PPP-2.ubx", "ubx/pyubx2_pygpsdata-ALL.log",
             "ubx/rtklib_ubx_20080526.ubx"]
    return tuple(f for n in names for f in iter_frames(_capture(n), frozenset({Protocol.UBX})))


def _decode_all(data: bytes, chunk: int) -> tuple[list[Frame], DecodeStats]:
    frames: list[Frame] = []
    stats = DecodeStats()
    chunks = [data[i : i + chunk] for i in range(0, len(data), chunk)]
    list(iter_decoded(chunks, stats, on_frame=frames.append))
    return frames, stats


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=4000), st.integers(1, 700))
def test_random_bytes_never_raise(data: bytes, chunk: int) -> None:
    frames, stats = _decode_all(data, chunk)
    assert stats.frames == sum(f.protocol is Protocol.UBX for f in frames)
    assert stats.decoded + stats.ignored + stats.failures == stats.frames


@settings(max_examples=400, deadline=None)
@given(st.sampled_from(KNOWN_IDS), st.binary(max_size=600))
def test_random_payloads_of_known_messages_never_raise(ids: tuple[int, int], payload: bytes) -> None:
    """A checksum-valid frame with any payload: None or one of our types, counted either way."""
    (frame,) = iter_frames(ubx_frame(ids[0], ids[1], payload))
    stats = DecodeStats()
    decode_frame(frame, stats)
    assert stats.frames == 1 and stats.decoded + stats.ignored + stats.failures == 1


@settings(max_examples=150, deadline=None)
@given(st.sampled_from(KNOWN_IDS), st.integers(0, 6), st.data())
def test_real_frames_with_bytes_flipped_never_raise(ids: tuple[int, int], n_flips: int, data: st.DataObject) -> None:
    """Real payloads with a few bytes changed (checksum recomputed, so the decoder sees them)."""
    frame = data.draw(st.sampled_from(_real_frames()))
    payload = bytearray(frame.payload)
    for _ in range(n_flips if payload else 0):
        payload[data.draw(st.integers(0, len(payload) - 1))] = data.draw(st.integers(0, 255))
    (damaged,) = iter_frames(ubx_frame(frame.msg_class, frame.msg_id, bytes(payload)))
    stats = DecodeStats()
    decode_frame(damaged, stats)
    assert stats.decoded + stats.ignored + stats.failures == 1


DAMAGE = st.sampled_from(["replace", "insert", "delete", "truncate"])


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from(["ubx/gpsd_ublox-neo-m8t.log", "ubx/pyublox_6P-raw-PPP-2.ubx"]), DAMAGE,
       st.integers(0, 10**9), st.binary(min_size=1, max_size=300), st.integers(1, 4096))
@pytest.mark.slow
def test_damaged_capture_resynchronises(name: str, kind: str, where: int, junk: bytes, chunk: int) -> None:
    """Corrupting, inserting, deleting or cutting bytes loses at most the frames the damage touches: every
    original frame wholly before or wholly after the damaged span is still framed and decoded identically."""
    original = _capture(name)
    ref_frames = StreamFramer().feed(original)
    pos = where % len(original)
    if kind == "replace":
        end = min(len(original), pos + len(junk))
        damaged = original[:pos] + junk[: end - pos] + original[end:]
        shift = 0
    elif kind == "insert":
        end = pos
        damaged = original[:pos] + junk + original[pos:]
        shift = len(junk)
    elif kind == "delete":
        end = min(len(original), pos + len(junk))
        damaged = original[:pos] + original[end:]
        shift = pos - end
    else:
        end = len(original)
        damaged = original[:pos]
        shift = 0
    frames, _stats = _decode_all(damaged, chunk)
    got = {(f.offset, f.raw) for f in frames}
    for f in ref_frames:
        before = f.offset + len(f.raw) <= pos
        after = f.offset >= end and kind != "truncate"
        if before:
            assert (f.offset, f.raw) in got
        elif after:
            assert (f.offset + shift, f.raw) in got, f"frame at {f.offset} lost after {kind} at {pos}"
    # and they decode to the same things
    for f in frames[-3:]:
        ref = next((r for r in ref_frames if r.raw == f.raw), None)
        if ref is not None:
            a, b = decode_frame(f), decode_frame(ref)
            assert type(a) is type(b)
