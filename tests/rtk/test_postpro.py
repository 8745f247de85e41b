"""Base/rover epoch pairing, forward/backward/combined runs and their combination rules."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from onboard.formats.rinex_nav import read_rinex_nav
from onboard.formats.rinex_obs import read_rinex_obs
from onboard.gnsstime import GpsTime
from onboard.rtk.ephemeris import EphemerisStore
from onboard.rtk.options import RtkOptions
from onboard.rtk.postpro import (
    beside_disputes,
    combine,
    combine_passes,
    contested_hypotheses,
    fix_hypotheses,
    fix_runs,
    handover_anchors,
    pair_epochs,
    postprocess,
)
from onboard.rtk.rtkpos import NX0, Nav, _apply_anchor, rtk_init
from onboard.rtk.types import GNSS_GLONASS, GNSS_GPS, Q_FIX, Q_FLOAT, Q_NONE, Q_SINGLE, ObsEpoch, Solution
from tests.conftest import shared_file


def _epoch(tow_s: float, gnss: int = GNSS_GPS) -> ObsEpoch:
    one = np.ones(1)
    return ObsEpoch(GpsTime.from_week_tow_s(2021, tow_s), np.array([gnss], np.int8), np.array([5], np.int16),
                    one * 2e7, one, one, one, one * np.nan, np.zeros(1, np.uint8))


def test_rover_at_999_and_992_ms_pairs_with_the_base_epoch_on_the_second():
    base = [_epoch(100.0), _epoch(101.0), _epoch(102.0)]
    rover = [_epoch(100.999), _epoch(101.992), _epoch(100.5)]
    paired = pair_epochs(rover, base)
    assert [p.time.tow_s for p in paired] == [101.0, 102.0, 100.0]
    age = [r.time.diff_s(p.time) for r, p in zip(rover, paired)]
    assert age == pytest.approx([-0.001, -0.008, 0.5])


def test_pairing_is_causal_with_missing_base_epochs_and_skips_glonass_only_epochs():
    base = [_epoch(100.0), _epoch(103.0, GNSS_GLONASS), _epoch(105.0)]
    rover = [_epoch(99.0), _epoch(103.999), _epoch(104.0), _epoch(106.0), _epoch(140.0)]
    paired = pair_epochs(rover, base, max_age_s=30.0)
    assert paired[0] is None  # nothing before the first base epoch
    assert paired[1].time.tow_s == 100.0  # the GLONASS-only 103 s epoch is skipped, 105 s is in the future
    assert paired[2].time.tow_s == 100.0
    assert paired[3].time.tow_s == 105.0
    assert paired[4] is None  # 35 s old: too old


def _sol(q: int, pos, sd: float = 0.01) -> Solution:
    return Solution(GpsTime(2021, 0), np.asarray(pos, float), np.zeros(3), q, 8, np.eye(3) * sd**2,
                    np.eye(3), 1.0, 5.0)


def test_combine_rules():
    a = np.array([1.0, 2.0, 3.0])
    both = combine(_sol(Q_FIX, a, 0.003), _sol(Q_FIX, a + 0.004, 0.003))
    assert both.q == Q_FIX and np.allclose(both.pos_ecef_m, a + 0.002)
    disagree = combine(_sol(Q_FIX, a, 0.003), _sol(Q_FIX, a + [0.19, 0, 0], 0.003))
    assert disagree.q == Q_FLOAT  # two different integer sets: neither is trusted
    assert np.allclose(disagree.pos_ecef_m, a + [0.095, 0, 0]) and disagree.cov_pos_m2[0, 0] > 0.09**2
    one = combine(_sol(Q_FLOAT, a + 0.1, 0.2), _sol(Q_FIX, a, 0.003))
    assert one.q == Q_FIX and np.allclose(one.pos_ecef_m, a)  # a fix beats a float (RTKLIB combres)
    biased = combine(_sol(Q_FIX, a, 0.003), _sol(Q_FLOAT, a + 0.8, 0.1))
    assert biased.q == Q_FIX  # a code-biased float (metres off, decimetre σ) cannot veto a fix
    held = combine(_sol(Q_FIX, a, 0.003), _sol(Q_FLOAT, a + [0.2, 0, 0], 0.01))
    assert held.q == Q_FLOAT  # a float pinned to centimetres (just released from a hold) disagrees as a fix would
    agrees = combine(_sol(Q_FIX, a, 0.003), _sol(Q_FLOAT, a + [0.02, 0, 0], 0.01))
    assert agrees.q == Q_FIX and np.allclose(agrees.pos_ecef_m, a)
    floats = combine(_sol(Q_FLOAT, a, 0.1), _sol(Q_FLOAT, a + [0.3, 0, 0], 0.1))
    assert floats.q == Q_FLOAT and np.allclose(floats.pos_ecef_m, a + [0.15, 0, 0])
    assert combine(_sol(Q_SINGLE, a + 3.0, 2.0), _sol(Q_FLOAT, a, 0.1)).q == Q_FLOAT
    assert combine(_sol(Q_NONE, a, 1.0), _sol(Q_SINGLE, a, 2.0)).q == Q_SINGLE


def _timed(sols: list[Solution]) -> list[Solution]:
    """The solutions one second apart."""
    return [replace(s, time=GpsTime.from_week_tow_s(2021, 100.0 + i)) for i, s in enumerate(sols)]


def test_a_hypothesis_the_other_pass_refutes_is_float_where_that_pass_has_no_fix():
    a = np.array([1.0, 2.0, 3.0])
    fix, far, near = _sol(Q_FIX, a, 0.003), _sol(Q_FIX, a + [0.3, 0, 0], 0.003), _sol(Q_FIX, a + [0.01, 0, 0], 0.003)
    flt, none = _sol(Q_FLOAT, a, 0.3), _sol(Q_NONE, a, 1.0)
    # forward: one run 0-9 s, float, a run 11-17 s; backward: fixed 30 cm away at 0-5 s, then float
    fwd = _timed([fix] * 10 + [flt] + [fix] * 7)
    bwd = _timed([far] * 6 + [flt] * 4 + [none] + [near] + [none] * 6)
    assert fix_runs(fwd) == [0] * 10 + [-1] + [1] * 7
    assert fix_hypotheses(bwd)[:7] == [("run", 0)] * 6 + [None]
    assert contested_hypotheses(fwd, bwd, 0.10, 5.0) == ({("run", 0)}, {("run", 0)})
    out = combine_passes(fwd, bwd, 0.10, 5.0)
    # the refuted run is float at every epoch, also 6-9 s where the backward pass has no fix; the other run is not
    assert [s.q for s in out] == [Q_FLOAT] * 11 + [Q_FIX] * 7
    assert np.allclose(out[8].pos_ecef_m, a) and out[8].cov_pos_m2[0, 0] >= 0.05**2 / 4
    # epoch by epoch (0 disables), the run's fix is taken where the backward pass has none
    assert [s.q for s in combine_passes(fwd, bwd, 0.0)][:10] == [Q_FLOAT] * 6 + [Q_FIX] * 4
    # a hypothesis held less than 5 s refutes nothing, and is itself not taken where the other pass is float
    short = _timed([far] * 3 + [flt] * 15)
    assert contested_hypotheses(fwd, short, 0.10, 5.0) == (set(), {("run", 0)})
    # (and the forward fix at 3 s, beside the dispute at 2 s, is not taken alone either: beside_disputes)
    assert [s.q for s in combine_passes(fwd, short, 0.10, 5.0)][:10] == [Q_FLOAT] * 4 + [Q_FIX] * 6
    alone = _timed([flt] * 18)
    assert [s.q for s in combine_passes(_timed([fix] * 3 + [flt] * 15), alone, 0.10, 5.0)][:4] == [Q_FLOAT] * 4
    # one set straying at a minority of the common epochs is not another set: those epochs alone are float
    stray = _timed([far] * 2 + [near] * 8 + [flt] * 8)
    assert contested_hypotheses(fwd, stray, 0.10, 5.0) == (set(), set())
    assert [s.q for s in combine_passes(fwd, stray, 0.10, 5.0)][:10] == [Q_FLOAT] * 2 + [Q_FIX] * 8


def test_a_fix_beside_a_dispute_of_its_own_set_is_float_where_the_other_pass_has_no_fix():
    a = np.array([1.0, 2.0, 3.0])
    fix = replace(_sol(Q_FIX, a, 0.003), fix_id=1)
    near, far = _sol(Q_FIX, a + [0.01, 0, 0], 0.003), _sol(Q_FIX, a + [0.2, 0, 0], 0.003)
    flt = _sol(Q_FLOAT, a, 0.07)
    # the backward pass holds one set throughout and strays 20 cm at 3-6 s (a slip not yet caught), where the
    # forward pass, one lineage, is float at 3 and 6 s and fixed, disputing it, at 4 and 5 s (hil_sim LEA-6T
    # harsh, seed 10)
    fwd = _timed([fix] * 3 + [flt] + [fix] * 2 + [flt] + [fix] * 5)
    bwd = _timed([near] * 3 + [far] * 4 + [near] * 5)
    assert contested_hypotheses(fwd, bwd, 0.10, 5.0) == (set(), set())  # disputed at 2 of 10 common epochs
    assert beside_disputes(fwd, bwd, fix_hypotheses(fwd), fix_hypotheses(bwd)) == {3, 4, 5, 6}
    assert [s.q for s in combine_passes(fwd, bwd, 0.10, 5.0)] == [Q_FIX] * 3 + [Q_FLOAT] * 4 + [Q_FIX] * 5
    # epoch by epoch (RTKLIB), the stray fixes at 3 and 6 s are taken
    assert [s.q for s in combine_passes(fwd, bwd, 0.0)] == [Q_FIX] * 4 + [Q_FLOAT] * 2 + [Q_FIX] * 6
    # another hypothesis of the backward pass after a break is not the disputed one
    broken = _timed([near] * 3 + [far] * 3 + [_sol(Q_FLOAT, a, 0.3)] + [far] + [near] * 4)
    assert 6 not in beside_disputes(fwd, broken, fix_hypotheses(fwd), fix_hypotheses(broken))


def test_a_backward_pass_pinned_to_a_refuted_forward_set_is_refuted_with_it():
    a = np.array([1.0, 2.0, 3.0])
    fix, other, flt = _sol(Q_FIX, a, 0.003), _sol(Q_FIX, a + [0.3, 0, 0], 0.003), _sol(Q_FLOAT, a, 0.3)
    fwd = _timed([flt] * 5 + [fix] * 11 + [flt] * 4)  # one set at 5-15 s
    # backward: refutes it at 10-15 s, loses its hold, is pinned to it at 5 s and carries it back to 0 s
    bwd = _timed([fix] * 6 + [flt] * 4 + [other] * 6 + [flt] * 4)
    anchors = [None] * 5 + [fwd[5]] + [None] * 14
    assert [s.q for s in combine_passes(fwd, bwd, 0.10, 5.0)][:5] == [Q_FIX] * 5
    assert [s.q for s in combine_passes(fwd, bwd, 0.10, 5.0, anchors)] == [Q_FLOAT] * 20


def test_the_engines_lineage_joins_runs_into_one_hypothesis():
    a = np.array([1.0, 2.0, 3.0])
    fix = _sol(Q_FIX, a, 0.003)
    lineage = replace(fix, pos_ecef_m=a + [0.3, 0, 0], fix_id=4)
    # backward: fixed 30 cm away at 0-5 s and again at 8-9 s, one lineage across the break
    bwd = _timed([lineage] * 6 + [_sol(Q_FLOAT, a, 0.3)] * 2 + [lineage] * 2)
    fwd = _timed([fix] * 6 + [_sol(Q_FLOAT, a, 0.3)] * 4)
    assert fix_hypotheses(bwd)[7:] == [None, ("lineage", 4), ("lineage", 4)]
    out = combine_passes(fwd, bwd, 0.10, 5.0)
    assert [s.q for s in out][8:] == [Q_FLOAT, Q_FLOAT]  # the second run rests on the refuted integers too
    with pytest.raises(ValueError, match="combined_contest_distance_m"):
        RtkOptions(combined_contest_distance_m=float("nan"))


def _geonet_run(direction: str) -> tuple[np.ndarray, np.ndarray]:
    d = "gnss/geonet-0759-3040-20050402/"
    nav = read_rinex_nav(shared_file(d + "07590920.05n.gz"))
    rov = read_rinex_obs(shared_file(d + "07590920.05o.gz")).epochs
    bas = read_rinex_obs(shared_file(d + "30400920.05o.gz")).epochs
    sols, stats = postprocess(rov, bas, Nav(EphemerisStore(nav.ephemerides), (nav.iono_alpha, nav.iono_beta)),
                              np.array([-3978241.958, 3382840.234, 3649900.853]), RtkOptions(), direction)
    assert len(stats) == (2 if direction == "combined" else 1) and len(sols) == 120
    ref = np.array([-3976219.1873, 3382371.6051, 3652511.1423])
    return np.array([s.q for s in sols]), np.array([np.linalg.norm(s.pos_ecef_m - ref) for s in sols])


def test_combined_run_on_geonet_fixes_more_than_forward_and_matches_the_reference():
    q, err = _geonet_run("combined")
    qf, _ = _geonet_run("forward")
    # the backward pass fixes the first 60 s the forward pass spends confirming its first fix
    assert np.mean(q == Q_FIX) > np.mean(qf == Q_FIX)  # 95.0 % vs 93.3 %
    assert err[q == Q_FIX].max() < 0.03


@pytest.mark.slow
def test_combined_run_on_m8p_with_the_lossy_rtcm_base_fixes_more_than_forward_and_never_wrong():
    """The combined M8P run was 1.7 % fixed while the backward pass held a 0.69 m wrong set: both passes are
    now wrong-free and combined covers forward's first 32 s and its later float spells."""
    d = "gnss/ublox-m8p-galway-2018/"
    rover = read_rinex_obs(shared_file(d + "rinex/rover-20181004-1237.obs.gz")).epochs
    base = read_rinex_obs(shared_file(d + "rinex/base-20181004-1236.rtcm.obs.gz"))
    f = read_rinex_nav(shared_file(d + "rinex/rover-20181004-1237.nav.gz"))
    nav = Nav(EphemerisStore(f.ephemerides), (f.iono_alpha, f.iono_beta))
    ref = np.array([3774088.9931, -601661.8217, 5089321.3853])  # dataset README, M8P-base-based
    out = {}
    for direction in ("forward", "combined"):
        sols, _ = postprocess(rover, base.epochs, nav, base.header.antenna_position_ecef_m(), RtkOptions(), direction)
        fixed = np.array([s.q == Q_FIX for s in sols])
        err = np.array([np.linalg.norm(s.pos_ecef_m - ref) for s in sols])
        assert err[fixed].max() <= 0.10
        out[direction] = fixed.mean()
    assert out["combined"] >= 0.97 and out["combined"] > out["forward"]  # 99.2 % vs 96.3 %


@pytest.mark.slow
def test_known_take_off_point_and_static_start_only_shape_the_forward_pass():
    """They describe the first epoch in time; the backward pass starts at the last one."""
    d = "gnss/geonet-0759-3040-20050402/"
    f = read_rinex_nav(shared_file(d + "07590920.05n.gz"))
    rov = read_rinex_obs(shared_file(d + "07590920.05o.gz")).epochs
    bas = read_rinex_obs(shared_file(d + "30400920.05o.gz")).epochs
    nav = Nav(EphemerisStore(f.ephemerides), (f.iono_alpha, f.iono_beta))
    base_pos = np.array([-3978241.958, 3382840.234, 3649900.853])
    known = np.array([-3976219.1873, 3382371.6051, 3652511.1423])
    start = RtkOptions(static_start=True)
    plain, _ = postprocess(rov, bas, nav, base_pos, RtkOptions(), "backward")
    seeded, _ = postprocess(rov, bas, nav, base_pos, start, "backward", known)
    assert all(np.array_equal(a.pos_ecef_m, b.pos_ecef_m) and a.q == b.q for a, b in zip(plain, seeded, strict=True))
    fwd, _ = postprocess(rov, bas, nav, base_pos, start, "forward", known)
    assert fwd[0].q == Q_FIX  # the known point fixes the first epoch
    comb, _ = postprocess(rov, bas, nav, base_pos, start, "combined", known)
    assert comb[0].q == Q_FIX


def test_onboard_rtk_combined_end_to_end_on_geonet(tmp_path, capsys):
    """`python -m onboard rtk --direction combined` writes the combined track (both passes run)."""
    from onboard.formats.pos import read_pos
    from onboard.postpro.rtk_cli import main

    d = "gnss/geonet-0759-3040-20050402/"
    out = tmp_path / "c.pos"
    rc = main(["rtk", "--rover", str(shared_file(d + "07590920.05o.gz")), "--base", str(shared_file(d + "30400920.05o.gz")),
               "--nav", str(shared_file(d + "07590920.05n.gz")), "--base-pos", "-3978241.958", "3382840.234",
               "3649900.853", "--direction", "combined", "-o", str(out)])
    assert rc == 0
    assert "combined" in capsys.readouterr().out
    track = read_pos(out)
    assert len(track.q) == 120 and np.mean(track.q == 1) >= 0.94  # 95 %: forward alone 92.5 %
    ref = np.array([-3976219.1873, 3382371.6051, 3652511.1423])
    assert np.linalg.norm(track.pos_ecef_m[track.q == 1] - ref, axis=1).max() < 0.03


def test_unknown_direction_is_refused():
    with pytest.raises(ValueError, match="direction"):
        postprocess([], [], Nav(EphemerisStore()), None, RtkOptions(), "sideways")


def _run_of(q_by_s: str) -> list[Solution]:
    """Solutions one second apart, fixed where the string has 'F', float where '.'."""
    return [Solution(GpsTime(2021, round(k * 1e9)), np.full(3, float(k)), np.zeros(3),
                     Q_FIX if c == "F" else Q_FLOAT, 8, np.eye(3) * 1e-6, np.eye(3), 1.0, 5.0)
            for k, c in enumerate(q_by_s)]


def test_handover_takes_the_first_epoch_of_each_long_run_of_fixes():
    sols = _run_of("..FFFFFFF..F..FFF.FFFFFF")
    anchors = handover_anchors(sols, 5.0)
    assert [k for k, a in enumerate(anchors) if a is not None] == [2, 18]
    assert all(anchors[k] is sols[k] for k in (2, 18))
    # shorter runs hand over with a shorter minimum; an isolated fix only with none
    assert [k for k, a in enumerate(handover_anchors(sols, 2.0)) if a is not None] == [2, 14, 18]
    assert [k for k, a in enumerate(handover_anchors(sols, 0.0)) if a is not None] == [2, 11, 14, 18]
    assert handover_anchors(_run_of("...."), 0.0) == [None] * 4
    assert handover_anchors([], 5.0) == []


@pytest.mark.parametrize("bad", [{"handover_sigma_m": 0.0}, {"handover_sigma_m": float("nan")},
                                 {"handover_min_run_s": -1.0}, {"handover_min_run_s": float("inf")}])
def test_handover_options_are_checked(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        RtkOptions(**bad)


def test_an_anchor_pins_a_free_float_and_leaves_a_held_set_alone():
    st = rtk_init(RtkOptions())
    truth = np.array([-3976219.19, 3382371.61, 3652511.14])
    st.x[:3] = truth + [0.8, -0.5, 0.3]
    st.p[:3, :3] = np.eye(3) * 0.25
    # one ambiguity correlated with the position's x: pinning the position moves it as well
    st.x[NX0], st.p[NX0, NX0], st.p[0, NX0], st.p[NX0, 0] = 10.0, 1.0, 0.4, 0.4
    ctx = SimpleNamespace(anchored=False)
    _apply_anchor(st, ctx, truth, np.eye(3) * 1e-4)  # type: ignore[arg-type]
    assert ctx.anchored and np.linalg.norm(st.x[:3] - truth) < 0.01 and np.all(np.diag(st.p[:3, :3]) < 1.1e-4)
    assert st.x[NX0] == pytest.approx(10.0 - 0.4 / 0.25 * 0.8, abs=0.01)
    x_held, p_held = st.x.copy(), st.p.copy()
    st.held_prns[3] = True
    ctx = SimpleNamespace(anchored=False)
    _apply_anchor(st, ctx, truth + 1.0, np.eye(3) * 1e-4)  # type: ignore[arg-type]
    assert not ctx.anchored and np.array_equal(st.x, x_held) and np.array_equal(st.p, p_held)
    st.held_prns[:] = False
    _apply_anchor(st, ctx, np.full(3, np.nan), np.eye(3) * 1e-4)  # type: ignore[arg-type]
    assert not ctx.anchored and np.array_equal(st.x, x_held)


def test_observed_systems_are_those_of_both_receivers_with_ephemerides():
    from onboard.postpro.inputs import RtkRunInputs, observed_systems
    from onboard.rtk.types import GNSS_GALILEO, GNSS_QZSS

    rover = [_epoch(100.0), _epoch(101.0, GNSS_GLONASS), _epoch(102.0, GNSS_GALILEO), _epoch(103.0, GNSS_QZSS)]
    base = [_epoch(100.0), _epoch(100.0, GNSS_GLONASS), _epoch(101.0, GNSS_QZSS)]
    eph = SimpleNamespace(satellites=lambda: [(GNSS_GPS, 5), (GNSS_GLONASS, 5), (GNSS_GALILEO, 5)])
    run = RtkRunInputs(rover, base, SimpleNamespace(broadcast=eph), np.zeros(3), "given")  # type: ignore[arg-type]
    # Galileo: the base has none; QZSS: no ephemeris
    assert observed_systems(run) == "GR"
    run = RtkRunInputs(rover[:1], base, SimpleNamespace(broadcast=None), np.zeros(3), "given")  # type: ignore[arg-type]
    assert observed_systems(run) == "G"
