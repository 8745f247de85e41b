"""The M8P walk under trees with GPS+GLONASS against the receiver's own RTK fixes: a large integer set is not
refused by a float made overconfident by correlated code, the first fix's confirmation survives satellites coming
and going, and the walker's first steps (which the 1 Hz Doppler misses) are no slips of the held set; the
weak signals' code weighted less, and the GLONASS channels' code biases learned at fixes, keep the float near the
truth."""

from __future__ import annotations

from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from onboard.postpro.inputs import RtkRunInputs, load_rtk_inputs
from onboard.rtk.geodesy import ecef_to_llh, enu_rotation
from onboard.rtk.options import RtkOptions
from onboard.rtk.postpro import postprocess
from onboard.rtk.types import Q_FIX
from tests.conftest import shared_file

pytestmark = pytest.mark.slow
M8P = "gnss/ublox-m8p-galway-2018/"
BASE_ECEF_M = [3774085.6456, -601662.5769, 5089316.3970]
OPTIONS = RtkOptions(systems="GR")
BEFORE_CODE_MODEL = replace(OPTIONS, code_cn0_ref_dbhz=0.0, glonass_code_bias_min_epochs=0)
"""The code weighted by elevation alone and taken as it comes: the engine on which the first tests' mechanisms
were measured (the code model since moves their figures)."""


@cache
def _inputs(rover: Path, base: Path, nav: Path) -> RtkRunInputs:
    return load_rtk_inputs(rover, base, [nav], BASE_ECEF_M, systems="GR")


def _run(options: RtkOptions, horizontal: bool = False, direction: str = "forward"
         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rover tow s, Q, 3D (or horizontal) distance (m) from the M8P's own fixed solution at that tow, NaN where
    it has none)."""
    run = _inputs(shared_file(M8P + "rinex/rover-20181004-1532.obs.gz"),
                  shared_file(M8P + "rinex/base-20181004-1452.rawx.obs.gz"),
                  shared_file(M8P + "rinex/rover-20181004-1532.nav.gz"))
    ref = np.loadtxt(shared_file(M8P + "ref/rover-20181004-1532.m8p_rtk_fixed.csv"), delimiter=",", skiprows=1)
    sols, _ = postprocess(run.rover, run.base, run.nav, run.base_pos_ecef_m, options, direction)
    tow = np.array([s.time.tow_ns / 1e9 for s in sols])
    q = np.array([s.q for s in sols])
    j = np.clip(np.searchsorted(ref[:, 0], tow), 1, len(ref) - 1)
    j = np.where(np.abs(ref[j - 1, 0] - tow) < np.abs(ref[j, 0] - tow), j - 1, j)
    diff = np.array([s.pos_ecef_m for s in sols]) - ref[j, 1:4]
    if horizontal:
        lat, lon, _ = ecef_to_llh(ref[0, 1:4])
        diff = (diff @ enu_rotation(lat, lon).T)[:, :2]
    d = np.linalg.norm(diff, axis=1)
    d[np.abs(ref[j, 0] - tow) > 0.06] = np.nan
    return tow, q, d


def test_a_large_set_is_not_refused_by_a_float_overconfident_under_trees() -> None:
    """Standing under trees, the float is 0.5-1.6 m off with a covariance a few decimetres wide (code multipath
    correlated over tens of seconds); the full set of 11-12 double differences that wins the ratio test from
    60 s on is right (its fixed position within 3 cm of the M8P's), yet lies at Mahalanobis 16.3-68 from the
    float (105 refused epochs over the walk). With the float's covariance × 4 in that test for such sets the walk fixes from about 62 s and over
    35 % of its epochs, none more than 10 cm from the M8P's fixes horizontally; with the plain test, not before
    150 s and under 30 %."""
    tow, q, d = _run(OPTIONS, horizontal=True)
    first = tow[np.argmax(q == Q_FIX)] - tow[0]
    assert 55.0 <= first <= 75.0
    assert np.mean(q == Q_FIX) > 0.35
    early = (q == Q_FIX) & (tow - tow[0] < 150.0) & np.isfinite(d)
    assert early.sum() >= 40 and np.all(d[early] < 0.03)
    checked = (q == Q_FIX) & np.isfinite(d)
    assert checked.sum() >= 300 and np.all(d[checked] < 0.10)
    tow, q, _ = _run(replace(BEFORE_CODE_MODEL, float_fix_gate_scale=1.0))
    assert tow[np.argmax(q == Q_FIX)] - tow[0] >= 150.0 and np.mean(q == Q_FIX) < 0.30


def test_a_confirmation_goes_on_while_satellites_come_and_go() -> None:
    """Standing under trees for the first 220 s, the walker's set keeps its integers while satellites join and
    leave every few seconds: carried across those changes the confirmation fixes at 162 s (every fix of the
    first 180 s within 3 cm of the M8P's); restarted with each, not before 400 s. (With the float-fix test as it
    was before float_fix_gate_scale, which otherwise lets the set fix at 62 s, and BEFORE_CODE_MODEL, whose
    better float otherwise fixes at 232 s even without the carried confirmation.)"""
    tow, q, d = _run(replace(OPTIONS, float_fix_gate_scale=1.0, code_cn0_ref_dbhz=0.0))
    first = tow[np.argmax(q == Q_FIX)] - tow[0]
    assert 150.0 <= first <= 170.0
    early = (q == Q_FIX) & (tow - tow[0] < 180.0) & np.isfinite(d)
    assert early.sum() >= 15 and np.all(d[early] < 0.03)
    tow, q, _ = _run(replace(BEFORE_CODE_MODEL, float_fix_gate_scale=1.0, confirm_across_set_changes=False))
    assert tow[np.argmax(q == Q_FIX)] - tow[0] >= 390.0


def test_the_walkers_first_steps_are_no_slips_of_the_held_set() -> None:
    """At 401794 s the walker sets off: the Doppler, once a second, misses the antenna's swing by up to 1.9
    cycles and flags six of the twelve held satellites, none of which slipped (their phase stays on the M8P's
    position). The time-differenced phase clears them and the fix stays within 3 cm of the M8P's to 401806 s;
    on the Doppler alone the hold is left on four double differences and its fix goes 10-20 cm off."""
    tow, q, d = _run(OPTIONS)
    steps = (tow >= 401790.0) & (tow <= 401806.5)
    assert np.all(q[steps] == Q_FIX) and np.nanmax(d[steps]) < 0.03
    tow, q, d = _run(replace(OPTIONS, tdcp_slip_test=False))
    fixed = steps & (q == Q_FIX)
    assert np.nanmax(d[fixed]) > 0.1


def test_combined_passes_hand_their_fixes_over() -> None:
    """Post-processed forward and backward, each direction loses its hold at the walker's slips and confirms a
    new first fix only later, while the other direction crossed those epochs fixed. The backward pass pinned to
    the forward fix where a run of forward fixes starts carries that fix on into the epochs before: the walk
    combined fixes over 92 % of its epochs (95.5 %, from the first epoch on), at least 3 points more than when
    the passes are only combined as RTKLIB does (89.4 %), and no fixed epoch lies more than 10 cm from the M8P's
    fixes horizontally. (With BEFORE_CODE_MODEL: 61.2 against 53.2 %.)"""
    _tow, q, d = _run(OPTIONS, horizontal=True, direction="combined")
    assert np.mean(q == Q_FIX) > 0.92
    assert q[0] == Q_FIX
    checked = (q == Q_FIX) & np.isfinite(d)
    assert checked.sum() >= 500 and np.all(d[checked] < 0.10)
    _, q_plain, _ = _run(replace(OPTIONS, combined_handover=False), direction="combined")
    assert np.mean(q_plain == Q_FIX) < np.mean(q == Q_FIX) - 0.03


def test_weak_signals_code_does_not_drag_the_float_off() -> None:
    """Under the trees the weak signals' code is the biased code: against the M8P's fixes, single-differenced
    code residuals have an RMS of 2.2 m at ≥ 45 dB-Hz, 5.9 m at 35-40 and 9.8 m at 30-35 dB-Hz (in proportion
    to 10^(−C/N0/20)). Weighted as strong code it holds the float further off: weighted by C/N0
    (code_cn0_ref_dbhz, the channel biases left alone), the walk forward fixes over 47 % of its epochs (49.7 %),
    against under 42 % (38.6 %) without, none more than 10 cm from the M8P's fixes horizontally."""
    _tow, q, d = _run(replace(BEFORE_CODE_MODEL, code_cn0_ref_dbhz=OPTIONS.code_cn0_ref_dbhz), horizontal=True)
    assert np.mean(q == Q_FIX) > 0.47
    checked = (q == Q_FIX) & np.isfinite(d)
    assert checked.sum() >= 380 and np.all(d[checked] < 0.10)
    _, q_off, _ = _run(BEFORE_CODE_MODEL)
    assert np.mean(q_off == Q_FIX) < 0.42


def test_glonass_channel_code_biases_learned_at_fixes_keep_the_float_near_the_truth() -> None:
    """The rover's and base's M8P code delays differ by GLONASS channel (SD code residuals at the M8P's fixes,
    strong signals, 90-560 s: R08 −4.1 m, R09 and R10 −1.2 m, R01 +0.8 m, relative to the others). Taken as they
    come, they hold the float 2.3-2.6 m too high with a 0.11 m σ through 870-920 s, and 720-1095 s stays float.
    Learned at the fixed epochs (glonass_code_bias_min_epochs) and taken off the code, the walk forward fixes
    over 72 % of its epochs (76.4 %), against under 55 % (49.7 %) without, from 62 s as before, none more than
    10 cm from the M8P's fixes horizontally."""
    tow, q, d = _run(OPTIONS, horizontal=True)
    assert np.mean(q == Q_FIX) > 0.72
    assert 55.0 <= tow[np.argmax(q == Q_FIX)] - tow[0] <= 75.0
    checked = (q == Q_FIX) & np.isfinite(d)
    assert checked.sum() >= 450 and np.all(d[checked] < 0.10)
    late = checked & (tow - tow[0] > 720.0) & (tow - tow[0] < 1095.0)
    assert late.sum() >= 50  # the span that stayed float
    _, q_off, _ = _run(replace(OPTIONS, glonass_code_bias_min_epochs=0))
    assert np.mean(q_off == Q_FIX) < 0.55
