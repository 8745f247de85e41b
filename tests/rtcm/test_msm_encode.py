"""MSM4/5/7 of every constellation: real MSM7 epochs re-encoded by our MsmEncoder, decoded by RTKLIB and by us (the
only MSM4/MSM5 frames we have: no public capture holds them for every system)."""

from __future__ import annotations

import collections
import math

import numpy as np
import pytest
from pyrtcm import RTCMReader

from onboard.gnsstime import GpsTime
from onboard.receiver.base_epochs import collect_rtcm
from onboard.receiver.framing import iter_frames
from onboard.receiver.rtcm import MsmEncoder, RtcmDecoder
from onboard.rtk.consts import LAMBDA_L1_M
from onboard.rtk.types import FCN_NONE, GNSS_BEIDOU, GNSS_GALILEO, GNSS_GLONASS, GNSS_GPS, GNSS_QZSS, ObsEpoch
from tests.conftest import shared_file
from tests.rtcm.rtklib_rtcm import rtklib_msm_rows

STREAMS = {
    "rtcm/pygnssutils_pygpsdata-rtcm3.log": (GNSS_GPS, GNSS_GLONASS, GNSS_GALILEO, GNSS_BEIDOU),
    "rtcm/rtklib_GMSD7_20121014.rtcm3": (GNSS_GPS, GNSS_GLONASS, GNSS_QZSS),
}
# resolution of the fine pseudorange / phase range (m) and Doppler (Hz) of each kind
RESOLUTION = {4: (2**-24 * 299_792.458, 2**-29 * 299_792.458), 5: (2**-24 * 299_792.458, 2**-29 * 299_792.458),
              7: (2**-29 * 299_792.458, 2**-31 * 299_792.458)}


def _real_epochs(file: str) -> tuple[list[ObsEpoch], GpsTime]:
    data = shared_file(file).read_bytes()[:120_000]  # the first ~40 epochs (time: these streams are long)
    if "GMSD7" in file:
        ref = GpsTime.from_week_tow_s(1709, 604784.0)
    else:
        first = next(f for f in iter_frames(data) if f.msg_id == 1077)
        ref = GpsTime.from_week_tow_s(2200, RTCMReader.parse(first.raw).DF004 / 1000.0)
    return [e.obs for e in collect_rtcm([data], ref).gnss_epochs[:40]], ref


@pytest.mark.parametrize("kind", [4, 5, 7])
@pytest.mark.parametrize("file", sorted(STREAMS))
def test_msm_encoded_and_decoded_by_rtklib_and_us(file: str, kind: int) -> None:
    epochs, ref = _real_epochs(file)
    systems = STREAMS[file]
    encoder = MsmEncoder(station_id=7)
    stream = bytearray()
    for e in epochs:
        present = [g for g in systems if g in e.systems()]
        for k, g in enumerate(present):
            frame = encoder.encode(e, g, kind, more_follow=k < len(present) - 1)
            assert frame is not None and RTCMReader.parse(frame).identity == str(1070 + 10 * [
                GNSS_GPS, GNSS_GLONASS, GNSS_GALILEO, 99, GNSS_QZSS, GNSS_BEIDOU].index(g) + kind)
            stream += frame
    data = bytes(stream)
    # MSM4 has no GLONASS channel: give the decoders' table (as from 1020 or the rover's RXM-RAWX)
    fcn = {int(s): int(k) for e in epochs for g, s, k in zip(e.gnss_id, e.sv_id, e.glo_fcn) if g == GNSS_GLONASS}
    col = collect_rtcm([data], ref, glo_fcn=fcn if kind == 4 else None)
    ours = {e.time.total_ns: e for e in col.gnss_epochs}
    assert len(ours) == len(epochs) and all(e.complete for e in col.gnss_epochs)
    pr_res, cp_res = RESOLUTION[kind]
    n = collections.Counter()
    for src in epochs:
        got = ours[src.time.total_ns].obs
        assert sorted(zip(got.gnss_id.tolist(), got.sv_id.tolist())) == sorted(
            (g, s) for g, s, p in zip(src.gnss_id.tolist(), src.sv_id.tolist(), src.pr_m)
            if math.isfinite(p) and g in systems)
        for g in systems:
            a, b = src.system(g), got.system(g)
            assert a.sv_id.tolist() == b.sv_id.tolist()
            if not len(a):
                continue
            np.testing.assert_allclose(b.pr_m, a.pr_m, atol=pr_res)
            lam = np.array([LAMBDA_L1_M if g != GNSS_GLONASS else 299_792_458.0 / (1602e6 + 0.5625e6 * k)
                            for k in b.glo_fcn.tolist()])
            dcp = (b.cp_cyc - a.cp_cyc) * lam  # the encoder keeps the phase (no whole-cycle move needed here)
            assert np.all(np.isnan(dcp) == np.isnan(a.cp_cyc)) and np.nanmax(np.abs(dcp)) <= cp_res + 1e-9
            if kind == 4:
                assert np.all(np.isnan(b.dop_hz))
            else:
                np.testing.assert_allclose(b.dop_hz * lam, a.dop_hz * lam, atol=0.0001 / 2 + 1e-9)
            assert b.glo_fcn.tolist() == a.glo_fcn.tolist()
            n[g] += len(b)
    assert set(n) == set(systems) and min(n.values()) > 30
    # RTKLIB decodes the same frames to the same values (its DF419 channels for MSM5/7; for MSM4 its 1020-less
    # decoder has no channel: GLONASS phase compared only where it has one)
    theirs = rtklib_msm_rows(data, ref)
    assert {k[1] for k in theirs} == set(systems)
    for key, (pr, cp, dop, cn0, lli, code) in theirs.items():
        e = ours[key[0]].obs
        i = next(i for i, (g, s) in enumerate(zip(e.gnss_id.tolist(), e.sv_id.tolist())) if (g, s) == key[1:])
        assert abs(e.pr_m[i] - pr) <= 1e-3 and str(e.signal[i]) == code, key
        if cp:
            assert abs(e.cp_cyc[i] - cp) <= 1e-3, key
        if dop:
            assert abs(e.dop_hz[i] - dop) <= 1e-3 * max(1.0, abs(dop)), key
        assert abs(e.cn0_dbhz[i] - cn0) <= 1e-3 and (e.lli[i] & 3) == (lli & 3), key


def test_msm4_glonass_without_channel_keeps_code_only() -> None:
    epochs, ref = _real_epochs("rtcm/pygnssutils_pygpsdata-rtcm3.log")
    frame = MsmEncoder(1).encode(epochs[0], GNSS_GLONASS, 4)
    (f,) = iter_frames(frame)
    decoder = RtcmDecoder()
    got = decoder.decode(f, ref)
    src = epochs[0].system(GNSS_GLONASS)
    assert isinstance(got, ObsEpoch) and got.sv_id.tolist() == src.sv_id.tolist()
    np.testing.assert_allclose(got.pr_m, src.pr_m, atol=0.02)
    assert np.all(np.isnan(got.cp_cyc)) and set(got.glo_fcn.tolist()) == {FCN_NONE}
    assert decoder.glo_phase_without_fcn == len(got)


def test_phase_far_from_the_code_is_moved_by_whole_cycles_and_flagged() -> None:
    epochs, ref = _real_epochs("rtcm/pygnssutils_pygpsdata-rtcm3.log")
    e = epochs[0].system(GNSS_GPS)
    from dataclasses import replace

    far = replace(e, cp_cyc=e.cp_cyc + 1_000_000.0)  # 190 km of integer ambiguity
    encoder = MsmEncoder(1)
    (f,) = iter_frames(encoder.encode(far, GNSS_GPS, 7))
    got = RtcmDecoder().decode(f, ref)
    moved = got.cp_cyc - far.cp_cyc
    np.testing.assert_allclose(moved, np.round(moved), atol=1e-3)
    assert np.all(np.abs(got.cp_cyc * LAMBDA_L1_M - got.pr_m) < 600.0)
    assert np.all(got.lock_ms == 0.0)  # a moved phase starts a new lock
