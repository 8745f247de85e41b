"""Slips from time-differenced phase (onboard.rtk.tdcp_slips): blind to the receiver's motion and clock, a slip
of one or several satellites flagged alone, undecidable with too few satellites."""

from __future__ import annotations

import numpy as np
import pytest

from onboard.rtk.consts import LAMBDA_L1_M
from onboard.rtk.tdcp_slips import MIN_SATS, tdcp_slips

N = 10
LAM = np.full(N, LAMBDA_L1_M)
LAM[6:] = 299792458.0 / (1602e6 + 5 * 562.5e3)  # GLONASS channel +5: its own cycle


def _sky(seed: int = 1) -> np.ndarray:
    """N unit lines of sight above 10° elevation (a local frame stands in for ECEF: the test is frame-free)."""
    rng = np.random.default_rng(seed)
    az = rng.uniform(0, 2 * np.pi, N)
    el = rng.uniform(np.radians(10), np.radians(85), N)
    return np.column_stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)])


def _y(los: np.ndarray, move_m: np.ndarray, clock_m: float, noise_m: float = 0.002, seed: int = 2) -> np.ndarray:
    """Phase change minus modelled range change (m): −e·Δx + clock + phase noise."""
    return -los @ move_m + clock_m + np.random.default_rng(seed).normal(0, noise_m, N)


ALL = np.ones(N, bool)


@pytest.mark.parametrize("move", [(0.0, 0.0, 0.0), (0.4, -0.1, 0.05), (20.0, -7.0, 3.0)])
def test_motion_and_clock_between_epochs_are_no_slip(move: tuple[float, float, float]) -> None:
    """A walker's step the Doppler missed (0.4 m), a drone's 20 m, a receiver clock step of 300 km: no flag."""
    los = _sky()
    flags = tdcp_slips(_y(los, np.array(move), 3.0e5), los, LAM, ALL, 0.35)
    assert flags is not None and not flags.any()


@pytest.mark.parametrize("slipped", [[2], [8], [1, 7], [0, 4, 9]])
def test_slipped_satellites_are_flagged_alone(slipped: list[int]) -> None:
    los = _sky()
    y = _y(los, np.array([0.4, -0.1, 0.05]), -12.0)
    sizes = [1.0, -2.0, 0.5]  # cycles; half a cycle is the smallest receiver jump
    for k, cyc in zip(slipped, sizes):
        y[k] += cyc * LAM[k]
    flags = tdcp_slips(y, los, LAM, ALL, 0.35)
    assert flags is not None and flags.nonzero()[0].tolist() == sorted(slipped)


def test_too_few_satellites_cannot_decide() -> None:
    los = _sky()
    y = _y(los, np.zeros(3), 0.0)
    few = np.zeros(N, bool)
    few[:MIN_SATS - 1] = True
    assert tdcp_slips(y, los, LAM, few, 0.35) is None
    # six usable, one slipped: the other five cannot isolate a second, so the verdict stands only while six remain
    six = np.zeros(N, bool)
    six[:MIN_SATS] = True
    y[0] += LAM[0]
    assert tdcp_slips(y, los, LAM, six, 0.35) is None
    flags = tdcp_slips(y, los, LAM, six | (np.arange(N) == 6), 0.35)
    assert flags is not None and flags.nonzero()[0].tolist() == [0]


def test_unusable_and_non_finite_slots_are_not_judged() -> None:
    los = _sky()
    y = _y(los, np.zeros(3), 0.0)
    y[3] = np.nan
    y[5] += 3 * LAM[5]
    usable = ALL.copy()
    usable[5] = False
    flags = tdcp_slips(y, los, LAM, usable, 0.35)
    assert flags is not None and not flags.any()
