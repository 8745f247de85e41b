"""The issue-3 hil_sim scenarios, short flights, through the real byte paths (`hil_sim.rtk_scenarios`: UBX
RXM-RAW/RAWX → our decoder; base → `BaseCore` RTCM3 1004/1006/1019 → radio with dropouts → `collect_rtcm`).

Flights of 200 s (take-off at 60 s, climb to 84 s, then survey lines); truth = the World's antenna. A wrong
fix is Q=1 more than 10 cm off in 3D, counted over all epochs (those on base data older than 30 s too).
`bench/rtk_sim.py` runs the full 600 s matrix.
"""

from __future__ import annotations

import numpy as np
import pytest

from onboard.rtk.options import RtkOptions
from onboard.rtk.types import Q_FIX, Q_FLOAT, Q_SINGLE
from tests.conftest import shared_file

pytestmark = pytest.mark.shared_data


@pytest.fixture(autouse=True)
def _nav() -> None:
    shared_file("gnss/broadcast-nav-20100701/brdc1820.10n")


def _run(model: str = "m8t", options: RtkOptions | None = None, **kw):  # type: ignore[no-untyped-def]
    from hil_sim.rtk_scenarios import SimCase, evaluate

    return evaluate(SimCase("test", "", duration_s=kw.pop("duration_s", 200.0), **kw), model, options)


_WITHOUT_STATIC_CODE_FACTOR = RtkOptions(static_code_correlation_s=0.0)
"""Standing code weighted as independent at every epoch: the cold-start rules (settled sets) on their own."""


@pytest.mark.parametrize("model", ["lea6t", "m8t"])
@pytest.mark.slow
def test_radio_gaps_of_5_10_20_s_while_flying_keep_the_fix(model: str) -> None:
    gaps = ((100.0, 105.0), (120.0, 130.0), (150.0, 170.0))
    r = _run(model, gaps_s=gaps)
    assert r["wrong"] == 0 and r["stale"] == 0
    assert r["air fix %"] >= 99.0 and r["3D RMS cm"] <= 2.0
    q, k = r["q"], np.arange(len(r["q"]))
    in_gap = np.zeros(len(q), bool)
    for a, b in gaps:
        in_gap |= (k >= a) & (k < b)
    assert set(q[in_gap].tolist()) <= {Q_FIX, Q_FLOAT}  # never single on base data ≤ 30 s old


@pytest.mark.slow
def test_a_45_s_gap_goes_single_past_30_s_never_wrong_and_fixes_after() -> None:
    r = _run("lea6t", gaps_s=((110.0, 155.0),))
    q, stale = r["q"], r["age_s"] > 30.0
    assert 10 <= r["stale"] <= 16 and set(q[stale].tolist()) == {Q_SINGLE}
    assert r["wrong"] == 0 and r["stale fixed"] == 0
    assert np.all(q[156:166] == Q_FIX)  # the held ambiguities are good again as soon as the base is back
    assert r["air fix %"] >= 99.0  # stale epochs excluded


@pytest.mark.slow
def test_known_take_off_point_fixes_at_the_first_epoch() -> None:
    r = _run("m8t", known_start=True)
    assert r["q"][0] == Q_FIX and r["first fix s"] == 0.0
    assert r["wrong"] == 0 and r["air fix %"] >= 99.0 and r["3D RMS cm"] <= 2.0
    # PRN 12 slips at 160 s and is re-initialised from code: it fits the ambiguities seeded from the surveyed
    # point (their receiver-clock part removed) instead of failing as a 168 km outlier every epoch after
    assert r["slips"] <= 8


@pytest.mark.slow
def test_five_satellites_never_report_a_wrong_fix() -> None:
    # 5 satellites (the 5 highest): even the right integers give 3D errors up to 11 cm (σ 6.6 cm) in flight,
    # so the engine holds the fix internally and reports float; nothing it reports as fixed is wrong
    for known in (False, True):
        r = _run("m8t", max_sats=5, known_start=known)
        assert r["wrong"] == 0, known
    assert r["q"][0] == Q_FIX  # with the surveyed take-off point the ground epochs fix at once …
    assert r["max cm"] < 2.0  # … to the centimetre (static mode)


@pytest.mark.slow
def test_undetected_slips_make_no_wrong_fix() -> None:
    r = _run("m8t", undetected_slips_per_h=2.0)
    assert r["wrong"] == 0 and r["slips"] >= 5


@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.slow
def test_5_km_baseline_never_fixes_wrong(seed: int) -> None:
    # seed 2 fixed a set ~1.6 m off at 74 s and held it before the baseline-scaled ambiguity noise; seed 1 one
    # 1.6 m off at 58 s (a partial set after 10 s of wins) before the partial-set confirmation outlasted the
    # code multipath's 30 s correlation time
    r = _run("m8t", baseline_m=5000.0, seed=seed)
    assert r["wrong"] == 0 and r["stale fixed"] == 0



@pytest.mark.slow
def test_undetected_slips_2_per_hour_in_a_600_s_flight_keep_most_airborne_epochs_fixed() -> None:
    # a slip of the DD reference makes every phase residual fail the held fix's check at once: resetting
    # the reference alone (not all seven) keeps the flight fixed (71.6 % → 91.1 % airborne on this one)
    r = _run("m8t", duration_s=600.0, undetected_slips_per_h=2.0)
    assert r["wrong"] == 0 and r["air fix %"] >= 90.0 and r["3D RMS cm"] <= 2.0


@pytest.mark.slow
def test_the_rover_is_held_static_on_the_ground_and_released_at_take_off(caplog: pytest.LogCaptureFixture) -> None:
    """Standstill detection (time-differenced phase) holds the waiting drone static 10 s after the start and
    lets go at take-off (60 s), once each: no flapping on the ground or in flight, and no wrong fix around it."""
    import logging

    with caplog.at_level(logging.INFO, logger="onboard.rtk.rtkpos"):
        r = _run("m8t")
    tow = {}
    for rec in caplog.records:
        msg = rec.getMessage()
        for key in ("static hold", "leaving static mode"):
            if key in msg:
                tow.setdefault(key, []).append(float(msg.split(":")[1]))
    assert len(tow["static hold"]) == 1 and len(tow["leaving static mode"]) == 1, tow
    held_s = tow["leaving static mode"][0] - tow["static hold"][0]
    assert 47.0 <= held_s <= 51.0, held_s  # held from ~10 s to the take-off at ~60 s
    assert r["wrong"] == 0 and r["air fix %"] >= 99.0


@pytest.mark.slow
def test_lea6t_half_cycle_resolved_after_a_slip_makes_no_wrong_fix() -> None:
    # seed 2: rover PRN 27 slips at 510.7 s, its half cycle is resolved (phase moved ½ cycle, RXM-RAW reports
    # no slip) at 513 s; kept, that step made the held set exclude the wrong satellite: 22 fixes 8-16 cm off
    r = _run("lea6t", duration_s=600.0, seed=2)
    assert r["wrong"] == 0
    q = r["q"]
    assert np.all(q[505:560] == Q_FIX)  # the held fix carries on through the slip and the parity fix


@pytest.mark.slow
def test_a_cold_start_fixes_when_the_right_set_keeps_winning_against_an_overconfident_float() -> None:
    # seed 3 (measured u-blox error model), its standing code weighted as independent every epoch
    # (static_code_correlation_s = 0): the right integer set wins the ratio test from 25 s on while the float,
    # built on 60 s of static correlated code multipath, stays 0.6-2.9 m off and rejects it at every epoch
    # for its Mahalanobis distance (no fix in 600 s); once it has won for settled_fix_span_s (60 s) it fixes
    # (82 s, 22 s after the take-off)
    r = _run("m8t", duration_s=600.0, seed=3, options=_WITHOUT_STATIC_CODE_FACTOR)
    assert r["wrong"] == 0 and r["stale fixed"] == 0
    assert r["first fix s"] <= 90.0 and r["air fix %"] >= 95.0 and r["3D RMS cm"] <= 2.0


@pytest.mark.slow
def test_a_cold_start_settles_faster_once_the_rover_flies() -> None:
    # seed 2, its standing code weighted every epoch: the float is 2.2-2.9 m off through the 60 s on the
    # ground (static code multipath, σ of a few decimetres); the right full set wins the ratio test from 65 s
    # on, after take-off, and the float rejects it. Counted at the static rate (settled_fix_span_s, 60 s) it
    # fixes at 125 s; in flight, where the code multipath decorrelates within seconds, it settles in
    # settled_fix_span_moving_s (30 s): 96 s
    from dataclasses import replace

    r = _run("m8t", seed=2, options=_WITHOUT_STATIC_CODE_FACTOR)
    assert r["wrong"] == 0 and 90.0 <= r["first fix s"] <= 100.0
    static_rate = _run("m8t", seed=2, options=replace(_WITHOUT_STATIC_CODE_FACTOR, settled_fix_span_moving_s=60.0))
    assert static_rate["first fix s"] >= 120.0 and static_rate["wrong"] == 0


@pytest.mark.slow
def test_standing_code_counted_once_per_correlation_time_fixes_the_cold_start_on_the_ground() -> None:
    # the same seed with the default static_code_correlation_s (17 s): the standing rover's code gets 17×
    # its variance, the float stops trusting one draw of the multipath as if it were 60, and the right set
    # fixes on the ground (35 s) instead of 36 s after the take-off
    r = _run("m8t", seed=2)
    assert r["wrong"] == 0 and r["first fix s"] <= 60.0
    assert r["air fix %"] == 100.0 and r["3D RMS cm"] <= 2.0


@pytest.mark.slow
def test_a_partial_set_at_5_km_waits_longer_for_its_confirmation() -> None:
    # seed 7: a partial set 1.5 m off won the ratio test (3.1-3.5) for 30 s and was fixed for 3 epochs; the
    # differential ionosphere keeps a u-blox float off for minutes: 6 s per km more (confirm_fix_span_per_km_s)
    r = _run("m8t", duration_s=600.0, baseline_m=5000.0, seed=7)
    assert r["wrong"] == 0 and r["air fix %"] >= 70.0


@pytest.mark.slow
def test_a_partial_set_contradicting_the_full_set_is_not_a_first_fix() -> None:
    # seed 17 at 5 km: partial AR's survivor (6 satellites) had PRN 11, 14 and 25 one cycle off the full set's
    # best integers, won the ratio test at 6-9 for 60 s on a float 10 cm from the truth, and was fixed 35 cm off
    # at 85 s and held (114 wrong epochs in these 200 s without the check)
    from dataclasses import replace

    r = _run("m8t", baseline_m=5000.0, seed=17)
    assert r["wrong"] == 0 and r["first fix s"] <= 120.0 and r["3D RMS cm"] <= 2.0
    unchecked = _run("m8t", replace(RtkOptions(), partial_agrees_with_full=False), baseline_m=5000.0, seed=17)
    assert unchecked["wrong"] > 50


@pytest.mark.slow
def test_no_cold_first_fix_beyond_the_maximum_baseline_but_a_known_take_off_point_fixes() -> None:
    # seed 12 at 20 km: the full set won the ratio test on a float biased by the differential ionosphere and was
    # fixed 28 cm off at 95 s and held, without max_first_fix_baseline_km
    from dataclasses import replace

    r = _run("m8t", baseline_m=20000.0, seed=12)
    assert r["wrong"] == 0 and not np.any(r["q"] == Q_FIX)
    unlimited = _run("m8t", replace(RtkOptions(), max_first_fix_baseline_km=0.0), baseline_m=20000.0, seed=12)
    assert unlimited["wrong"] > 10
    # integers from the surveyed take-off point are known, not guessed: they are held at 10 km
    known = _run("m8t", baseline_m=10000.0, seed=14, known_start=True)
    assert known["wrong"] == 0 and known["first fix s"] == 0.0
    assert known["air fix %"] >= 99.0 and known["3D RMS cm"] <= 2.0


@pytest.mark.slow
def test_a_float_stuck_on_absorbed_slips_restarts_instead_of_fixing_wrong() -> None:
    # the 19:00 sky (6 satellites over the mask), undetected slips 2/h, seed 1: slips absorbed during the cold
    # start left the float 1.7 m off while its ambiguities looked determined (success rate 1.0, ratio 1.0-1.8
    # for 180 s); at 353 s its full set won twice at ratio 3.3, was fixed 1.59 m off and held (217 wrong
    # epochs) before stuck_float_s
    from dataclasses import replace

    # (and full_set_min_dd, since 2026-12-06, refuses that set of 5 double differences on its two wins anyway:
    # off for the counterfactual)
    r = _run("m8t", duration_s=600.0, undetected_slips_per_h=2.0, seed=1, start_hour=19.0)
    assert r["wrong"] == 0 and r["float restarts"] >= 1
    never = _run("m8t", replace(RtkOptions(), stuck_float_s=0.0, full_set_min_dd=0), duration_s=600.0,
                 undetected_slips_per_h=2.0, seed=1, start_hour=19.0)
    assert never["wrong"] > 100 and never["float restarts"] == 0


@pytest.mark.slow
def test_one_cycle_base_slips_are_caught_by_the_base_geometry_check() -> None:
    # seed 3, undetected slips 2/h: base PRN 11 and 17 slip by -1 cycle (no LLI) at 256.8 and 260.6 s, under a
    # held fix; a 1.0-cycle threshold on the base's phase - range step let both through and the hold settled
    # 21 cm off to the end of the flight (338 wrong epochs)
    # (this seed's cold start fixes at 138 s; the slips come under the held fix after it)
    r = _run("m8t", duration_s=600.0, undetected_slips_per_h=2.0, seed=3)
    assert r["wrong"] == 0 and r["3D RMS cm"] <= 2.0
    assert np.all(r["q"][250:] == Q_FIX)


@pytest.mark.slow
def test_a_one_cycle_rover_slip_under_a_held_fix_is_caught_by_the_doppler() -> None:
    # seed 6, undetected slips 2/h: rover PRN 17 slips +1 cycle (no LLI) at 330.7 s under a held fix; the
    # Doppler test at 2 cycles let it through and the hold settled 18 cm off (268 wrong epochs, main too)
    r = _run("m8t", duration_s=600.0, undetected_slips_per_h=2.0, seed=6)
    assert r["wrong"] == 0 and r["air fix %"] >= 95.0 and r["3D RMS cm"] <= 2.0


@pytest.mark.slow
def test_a_slip_the_hold_absorbed_is_excluded_not_an_innocent_satellite() -> None:
    # seed 15, undetected slips 2/h: rover PRN 17 slips -1 cycle (no LLI) at 317.3 s in a manoeuvre. With the
    # fixed Doppler threshold alone (slip_outlier_factor = 0, no time-differenced phase test) the test sees
    # 0.83 < 0.85 cycle and, a
    # high-leverage satellite, it pulls the held position 22 cm for two epochs without any residual failing. At
    # 320 s PRN 22 misfits; leaving out PRN 22 fits the pulled position, but leaving out PRN 17 fits better
    # (smaller post-fit χ²). Taking the lone suspect held the wrong set for the rest of the flight (281 wrong
    # epochs); the χ²-best exclusion leaves the two undetected epochs
    from dataclasses import replace

    from hil_sim.rtk_scenarios import SimCase, evaluate
    from onboard.rtk.options import RtkOptions

    case = SimCase("test", "", duration_s=600.0, undetected_slips_per_h=2.0, seed=15)
    r = evaluate(case, "m8t", replace(RtkOptions(), slip_outlier_factor=0.0, tdcp_slip_test=False))
    wrong = np.flatnonzero((r["q"] == Q_FIX) & (r["err_m"] > 0.10))
    assert wrong.tolist() == [318, 319]
    assert r["air fix %"] >= 99.0
    # the Doppler test against the other satellites' spread at that epoch catches the slip itself, and so does
    # the time-differenced phase, each without the other
    for options in (replace(RtkOptions(), tdcp_slip_test=False), replace(RtkOptions(), slip_outlier_factor=0.0)):
        r = evaluate(case, "m8t", options)
        assert r["wrong"] == 0 and r["air fix %"] >= 99.0
    r = evaluate(case, "m8t")
    assert r["wrong"] == 0 and r["air fix %"] >= 99.0


@pytest.mark.slow
def test_a_base_half_cycle_arc_does_not_reach_the_rover_unflagged() -> None:
    # seed 10, undetected slips 2/h: base PRN 27 restarts (LLI) with an unresolved half cycle at 372.7 s; sent
    # in 1004, which cannot flag it, as whole-cycle phase, the held set ended 10-15 cm off (10 fixes, 380-409 s). The base
    # now withholds such phase and restarts the lock time when the half cycle resolves
    r = _run("m8t", duration_s=600.0, undetected_slips_per_h=2.0, seed=10)
    assert r["wrong"] == 0 and r["air fix %"] >= 99.0


@pytest.mark.slow
def test_evaluate_scores_the_combined_solution_when_asked() -> None:
    """bench/rtk_sim.py --direction combined: the ground's deliverable on the same flight. The backward pass
    carries the fix back over the seconds the forward pass spent confirming its first one (9 s when measured)."""
    from hil_sim.rtk_scenarios import SimCase, evaluate, simulate

    case = SimCase("test", "", duration_s=200.0)
    data = simulate(case, "m8t")
    forward = evaluate(case, "m8t", data=data)
    combined = evaluate(case, "m8t", data=data, direction="combined")
    assert forward["first fix s"] > 3.0 and combined["first fix s"] == 0.0
    assert combined["wrong"] == 0 and combined["air fix %"] >= forward["air fix %"]
