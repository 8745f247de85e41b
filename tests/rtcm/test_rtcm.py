"""RTCM3: decoding real base streams, and our encoder checked by parsing back with pyrtcm."""

from __future__ import annotations

import gzip
import itertools
import math

import numpy as np
import pytest
from pyrtcm import RTCMReader

from onboard.formats.rinex_nav import read_rinex_nav
from onboard.gnsstime import GpsTime
from onboard.receiver.framing import iter_frames
from onboard.receiver.rtcm import (
    BasePosition,
    RtcmDecoder,
    encode_base_position,
    encode_ephemeris,
    encode_gps_observations,
    lock_ms_from_df013,
    lock_ms_from_df407,
    rtcm3_frame,
)
from onboard.rtk.consts import LAMBDA_L1_M
from onboard.rtk.types import GNSS_GPS, Ephemeris, ObsEpoch
from tests.conftest import shared_file

REF_2018 = GpsTime.from_week_tow_s(2021, 390000.0)


def _epoch(t: GpsTime, prns: list[int], pr: list[float], cp: list[float], lock_ms: float = 5000.0) -> ObsEpoch:
    n = len(prns)
    return ObsEpoch(
        time=t, gnss_id=np.full(n, GNSS_GPS, np.int8), sv_id=np.array(prns, np.int16), pr_m=np.array(pr),
        cp_cyc=np.array(cp), dop_hz=np.full(n, np.nan), cn0_dbhz=np.full(n, 45.0), lock_ms=np.full(n, lock_ms),
        lli=np.zeros(n, np.uint8),
    )


@pytest.mark.parametrize("message", [1002, 1004])
def test_observation_round_trip_through_pyrtcm(message: int) -> None:
    t = GpsTime.from_week_tow_s(2021, 390123.0)
    pr = [20_512_345.67, 23_987_654.32, 21_000_000.01]
    # phase offset from pr/λ by arbitrary integers plus a few metres of code-carrier divergence
    cp = [pr[0] / LAMBDA_L1_M + 12.3, pr[1] / LAMBDA_L1_M - 4000.25, pr[2] / LAMBDA_L1_M + 1499.9]
    frame_bytes = encode_gps_observations(_epoch(t, [3, 17, 32], pr, cp), station_id=7, message=message)
    parsed = RTCMReader.parse(frame_bytes)
    assert parsed.identity == str(message) and parsed.DF003 == 7 and parsed.DF006 == 3
    (frame,) = iter_frames(frame_bytes)
    obs = RtcmDecoder().decode(frame, REF_2018)
    assert isinstance(obs, ObsEpoch)
    assert obs.time == t
    np.testing.assert_array_equal(obs.sv_id, [3, 17, 32])
    np.testing.assert_allclose(obs.pr_m, pr, atol=0.011)  # DF011 resolution 0.02 m
    # carrier phase: equal up to a whole number of 1500-cycle wraps, to DF012 resolution
    dphi = (obs.cp_cyc - np.array(cp)) / 1500.0
    assert np.allclose(dphi, np.round(dphi), atol=(0.011 + 0.0003) / LAMBDA_L1_M / 1500.0)
    assert np.all(obs.lock_ms <= 5000.0) and np.all(obs.lock_ms >= 4000.0)


def test_phase_stays_continuous_across_a_ppr_wrap() -> None:
    decoder = RtcmDecoder()
    t0 = GpsTime.from_week_tow_s(2021, 390000.0)
    pr0 = 21_000_000.0
    base_cp = pr0 / LAMBDA_L1_M + 749.0  # near the ±750-cycle wrap of the encoder
    phases = []
    for k in range(5):
        drift_cyc = 0.6 * k  # code-carrier divergence pushes it over the wrap
        ep = _epoch(t0.add_s(k), [5], [pr0], [base_cp + drift_cyc])
        (frame,) = iter_frames(encode_gps_observations(ep, 1, 1002))
        obs = decoder.decode(frame, t0)
        phases.append(obs.cp_cyc[0])
    steps = np.diff(phases)
    np.testing.assert_allclose(steps, 0.6, atol=0.01)


def test_base_position_1005_1006_round_trip() -> None:
    pos = BasePosition(station_id=42, arp_ecef_m=(3774089.2120, -601661.6157, 5089321.2474), antenna_height_m=1.5)
    for with_height in (False, True):
        raw = encode_base_position(pos, with_height)
        parsed = RTCMReader.parse(raw)
        assert abs(parsed.DF025 - 3774089.2120) < 1e-4 and abs(parsed.DF027 - 5089321.2474) < 1e-4
        (frame,) = iter_frames(raw)
        got = RtcmDecoder().decode(frame, REF_2018)
        assert isinstance(got, BasePosition)
        np.testing.assert_allclose(got.arp_ecef_m, pos.arp_ecef_m, atol=1e-4)
        assert got.antenna_height_m == pytest.approx(1.5 if with_height else 0.0)
    up = np.linalg.norm(got.phase_centre_ecef_m - np.array(pos.arp_ecef_m))
    assert up == pytest.approx(1.5, abs=1e-6)


def test_ephemeris_1019_round_trip_every_brdc_record() -> None:
    nav = read_rinex_nav(shared_file("gnss/broadcast-nav-20100701/brdc1820.10n"))
    decoder = RtcmDecoder()
    for eph in nav.ephemerides[:60]:
        raw = encode_ephemeris(eph)
        assert len(raw) == 3 + 61 + 3
        (frame,) = iter_frames(raw)
        got = decoder.decode(frame, eph.toe)
        assert isinstance(got, Ephemeris)
        assert (got.prn, got.iode, got.iodc, got.toe, got.toc) == (eph.prn, eph.iode, eph.iodc, eph.toe, eph.toc)
        assert abs(got.sqrt_a - eph.sqrt_a) <= 2**-19 and abs(got.e - eph.e) <= 2**-33
        assert abs(got.m0_rad - eph.m0_rad) <= 2**-31 * math.pi
        assert abs(got.af0_s - eph.af0_s) <= 2**-31 and abs(got.tgd_s - eph.tgd_s) <= 2**-31


def test_real_ntrip_capture_1004_1077_1005_1019() -> None:
    data = shared_file("rtcm/pyrtcm_pygpsdata-NTRIP-USCL00CHL0.log").read_bytes()
    decoder = RtcmDecoder()
    ref = GpsTime.from_week_tow_s(2200, 318945.0)
    kinds = {}
    for frame in iter_frames(data):
        out = decoder.decode(frame, ref)
        if out is not None:
            kinds[frame.msg_id] = out
    assert {1002, 1004, 1005, 1006, 1019, 1077} <= set(kinds)
    b = kinds[1006]
    assert isinstance(b, BasePosition) and b.antenna_height_m == pytest.approx(0.0343)
    for number in (1002, 1004, 1077):
        obs = kinds[number]
        assert isinstance(obs, ObsEpoch) and len(obs) >= 8
        assert np.all((obs.pr_m > 1.9e7) & (obs.pr_m < 2.7e7))
        # the phase − pseudorange offset of each satellite stays within the legacy DF012 range (±262 m)
        diff_m = np.abs(obs.cp_cyc * LAMBDA_L1_M - obs.pr_m)
        assert np.nanmax(diff_m) < 262.144
    msm, legacy = kinds[1077], kinds[1004]
    common = np.intersect1d(msm.sv_id, legacy.sv_id)
    assert len(common) >= 6
    dt = msm.time.diff_s(legacy.time)
    assert abs(dt) < 2.0


@pytest.mark.slow
def test_m8p_lossy_base_stream_decodes_every_gps_epoch() -> None:
    path = shared_file("gnss/ublox-m8p-galway-2018/rtcm3/base-20181004-1236.rtcm3.gz")
    frames = iter_frames(gzip.decompress(path.read_bytes()))
    decoder = RtcmDecoder()
    epochs = [o for f in frames if f.msg_id == 1077 and isinstance(o := decoder.decode(f, REF_2018), ObsEpoch)]
    positions = [o for f in frames if isinstance(o := decoder.decode(f, REF_2018), BasePosition)]
    assert len(epochs) == sum(f.msg_id == 1077 for f in frames) == 607
    assert decoder.errors == 0
    np.testing.assert_allclose(positions[0].arp_ecef_m, (3774089.2120, -601661.6157, 5089321.2474), atol=1e-4)
    assert all(b.time > a.time for a, b in itertools.pairwise(epochs))
    # the M8P base tags its RTCM epochs on the second or at …999 ms (receiver time): never in between
    assert {e.time.tow_ns % 1_000_000_000 for e in epochs} == {0, 999_000_000}
    assert all(len(e) >= 4 for e in epochs)


def test_lock_time_tables() -> None:
    assert lock_ms_from_df013(0) == 0 and lock_ms_from_df013(23) == 23_000 and lock_ms_from_df013(24) == 24_000
    assert lock_ms_from_df013(127) == 937_000
    assert [lock_ms_from_df407(i) for i in (0, 63, 64, 95, 96, 128)] == [0, 63, 64, 126, 128, 256]
    values = [lock_ms_from_df407(i) for i in range(705)]
    assert all(b > a for a, b in itertools.pairwise(values))


def test_corrupt_and_foreign_frames_do_not_raise() -> None:
    decoder = RtcmDecoder()
    junk = rtcm3_frame(bytes([0x3E, 0xC0]) + bytes(5))  # claims 1004 but is far too short
    (frame,) = iter_frames(junk)
    assert decoder.decode(frame, REF_2018) is None
    assert decoder.errors == 1
