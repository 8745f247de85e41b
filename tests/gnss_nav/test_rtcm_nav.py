"""RTCM 1020/1042/1045/1046 ephemerides from real streams in ../shared/data/rtcm, and the BeiDou GEO orbit
(PRN 1–5, 59–63 rotation) against RTKLIB eph2pos on the decoded real GEO ephemerides.

No capture holds 1044 (QZSS); it shares the LNAV layout with 1019, decoded by the same code path as the others.
The streams carry no RINEX twin, so the checks are what a wrong scale or sign would break: orbit radius of each
constellation, clock sizes, toe near the stream's time, and RTKLIB's own orbit evaluation of the same numbers.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from onboard.gnsstime import GpsTime
from onboard.receiver.decode import iter_file_bytes
from onboard.receiver.framing import Protocol, StreamFramer
from onboard.receiver.rtcm_nav import DATA_SOURCE_FNAV, decode_nav_message
from onboard.rtk.ephemeris import eph_position
from onboard.rtk.glonass import glonass_position
from onboard.rtk.gnss import is_beidou_geo
from onboard.rtk.types import GNSS_BEIDOU, GNSS_GALILEO, Ephemeris, GlonassEphemeris
from tests.conftest import shared_file

pytestmark = pytest.mark.shared_data

# stream → (a GPS time within hours of it: the week and toe of its 1019 GPS ephemerides, leap seconds)
STREAMS = {
    "rtcm/rtklib_testglo.rtcm3": (GpsTime(1562, 518_400 * 10**9), 15),
    "rtcm/rtklib_GMSD7_20121014.rtcm3": (GpsTime(1710, 7_200 * 10**9), 16),
    "rtcm/pyrtcm_pygpsdata-NTRIP-USCL00CHL0.log": (GpsTime(2305, 324_000 * 10**9), 18),
    "rtcm/pygnssutils_ntrip_encode_none.bin": (GpsTime(2328, 79_200 * 10**9), 18),
    "rtcm/pygnssutils_ntrip_chunked.bin": (GpsTime(2328, 547_200 * 10**9), 18),
}
COUNTS = {"rtcm/rtklib_testglo.rtcm3": 19, "rtcm/rtklib_GMSD7_20121014.rtcm3": 16,
          "rtcm/pyrtcm_pygpsdata-NTRIP-USCL00CHL0.log": 4, "rtcm/pygnssutils_ntrip_encode_none.bin": 99,
          "rtcm/pygnssutils_ntrip_chunked.bin": 12}


def _decoded(rel: str) -> Iterator[Ephemeris | GlonassEphemeris]:
    ref, leap = STREAMS[rel]
    framer = StreamFramer(frozenset({Protocol.RTCM3}))
    for chunk in iter_file_bytes(shared_file(rel)):
        for frame in framer.feed(chunk):
            e = decode_nav_message(frame, ref, leap)
            if e is not None:
                yield e


@pytest.mark.parametrize("rel", sorted(STREAMS))
def test_real_rtcm_ephemerides_are_physical(rel: str) -> None:
    ref, _ = STREAMS[rel]
    ephs = list(_decoded(rel))
    assert len(ephs) == COUNTS[rel]
    for e in ephs:
        assert abs(e.toe.diff_s(ref)) < 3 * 3600  # week / day resolved to the stream's time
        if isinstance(e, GlonassEphemeris):
            pos, clk = glonass_position(e, e.toe)
            assert 25.3e6 < np.linalg.norm(pos) < 25.6e6
            assert 2.5e3 < np.linalg.norm(e.vel_m_s) < 4.0e3  # ECEF speed of a GLONASS orbit
            assert abs(e.tau_n_s) < 1e-3 and abs(e.gamma_n) < 1e-9 and -7 <= e.channel <= 6
            assert clk == -e.tau_n_s
        else:
            pos, clk = eph_position(e, e.toe)
            r = np.linalg.norm(pos)
            if e.gnss_id == GNSS_GALILEO:
                assert 29.4e6 < r < 29.7e6
            else:
                assert e.gnss_id == GNSS_BEIDOU
                assert (42.0e6 < r < 42.3e6) if (is_beidou_geo(e.prn) or r > 35e6) else (27.8e6 < r < 28.0e6)
            assert abs(clk) < 5e-3 and abs(e.tgd_s) < 1e-7


def test_galileo_fnav_and_inav_carry_their_sources() -> None:
    ephs = [e for e in _decoded("rtcm/pyrtcm_pygpsdata-NTRIP-USCL00CHL0.log") if isinstance(e, Ephemeris)
            and e.gnss_id == GNSS_GALILEO]
    assert sorted(e.code_on_l2 for e in ephs) == sorted([DATA_SOURCE_FNAV, 0x201])
    assert all(e.toe.week == 2305 for e in ephs)  # GST week 1281 + 1024


def test_beidou_geo_orbits_from_rtcm_equal_rtklib_eph2pos() -> None:
    """The GEO rotation (−5° about x, then the Earth's rotation) against RTKLIB on real GEO ephemerides (and
    the MEO/IGSO ones against the ordinary path)."""
    p = pytest.importorskip("pyrtklib", reason="pyrtklib (RTKLIB bindings) has wheels for x86_64 only")
    ephs = {(e.prn, e.toe): e for rel in STREAMS for e in _decoded(rel)
            if isinstance(e, Ephemeris) and e.gnss_id == GNSS_BEIDOU}
    geo = {prn for prn, _ in ephs if is_beidou_geo(prn)}
    assert geo and len(ephs) > len(geo)
    for (prn, _), e in ephs.items():
        r = p.eph_t()
        r.sat = p.satno(p.SYS_CMP, prn)
        r.A, r.e, r.i0, r.OMG0, r.omg, r.M0 = e.sqrt_a**2, e.e, e.i0_rad, e.omega0_rad, e.omega_rad, e.m0_rad
        r.deln, r.OMGd, r.idot = e.delta_n_rad_s, e.omega_dot_rad_s, e.idot_rad_s
        r.crc, r.crs, r.cuc, r.cus, r.cic, r.cis = e.crc_m, e.crs_m, e.cuc_rad, e.cus_rad, e.cic_rad, e.cis_rad
        r.f0, r.f1, r.f2 = e.af0_s, e.af1_s_s, e.af2_s_s2
        r.toe = p.gpst2time(e.toe.week, e.toe.tow_s)
        r.toc = p.gpst2time(e.toc.week, e.toc.tow_s)
        r.toes = e.toe.add_s(-14).tow_s  # BDT seconds of week
        for dt in (-3600.0, 0.0, 2700.0):
            t = e.toe.add_s(dt)
            rs, dts, var = p.Arr1Ddouble(3), p.Arr1Ddouble(1), p.Arr1Ddouble(1)
            p.eph2pos(p.gpst2time(t.week, t.tow_s), r, rs, dts, var)
            pos, _ = eph_position(e, t)
            np.testing.assert_allclose(pos, [rs[0], rs[1], rs[2]], rtol=0, atol=1e-3)


# RTCM 10403.3 Table 3.5-104 (message 1044), field, bits, signed, scale (semicircle fields scaled by π later)
_BODY_1044 = (("DF002", 12, False, 1), ("DF429", 4, False, 1), ("DF430", 16, False, 16),
              ("DF431", 8, True, 2**-55), ("DF432", 16, True, 2**-43), ("DF433", 22, True, 2**-31),
              ("DF434", 8, False, 1), ("DF435", 16, True, 2**-5), ("DF436", 16, True, 2**-43),
              ("DF437", 32, True, 2**-31), ("DF438", 16, True, 2**-29), ("DF439", 32, False, 2**-33),
              ("DF440", 16, True, 2**-29), ("DF441", 32, False, 2**-19), ("DF442", 16, False, 16),
              ("DF443", 16, True, 2**-29), ("DF444", 32, True, 2**-31), ("DF445", 16, True, 2**-29),
              ("DF446", 32, True, 2**-31), ("DF447", 16, True, 2**-5), ("DF448", 32, True, 2**-31),
              ("DF449", 24, True, 2**-43), ("DF450", 14, True, 2**-43), ("DF451", 2, False, 1),
              ("DF452", 10, False, 1), ("DF453", 4, False, 1), ("DF454", 6, False, 1), ("DF455", 8, True, 2**-31),
              ("DF456", 10, False, 1), ("DF457", 1, False, 1))


def test_qzss_1044_built_from_a_real_record_decodes_back() -> None:
    """A 1044 packed from a real QZSS broadcast record (brdc3050.12q), parsed by pyrtcm and decoded by us, gives
    the record back to the LSB (the encoder here is the test's: the product never sends 1044)."""
    from onboard.formats.rinex_nav import read_rinex_nav
    from onboard.receiver.framing import iter_frames
    from onboard.receiver.rtcm import BitWriter, rtcm3_frame
    from onboard.rtk.lnav import SC2RAD

    q = read_rinex_nav(shared_file("gnss/broadcast-nav-20121031/brdc3050.12q")).qzss[0]
    w = BitWriter()
    w.put_fields(_BODY_1044, {
        "DF002": 1044, "DF429": q.prn, "DF430": q.toc.tow_s, "DF431": q.af2_s_s2, "DF432": q.af1_s_s,
        "DF433": q.af0_s, "DF434": q.iode, "DF435": q.crs_m, "DF436": q.delta_n_rad_s / SC2RAD,
        "DF437": q.m0_rad / SC2RAD, "DF438": q.cuc_rad, "DF439": q.e, "DF440": q.cus_rad, "DF441": q.sqrt_a,
        "DF442": q.toe.tow_s, "DF443": q.cic_rad, "DF444": q.omega0_rad / SC2RAD, "DF445": q.cis_rad,
        "DF446": q.i0_rad / SC2RAD, "DF447": q.crc_m, "DF448": q.omega_rad / SC2RAD,
        "DF449": q.omega_dot_rad_s / SC2RAD, "DF450": q.idot_rad_s / SC2RAD, "DF451": q.code_on_l2,
        "DF452": q.toe.week % 1024, "DF453": q.ura_index, "DF454": q.health, "DF455": q.tgd_s, "DF456": q.iodc,
        "DF457": 0,
    })
    [frame] = iter_frames(rtcm3_frame(w.to_bytes()))
    e = decode_nav_message(frame, q.toe.add_s(3600), 16)
    assert isinstance(e, Ephemeris)
    assert (e.prn, e.toe, e.toc, e.iode, e.iodc, e.gnss_id, e.fit_interval_h) == (
        q.prn, q.toe, q.toc, q.iode, q.iodc, q.gnss_id, 2.0)
    for name in ("sqrt_a", "e", "i0_rad", "omega0_rad", "omega_rad", "m0_rad", "delta_n_rad_s", "omega_dot_rad_s",
                 "idot_rad_s", "af0_s", "af1_s_s", "af2_s_s2", "tgd_s", "crs_m", "crc_m", "cuc_rad", "cus_rad"):
        assert getattr(e, name) == pytest.approx(getattr(q, name), rel=1e-12, abs=1e-25), name
    pos_e, _ = eph_position(e, q.toe.add_s(600))
    pos_q, _ = eph_position(q, q.toe.add_s(600))
    assert np.linalg.norm(pos_e - pos_q) < 1e-3
