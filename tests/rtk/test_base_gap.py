"""Radio gaps (no new base data) while the hil_sim drone manoeuvres.

Up to `max_age_s` (30 s) the engine keeps differencing the rover with the last base epoch, carried forward
along each satellite's correction rate: float or a held fix, never single, never wrong. The rover's phase is
still watched, so the gap neither fakes slips on every satellite nor hides one. Past 30 s: single, then the
fix returns with the base.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from onboard.rtk.ephemeris import EphemerisStore
from onboard.rtk.options import RtkOptions
from onboard.rtk.postpro import pair_epochs
from onboard.rtk.rtkpos import Nav, rtk_init, rtk_pos
from onboard.rtk.types import Q_FIX, Q_FLOAT, Q_SINGLE
from tests.conftest import shared_file

GAP = range(150, 170)  # s after start, in flight (20 s)
LONG_GAP = range(150, 195)  # 45 s: the last 15 s are past the 30 s maximum age


@pytest.fixture(scope="module")
def flight():
    shared_file("gnss/broadcast-nav-20100701/brdc1820.10n")
    from hil_sim.scenario import Scenario
    from hil_sim.world import World

    world = World(Scenario.default("m8t", duration_s=300.0))
    rover = [world.observe("rover", world.start.add_s(k)) for k in range(240)]
    base = [world.observe("base", world.start.add_s(k)) for k in range(240)]
    return world, rover, base


def _run(world, rover, base, gap: range, slip_prn: int | None = None):
    if slip_prn is not None:  # the rover slips 5 cycles inside the gap, LLI not set
        for ep in rover[gap.start + 5:]:
            ep.cp_cyc[ep.sv_id == slip_prn] += 5.0
    base = [b for k, b in enumerate(base) if k not in gap]
    nav = Nav(EphemerisStore(world.ephemerides()), world.iono_params())
    opts = RtkOptions()
    st = rtk_init(opts)
    out = []
    for r, b in zip(rover, pair_epochs(rover, base, opts.pair_tolerance_s, opts.max_age_s)):
        before = st.slips
        s = rtk_pos(st, r, b, nav, world.base_ecef_m)
        err = float(np.linalg.norm(s.pos_ecef_m - world.truth(s.time)["antenna_ecef_m"]))
        out.append((s.q, err, st.slips - before))
    return out


@pytest.mark.slow
def test_a_20_s_radio_gap_keeps_the_fix_without_wrong_fixes_and_fakes_no_slips(flight):
    world, rover, base = flight
    out = _run(world, rover, base, GAP)
    assert out[GAP.start - 1][0] == Q_FIX  # fixed when the radio drops
    in_gap = [x[0] for x in out[GAP.start:GAP.stop]]
    assert set(in_gap) <= {Q_FIX, Q_FLOAT}  # never single on corrections ≤ 30 s old …
    assert in_gap.count(Q_FIX) >= 18  # … and the held fix carries through (carried-forward corrections)
    assert sum(x[2] for x in out[GAP.start:GAP.stop + 20]) == 0  # neither the gap nor its end resets anything
    assert all(x[0] == Q_FIX for x in out[GAP.stop:GAP.stop + 20])
    assert all(x[1] <= 0.10 for x in out if x[0] == Q_FIX)


@pytest.mark.slow
def test_rover_slip_inside_a_radio_gap_is_caught_where_it_happens(flight):
    world, rover, base = flight
    rover = copy.deepcopy(rover)
    prn = int(rover[GAP.start].sv_id[0])
    out = _run(world, rover, base, GAP, slip_prn=prn)
    assert sum(x[2] for x in out[GAP.start:GAP.stop + 20]) == 1  # that satellite's ambiguity, and only it
    assert out[GAP.start + 5][2] == 1
    assert all(x[1] <= 0.10 for x in out if x[0] == Q_FIX)


@pytest.mark.slow
def test_past_30_s_without_base_single_then_the_fix_returns(flight):
    world, rover, base = flight
    out = _run(world, rover, base, LONG_GAP)
    q = [x[0] for x in out]
    fresh = LONG_GAP.start + 30  # the last base epoch is LONG_GAP.start − 1: > 30 s old from here on
    assert set(q[LONG_GAP.start:fresh - 1]) <= {Q_FIX, Q_FLOAT}
    assert set(q[fresh + 1:LONG_GAP.stop]) == {Q_SINGLE}
    assert Q_FIX in q[LONG_GAP.stop:LONG_GAP.stop + 10]
    assert all(x[1] <= 0.10 for x in out if x[0] == Q_FIX)


def test_the_last_base_epoch_carried_forward_20_s_matches_the_base_then(flight):
    """What the rover is differenced with at the end of a 20 s gap: the last base epoch moved along each
    satellite's correction rate, against what the base actually observed then (not sent)."""
    from onboard.rtk.consts import LAMBDA_L1_M
    from onboard.rtk.rtkpos import _extrapolated_base, _model_range_m, _remember_base, _slots

    world, _, base = flight
    store = EphemerisStore(world.ephemerides())

    def corr(ep):  # phase − modelled range (cycles) per slot, above the engine's 15° mask
        b = _slots(ep, store)
        rng, _, _, el = _model_range_m(b, world.base_ecef_m)
        return b, np.where(el >= np.radians(15.0), (LAMBDA_L1_M * b.cp_cyc - rng) / LAMBDA_L1_M, np.nan)

    st = rtk_init(RtkOptions())
    for ep in base[GAP.start - 22:GAP.start]:
        _remember_base(st, _slots(ep, store), ep.time, corr(ep)[1])
    last, z0 = corr(base[GAP.start - 1])
    _, z1 = corr(base[GAP.stop - 1])
    age = base[GAP.stop - 1].time.diff_s(base[GAP.start - 1].time)
    carried = _extrapolated_base(st, last, age)
    ok = np.isfinite(z0) & np.isfinite(z1)
    true_change = (z1 - z0)[ok] - np.median((z1 - z0)[ok])  # the base clock is common: only differences count
    miss = (z1 - z0)[ok] - (carried.cp_cyc - last.cp_cyc)[ok]
    miss -= np.median(miss)
    raw_m, miss_m = np.abs(true_change) * LAMBDA_L1_M, np.abs(miss) * LAMBDA_L1_M
    assert raw_m.max() > 0.03  # raw, the old epoch is centimetres off …
    # … carried forward, what is left is mostly the phase noise of the two epochs (3 mm/sin el each)
    assert miss_m.max() < 0.02 and np.sqrt(np.mean(miss_m**2)) < 0.5 * np.sqrt(np.mean(raw_m**2))


def test_the_correction_rate_is_shared_by_the_rover_epochs_of_one_base_epoch(flight):
    """The rover epochs of one base epoch (a radio gap) reuse the rate memoised on its receiver: each age gets
    exactly what a receiver without the memo gets, and a new base epoch (another history) gets its own rate."""
    from onboard.rtk.consts import LAMBDA_L1_M
    from onboard.rtk.rtkpos import _extrapolated_base, _model_range_m, _remember_base, _slots

    world, _, base = flight
    store = EphemerisStore(world.ephemerides())

    def remember(ep):  # phase − modelled range (cycles) per slot, as rtk_pos gives _remember_base
        b = _slots(ep, store)
        _remember_base(st, b, ep.time, (LAMBDA_L1_M * b.cp_cyc - _model_range_m(b, world.base_ecef_m)[0]) / LAMBDA_L1_M)

    st = rtk_init(RtkOptions())
    for ep in base[GAP.start - 22:GAP.start]:
        remember(ep)
    last = _slots(base[GAP.start - 1], store)
    for age in (6.0, 7.5, 12.0, 19.0):  # carried from 5 s on
        shared = _extrapolated_base(st, last, age)
        alone = _extrapolated_base(st, _slots(base[GAP.start - 1], store), age)
        assert not np.array_equal(shared.cp_cyc, last.cp_cyc, equal_nan=True)  # carried
        assert np.array_equal(shared.cp_cyc, alone.cp_cyc, equal_nan=True)
    assert len([k for k in last.memo if k[0] == "rate"]) == 1
    remember(base[GAP.start])
    _extrapolated_base(st, last, 6.0)
    assert len([k for k in last.memo if k[0] == "rate"]) == 2
