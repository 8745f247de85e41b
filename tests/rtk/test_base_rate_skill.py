"""Carrying the last base epoch across a radio gap from its first second, under a hold, for a satellite whose
correction rate has been predicting the base's own data (`base_rate_skill_min`).

Synthetic histories of the base's phase − modelled range (cycles, 1 Hz, GPS slots): a satellite whose
ionosphere drifts steadily (6 mm/s, what hil_sim's solar-maximum sky gives a satellite of the gr-2012 world),
one with multipath that does not continue its trend, and quiet ones.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from onboard.gnsstime import GpsTime
from onboard.rtk.consts import LAMBDA_L1_M
from onboard.rtk.ephemeris import SatState
from onboard.rtk.options import RtkOptions
from onboard.rtk.rtkpos import (
    NSAT,
    RtkState,
    _extrapolated_base,
    _rate_skill,
    _Receiver,
    _remember_base,
    rtk_init,
)

DRIFT_CYC_S = 0.006 / LAMBDA_L1_M
"""6 mm/s of a steadily drifting ionosphere, in L1 cycles per second."""
T0 = GpsTime(1712, 266_400 * 10**9)
SLOTS = [1, 4, 7, 12, 19, 24]
DRIFTING, MULTIPATH = SLOTS[0], SLOTS[1]


def _multipath_cyc(t_s: np.ndarray) -> np.ndarray:
    """A reflection's 25-s oscillation, 2 cm: its trend over a few seconds reverses within the window."""
    return 0.02 * np.sin(2.0 * np.pi * t_s / 25.0) / LAMBDA_L1_M


def test_the_skill_tells_a_steady_drift_from_multipath() -> None:
    rng = np.random.default_rng(3)
    tk = np.arange(-20.0, 1.0)  # newest last, relative to it
    noise = rng.normal(0.0, 0.003 / LAMBDA_L1_M, (tk.size, 3))
    z = np.column_stack([DRIFT_CYC_S * tk, _multipath_cyc(tk + 3.0), np.zeros(tk.size)]) + noise
    skill = _rate_skill(z, tk, 5.0)
    assert skill[0] > 0.9  # the line fitted to -20 … -6 s predicts the last 5 s
    assert skill[1] < 0.5  # the reflection's trend turned: no better than holding
    assert skill[2] < 0.5  # noise alone
    # too few epochs on either side to tell
    assert np.all(_rate_skill(z[-4:], tk[-4:], 5.0) == -np.inf)
    assert np.all(_rate_skill(z[:3], tk[:3], 0.5) == -np.inf)


def _receiver(cp_cyc: np.ndarray) -> _Receiver:
    n = NSAT
    sats = SatState(np.arange(1, n + 1, dtype=np.int16), np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n),
                    np.zeros(n), np.zeros(n), np.ones(n, bool))
    has = np.isfinite(cp_cyc)
    return _Receiver(np.where(has, 2.2e7, np.nan), cp_cyc, np.zeros(n), np.zeros(n, np.uint8), sats, has)


def _history(options: RtkOptions) -> tuple[RtkState, _Receiver]:
    """A filter state that has seen 21 s of base epochs (the last one returned) before a gap."""
    st = rtk_init(options)
    rng = np.random.default_rng(7)
    last = None
    for k in range(21):
        t = float(k)
        zb = np.full(NSAT, np.nan)
        zb[SLOTS] = rng.normal(0.0, 0.002 / LAMBDA_L1_M, len(SLOTS))
        zb[DRIFTING] += DRIFT_CYC_S * t
        zb[MULTIPATH] += _multipath_cyc(np.array([t + 3.0]))[0]
        last = _receiver(1000.0 + zb)
        _remember_base(st, last, T0.add_s(t), zb)
    assert last is not None
    return st, last


def test_under_a_hold_a_predicting_rate_is_carried_from_the_first_second() -> None:
    st, last = _history(RtkOptions())
    st.held_prns[SLOTS] = True
    carried = _extrapolated_base(st, last, 2.0).cp_cyc - last.cp_cyc
    # the drifting satellite moves with its rate from the gap's start: 2 s × 6 mm/s, within the fit's noise
    assert abs(carried[DRIFTING] * LAMBDA_L1_M - 0.012) < 0.002
    # the reflection waits for base_extrapolate_min_age_s, as before; a quiet satellite's rate is noise, carried
    # or not (its skill is luck), a fraction of a millimetre
    assert carried[MULTIPATH] == 0.0
    quiet = [s for s in SLOTS if s not in (DRIFTING, MULTIPATH)]
    assert np.all(np.abs(carried[quiet]) * LAMBDA_L1_M < 0.001)
    # past it, those are carried from there (rate × (age − 5 s)), the drifting one over the whole age
    later = _extrapolated_base(st, last, 8.0).cp_cyc - last.cp_cyc
    assert abs(later[DRIFTING] * LAMBDA_L1_M - 0.048) < 0.006
    assert abs(later[MULTIPATH]) > 0.0


def test_without_a_hold_or_with_the_option_off_the_first_seconds_stay_raw() -> None:
    st, last = _history(RtkOptions())
    assert np.array_equal(_extrapolated_base(st, last, 2.0).cp_cyc, last.cp_cyc, equal_nan=True)  # float: raw
    st, last = _history(replace(RtkOptions(), base_rate_skill_min=1.0))
    st.held_prns[SLOTS] = True
    assert np.array_equal(_extrapolated_base(st, last, 2.0).cp_cyc, last.cp_cyc, equal_nan=True)
    # from 5 s on, the carrying of before, starting from zero there
    off = _extrapolated_base(st, last, 8.0).cp_cyc - last.cp_cyc
    st, last = _history(RtkOptions())
    on = _extrapolated_base(st, last, 8.0).cp_cyc - last.cp_cyc  # not held: the same as off
    assert np.array_equal(off, on, equal_nan=True)
    assert abs(off[DRIFTING] * LAMBDA_L1_M - 0.018) < 0.003  # 3 s × 6 mm/s: the first 5 s of drift stay


def test_the_option_must_be_a_number() -> None:
    with pytest.raises(ValueError, match="base_rate_skill_min"):
        RtkOptions(base_rate_skill_min=float("nan"))
