"""bench/rtk_sim_rtklib.py's pure parts and hil_sim.rtk_scenarios' scoring: RTKLIB rows onto rover epochs, the
matrix figures from per-epoch arrays, and the RINEX export of simulated epochs read back (demo5 itself and the
World are not run here)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hil_sim.rtk_scenarios import SimData, base_age_s, score_epochs
from onboard.formats.rinex_obs import read_rinex_obs
from onboard.gnsstime import GpsTime
from onboard.rtk.types import FCN_NONE, GNSS_GLONASS, GNSS_GPS, LLI_SLIP, ObsEpoch
from tests.bench.bench_modules import load_bench

mod = load_bench("rtk_sim_rtklib")
T0 = GpsTime(1712, 266_400 * 1_000_000_000)


def _epoch(t: GpsTime, k: int) -> ObsEpoch:
    gnss = np.array([GNSS_GPS, GNSS_GPS, GNSS_GLONASS], np.int8)
    return ObsEpoch(time=t, gnss_id=gnss, sv_id=np.array([3, 17, 9], np.int16),
                    pr_m=np.array([2.1e7, 2.3e7, 2.2e7]) + k, cp_cyc=np.array([1.1e8, 1.2e8, 1.17e8]) + 5.25 * k,
                    dop_hz=np.array([-120.5, 830.25, 40.0]), cn0_dbhz=np.array([44.0, 38.0, 41.0]),
                    lock_ms=np.full(3, 1000.0), lli=np.array([0, LLI_SLIP if k == 1 else 0, 0], np.uint8),
                    glo_fcn=np.array([FCN_NONE, FCN_NONE, -2], np.int8), signal=np.array(["1C"] * 3))


def test_solutions_per_epoch_matches_rows_to_rover_epochs() -> None:
    rover_s = 1712 * 604800.0 + 266_400 + np.arange(5) - 0.008  # tags at ...992 ms
    truth = np.array([100.0, 200.0, 300.0])
    rows = np.array([
        [1712, 266_400.0 - 0.0085, *(truth + [0.03, 0, 0]), 1],  # epoch 0, fixed, 3 cm
        [1712, 266_402.0 - 0.0075, *(truth + [0, 0.2, 0]), 1],  # epoch 2, fixed, 20 cm: wrong
        [1712, 266_403.0 - 0.0080, *(truth + [1.0, 0, 0]), 2],  # epoch 3, float
        [1712, 266_404.5, *truth, 1],  # 0.5 s off any epoch: ignored
    ])
    q, err = mod.solutions_per_epoch(rows, rover_s, lambda week, tow: truth)
    assert q.tolist() == [1, 0, 1, 2, 0]
    np.testing.assert_allclose(err[[0, 2, 3]], [0.03, 0.2, 1.0])
    assert np.isnan(err[[1, 4]]).all()
    q0, err0 = mod.solutions_per_epoch(np.zeros((0, 6)), rover_s, lambda week, tow: truth)
    assert q0.tolist() == [0] * 5 and np.isnan(err0).all()


def test_score_epochs_airborne_wrong_and_first_fix() -> None:
    q = np.array([2, 1, 1, 0, 1, 1])
    err = np.array([0.5, 0.01, 0.02, np.nan, 0.3, 0.01])
    armed = np.array([False, False, True, True, True, True])
    age = np.array([0.0, 0.0, 1.0, 2.0, 31.0, 0.0])  # epoch 4 stale: not airborne, but its wrong fix counts
    r = score_epochs(q, err, armed, age, np.arange(6.0) * 2)
    assert r["airborne"] == 3 and r["air fix %"] == pytest.approx(200 / 3)
    assert r["wrong"] == 1 and r["stale wrong"] == 1 and r["stale"] == 1
    assert r["first fix s"] == 2.0 and r["fixed"] == 4 and r["solved"] == 5
    assert r["max cm"] == pytest.approx(30.0)
    assert r["3D RMS cm"] == pytest.approx(100 * np.sqrt(np.mean(np.array([0.01, 0.02, 0.3, 0.01]) ** 2)))
    none = score_epochs(np.zeros(3, int), np.full(3, np.nan), np.ones(3, bool), np.zeros(3), np.arange(3.0))
    assert none["air fix %"] == 0.0 and np.isnan(none["first fix s"]) and none["wrong"] == 0


def test_base_age_counts_the_newest_base_epoch() -> None:
    rover = [_epoch(T0.add_s(k - 0.008), k) for k in range(4)]
    base = [_epoch(T0.add_s(k - 0.008), k) for k in (0, 1)]
    np.testing.assert_allclose(base_age_s(rover, base, 0.005), [0.0, 0.0, 1.0, 2.0])
    assert np.isinf(base_age_s(rover, base[1:], 0.005)[0])


def test_rinex_export_reads_back(tmp_path: Path) -> None:
    rover = [_epoch(T0.add_s(k - 0.008), k) for k in range(3)]
    base = [_epoch(T0.add_s(k - 0.008), k) for k in (0, 2)]
    data = SimData(rover, base, None, np.array([-3960704.75, 3349563.54, 3698945.77]),  # type: ignore[arg-type]
                   lambda t: {"antenna_ecef_m": np.array([-3960700.0, 3349560.0, 3698940.0])}, None, 0, 0)
    rover_path, base_path = mod.write_rinex_inputs(data, tmp_path)
    back = read_rinex_obs(rover_path)
    assert len(back.epochs) == 3 and back.header.glo_fcn == {9: -2}
    for a, b in zip(rover, back.epochs):
        assert abs(b.time.diff_s(a.time)) < 1e-7
        assert b.sv_id.tolist() == a.sv_id.tolist() and b.gnss_id.tolist() == a.gnss_id.tolist()
        np.testing.assert_allclose(b.pr_m, a.pr_m, atol=1e-3)
        np.testing.assert_allclose(b.cp_cyc, a.cp_cyc, atol=1e-3)
        assert b.lli.tolist() == a.lli.tolist()
        assert b.glo_fcn.tolist() == [FCN_NONE, FCN_NONE, -2]
    base_back = read_rinex_obs(base_path)
    assert [e.time.diff_s(T0) for e in base_back.epochs] == pytest.approx([-0.008, 1.992])
    np.testing.assert_allclose(base_back.header.approx_pos_ecef_m, data.base_pos_ecef_m, atol=1e-4)


def test_summary_over_seeds() -> None:
    runs = [{"air fix %": 20.0, "fix %": 30.0, "first fix s": 10.0, "wrong": 2, "fixed": 100},
            {"air fix %": 60.0, "fix %": 50.0, "first fix s": float("nan"), "wrong": 0, "fixed": 0},
            {"air fix %": 40.0, "fix %": 70.0, "first fix s": 30.0, "wrong": 3, "fixed": 150}]
    assert mod.summary(runs) == ("air % 20.0 / 40.0 / 40.0, all % 30.0 / 50.0 / 50.0, 1st fix 20 s, wrong 5 of 250 "
                                 "fixed (2.0 %) in 2 seeds")


def test_undetected_slips_of_a_harsh_case_set_the_rover_environment_too() -> None:
    from hil_sim.rtk_scenarios import SimCase, scenario_for
    from hil_sim.scenario import HARSH

    assert scenario_for(SimCase("h", "", harsh=True), "m8t").rover_environment == HARSH
    sc = scenario_for(SimCase("h", "", harsh=True, undetected_slips_per_h=0.5), "m8t")
    assert sc.rover_environment.unflagged_slips_per_h == 0.5 and sc.errors.slip_undetected_rate_per_h == 0.5
    assert sc.rover_environment.lli_slips_per_h == HARSH.lli_slips_per_h
