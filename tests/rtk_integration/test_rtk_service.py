"""Real-time RTK service: hil_sim rover epochs in, base RTCM3 through a real pty radio with 15-20 s gaps.

Truth is the simulator's World. A wrong fix is Q=1 more than 10 cm (3D) from the true antenna position.
"""

from __future__ import annotations

import os
import time
import tty
from pathlib import Path

import numpy as np
import pytest

from onboard.base.station import BaseCore, BaseOptions
from onboard.errors import LinkLost
from onboard.formats.pos import read_pos
from onboard.hw.fake import FakeByteStream
from onboard.hw.serial_port import SerialByteStream
from onboard.logger.journal import iter_journal_bytes
from onboard.postpro.inputs import read_base_observations
from onboard.realtime.service import RADIO_DIR, SOLUTION_NAME, BaseStream, RtkService, RtkServiceOptions
from onboard.receiver.decode import DecodeStats, decode_frame
from onboard.receiver.framing import iter_frames
from onboard.rtk.types import GNSS_GPS, Q_FIX, Q_FLOAT, Q_SINGLE
from tests.conftest import shared_file
from tests.daemon.helpers import wait_until

pytestmark = [pytest.mark.timeout(120)]
GAPS_S = [(70, 85), (150, 170)]  # radio dropouts (s after start): 15 s and 20 s
DURATION_S = 240


@pytest.fixture(scope="module")
def world():
    shared_file("gnss/broadcast-nav-20100701/brdc1820.10n")
    from hil_sim.scenario import Scenario
    from hil_sim.world import World

    return World(Scenario.default("m8t", duration_s=DURATION_S + 60.0))


def _base_frames(world, seconds: int, announced_ecef_m: tuple[float, ...] | None = None) -> list[bytes]:
    """What `onboard base` would send each second (1004 + 1006 + 1019), from the world's base receiver;
    `announced_ecef_m` the position its 1006 announces (default the true one)."""
    position = tuple(world.base_ecef_m) if announced_ecef_m is None else announced_ecef_m
    core = BaseCore(BaseOptions(station_id=1, position_ecef_m=position, radio_budget_bytes_s=2000.0))
    for eph in world.ephemerides():
        core.on_item(eph)
    t0 = world.scenario.start
    return [b"".join(f for _, f in core.on_item(world.observe("base", t0.add_s(k)))) for k in range(seconds)]


def test_base_stream_decodes_rtcm_and_needs_a_rover_time_for_the_week(world) -> None:
    frames = _base_frames(world, 12)
    bs = BaseStream()
    assert bs.feed(frames[0], None) == 0  # no week yet: observations and 1019 skipped, the position is kept
    assert bs.position is not None and bs.ephemerides == []
    np.testing.assert_allclose(bs.position.phase_centre_ecef_m, world.base_ecef_m, atol=1e-3)
    t0 = world.scenario.start
    data = b"".join(frames[1:])
    assert sum(bs.feed(data[k:k + 100], t0) for k in range(0, len(data), 100)) == 11
    # receiver time tags (clock offset included), to the ms of DF004
    tags = [world.observe("base", t0.add_s(k)).time.tow_ns // 1_000_000 for k in range(1, 12)]
    assert [e.time.tow_ns // 1_000_000 for e in bs.epochs] == tags
    gps = frozenset({GNSS_GPS})
    assert bs.pair(t0.add_s(5.5), 0.025, gps).time == bs.epochs[4].time
    bs.feed(frames[0], t0)  # the same 1019s with a week reference: decoded
    assert len(bs.ephemerides) == frames[0].count(b"\xd3\x00\x3d")  # 1019: 61-byte payload
    assert bs.pair(t0, 0.025, gps) is None


def _run_service(world, tmp_path: Path, gaps, options: RtkServiceOptions | None = None,
                 seconds: int = DURATION_S, announced_ecef_m: tuple[float, ...] | None = None,
                 events: list | None = None, encode=None) -> tuple[RtkService, list, Path, dict]:
    """`encode` (ObsEpoch → UBX bytes, e.g. hil_sim's rxm_raw): the rover epochs go in as frames, as the recorder
    hands them over (`submit_frame`, then the decoded item to `submit`); None: the epochs themselves."""
    frames = _base_frames(world, seconds, announced_ecef_m)
    master, slave = os.openpty()
    tty.setraw(slave)
    radio_path = os.ttyname(slave)
    options = options or RtkServiceOptions(base_wait_s=0.3)
    svc = RtkService(options, lambda: SerialByteStream(radio_path, 57600, 0.02),
                     on_event=None if events is None else events.append)
    flight = tmp_path / "flight"
    flight.mkdir()
    svc.start(flight)
    t0 = world.scenario.start
    stats = DecodeStats()

    def submit_rover(epoch) -> None:  # type: ignore[no-untyped-def]
        if encode is None:
            svc.submit(epoch)
            return
        for frame in iter_frames(encode(epoch)):
            svc.submit_frame(frame)
            item = decode_frame(frame, stats)
            if item is not None:
                svc.submit(item)

    for eph in world.ephemerides():
        svc.submit(eph)
    sent = bytearray()
    ages: dict[int, float | None] = {}
    try:
        wait_until(lambda: svc.snapshot()["radio_open"], 5, "radio open")
        for k in range(seconds):
            if not any(a <= k < b for a, b in gaps):
                os.write(master, frames[k])
                sent += frames[k]
            wait_until(lambda: svc._queue.qsize() < 8, 10, "engine to keep up")
            submit_rover(world.observe("rover", t0.add_s(k)))
            if any(a <= k < b for a, b in gaps):
                wait_until(lambda: svc.snapshot()["epochs"] == k + 1, 10, "gap epoch solved")  # noqa: B023
                ages[k] = svc.snapshot()["age_s"]
        wait_until(lambda: svc.snapshot()["epochs"] == seconds, 30, "all epochs solved")
    finally:
        svc.stop()
        os.close(master)
        os.close(slave)
    return svc, list(sent), flight, ages


@pytest.mark.slow
def test_radio_gaps_degrade_without_wrong_fixes_and_fix_again_after(world, tmp_path) -> None:
    svc, sent, flight, ages = _run_service(world, tmp_path, GAPS_S)
    track = read_pos(flight / SOLUTION_NAME)
    assert len(track.q) == DURATION_S
    t0 = world.scenario.start
    k_of = [round(t.diff_s(t0)) for t in track.time]
    err = np.array([np.linalg.norm(p - world.truth(t)["antenna_ecef_m"]) for t, p in zip(track.time, track.pos_ecef_m)])
    wrong = [(k, e) for k, q, e in zip(k_of, track.q, err) if q == Q_FIX and e > 0.10]
    assert wrong == []
    for a, b in GAPS_S:
        # corrections up to 30 s old are still used, carried forward: float or the held fix, never single
        in_gap = [q for k, q in zip(k_of, track.q) if a <= k < b]
        assert len(in_gap) == b - a and set(in_gap) <= {Q_FIX, Q_FLOAT}
        assert in_gap.count(Q_FIX) >= len(in_gap) - 2, in_gap
        # rtk.json shows the age of corrections growing through the gap (1 s base interval)
        assert [round(ages[k]) for k in range(a, b)] == list(range(1, b - a + 1))
        after = [q for k, q in zip(k_of, track.q) if b <= k < b + 20]
        assert Q_FIX in after, f"no fix again within 20 s after the gap ending at {b} s"
    snap = svc.snapshot()
    assert snap["fixed"] == int(np.sum(track.q == Q_FIX)) and snap["ttff_s"] is not None
    assert snap["dropped_epochs"] == 0 and snap["errors"] == 0
    assert snap["baseline_m"] is not None and snap["baseline_m"] > 100.0  # the flight is ~1 km from the base
    # the radio journal holds every byte the radio delivered, in order, and the ground can re-process it
    assert b"".join(iter_journal_bytes(flight / RADIO_DIR)) == bytes(sent)
    again = read_base_observations(flight / RADIO_DIR, t0)
    assert again.kind == "rtcm3" and len(again.epochs) == DURATION_S - sum(b - a for a, b in GAPS_S)
    np.testing.assert_allclose(again.antenna_pos_ecef_m, world.base_ecef_m, atol=1e-3)


@pytest.mark.slow
def test_an_rxm_raw_rover_stays_gps_only_whatever_receiver_gnss_says(world, tmp_path) -> None:
    """The LEA-6T path: with the systems the shipped configuration derives (GREJ for an RXM-RAWX receiver), a
    rover sending RXM-RAW runs the GPS engine, with the same options as without any derivation; it fixes."""
    from hil_sim.ubx_encode import rxm_raw
    from onboard.recorder.app import rtk_receiver_systems
    from onboard.recorder.settings import default_config_path, load_settings

    derived = rtk_receiver_systems(load_settings(default_config_path(), environ={}))
    assert derived["RXM-RAWX"] == "GREJ"
    runs = []
    for name, receiver_systems in (("derived", derived), ("plain", {})):
        (tmp_path / name).mkdir()
        svc, *_ = _run_service(world, tmp_path / name, [], RtkServiceOptions(
            base_wait_s=0.3, receiver_systems=receiver_systems), seconds=60, encode=rxm_raw)
        assert svc.snapshot()["systems"] == "G" and svc.engine_options.systems == "G"
        runs.append(svc.engine_options)
    assert runs[0] == runs[1]
    track = read_pos(tmp_path / "derived" / "flight" / SOLUTION_NAME)
    err = np.array([np.linalg.norm(p - world.truth(t)["antenna_ecef_m"]) for t, p in zip(track.time, track.pos_ecef_m)])
    assert len(track.q) == 60 and np.sum(track.q == Q_FIX) >= 30 and not np.any((track.q == Q_FIX) & (err > 0.10))


def test_a_surveyed_take_off_point_fixes_the_first_epoch(world, tmp_path) -> None:
    """rtk.takeoff_position: the real-time engine starts static on the surveyed antenna position and fixes at
    the first epoch with corrections (a cold start on this flight fixes after 9 s); the solutions are the truth
    to the centimetre. The first epoch or two have none (single): the base stream's first 1004 comes before any
    rover time gives it its GPS week (see the test above), and the next may race the rover epoch."""
    t0 = world.scenario.start
    takeoff = tuple(float(v) for v in world.truth(t0)["antenna_ecef_m"])
    svc, _, flight, _ = _run_service(world, tmp_path, [], RtkServiceOptions(base_wait_s=0.3,
                                                                            takeoff_position_ecef_m=takeoff), 20)
    track = read_pos(flight / SOLUTION_NAME)
    first = int(np.flatnonzero(track.q != Q_SINGLE)[0])  # the first epoch with corrections
    assert len(track.q) == 20 and first <= 3 and np.all(track.q[first:] == Q_FIX)
    err = [np.linalg.norm(p - world.truth(t)["antenna_ecef_m"])
           for t, p in zip(track.time[first:], track.pos_ecef_m[first:])]
    assert max(err) < 0.02
    # fixed by the fourth epoch at the latest, as `first` allows (3.00035 s on the rover's clock-offset tags)
    assert svc.snapshot()["ttff_s"] < 3.5


@pytest.mark.parametrize("offset_m", [0.0, 60.0])
def test_a_wrong_announced_base_position_is_refused_in_real_time(world, tmp_path, offset_m) -> None:
    """The base announces (1006) a position `offset_m` off its antenna: beyond post-processing's bound (30 m)
    it is refused as post-processing refuses it (same check): no epoch is differenced against it (all single),
    rtk.json says so, an event names it. The true position passes and fixes."""
    t0 = world.scenario.start
    announced = tuple(float(v) for v in np.asarray(world.base_ecef_m) + np.array([offset_m, 0.0, 0.0]))
    takeoff = tuple(float(v) for v in world.truth(t0)["antenna_ecef_m"])  # a fix from the first epochs if allowed
    events: list = []
    svc, _, flight, _ = _run_service(world, tmp_path, [], RtkServiceOptions(base_wait_s=0.3,
                                                                            takeoff_position_ecef_m=takeoff),
                                     20, announced_ecef_m=announced, events=events)
    track = read_pos(flight / SOLUTION_NAME)
    snap = svc.snapshot()
    assert len(track.q) == 20
    if offset_m == 0.0:
        assert snap["base_position_check"].startswith("ok: ") and events == []
        assert np.sum(track.q == Q_FIX) >= 15
        return
    assert set(track.q.tolist()) == {Q_SINGLE}, track.q  # never a fixed (or float) solution against it
    assert snap["base_position_check"].startswith("rejected: base position 6") and snap["fixed"] == 0
    assert "more than 30 m; check the base position" in snap["base_position_check"]
    (event,) = events
    assert event["event"] == "base_position_rejected" and 55.0 < event["offset_m"] < 65.0
    assert event["bound_m"] == 30.0


def test_submit_never_blocks_and_counts_drops(world, tmp_path) -> None:
    svc = RtkService(RtkServiceOptions(queue_max_items=2), None)  # not started: nothing drains the queue
    ep = world.observe("rover", world.scenario.start)
    t = time.monotonic()
    results = [svc.submit(ep) for _ in range(500)]
    assert time.monotonic() - t < 0.5
    assert results[:2] == [True, True] and not any(results[2:])
    assert svc.snapshot()["dropped_epochs"] == 498


@pytest.mark.slow
def test_unplugged_radio_is_reopened_and_corrections_resume(world, tmp_path) -> None:
    frames = _base_frames(world, 40)
    streams: list[FakeByteStream] = []
    opens = {"n": 0}

    def open_radio() -> FakeByteStream:
        opens["n"] += 1
        if opens["n"] == 2:
            raise LinkLost("radio unplugged")  # the first reopen fails, the next succeeds
        streams.append(FakeByteStream(0.02))
        return streams[-1]

    svc = RtkService(RtkServiceOptions(base_wait_s=0.3, radio_reopen_s=0.05), open_radio)
    flight = tmp_path / "f"
    flight.mkdir()
    svc.start(flight)
    t0 = world.scenario.start
    for eph in world.ephemerides():
        svc.submit(eph)
    try:
        for k in range(40):
            if k == 15:
                streams[-1].unplug()
                wait_until(lambda: len(streams) == 2, 5, "radio reopened")
                assert opens["n"] == 3
            streams[-1].feed(frames[k])
            svc.submit(world.observe("rover", t0.add_s(k)))
            wait_until(lambda: svc.snapshot()["epochs"] == k + 1, 10, "epoch solved")  # noqa: B023
    finally:
        svc.stop()
    snap = svc.snapshot()
    assert snap["base_epochs"] >= 38 and snap["radio_open"] is False
    track = read_pos(flight / SOLUTION_NAME)
    assert np.sum(track.q == Q_FLOAT) + np.sum(track.q == Q_FIX) >= 35


def test_ubx_relay_from_the_base_decodes_to_the_base_epochs(world) -> None:
    from hil_sim import ubx_encode as enc
    from onboard.receiver.framing import iter_frames

    core = BaseCore(BaseOptions(relay="ubx", radio_budget_bytes_s=1000.0, position_ecef_m=tuple(world.base_ecef_m),
                                position_interval_s=5.0))
    bs = BaseStream()
    t0 = world.scenario.start
    sent = 0
    for k in range(10):
        src = world.observe("base", t0.add_s(k))
        for frame in iter_frames(enc.rxm_rawx(src) + enc.nav_sol(src.time, world.base_ecef_m, np.zeros(3), 8, 2.0, 1.5)):
            for _, raw in core.on_frame(frame, float(k)):  # NAV-SOL is not relayed
                sent += len(raw)
                bs.feed(raw, None)
        ep = bs.epochs[-1]
        assert ep.time == src.time and list(ep.sv_id) == list(src.gps_only().sv_id)
        np.testing.assert_allclose(ep.pr_m, src.gps_only().pr_m, rtol=0, atol=0.01)
        assert core.on_item(src) == []  # decoded items only survey / collect ephemerides in relay mode
    assert bs.epoch_count == 10 and core.scheduler.counts.sent == {"obs": 10, "position": 2}  # 1006 at 0 and 5 s
    assert bs.position is not None
    np.testing.assert_allclose(bs.position.phase_centre_ecef_m, world.base_ecef_m, atol=1e-3)


def test_max_base_age_comes_from_the_settings_and_defaults_to_30_s(tmp_path) -> None:
    from onboard.realtime.service import RtkFeature
    from onboard.recorder.app import recorder_for
    from onboard.recorder.daemon import RecorderDeps
    from onboard.recorder.settings import default_config_path, load_settings

    deps = RecorderDeps(open_port=lambda: FakeByteStream(0.02))
    shipped = load_settings(default_config_path(), environ={})
    assert shipped.rtk_max_base_age_s == 30.0 and RtkServiceOptions().max_base_age_s == 30.0
    settings = load_settings(default_config_path(), environ={}, overrides={
        "rtk.max_base_age_s": 12.5, "rtk.base_stream": "tcp://127.0.0.1:9", "journal.data_dir": str(tmp_path)})
    (feature,) = recorder_for(settings, deps, settings.rtk_base_stream).features
    assert isinstance(feature, RtkFeature)
    assert feature.rtk.options.max_base_age_s == 12.5 and feature.rtk.engine_options.max_age_s == 12.5
    assert feature.rtk.options.takeoff_position_ecef_m is None  # shipped: a cold start


def test_engine_options_come_from_the_rtk_engine_table_and_bad_ones_are_refused(tmp_path) -> None:
    from onboard.realtime.service import RtkFeature
    from onboard.recorder.app import recorder_for
    from onboard.recorder.daemon import RecorderDeps
    from onboard.recorder.settings import ConfigFileError, default_config_path, load_settings

    base = {"rtk.base_stream": "tcp://127.0.0.1:9", "journal.data_dir": str(tmp_path)}
    settings = load_settings(default_config_path(), environ={"ONBOARD_RTK_ENGINE_PARTIAL_AR": "false"}, overrides={
        **base, "rtk.engine.elevation_mask_deg": 20, "rtk.engine.max_first_fix_baseline_km": 4.5})
    (feature,) = recorder_for(settings, RecorderDeps(open_port=lambda: FakeByteStream(0.02)),
                              settings.rtk_base_stream).features
    assert isinstance(feature, RtkFeature)
    engine = feature.rtk.engine_options
    assert (engine.elmask_deg, engine.partial_ar, engine.max_first_fix_baseline_km) == (20.0, False, 4.5)
    assert engine.max_age_s == 30.0  # from rtk.max_base_age_s
    assert feature.rtk.snapshot()["max_first_fix_baseline_km"] == 4.5  # what the pre-flight page reads
    for bad, why in ((("rtk.engine.elevation_mask", 20), "unknown key 'rtk.engine.elevation_mask'"),
                     (("rtk.engine.ratio_threshold", "three"), "rtk.engine.ratio_threshold .three.: must be a number"),
                     (("rtk.engine.ar_mode", "sometimes"), "rtk.engine.ar_mode .sometimes.: ar_mode must be one of"),
                     (("rtk.engine.max_age_s", 10.0), "set rtk.max_base_age_s instead")):
        with pytest.raises(ConfigFileError, match=why):
            load_settings(default_config_path(), environ={}, overrides={**base, bad[0]: bad[1]})


def test_the_shipped_configuration_documents_the_engine_defaults() -> None:
    """The commented `[rtk.engine]` lines of default_config.toml, uncommented, are RtkOptions' defaults and
    name every key but max_age_s (set by rtk.max_base_age_s)."""
    import tomllib

    from onboard.recorder.settings import default_config_path
    from onboard.rtk.options import TOML_KEYS, RtkOptions, options_from_mapping

    text = default_config_path().read_text().split("[rtk.engine]", 1)[1]
    lines = [line[2:] for line in text.splitlines() if line.startswith("# ") and " = " in line]
    documented = tomllib.loads("\n".join(lines))
    assert set(documented) == set(TOML_KEYS) - {"max_age_s"}
    assert options_from_mapping(documented) == RtkOptions()


def test_the_take_off_position_comes_from_the_settings_and_bad_values_are_refused(tmp_path) -> None:
    from onboard.realtime.service import RtkFeature
    from onboard.recorder.app import recorder_for
    from onboard.recorder.daemon import RecorderDeps
    from onboard.recorder.settings import ConfigFileError, default_config_path, load_settings

    base = {"rtk.base_stream": "tcp://127.0.0.1:9", "journal.data_dir": str(tmp_path)}
    settings = load_settings(default_config_path(), environ={}, overrides={
        **base, "rtk.takeoff_position": "4027893.9, 307045.6, 4919475.2"})
    (feature,) = recorder_for(settings, RecorderDeps(open_port=lambda: FakeByteStream(0.02)),
                              settings.rtk_base_stream).features
    assert isinstance(feature, RtkFeature)
    assert feature.rtk.options.takeoff_position_ecef_m == (4027893.9, 307045.6, 4919475.2)
    for bad, why in (("4027893.9,307045.6", "expected X,Y,Z"), ("a,b,c", "expected X,Y,Z"),
                     ("48.85,2.35,35.0", "not near the Earth's surface"), ("nan,0,0", "expected X,Y,Z")):
        with pytest.raises(ConfigFileError, match=why):
            load_settings(default_config_path(), environ={}, overrides={**base, "rtk.takeoff_position": bad})
