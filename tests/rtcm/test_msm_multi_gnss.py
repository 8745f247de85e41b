"""MSM observations of every constellation against RTKLIB (convbin's RINEX, or its decoder through pyrtklib), the
per-epoch reassembly of split base epochs on the real M8P streams, GLONASS channels and code-phase biases."""

from __future__ import annotations

import collections
import gzip
import math

import numpy as np
import pytest

from onboard.formats.rinex_obs import read_rinex_obs
from onboard.formats.rinex_write import obs_field
from onboard.gnsstime import GpsTime, gps_from_bdt_tow_ns, gps_from_glonass_tod
from onboard.receiver.base_epochs import BaseEpoch, RtcmCollected, collect_rtcm, latest_base_epoch
from onboard.receiver.framing import iter_frames
from onboard.receiver.rtcm import GlonassChannel, RtcmDecoder
from onboard.rtk.types import FCN_NONE, GNSS_BEIDOU, GNSS_GALILEO, GNSS_GLONASS, GNSS_GPS, GNSS_QZSS
from tests.conftest import shared_file
from tests.rtcm.rtklib_rtcm import rtklib_msm_rows, single_message_epochs

M8P = "gnss/ublox-m8p-galway-2018"
REF_2018 = GpsTime.from_week_tow_s(2021, 390000.0)


def _m8p_stream(name: str) -> RtcmCollected:
    return collect_rtcm([gzip.decompress(shared_file(f"{M8P}/rtcm3/{name}.rtcm3.gz").read_bytes())], REF_2018)


def _rows(epochs: list[BaseEpoch]) -> dict[tuple[int, int, int], tuple]:
    out = {}
    for e in epochs:
        o = e.obs
        for i in range(len(o)):
            out[(o.time.total_ns, int(o.gnss_id[i]), int(o.sv_id[i]))] = (
                float(o.pr_m[i]), float(o.cp_cyc[i]), float(o.dop_hz[i]), float(o.cn0_dbhz[i]), int(o.lli[i]),
                str(o.signal[i]))
    return out


@pytest.mark.slow
@pytest.mark.parametrize(("name", "common", "rows", "ours"), [("base-20181004-1236", 623, 9070, 820),
                                                               ("base-20181004-1452", 1721, 22286, 2239)])
def test_m8p_msm7_gps_glonass_equal_convbin(name: str, common: int, rows: int, ours: int) -> None:
    """Every epoch of convbin's RINEX of the stream is ours, with the same satellites, pseudorange, phase and
    C/N0 as written (F14.3) and LLI. We keep more: the GPS epochs whose GLONASS message was lost (convbin drops a
    multi-message epoch that never gets its last message)."""
    col = _m8p_stream(name)
    ref = read_rinex_obs(shared_file(f"{M8P}/rinex/{name}.rtcm.obs.gz")).epochs
    by_time = {e.time.total_ns: e.obs for e in col.gnss_epochs}
    assert len(ref) == common and len(by_time) == ours
    n = 0
    for b in ref:
        a = by_time[b.time.total_ns]
        assert sorted(zip(a.gnss_id.tolist(), a.sv_id.tolist())) == sorted(zip(b.gnss_id.tolist(), b.sv_id.tolist()))
        at = {(g, s): i for i, (g, s) in enumerate(zip(a.gnss_id.tolist(), a.sv_id.tolist()))}
        for j, key in enumerate(zip(b.gnss_id.tolist(), b.sv_id.tolist())):
            i = at[key]
            for q in ("pr_m", "cp_cyc", "cn0_dbhz"):
                assert obs_field(float(getattr(a, q)[i]))[:14] == obs_field(float(getattr(b, q)[j]))[:14], (q, b.time, key)
            if math.isfinite(b.cp_cyc[j]):
                assert int(a.lli[i]) == int(b.lli[j]), (b.time, key)
            n += 1
    assert n == rows
    extra = [e for e in col.gnss_epochs if e.time.total_ns not in {b.time.total_ns for b in ref}]
    assert extra and all(e.systems == {GNSS_GPS} and not e.complete for e in extra)


@pytest.mark.parametrize(("file", "reference", "systems"), [
    ("rtcm/rtklib_GMSD7_20121014.rtcm3", GpsTime.from_week_tow_s(1709, 604784.0),
     {GNSS_GPS: 3084, GNSS_GLONASS: 1542, GNSS_QZSS: 257, GNSS_BEIDOU: 2068}),
    ("rtcm/pygnssutils_pygpsdata-rtcm3.log", None, {GNSS_GPS: 1347, GNSS_GLONASS: 1020, GNSS_GALILEO: 785,
                                                    GNSS_BEIDOU: 1220}),
    ("rtcm/pygnssutils_ntrip_encode_none.bin", None, {GNSS_GPS: 297, GNSS_GLONASS: 264, GNSS_GALILEO: 231,
                                                      GNSS_BEIDOU: 320}),
])
@pytest.mark.slow
def test_msm7_every_constellation_equals_rtklib(file: str, reference: GpsTime | None,
                                                systems: dict[int, int]) -> None:
    """GPS, GLONASS, Galileo, QZSS and BeiDou MSM7 of real streams: the same rows as RTKLIB's decoder (each
    message fed to it as its own epoch), pseudorange and phase to 1 mm / 1 mcycle, Doppler, C/N0, LLI, signal."""
    data = shared_file(file).read_bytes()
    if reference is None:  # a stream of the same week as its first GPS MSM: any week does for both decoders
        first = next(f for f in iter_frames(data) if f.msg_id == 1077)
        reference = RtcmDecoder().decode(first, GpsTime.from_week_tow_s(2200, 0.0)).time  # type: ignore[union-attr]
    ours = _rows(collect_rtcm([data], reference).gnss_epochs)
    theirs = rtklib_msm_rows(single_message_epochs(data, frozenset(range(1071, 1128))), reference)
    assert collections.Counter(k[1] for k in theirs) == systems
    assert set(theirs) <= set(ours)
    for key, (pr, cp, dop, cn0, lli, code) in theirs.items():
        a = ours[key]
        assert abs(a[0] - pr) <= 1e-3, key
        assert (abs(a[1] - cp) <= 1e-3) if cp else math.isnan(a[1]), key
        assert (abs(a[2] - dop) <= 1e-3 * max(1.0, abs(dop))) if dop else math.isnan(a[2]), key  # RTKLIB: float32
        assert abs(a[3] - cn0) <= 1e-3 and a[4] == lli and a[5] == code, key


@pytest.mark.slow
def test_split_base_epochs_reassembled_on_the_real_stream() -> None:
    """The M8P base sends 1077 (multiple-message bit set) then 1087 per epoch; the radio lost either. Each message
    lands in its own epoch (GLONASS time of day converted to GPS time), nothing is lost, and a pairing takes each
    system from the newest epoch that has it."""
    col = _m8p_stream("base-20181004-1236")
    kinds = collections.Counter((tuple(sorted(e.systems)), e.messages, e.complete) for e in col.gnss_epochs)
    assert kinds == {((GNSS_GPS, GNSS_GLONASS), (1077, 1087), True): 410,
                     ((GNSS_GLONASS,), (1087,), True): 213,  # GPS message lost: a third of the epochs
                     ((GNSS_GPS,), (1077,), False): 197}  # GLONASS (the last message) lost
    assert col.late_messages == 0 and col.undecodable == 0
    times = [e.time.total_ns for e in col.gnss_epochs]
    assert times == sorted(times) and len(set(times)) == len(times) == col.messages[1087] + 197
    # the GPS view is what the GPS engine used before: one epoch per 1077, GPS satellites only
    assert len(col.epochs) == col.messages[1077] == 607
    assert [e.time for e in col.epochs] == [e.time for e in col.gnss_epochs if GNSS_GPS in e.systems]
    assert all(set(e.gnss_id.tolist()) == {GNSS_GPS} for e in col.epochs)
    # pairing per system: at a GLONASS-only epoch, GPS comes from the epoch before, GLONASS from this one
    k = next(i for i, e in enumerate(col.gnss_epochs) if e.systems == {GNSS_GLONASS} and i > 0
             and GNSS_GPS in col.gnss_epochs[i - 1].systems)
    t = col.gnss_epochs[k].time
    assert latest_base_epoch(col.gnss_epochs, t, GNSS_GLONASS, 5.0) is col.gnss_epochs[k]
    assert latest_base_epoch(col.gnss_epochs, t, GNSS_GPS, 5.0) is col.gnss_epochs[k - 1]
    assert latest_base_epoch(col.gnss_epochs, t, GNSS_GPS, 0.5) is None  # older than the age limit
    assert latest_base_epoch(col.gnss_epochs, t, GNSS_GALILEO, 30.0) is None


@pytest.mark.slow
def test_stream_with_one_system_off_in_time_keeps_the_others() -> None:
    """GMSD7 writes GPS time into BeiDou's DF427 (its BeiDou epochs come out 14 s after the others): RTKLIB then
    drops every GPS/GLONASS/QZSS epoch; we keep each system's epochs (incomplete where BeiDou was to close them)."""
    ref = GpsTime.from_week_tow_s(1709, 604784.0)
    data = shared_file("rtcm/rtklib_GMSD7_20121014.rtcm3").read_bytes()
    col = collect_rtcm([data], ref)
    rtklib = rtklib_msm_rows(data, ref)
    assert {k[1] for k in rtklib} == {GNSS_BEIDOU}
    rows = collections.Counter(g for e in col.gnss_epochs for g in e.obs.gnss_id.tolist())
    assert rows == {GNSS_GPS: 3084, GNSS_GLONASS: 1542, GNSS_QZSS: 257, GNSS_BEIDOU: 2068}  # none lost
    assert sum(GNSS_GPS in e.systems for e in col.gnss_epochs) == 257 and col.late_messages == 0
    first_gps = next(e for e in col.gnss_epochs if GNSS_GPS in e.systems)
    assert first_gps.time == ref and not first_gps.complete


@pytest.mark.slow
def test_glonass_channels_from_msm7_and_1020_and_biases_from_1230() -> None:
    col = _m8p_stream("base-20181004-1236")
    # the same channels as convbin's header (from the same stream's DF419)
    rnx = read_rinex_obs(shared_file(f"{M8P}/rinex/base-20181004-1236.rtcm.obs.gz"))
    assert col.glo_fcn == rnx.header.glo_fcn == {6: -4, 7: 5, 8: 6, 14: -7, 15: 0, 21: 4, 22: -3, 23: 3}
    glo = next(e for e in col.gnss_epochs if e.systems == {GNSS_GLONASS}).obs
    assert [col.glo_fcn[s] for s in glo.sv_id.tolist()] == glo.glo_fcn.tolist()
    gps = col.epochs[0]
    assert set(gps.glo_fcn.tolist()) == {FCN_NONE} and set(gps.signal.tolist()) == {"1C"}
    b = col.glonass_biases
    assert b is not None and b.aligned and b.l1ca_m == pytest.approx(84.94) and b.l1p_m is None
    # 1020: the channel is learned (NTRIP capture: R09 on channel −2)
    decoder = RtcmDecoder()
    data = shared_file("rtcm/pyrtcm_pygpsdata-NTRIP-USCL00CHL0.log").read_bytes()
    got = [decoder.decode(f, GpsTime.from_week_tow_s(2200, 318945.0)) for f in iter_frames(data) if f.msg_id == 1020]
    assert got == [GlonassChannel(9, -2)] and decoder.glo_fcn[9] == -2


def test_glonass_msm_phase_needs_the_channel() -> None:
    """An MSM6 (no DF419) GLONASS cell: phase NaN without a channel, in cycles of its own carrier with one."""
    data = shared_file("rtcm/pyrtcm_pygpsdata-NTRIP-USCL00CHL0.log").read_bytes()
    (frame,) = [f for f in iter_frames(data) if f.msg_id == 1086]
    ref = GpsTime.from_week_tow_s(2200, 318945.0)
    blind = RtcmDecoder()
    a = blind.decode(frame, ref)
    assert np.all(np.isnan(a.cp_cyc)) and np.all(np.isfinite(a.pr_m)) and set(a.glo_fcn.tolist()) == {FCN_NONE}
    assert blind.glo_phase_without_fcn == len(a)
    table = {int(s): k for s, k in zip(a.sv_id.tolist(), [(-7 + i) % 14 - 7 for i in range(len(a))])}
    b = RtcmDecoder(glo_fcn=table).decode(frame, ref)
    assert b.time == a.time and np.all(np.isfinite(b.cp_cyc))
    lam = 299_792_458.0 / (1602e6 + 0.5625e6 * b.glo_fcn.astype(float))
    assert b.glo_fcn.tolist() == [table[int(s)] for s in b.sv_id.tolist()]
    np.testing.assert_allclose(b.cp_cyc * lam, b.pr_m, atol=300.0)  # phase range within the code's DF405 span


def test_glonass_and_beidou_epoch_times() -> None:
    ref = GpsTime.from_week_tow_s(2021, 391036.0)  # 2018-10-04 12:37:16 GPST (leap 18 s)
    assert gps_from_glonass_tod(56_218_999_000_000, ref) == GpsTime.from_week_tow_s(2021, 391036.999)
    # just after Moscow midnight = 21:00 UTC the day before: the day nearest the reference
    late = GpsTime.from_week_tow_s(2021, 4 * 86400 + 21 * 3600 + 18 - 1.0)
    assert gps_from_glonass_tod(1_000_000, late) == GpsTime.from_week_tow_s(2021, 4 * 86400 + 21 * 3600 + 18.001)
    assert gps_from_bdt_tow_ns(604_790 * 10**9, GpsTime.from_week_tow_s(2021, 604_799.0)) == \
        GpsTime.from_week_tow_s(2022, 4.0)
