"""Real-time RTK on every constellation the receiver tracks: the engine's systems from the receiver kind and
`receiver.gnss`, the real M8P rover (UBX: RXM-RAWX of GPS + GLONASS + QZSS, RXM-SFRBX) and its base's lossy RTCM3
stream (1077 + 1087 per epoch, a third of the messages lost) replayed through the live service over a real pty.

Truth of the static rover: the mean of 1121 M8P RTK-fixed epochs in the base's frame (README of the data set).
"""

from __future__ import annotations

import collections
import gzip
import itertools
import os
import time
import tty
from pathlib import Path

import numpy as np
import pytest

from onboard.formats.pos import read_pos
from onboard.gnsstime import GpsTime
from onboard.hw.fake import FakeByteStream
from onboard.hw.serial_port import SerialByteStream
from onboard.realtime.service import SOLUTION_NAME, BaseStream, RtkFeature, RtkServiceOptions
from onboard.receiver.decode import DecodeStats, decode_frame
from onboard.receiver.framing import Frame, iter_frames
from onboard.receiver.profiles import rtk_systems
from onboard.receiver.rtcm import RtcmDecoder
from onboard.rtk.types import GNSS_GLONASS, GNSS_GPS, Q_FIX, ObsEpoch
from tests.conftest import shared_file
from tests.daemon.helpers import wait_until

M8P = "gnss/ublox-m8p-galway-2018"
ROVER_TRUTH_ECEF_M = np.array([3774088.9931, -601661.8217, 5089321.3853])
RXM_RAWX = (0x02, 0x15)
TOLERANCE_S = 0.025


def test_engine_systems_follow_the_receiver_kind_and_its_gnss_setting() -> None:
    assert rtk_systems("RXM-RAWX", "GPS,GLONASS,Galileo,QZSS") == "GREJ"  # the shipped receiver.gnss
    assert rtk_systems("RXM-RAWX", "GPS, QZSS, BeiDou, GLONASS") == "GRCJ"  # RINEX order, spaces allowed
    assert rtk_systems("RXM-RAWX", "GLONASS,Galileo,SBAS") == "RE"  # SBAS: not for RTK
    for gnss in ("GPS,GLONASS,Galileo,QZSS", "GLONASS,BeiDou", ""):
        assert rtk_systems("RXM-RAW", gnss) == "G"  # the LEA-6T has GPS alone, whatever the setting
    with pytest.raises(ValueError, match="names none"):
        rtk_systems("RXM-RAWX", "SBAS,IMES")
    with pytest.raises(ValueError, match="raw_message"):
        rtk_systems("NAV-PVT", "GPS")


def test_the_composition_root_derives_them_unless_rtk_engine_systems_is_set(tmp_path) -> None:
    from onboard.recorder.app import recorder_for, rtk_receiver_systems
    from onboard.recorder.daemon import RecorderDeps
    from onboard.recorder.settings import default_config_path, load_settings

    base = {"rtk.base_stream": "tcp://127.0.0.1:9", "journal.data_dir": str(tmp_path)}
    shipped = load_settings(default_config_path(), environ={}, overrides=base)
    assert rtk_receiver_systems(shipped) == {"RXM-RAW": "G", "RXM-RAWX": "GREJ"}
    (feature,) = recorder_for(shipped, RecorderDeps(open_port=lambda: FakeByteStream(0.02)),
                              shipped.rtk_base_stream).features
    assert isinstance(feature, RtkFeature)
    assert feature.rtk.options.receiver_systems == {"RXM-RAW": "G", "RXM-RAWX": "GREJ"}
    beidou = load_settings(default_config_path(), environ={}, overrides={
        **base, "receiver.gnss": "GPS,BeiDou,QZSS"})
    assert rtk_receiver_systems(beidou) == {"RXM-RAW": "G", "RXM-RAWX": "GCJ"}
    explicit = load_settings(default_config_path(), environ={}, overrides={**base, "rtk.engine.systems": "GR"})
    assert rtk_receiver_systems(explicit) == {}  # the engine's own systems, whatever the receiver
    (feature,) = recorder_for(explicit, RecorderDeps(open_port=lambda: FakeByteStream(0.02)),
                              explicit.rtk_base_stream).features
    assert isinstance(feature, RtkFeature) and feature.rtk.engine_options.systems == "GR"


def _rover_frames() -> list[Frame]:
    return list(iter_frames(gzip.decompress(shared_file(f"{M8P}/raw/rover-20181004-1237.ubx.gz").read_bytes())))


def _base_bytes() -> bytes:
    return gzip.decompress(shared_file(f"{M8P}/rtcm3/base-20181004-1236.rtcm3.gz").read_bytes())


def _rover_epoch_times(frames: list[Frame]) -> list[GpsTime]:
    stats = DecodeStats()
    return [e.time for f in frames if (f.msg_class, f.msg_id) == RXM_RAWX
            and isinstance(e := decode_frame(f, stats), ObsEpoch)]


def _timed_base_frames(reference: GpsTime) -> list[tuple[GpsTime | None, bytes]]:
    """The base stream's frames in order, each with the time of its observations (None: not an observation)."""
    decoder = RtcmDecoder()
    out: list[tuple[GpsTime | None, bytes]] = []
    for f in iter_frames(_base_bytes()):
        item = decoder.decode(f, reference)
        out.append((item.time if isinstance(item, ObsEpoch) else None, f.raw))
    return out


def _frames_until(base: list[tuple[GpsTime | None, bytes]], start: int, t: GpsTime) -> int:
    """Index after the base frames that can serve rover time `t` (observations up to t + tolerance), from `start`."""
    limit = t.add_s(TOLERANCE_S)
    while start < len(base) and (base[start][0] is None or base[start][0] <= limit):
        start += 1
    return start


@pytest.mark.slow
def test_split_base_epochs_are_reassembled_and_each_rover_epoch_gets_a_whole_one() -> None:
    """The real base stream through the service's BaseStream, each frame fed before the first rover epoch it can
    serve (as the radio delivers it): each 1077 (multiple-message bit set) and its 1087 make one epoch; a
    GLONASS-only or GPS-only epoch (one message lost) is never paired with a GPS + GLONASS engine, which takes the
    whole epoch before; a GPS-only engine takes every epoch with GPS, as before."""
    rover_times = _rover_epoch_times(_rover_frames())
    base = _timed_base_frames(rover_times[0])
    every = BaseStream(buffer_epochs=100_000)
    every.feed(b"".join(raw for _, raw in base), rover_times[0])
    kinds = collections.Counter(tuple(sorted(e.systems)) for e in every.candidates())
    both, glo_only, gps_only = kinds[(GNSS_GPS, GNSS_GLONASS)], kinds[(GNSS_GLONASS,)], kinds[(GNSS_GPS,)]
    counts = f"base epochs: {both} GPS+GLONASS, {glo_only} GLONASS-only, {gps_only} GPS-only"
    assert (both, glo_only, gps_only) == (410, 213, 197), counts
    gr, g = frozenset({GNSS_GPS, GNSS_GLONASS}), frozenset({GNSS_GPS})
    bs, n = BaseStream(), 0  # the service's buffer (30 epochs)
    ages_gr, ages_g, older = [], [], 0
    for t in rover_times:
        k = _frames_until(base, n, t)
        bs.feed(b"".join(raw for _, raw in base[n:k]), t)
        n = k
        whole, gps = bs.pair(t, TOLERANCE_S, gr), bs.pair(t, TOLERANCE_S, g)
        assert whole is not None and gps is not None
        assert whole.systems() == gr and gps.systems() == g, t  # never half an epoch
        ages_gr.append(t.diff_s(whole.time))
        ages_g.append(t.diff_s(gps.time))
        older += whole.time < gps.time
    summary = (f"{counts}; {len(rover_times)} rover epochs: GPS+GLONASS base age mean {np.mean(ages_gr):.2f} s "
               f"max {max(ages_gr):.2f} s, GPS base age mean {np.mean(ages_g):.2f} s max {max(ages_g):.2f} s, "
               f"{older} rover epochs on an older whole epoch than the newest with GPS")
    print(summary)
    assert max(ages_gr) <= 30.0 and np.mean(ages_gr) < 3.0 and older > 300, summary


def _replay(tmp_path: Path, options: RtkServiceOptions, seconds: int) -> tuple[RtkFeature, Path, dict, list]:
    """The rover log's frames through `RtkFeature` (on_frame, then on_decoded, as the recorder's loop calls them),
    its base's RTCM3 through a pty radio, each base frame written before the first rover epoch it can serve."""
    rover = _rover_frames()
    base = _timed_base_frames(_rover_epoch_times(rover)[0])
    master, slave = os.openpty()
    tty.setraw(slave)
    radio_path = os.ttyname(slave)
    feature = RtkFeature(options, lambda: SerialByteStream(radio_path, 115200, 0.02))
    svc = feature.rtk
    flight = tmp_path / "flight"
    flight.mkdir()
    svc.start(flight)
    stats, n_base, epochs, sent = DecodeStats(), 0, 0, 0
    gps_count: dict[int, int] = {}
    try:
        wait_until(lambda: svc.snapshot()["radio_open"], 5, "radio open")
        for frame in rover:
            item = decode_frame(frame, stats)
            if isinstance(item, ObsEpoch):
                if epochs == seconds:
                    break
                k = _frames_until(base, n_base, item.time)
                if k > n_base:
                    chunk = b"".join(raw for _, raw in base[n_base:k])
                    os.write(master, chunk)
                    sent += len(chunk)
                    # the radio thread has read it: the pairing does not depend on the machine's load
                    wait_until(lambda: svc.snapshot()["radio_bytes"] == sent, 10, "base bytes read")  # noqa: B023
                n_base = k
                wait_until(lambda: svc._queue.qsize() < 8, 10, "engine to keep up")
                gps_count[round(item.time.total_ns / 1e9)] = len(item.gps_only())
                epochs += 1
            feature.on_frame(frame)
            if item is not None:
                feature.on_decoded(item)
        # the epochs before the first ephemeris get no solution: done when the queue stays empty and nothing moves
        last: list[int] = []
        wait_until(lambda: svc._queue.qsize() == 0 and last[-3:] == [svc.snapshot()["epochs"]] * 3
                   or last.append(svc.snapshot()["epochs"]) or (time.sleep(0.2) and False), 60, "all epochs done")
    finally:
        snap = svc.snapshot()
        svc.stop()
        os.close(master)
        os.close(slave)
    track = read_pos(flight / SOLUTION_NAME)
    return feature, flight, snap, [gps_count[round(t.total_ns / 1e9)] for t in track.time]  # 1 Hz


@pytest.mark.slow
def test_real_m8p_rover_and_rtcm_base_use_glonass_and_fix(tmp_path) -> None:
    """The M8P rover log and its base's RTCM3, live: the engine runs on the systems the shipped configuration
    gives an RXM-RAWX receiver (GREJ), its GLONASS ephemerides decoded from the rover's RXM-SFRBX, the base's
    split epochs reassembled; the solutions use more satellites than the rover has GPS ones, and fix on the
    surveyed point."""
    from onboard.recorder.app import rtk_receiver_systems
    from onboard.recorder.settings import default_config_path, load_settings

    seconds = 600
    systems = rtk_receiver_systems(load_settings(default_config_path(), environ={}))
    _, flight, snap, n_gps = _replay(tmp_path, RtkServiceOptions(base_wait_s=0.3, receiver_systems=systems),
                                           seconds)
    track = read_pos(flight / SOLUTION_NAME)
    fixed = track.q == Q_FIX
    err_m = np.linalg.norm(track.pos_ecef_m[fixed] - ROVER_TRUTH_ECEF_M, axis=1)
    more = int(np.sum(track.ns[fixed] > np.array(n_gps)[fixed]))
    summary = (f"systems {snap['systems']}, {len(track.q)} solutions, {int(fixed.sum())} fixed, ttff "
               f"{snap['ttff_s']} s, ns mean {track.ns.mean():.1f} vs GPS satellites of the rover "
               f"{np.mean(n_gps):.1f}; {more} fixed epochs with more satellites than GPS alone has; fixed error "
               f"median {np.median(err_m) * 100:.1f} cm, max {err_m.max() * 100:.1f} cm; base ephemerides "
               f"{snap['base_ephemerides']}, last base epoch {snap['base_systems']}")
    print(summary)
    assert snap["systems"] == "GREJ" and snap["errors"] == 0 and snap["dropped_epochs"] == 0, summary
    assert snap["base_systems"] == "GR", summary  # whole epochs only: GPS and GLONASS
    first = int(np.argmax(fixed))
    after = float(fixed[first:].mean())
    runs = [(int(q), len(list(g))) for q, g in itertools.groupby(track.q)]
    summary += (f"; {after:.1%} fixed after the first fix; runs (Q, epochs) {runs}; base position "
                f"{snap['base_position_check']}")
    # a cold start: GPS ephemerides from the rover's subframes (~30 s), the base position checked, a stable
    # integer set before the first fix; then fixed throughout
    assert len(track.q) >= seconds - 60 and snap["ttff_s"] < 120.0 and after >= 0.9, summary
    assert fixed[-300:].all(), summary
    assert snap["base_position_check"].startswith("ok"), summary
    assert more >= 0.9 * fixed.sum(), summary  # GLONASS satellites in the solutions
    assert np.median(err_m) < 0.02 and err_m.max() < 0.10, summary


def test_base_stream_takes_every_constellations_ephemerides_and_epochs_from_rtcm() -> None:
    """A real NTRIP capture (MSM7 of GPS, GLONASS, Galileo, BeiDou with 1019/1020/1042/1046) in radio-sized
    pieces: every ephemeris decoded, the non-GPS ones for Nav.broadcast, and whole four-system epochs paired."""
    from onboard.realtime.service import _add_ephemeris
    from onboard.rtk.ephemeris import EphemerisStore
    from onboard.rtk.navstore import BroadcastNavigation, sat_key
    from onboard.rtk.rtkpos import Nav
    from onboard.rtk.types import GNSS_BEIDOU, GNSS_GALILEO

    data = shared_file("rtcm/pygnssutils_ntrip_encode_none.bin").read_bytes()
    bs = BaseStream()
    bs.leap_s = 18
    reference = GpsTime(2328, 79_200 * 10**9)  # the week and toe of its 1019 (tests/gnss_nav/test_rtcm_nav.py)
    for k in range(0, len(data), 700):
        bs.feed(data[k:k + 700], reference)
    by_system = collections.Counter(sat_key(e)[0] for e in bs.ephemerides)
    assert by_system == {GNSS_GPS: 33, GNSS_GLONASS: 33, GNSS_GALILEO: 33, GNSS_BEIDOU: 33} and bs.nav_errors == 0
    nav = Nav(EphemerisStore(), None, BroadcastNavigation())
    for eph in bs.ephemerides:
        _add_ephemeris(nav, eph)
    assert nav.broadcast is not None
    distinct = collections.Counter(sat_key(e)[0] == GNSS_GPS for e in set(bs.ephemerides))  # a base repeats them
    assert len(nav.store) == distinct[True] and len(nav.broadcast) == distinct[False] > 0, distinct  # GPS: store
    four = frozenset({GNSS_GPS, GNSS_GLONASS, GNSS_GALILEO, GNSS_BEIDOU})
    assert {e.systems for e in bs.candidates()} == {four}
    last = bs.candidates()[-1].time
    paired = bs.pair(last, TOLERANCE_S, four | {5})  # QZSS: the engine's, not sent by this base
    assert paired is not None and paired.time == last and paired.systems() == four
