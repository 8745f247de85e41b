"""`convert` of an RXM-RAW log (u-blox 6 family) against RTKLIB's own UBX decoder on the same bytes.

The M8P acceptance test compares RXM-RAWX output with RTKLIB's RINEX; this does the same for RXM-RAW, where
LLI comes from mesQI/lli rather than lock time: RTKLIB (pyrtklib `input_ubx`, what convbin runs) decodes the
capture epoch by epoch and every GPS observation we write must carry the same time, satellites, pseudorange,
phase, Doppler (to RINEX rounding) and LLI.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from onboard.formats.rinex_obs import read_rinex_obs
from onboard.gnsstime import NS_PER_S
from onboard.postpro.convert import convert_one
from tests.conftest import shared_file

GPS_EPOCH_POSIX_S = 315_964_800  # RTKLIB's gtime_t counts GPS time from 1970 without leap seconds


def _rtklib_epochs(data: bytes) -> list[tuple[int, dict[int, tuple[float, float, float, int]]]]:
    rtk = pytest.importorskip("pyrtklib", reason="pyrtklib (RTKLIB bindings, bench extra) is not installed")
    raw = rtk.raw_t()
    assert rtk.init_raw(raw, rtk.STRFMT_UBX) == 1
    out = []
    try:
        for byte in data:
            if rtk.input_ubx(raw, byte) == 1:
                t_ns = (raw.time.time - GPS_EPOCH_POSIX_S) * NS_PER_S + round(raw.time.sec * 1e6) * 1000
                rows = {}
                for i in range(raw.obs.n):
                    d = raw.obs.data[i]
                    if 1 <= d.sat <= 32:  # GPS (RTKLIB numbers GPS satellites 1–32 first)
                        rows[d.sat] = (d.P[0], d.L[0], float(d.D[0]), int(d.LLI[0]))
                out.append((t_ns, rows))
    finally:
        rtk.free_raw(raw)
    return out


def test_rxm_raw_observations_and_lli_equal_rtklib(tmp_path: Path) -> None:
    src = shared_file("ubx/rtklib_ubx_20080526.ubx")
    convert_one(src, tmp_path)
    ours = read_rinex_obs(tmp_path / "rtklib_ubx_20080526.obs").epochs
    ref = _rtklib_epochs(src.read_bytes())
    assert len(ours) == len(ref) == 242
    n_obs = n_lli = 0
    for epoch, (t_ns, rows) in zip(ours, ref, strict=True):
        gps = epoch.gps_only()
        assert gps.time.total_ns == t_ns
        assert sorted(int(s) for s in gps.sv_id) == sorted(rows)
        for k, sv in enumerate(gps.sv_id):
            pr, cp, dop, lli = rows[int(sv)]
            for name, ours_v, ref_v in (("pr", gps.pr_m[k], pr), ("cp", gps.cp_cyc[k], cp), ("dop", gps.dop_hz[k], dop)):
                if ref_v == 0.0:  # RTKLIB's "no value"
                    assert np.isnan(ours_v) or ours_v == 0.0, (name, epoch.time, int(sv))
                else:
                    assert abs(ours_v - ref_v) <= 0.0005 + 1e-9 * abs(ref_v), (name, epoch.time, int(sv), ours_v, ref_v)
            assert int(gps.lli[k]) == lli, (epoch.time, int(sv))
            n_obs += 1
            n_lli += lli != 0
    assert n_obs > 2000 and n_lli > 10  # the comparison covers slips, not only clean tracking
