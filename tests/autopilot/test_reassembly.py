"""GPS_RTCM_DATA reassembly: 180·k-byte messages, lost and reordered fragments, sequence wrap — a message is
delivered whole or lost, never wrong."""

from __future__ import annotations

import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from onboard.autopilot.rtcm_reassembly import (
    FRAGMENT_DATA_BYTES,
    GpsRtcmReassembler,
    fragment_rtcm,
    make_flags,
    split_flags,
)
from onboard.receiver.framing import Protocol, StreamFramer
from tests.autopilot.rtcm_frames import rtcm_frame


def feed_all(r: GpsRtcmReassembler, fragments: list[tuple[int, bytes]]) -> list[bytes]:
    out: list[bytes] = []
    for flags, data in fragments:
        out += r.feed(flags, data)
    return out


def test_flags_layout() -> None:
    assert make_flags(True, 2, 17) == 1 | (2 << 1) | (17 << 3)
    assert split_flags(make_flags(True, 3, 31)) == (True, 3, 31)
    assert split_flags(make_flags(False, 0, 5)) == (False, 0, 5)
    with pytest.raises(ValueError, match="fragment id 4"):
        make_flags(True, 4, 0)


@pytest.mark.parametrize("size", [10, 179])
def test_short_message_unfragmented(size: int) -> None:
    msg = rtcm_frame(size, size) if size >= 8 else bytes(size)
    frags = fragment_rtcm(msg, 3)
    assert frags == [(make_flags(False, 0, 3), msg)]
    r = GpsRtcmReassembler()
    assert feed_all(r, frags) == [msg]


@pytest.mark.parametrize("k", [1, 2, 3])
def test_180k_message_ends_with_empty_fragment(k: int) -> None:
    msg = rtcm_frame(FRAGMENT_DATA_BYTES * k, k)
    frags = fragment_rtcm(msg, 9)
    assert len(frags) == k + 1 and frags[-1][1] == b""
    assert all(split_flags(f)[0] for f, _ in frags)
    r = GpsRtcmReassembler()
    assert feed_all(r, frags[:-1]) == []  # not complete before the empty fragment
    assert r.feed(*frags[-1]) == [msg]
    assert r.stats.messages == 1 and r.stats.dropped == 0


def test_180k_message_without_empty_fragment_is_lost_not_wrong() -> None:
    """A sender that leaves out the empty fragment (Rpanion): the message cannot be told complete; it is
    dropped when the next sequence starts, and the next message still comes through."""
    first, second = rtcm_frame(360, 1), rtcm_frame(100, 2)
    r = GpsRtcmReassembler()
    assert feed_all(r, fragment_rtcm(first, 0)[:-1]) == []
    assert feed_all(r, fragment_rtcm(second, 1)) == [second]
    assert r.stats.dropped == 1


def test_720_byte_message_has_four_fragments_and_no_empty_one() -> None:
    msg = rtcm_frame(720, 7)
    frags = fragment_rtcm(msg, 30)
    assert [len(d) for _, d in frags] == [180] * 4
    assert feed_all(GpsRtcmReassembler(), frags) == [msg]
    with pytest.raises(ValueError, match="at most 720"):
        fragment_rtcm(bytes(721), 0)


def test_dropped_middle_fragment_loses_only_that_message() -> None:
    a, b, c = rtcm_frame(500, 1), rtcm_frame(400, 2), rtcm_frame(200, 3)
    fa, fb, fc = fragment_rtcm(a, 0), fragment_rtcm(b, 1), fragment_rtcm(c, 2)
    r = GpsRtcmReassembler()
    out = feed_all(r, fa + [fb[0], fb[2]] + fc)
    assert out == [a, c]
    assert r.stats.dropped == 1


def test_dropped_last_fragment_never_completes_with_the_next_message() -> None:
    """Same sequence id after a wrap cannot glue two messages: each new id resets."""
    a = rtcm_frame(300, 1)
    fa = fragment_rtcm(a, 4)
    r = GpsRtcmReassembler()
    assert feed_all(r, fa[:1]) == []
    others = [rtcm_frame(100 + i, 10 + i) for i in range(32)]
    out = []
    for i, m in enumerate(others):
        out += feed_all(r, fragment_rtcm(m, 5 + i))
    # id 4 comes round again (i = 31) with a short message: delivered alone, fragment 0 of `a` is long gone
    assert out == others
    assert r.stats.dropped == 1


def test_reordered_fragments_within_a_message() -> None:
    msg = rtcm_frame(700, 5)
    frags = fragment_rtcm(msg, 12)
    r = GpsRtcmReassembler()
    assert feed_all(r, [frags[2], frags[0], frags[3], frags[1]]) == [msg]


def test_repeated_fragment_restarts_the_message() -> None:
    """A sequence id reused by another message (lost messages between): the duplicate fragment id shows it;
    the old part is dropped, the new message is assembled from its own fragments only."""
    a, b = rtcm_frame(300, 1), rtcm_frame(250, 2)
    fa, fb = fragment_rtcm(a, 6), fragment_rtcm(b, 6)
    r = GpsRtcmReassembler()
    assert feed_all(r, [fa[0]] + fb) == [b]
    assert r.stats.dropped == 1


def test_short_fragment_before_the_last_is_rejected() -> None:
    r = GpsRtcmReassembler()
    assert r.feed(make_flags(True, 2, 1), bytes(180)) == []
    assert r.feed(make_flags(True, 1, 1), bytes(50)) == []  # short id 1 yet id 2 exists: mixed
    assert r.feed(make_flags(True, 0, 1), bytes(180)) == []
    assert r.stats.messages == 0 and r.stats.dropped == 1


def test_sequence_wrap() -> None:
    msgs = [rtcm_frame(200 + 7 * i, i) for i in range(70)]
    r = GpsRtcmReassembler()
    out = []
    for i, m in enumerate(msgs):
        out += feed_all(r, fragment_rtcm(m, i))  # fragment_rtcm takes the id mod 32
    assert out == msgs


@settings(max_examples=60, deadline=None)
@given(sizes=st.lists(st.integers(min_value=8, max_value=720), min_size=1, max_size=40),
       drop=st.floats(min_value=0.0, max_value=0.5), seed=st.integers(0, 2**16), reorder=st.booleans())
def test_lossy_link_delivers_only_whole_messages(sizes: list[int], drop: float, seed: int, reorder: bool) -> None:
    """Random sizes, random fragment loss, optional reordering inside each message: the output is exactly the
    messages whose every fragment arrived, in order, each CRC-valid — never a partial or mixed one."""
    rng = random.Random(seed)
    msgs = [rtcm_frame(n, seed + i) for i, n in enumerate(sizes)]
    r = GpsRtcmReassembler()
    intact, out = [], []
    for i, m in enumerate(msgs):
        frags = fragment_rtcm(m, i)
        kept = [f for f in frags if rng.random() >= drop]
        if len(kept) == len(frags):
            intact.append(m)
        if reorder:
            rng.shuffle(kept)
        out += feed_all(r, kept)
    assert out == intact
    framer = StreamFramer()
    frames = framer.feed(b"".join(out))
    assert [bytes(f.raw) for f in frames if f.protocol is Protocol.RTCM3] == intact
    assert framer.skipped_bytes == 0
