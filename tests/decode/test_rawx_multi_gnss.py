"""RXM-RAWX of every constellation: our decoder (with RTKLIB's lock rules) against RTKLIB's own UBX decoder, and the
GLONASS channels / signals of the real M8P logs."""

from __future__ import annotations

import collections
import math

import pytest

from onboard.formats.rinex_obs import read_rinex_obs
from onboard.gnsstime import NS_PER_S
from onboard.receiver.decode import iter_file, observation_epochs
from onboard.rtk.types import FCN_NONE, GNSS_BEIDOU, GNSS_GALILEO, GNSS_GLONASS, GNSS_GPS, GNSS_QZSS
from tests.conftest import shared_file

GPS_EPOCH_POSIX_S = 315_964_800
RTKLIB_SYSTEMS = {1: GNSS_GPS, 4: GNSS_GLONASS, 8: GNSS_GALILEO, 16: GNSS_QZSS, 32: GNSS_BEIDOU}


def _rtklib_rows(data: bytes) -> dict[tuple[int, int, int], tuple[float, float, float, int, str]]:
    rtk = pytest.importorskip("pyrtklib", reason="pyrtklib (RTKLIB bindings, x86_64 bench extra) is not installed")
    raw = rtk.raw_t()
    assert rtk.init_raw(raw, rtk.STRFMT_UBX) == 1
    prn = rtk.Arr1Dint(1)
    out = {}
    try:
        for byte in data:
            if rtk.input_ubx(raw, byte) != 1:
                continue
            for i in range(raw.obs.n):
                d = raw.obs.data[i]
                sys = rtk.satsys(d.sat, prn)
                if sys not in RTKLIB_SYSTEMS or not d.code[0]:
                    continue
                t_ns = (d.time.time - GPS_EPOCH_POSIX_S) * NS_PER_S + round(d.time.sec * 1e6) * 1000
                key = (t_ns, RTKLIB_SYSTEMS[sys], prn[0] - (192 if sys == 16 else 0))
                out[key] = (d.P[0], d.L[0], float(d.D[0]), int(d.LLI[0]), rtk.code2obs(d.code[0]))
    finally:
        rtk.free_raw(raw)
    return out


def test_rawx_every_constellation_equals_rtklib() -> None:
    """GPS, Galileo, BeiDou and GLONASS RXM-RAWX (a u-blox 9 log with signal ids): the same rows, values, signal
    codes and LLI (bits 0–1, where there is a phase) as RTKLIB's decoder."""
    path = shared_file("ubx/pygnssutils_pygpsdata_testobsnavdata.log")
    theirs = _rtklib_rows(path.read_bytes())
    ours = {}
    for e in observation_epochs(iter_file(path)):
        for i in range(len(e)):
            ours[(e.time.total_ns, int(e.gnss_id[i]), int(e.sv_id[i]))] = (
                float(e.pr_m[i]), float(e.cp_cyc[i]), float(e.dop_hz[i]), int(e.lli[i]), str(e.signal[i]),
                int(e.glo_fcn[i]))
    assert set(ours) == set(theirs)
    assert collections.Counter(k[1] for k in theirs) == {GNSS_GPS: 487, GNSS_GALILEO: 346, GNSS_BEIDOU: 300,
                                                          GNSS_GLONASS: 492}
    for key, (pr, cp, dop, lli, code) in theirs.items():
        a = ours[key]
        assert abs(a[0] - pr) <= 1e-6 and abs(a[2] - dop) <= 1e-3, key
        assert (abs(a[1] - cp) <= 1e-6 and (a[3] & 3) == (lli & 3)) if cp else math.isnan(a[1]), key
        assert a[4] == code, key
        assert (a[5] != FCN_NONE) == (key[1] == GNSS_GLONASS), key


@pytest.mark.slow
@pytest.mark.parametrize("name", ["rover-20181004-1532", "base-20181004-1452"])
def test_m8p_rawx_glonass_channels_and_qzss(name: str) -> None:
    """M8P RXM-RAWX (version 0: no signal ids): GPS, GLONASS and QZSS; each GLONASS entry carries the channel of
    its slot as convbin's header has it (freqId − 7); QZSS as J01…; every signal L1 C/A."""
    obs = "obs.gz" if name.startswith("rover") else "rawx.obs.gz"
    header = read_rinex_obs(shared_file(f"gnss/ublox-m8p-galway-2018/rinex/{name}.{obs}")).header
    systems: collections.Counter[int] = collections.Counter()
    seen: dict[int, int] = {}
    for e in observation_epochs(iter_file(shared_file(f"gnss/ublox-m8p-galway-2018/raw/{name}.ubx.gz"))):
        systems.update(e.gnss_id.tolist())
        assert set(e.signal.tolist()) <= {"1C"}
        for g, s, k in zip(e.gnss_id.tolist(), e.sv_id.tolist(), e.glo_fcn.tolist()):
            if g == GNSS_GLONASS:
                seen[s] = k
            else:
                assert k == FCN_NONE
    assert set(systems) == {GNSS_GPS, GNSS_GLONASS, GNSS_QZSS}
    assert seen == header.glo_fcn
