"""Standstill detection from time-differenced phase (onboard.rtk.standstill) on synthetic geometry."""

from __future__ import annotations

import numpy as np

from onboard.rtk.standstill import CHI2_3DOF_999, StandstillMonitor, tdcp_displacement

NSAT = 32
LAMBDA_M = 0.19029367279836487


def _los(n: int, seed: int = 3) -> np.ndarray:
    """Unit lines of sight to `n` satellites above 15° spread in azimuth (rows), on slots 0..n−1 of 32."""
    rng = np.random.default_rng(seed)
    az = np.linspace(0.0, 2 * np.pi, n, endpoint=False) + rng.uniform(0, 0.3, n)
    el = np.radians(np.linspace(20.0, 80.0, n))
    los = np.full((NSAT, 3), np.nan)
    los[:n] = np.column_stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)])
    return los


def _sd(los: np.ndarray, offset_m: np.ndarray, clock_m: float, amb_cyc: np.ndarray, noise: np.ndarray) -> np.ndarray:
    """SD phase − modelled range (m) of a rover `offset_m` from the position the range was modelled at."""
    return -(los @ offset_m) + clock_m + LAMBDA_M * amb_cyc + noise


def test_displacement_is_recovered_to_millimetres_whatever_the_ambiguities_and_clocks():
    los = _los(8)
    rng = np.random.default_rng(1)
    amb = np.where(np.arange(NSAT) < 8, rng.integers(-1000, 1000, NSAT), 0).astype(float)
    var = np.full(NSAT, 0.002**2)
    usable = np.arange(NSAT) < 8
    x0 = np.array([100.0, 200.0, 300.0])
    truth_move = np.array([0.30, -0.12, 0.05])
    # the filter's position guess moved by 0.1 m between epochs: it must be taken out
    x1 = x0 + np.array([0.1, 0.0, 0.0])
    sd0 = _sd(los, np.zeros(3), 123.4, amb, rng.normal(0, 0.002, NSAT))
    sd1 = _sd(los, x0 + truth_move - x1, -45.6, amb, rng.normal(0, 0.002, NSAT))
    d = tdcp_displacement(sd0, x0, sd1, x1, los, var, usable)
    assert d is not None and d.n_sats == 8
    assert np.abs(d.d_m - truth_move).max() < 0.01
    assert d.chi2 > CHI2_3DOF_999 * 100  # 30 cm is motion
    # a slot not continuous (slip) is left out; too few continuous slots: no verdict
    assert tdcp_displacement(sd0, x0, sd1, x1, los, var, np.arange(NSAT) < 4) is None


def test_monitor_sees_a_standstill_after_the_window_and_motion_at_once():
    los = _los(7)
    rng = np.random.default_rng(2)
    amb = np.where(np.arange(NSAT) < 7, 50.0, np.nan)
    var = np.full(NSAT, 0.003**2)
    valid = np.arange(NSAT) < 7
    mon = StandstillMonitor(window_s=10.0)
    lock = np.zeros(NSAT, np.int64)
    pos = np.zeros(3)
    t0 = 10**15
    still = []
    for k in range(30):
        lock[valid] += 1
        moving = k >= 20
        truth = np.array([0.0, 0.5 * (k - 20), 0.0]) if moving else np.zeros(3)
        sd = _sd(los, truth, rng.normal(0, 5.0), amb, rng.normal(0, 0.002, NSAT))
        mon.update(t0 + k * 10**9, sd, pos, los, var, lock, valid)
        still.append(mon.still_for_s(t0 + k * 10**9))
    assert still[0] == 0.0  # no window yet
    assert still[1] == 1.0 and still[10] == 10.0 and still[19] == 19.0
    assert still[21] == 0.0  # 0.5 m in one second: motion at once
    assert max(still[21:]) == 0.0


def test_monitor_leaves_out_a_satellite_that_slipped_inside_the_window():
    los = _los(7)
    amb = np.where(np.arange(NSAT) < 7, 10.0, np.nan)
    var = np.full(NSAT, 0.003**2)
    valid = np.arange(NSAT) < 7
    mon = StandstillMonitor(window_s=5.0)
    lock = np.zeros(NSAT, np.int64)
    t0 = 10**15
    for k in range(8):
        lock[valid] += 1
        a = amb.copy()
        if k >= 4:
            a[2] += 7.0  # slot 2 slipped 7 cycles at epoch 4: its lock count restarted
            if k == 4:
                lock[2] = 1
        d = mon.update(t0 + k * 10**9, _sd(los, np.zeros(3), 0.0, a, np.zeros(NSAT)), np.zeros(3), los, var, lock,
                       valid)
        if k >= 1:
            assert d is not None and np.abs(d.d_m).max() < 1e-6, (k, d)
            assert d.n_sats == (6 if 4 <= k <= 8 else 7)


def _standing_with_a_hidden_slip(cycles: float, exclude_one: bool, motion_m=(0.0, 0.0, 0.0), n: int = 8):
    """A rover standing 12 epochs; slot 3 jumps `cycles` at epoch 8 with its lock count running on (no LLI),
    the rover moves `motion_m` from epoch 8 too. Returns (monitor, displacements, slipped slots per epoch)."""
    los = _los(n)
    rng = np.random.default_rng(5)
    amb = np.where(np.arange(NSAT) < n, 20.0, np.nan)
    var = np.full(NSAT, 0.003**2)
    valid = np.arange(NSAT) < n
    mon = StandstillMonitor(window_s=5.0)
    lock = np.zeros(NSAT, np.int64)
    disps, slipped = [], []
    for k in range(12):
        lock[valid] += 1
        a = amb.copy()
        if k >= 8:
            a[3] += cycles
        move = np.asarray(motion_m) if k >= 8 else np.zeros(3)
        sd = _sd(los, move, rng.normal(0, 5.0), a, rng.normal(0, 0.002, NSAT))
        disps.append(mon.update(10**15 + k * 10**9, sd, np.zeros(3), los, var, lock, valid, exclude_one))
        slipped.append(mon.slipped_slot)
    return mon, disps, slipped


def test_a_standing_rover_names_the_one_satellite_whose_hidden_slip_fails_the_test():
    # one cycle (19 cm) on slot 3: the full set fails the test; without slot 3 the rest stands still
    mon, disps, slipped = _standing_with_a_hidden_slip(1.0, exclude_one=True)
    assert slipped[:8] == [-1] * 8 and slipped[8] == 3
    assert disps[8] is not None and disps[8].chi2 <= CHI2_3DOF_999 and disps[8].n_sats == 7
    assert mon.still_for_s(10**15 + 8 * 10**9) == 8.0  # the standstill goes on
    # asked not to (the rover moving by Doppler, or not held static), the same slip is motion
    mon, disps, slipped = _standing_with_a_hidden_slip(1.0, exclude_one=False)
    assert slipped[8] == -1 and disps[8].chi2 > CHI2_3DOF_999 and mon.still_for_s(10**15 + 8 * 10**9) == 0.0


def test_motion_is_not_mistaken_for_a_slip():
    # 15 cm of real motion moves every line of sight: no single exclusion explains it
    mon, disps, slipped = _standing_with_a_hidden_slip(0.0, exclude_one=True, motion_m=(0.12, -0.06, 0.06))
    assert slipped[8] == -1 and disps[8].chi2 > CHI2_3DOF_999 and mon.still_for_s(10**15 + 8 * 10**9) == 0.0
    # with 6 satellites a slip still has 5 to be judged by (one redundant); with 5, no exclusion is tried
    _, _, slipped6 = _standing_with_a_hidden_slip(1.0, exclude_one=True, n=6)
    _, d5, slipped5 = _standing_with_a_hidden_slip(1.0, exclude_one=True, n=5)
    assert slipped6[8] == 3 and slipped5[8] == -1 and d5[8].chi2 > CHI2_3DOF_999


def test_monitor_works_with_sparse_epochs_and_backward_in_time():
    """30 s epochs (GEONET) leave no earlier epoch inside a 10 s window: the previous one serves; a backward
    pass runs time downward."""
    los = _los(6)
    amb = np.where(np.arange(NSAT) < 6, 3.0, np.nan)
    var = np.full(NSAT, 0.003**2)
    valid = np.arange(NSAT) < 6
    for step in (30 * 10**9, -30 * 10**9):
        mon = StandstillMonitor(window_s=10.0)
        lock = np.zeros(NSAT, np.int64)
        for k in range(4):
            lock[valid] += 1
            t = 10**15 + k * step
            d = mon.update(t, _sd(los, np.zeros(3), 1.0 * k, amb, np.zeros(NSAT)), np.zeros(3), los, var, lock, valid)
            assert (d is None) == (k == 0)
        assert mon.still_for_s(t) == 90.0


def test_standing_code_variance_counts_once_per_correlation_time() -> None:
    from dataclasses import replace

    from onboard.rtk.options import RtkOptions, options_from_mapping
    from onboard.rtk.rtkpos import static_code_factor

    o = RtkOptions()
    assert static_code_factor(o, True, 1.0) == o.static_code_correlation_s == 17.0  # 1 Hz: 17 epochs per draw
    assert static_code_factor(o, True, 0.2) == 85.0  # 5 Hz
    assert static_code_factor(o, True, -1.0) == 17.0  # processed backward
    assert static_code_factor(o, True, 30.0) == 1.0  # sparser than the correlation: independent already
    assert static_code_factor(o, False, 1.0) == 1.0  # moving: the multipath decorrelates within seconds
    assert static_code_factor(o, True, 0.0) == 1.0
    off = options_from_mapping({"static_code_correlation_s": 0})
    assert off == replace(o, static_code_correlation_s=0.0) and static_code_factor(off, True, 1.0) == 1.0
