"""RTCM3 streams as base input for `onboard rtk`: the M8P base's lossy RTCM3 with the rover's raw UBX log."""

from __future__ import annotations

import gzip
from dataclasses import replace

import numpy as np
import pytest

from onboard.errors import InputError
from onboard.formats.rinex_obs import read_rinex_obs
from onboard.gnsstime import GpsTime
from onboard.postpro.inputs import read_base_observations, read_navigation, read_observations
from onboard.receiver.base_epochs import collect_rtcm
from onboard.receiver.rtcm import BasePosition, encode_base_position, encode_gps_observations
from onboard.rtk.options import RtkOptions
from onboard.rtk.postpro import postprocess
from onboard.rtk.types import Q_FIX
from tests.conftest import shared_file

M8P = "gnss/ublox-m8p-galway-2018/"
BASE_1005 = np.array([3774089.2120, -601661.6157, 5089321.2474])  # README: RTCM 1005 of this session
ROVER_REF = np.array([3774088.9931, -601661.8217, 5089321.3853])  # README: mean of the M8P's RTK fixes
REF_TIME = GpsTime.from_week_tow_s(2021, 391088.0)  # rover's first epoch (2018-10-04 12:38 GPST)


@pytest.mark.slow
def test_rtcm_base_epochs_equal_convbins_rinex_of_the_same_stream() -> None:
    base = read_base_observations(shared_file(M8P + "rtcm3/base-20181004-1236.rtcm3.gz"), REF_TIME)
    assert base.kind == "rtcm3"
    np.testing.assert_allclose(base.antenna_pos_ecef_m, BASE_1005, atol=1e-4)
    rnx = read_rinex_obs(shared_file(M8P + "rinex/base-20181004-1236.rtcm.obs.gz"))
    by_time = {e.time.total_ns: e.gps_only() for e in rnx.epochs if len(e.gps_only())}
    common = 0
    for ep in base.epochs:
        other = by_time.get(ep.time.total_ns)
        if other is None:
            continue
        common += 1
        assert list(ep.sv_id) == list(other.sv_id)
        # RINEX has 3 decimals: equal to within its rounding (pr m, phase cycles; DF012 unwrapped per sat)
        np.testing.assert_allclose(ep.pr_m, other.pr_m, rtol=0, atol=6e-4)
        np.testing.assert_allclose(ep.cp_cyc, other.cp_cyc, rtol=0, atol=6e-4)
    # convbin kept 410 GPS epochs; every one of them is ours (we keep more: 607, one per received 1077)
    assert common == len(by_time) == 410
    assert len(base.epochs) == 607
    assert all(b.time > a.time for a, b in zip(base.epochs, base.epochs[1:]))


@pytest.mark.slow
def test_rover_raw_log_with_the_lossy_rtcm_base_fixes_at_the_reference() -> None:
    rover = read_observations(shared_file(M8P + "raw/rover-20181004-1237.ubx.gz"))
    base = read_base_observations(shared_file(M8P + "rtcm3/base-20181004-1236.rtcm3.gz"), rover.epochs[0].time)
    nav = read_navigation([], rover.ephemerides + base.ephemerides)
    rov = [e for e in rover.epochs if len(e.gps_only())][:400]
    sols, _ = postprocess(rov, base.epochs, nav, base.antenna_pos_ecef_m,
                          replace(RtkOptions(), elmask_deg=15.0), "forward")
    q = np.array([s.q for s in sols])
    fixed = np.array([s.pos_ecef_m for s in sols])[q == Q_FIX]
    assert len(sols) == 400 and len(fixed) >= 100
    err = np.linalg.norm(fixed - ROVER_REF, axis=1)
    assert np.max(err) < 0.10  # no wrong fix, with the base from 1005 and the week from the rover


@pytest.mark.slow
def test_mixed_ubx_rtcm_base_log_uses_the_more_complete_source() -> None:
    # The M8P base log interleaves RAWX (every ~3-4 s) with the RTCM3 it sent (1077 on ~2 of 3 epochs).
    base = read_base_observations(shared_file(M8P + "raw/base-20181004-1236.ubx.gz"), REF_TIME)
    assert base.kind == "rtcm3" and len(base.epochs) == 607
    np.testing.assert_allclose(base.antenna_pos_ecef_m, BASE_1005, atol=1e-4)


def _encoded_stream(n: int = 20) -> tuple[bytes, list]:
    rnx = read_rinex_obs(shared_file(M8P + "rinex/base-20181004-1236.rtcm.obs.gz"))
    epochs = [e.gps_only() for e in rnx.epochs if len(e.gps_only()) >= 5][:n]
    pos = BasePosition(7, tuple(BASE_1005), 1.5)
    data = encode_base_position(pos) + b"".join(encode_gps_observations(e, 7) for e in epochs)
    return data, epochs


def test_encoded_1004_stream_round_trips_and_split_messages_merge() -> None:
    data, epochs = _encoded_stream()
    col = collect_rtcm([data[k:k + 37] for k in range(0, len(data), 37)], REF_TIME)  # odd chunking
    assert [e.time for e in col.epochs] == [e.time for e in epochs]
    assert col.base_position is not None and col.base_position.antenna_height_m == pytest.approx(1.5)
    for ours, src in zip(col.epochs, epochs):
        np.testing.assert_allclose(ours.pr_m, src.pr_m, rtol=0, atol=0.0101)
        np.testing.assert_allclose(ours.cp_cyc, src.cp_cyc, rtol=0, atol=0.0027)  # DF012: 0.5 mm
    # One epoch sent as two 1004 messages (e.g. split for the radio packet size) comes back as one epoch.
    e = epochs[0]
    half = len(e) // 2
    two = encode_gps_observations(e.select(np.arange(len(e)) < half), 7, synchronous=True) + \
        encode_gps_observations(e.select(np.arange(len(e)) >= half), 7)
    merged = collect_rtcm([two], REF_TIME).epochs
    assert len(merged) == 1 and sorted(merged[0].sv_id.tolist()) == sorted(e.sv_id.tolist())


def test_corrupt_frames_are_skipped_and_the_rest_survives(tmp_path) -> None:
    data, epochs = _encoded_stream()
    frames = []
    k = 0
    while k < len(data):
        n = ((data[k + 1] & 0x03) << 8 | data[k + 2]) + 6
        frames.append(bytearray(data[k:k + n]))
        k += n
    frames[3][10] ^= 0x40  # a bit error: CRC-24Q fails, the frame is dropped
    frames[5] = frames[5][: len(frames[5]) // 2]  # a frame cut short by a radio gap
    path = tmp_path / "radio.rtcm3.gz"
    path.write_bytes(gzip.compress(b"".join(bytes(f) for f in frames)))
    base = read_base_observations(path, REF_TIME)
    lost = {epochs[2].time, epochs[4].time}  # frames 3 and 5 (frame 0 is the 1006)
    assert [e.time for e in base.epochs] == [e.time for e in epochs if e.time not in lost]
    np.testing.assert_allclose(base.antenna_pos_ecef_m[:2], BASE_1005[:2], atol=2.0)


def test_unusable_rtcm_inputs_are_refused_with_a_reason(tmp_path) -> None:
    data, _ = _encoded_stream(3)
    path = tmp_path / "b.rtcm3"
    path.write_bytes(data)
    with pytest.raises(InputError, match="GPS week"):
        read_base_observations(path, None)  # a pure RTCM stream needs the rover's time
    only_pos = tmp_path / "pos.rtcm3"
    only_pos.write_bytes(encode_base_position(BasePosition(1, tuple(BASE_1005))) * 3)
    with pytest.raises(InputError, match="without GPS observations"):
        read_base_observations(only_pos, REF_TIME)
    with pytest.raises(InputError, match="no such file"):
        read_base_observations(tmp_path / "missing.rtcm3", REF_TIME)
