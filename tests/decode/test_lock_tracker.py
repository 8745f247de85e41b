"""RTKLIB's RXM-RAWX loss-of-lock rules (ublox.c decode_rxmrawx) applied across epochs by LockTracker."""

from __future__ import annotations

import math

import numpy as np

from onboard.gnsstime import GpsTime
from onboard.receiver.decode import LockTracker, LockTrackerOptions
from onboard.rtk.types import GNSS_BEIDOU, GNSS_GPS, LLI_HALF_CYCLE, LLI_SLIP, ObsEpoch


def _epoch(k: int, lock_ms: float, cp: float = 1000.0, half_sub: int = 0, half_unresolved: bool = False,
           cp_std_code: int = 1, gnss: int = GNSS_GPS, sv: int = 5) -> ObsEpoch:
    lli = (LLI_HALF_CYCLE if half_unresolved else 0) | (LLI_SLIP if lock_ms == 0 else 0)
    return ObsEpoch(
        time=GpsTime(2021, k * 1_000_000_000), gnss_id=np.array([gnss], np.int8), sv_id=np.array([sv], np.int16),
        pr_m=np.array([2e7]), cp_cyc=np.array([cp]), dop_hz=np.array([100.0]), cn0_dbhz=np.array([45.0]),
        lock_ms=np.array([lock_ms]), lli=np.array([lli], np.uint8), half_cyc_sub=np.array([half_sub], np.uint8),
        pr_std_m=np.array([0.32]), cp_std_cyc=np.array([0.004 * cp_std_code]),
    )


def _run(epochs: list[ObsEpoch], tracker: LockTracker | None = None) -> list[tuple[float, int]]:
    tracker = tracker or LockTracker()
    out = []
    for e in epochs:
        u = tracker.update(e)
        out.append((float(u.cp_cyc[0]), int(u.lli[0])))
    return out


def test_continuous_lock_has_no_slip() -> None:
    res = _run([_epoch(k, 1000.0 * (k + 1)) for k in range(5)])
    assert [lli for _, lli in res] == [0] * 5


def test_lock_time_zero_or_decreasing_is_a_slip() -> None:
    res = _run([_epoch(0, 5000), _epoch(1, 6000), _epoch(2, 0), _epoch(3, 1000), _epoch(4, 500), _epoch(5, 1500)])
    assert [lli for _, lli in res] == [0, 0, LLI_SLIP, 0, LLI_SLIP, 0]


def test_half_cycle_subtracted_flag_change_is_a_slip_both_ways() -> None:
    res = _run([_epoch(0, 5000, half_sub=0), _epoch(1, 6000, half_sub=1), _epoch(2, 7000, half_sub=1),
                _epoch(3, 8000, half_sub=0)])
    assert [lli for _, lli in res] == [0, LLI_SLIP, 0, LLI_SLIP]


def test_first_report_with_half_cycle_subtracted_is_a_slip() -> None:
    # RTKLIB's state starts at "not subtracted": the M8P rover's G22 gets LLI 1 on the first epoch this way.
    assert _run([_epoch(0, 64500, half_sub=1)]) == [(1000.0, LLI_SLIP)]


def test_half_cycle_unresolved_flag_only_on_valid_phase() -> None:
    res = _run([_epoch(0, 500, half_unresolved=True), _epoch(1, 600, cp=math.nan, half_unresolved=True)])
    assert res[0] == (1000.0, LLI_HALF_CYCLE)
    assert math.isnan(res[1][0]) and res[1][1] == 0


def test_slip_while_phase_invalid_is_carried_to_next_valid_phase() -> None:
    res = _run([_epoch(0, 5000), _epoch(1, 0, cp=math.nan), _epoch(2, 1000, cp=math.nan), _epoch(3, 2000),
                _epoch(4, 3000)])
    assert [lli for _, lli in res] == [0, 0, 0, LLI_SLIP, 0]


def test_cp_std_above_threshold_drops_phase_and_high_code_is_a_slip() -> None:
    res = _run([_epoch(0, 5000, cp_std_code=5), _epoch(1, 6000, cp_std_code=6), _epoch(2, 7000, cp_std_code=1)])
    assert res[0] == (1000.0, 0)  # code 5 (0.020 cycles) is still valid for a Gen8 receiver
    assert math.isnan(res[1][0])
    assert res[2] == (1000.0, 0)
    res = _run([_epoch(0, 5000), _epoch(1, 6000, cp_std_code=15), _epoch(2, 7000)])
    assert math.isnan(res[1][0]) and res[2] == (1000.0, LLI_SLIP)
    # a looser threshold keeps the phase of code 6
    loose = _run([_epoch(0, 5000, cp_std_code=6)], LockTracker(LockTrackerOptions(max_cp_std_code=14)))
    assert loose == [(1000.0, 0)]


def test_satellites_are_tracked_independently() -> None:
    tracker = LockTracker()
    tracker.update(_epoch(0, 9000, sv=5))
    tracker.update(_epoch(1, 1000, sv=7))
    assert int(tracker.update(_epoch(2, 2000, sv=7)).lli[0]) == 0
    assert int(tracker.update(_epoch(3, 8000, sv=5)).lli[0]) == LLI_SLIP


def test_beidou_geo_half_cycle_shift() -> None:
    out = LockTracker().update(_epoch(0, 5000, gnss=GNSS_BEIDOU, sv=3))
    assert float(out.cp_cyc[0]) == 1000.5
    out = LockTracker().update(_epoch(0, 5000, gnss=GNSS_BEIDOU, sv=20))
    assert float(out.cp_cyc[0]) == 1000.0


def test_rxm_raw_epochs_pass_through() -> None:
    e = _epoch(0, 0)
    raw = ObsEpoch(time=e.time, gnss_id=e.gnss_id, sv_id=e.sv_id, pr_m=e.pr_m, cp_cyc=e.cp_cyc, dop_hz=e.dop_hz,
                   cn0_dbhz=e.cn0_dbhz, lock_ms=np.array([np.nan]), lli=np.array([3], np.uint8))
    assert LockTracker().update(raw) is raw
