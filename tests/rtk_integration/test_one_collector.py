"""One RTCM→epoch collector: the real-time BaseStream and post-processing (`collect_rtcm`) give the same base
epochs, position and ephemerides on the same bytes: the real lossy M8P radio streams of ../shared, fed to the
real-time path in radio-sized chunks."""

from __future__ import annotations

import dataclasses
import gzip
import random
from pathlib import Path

import numpy as np
import pytest

from onboard.gnsstime import GpsTime
from onboard.realtime.service import BaseStream
from onboard.receiver.base_epochs import collect_rtcm
from onboard.receiver.decode import iter_file
from onboard.rtk.types import ObsEpoch
from tests.conftest import SHARED_DATA

STREAMS = sorted(SHARED_DATA.glob("gnss/*/rtcm3/*.rtcm3.gz"))


def _rover_reference(stream: Path) -> GpsTime:
    """The week reference the rover gives both paths: the first raw epoch of the data set's rover log."""
    rovers = sorted((stream.parent.parent / "raw").glob("rover-*.ubx.gz"))
    assert rovers, f"{stream}: no rover log beside it to take the GPS week from"
    return next(item.time for item in iter_file(rovers[0]) if isinstance(item, ObsEpoch))


def _assert_same_epoch(a: ObsEpoch, b: ObsEpoch) -> None:
    assert a.time == b.time
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray):
            np.testing.assert_array_equal(x, y, err_msg=f"{a.time} {f.name}")  # NaN equals NaN here
        else:
            assert x == y, (a.time, f.name)


@pytest.mark.slow
@pytest.mark.skipif(not STREAMS, reason="../shared/data/gnss/*/rtcm3/*.rtcm3.gz (real radio streams) not on this machine")
@pytest.mark.parametrize("stream", STREAMS, ids=[p.name for p in STREAMS])
def test_real_time_and_post_processing_collect_the_same_base_epochs(stream: Path) -> None:
    data = gzip.decompress(stream.read_bytes())
    reference = _rover_reference(stream)
    post = collect_rtcm([data], reference)
    assert len(post.epochs) > 100  # a real stream with its losses (merged MSM/legacy messages, gaps)

    rng = random.Random(stream.name)
    live = BaseStream(buffer_epochs=len(post.gnss_epochs) + 1)  # keep them all, to compare every one
    pos = 0
    while pos < len(data):
        n = rng.randint(1, 600)  # what a telemetry radio hands over per read
        live.feed(data[pos:pos + n], reference)
        pos += n

    # every system's epochs, reassembled the same (the last one still open in real time: the stream goes on)
    whole = live.candidates()
    assert live.epoch_count == len(post.epochs) and len(whole) == len(post.gnss_epochs)
    for a, b in zip(whole, post.gnss_epochs):
        _assert_same_epoch(a.obs, b.obs)
        assert (a.messages, a.complete) == (b.messages, b.complete), a.time
    assert live.position == post.base_position
    assert live.ephemerides == post.ephemerides
    assert [e.time for e in whole] == sorted({e.time for e in whole})  # strictly in time order


def test_one_lnav_dispatch_for_both_subframe_forms_and_only_gps() -> None:
    """`ephemeris_from_subframe` (used by real time, the base station and convert): RXM-SFRBX 30-bit words and
    RXM-SFRB 24-bit data words of the same subframes give the same ephemeris; another system's subframe gives
    None and leaves the assembler alone."""
    from onboard.formats.rinex_nav import read_rinex_nav
    from onboard.receiver.decode import SubframeWords, ephemeris_from_subframe
    from onboard.rtk.lnav import LnavAssembler, encode_subframes, sfrbx_words24
    from onboard.rtk.types import GNSS_GLONASS
    from tests.conftest import shared_file

    eph = read_rinex_nav(shared_file("gnss/broadcast-nav-20100701/brdc1820.10n")).ephemerides[0]
    tow_s = float(int(eph.toe.tow_s) // 30 * 30)  # a frame start at the ephemeris' reference time
    dwords = encode_subframes(eph, tow_s)
    words24 = [sfrbx_words24(d)[0] for d in dwords]
    results = []
    for words, bits in ((dwords, 30), (words24, 24)):
        assembler = LnavAssembler()
        other = ephemeris_from_subframe(assembler, SubframeWords(eph.prn, tuple(words[0]), bits, "x", GNSS_GLONASS),
                                        eph.toe.week)
        assert other is None and assembler.rejected == assembler.parity_failures == 0
        got = [ephemeris_from_subframe(assembler, SubframeWords(eph.prn, tuple(w), bits, "x"), eph.toe.week)
               for w in words]
        assert got[0] is None and got[1] is None and got[2] is not None
        results.append(got[2])
    reference = LnavAssembler()
    expected = [reference.add(eph.prn, w, eph.toe.week) for w in dwords][2]
    assert results[0] == results[1] == expected
    assert results[0].prn == eph.prn and results[0].toe == eph.toe
