"""The engine's options do what they name, its integrity rules hold (issues 13 and 14), on simulated
observations from real broadcast orbits (truth in, truth out)."""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np
import pytest

from onboard.formats.rinex_nav import read_rinex_nav
from onboard.rtk.ephemeris import EphemerisStore
from onboard.rtk.geodesy import enu_to_ecef
from onboard.rtk.options import TOML_KEYS, RtkOptions, option_names
from onboard.rtk.postpro import base_spp_offset_m, postprocess
from onboard.rtk.rtkpos import Nav, rtk_init, rtk_pos
from onboard.rtk.types import Q_FIX, Q_NONE, BasePositionRejected, ObsEpoch
from tests.conftest import shared_file
from tests.rtk._sim import BASE_ECEF_M, T0, SimReceiver, observe

ROVER_START_ENU_M = np.array([30.0, -20.0, 2.0])


@pytest.fixture(scope="module")
def nav() -> Nav:
    f = read_rinex_nav(shared_file("gnss/broadcast-nav-20100701/brdc1820.10n"))
    return Nav(EphemerisStore(f.ephemerides), (f.iono_alpha, f.iono_beta))


@pytest.fixture(scope="module")
def epochs(nav: Nav) -> tuple[list[ObsEpoch], list[ObsEpoch]]:
    """40 noise-free 1 Hz epochs of a static rover 36 m from the base."""
    rover_clk, base_clk = SimReceiver(clock_s=-0.8e-3, drift_s_s=2e-9, seed=1), SimReceiver(clock_s=1e-6, seed=2)
    pos = enu_to_ecef(ROVER_START_ENU_M, BASE_ECEF_M)
    rov = [observe(nav.store, rover_clk, pos, np.zeros(3), T0.add_s(k)) for k in range(40)]
    bas = [observe(nav.store, base_clk, BASE_ECEF_M, np.zeros(3), T0.add_s(k)) for k in range(40)]
    return rov, bas


def _run(nav: Nav, epochs: tuple[list[ObsEpoch], list[ObsEpoch]], options: RtkOptions):  # type: ignore[no-untyped-def]
    st = rtk_init(options)
    sols = [rtk_pos(st, r, b, nav, BASE_ECEF_M) for r, b in zip(*epochs, strict=True)]
    return sols, st


def test_every_option_field_is_read_by_the_engine() -> None:
    """No option that does nothing (min_fix_sats, hold_elmask_deg, max_innovation_code_m and max_iterations
    were never read): each field name appears in the engine's modules outside options.py."""
    from pathlib import Path

    import onboard.rtk as pkg

    src = "".join(p.read_text() for p in Path(pkg.__file__).parent.glob("*.py") if p.name != "options.py")
    unread = [n for n in option_names() if f".{n}" not in src and n != "elmask_deg"]
    assert unread == []
    assert "elmask_rad" in src  # elmask_deg is read through its radian property
    for gone in ("max_iterations", "max_innovation_code_m", "max_innovation_phase_m", "min_amb_dd"):
        assert gone not in option_names()
    assert {field for field, _ in TOML_KEYS.values()} <= set(option_names())


def test_defaults_reproduce_the_former_hard_coded_values() -> None:
    o = RtkOptions()
    assert (o.max_outlier_passes, o.outlier_gate_sigma, o.phase_outlier_floor_m) == (4, 6.0, 0.5 * 0.1)
    assert o.min_fix_sats == 5  # the former min_amb_dd = 4 double differences
    assert o.hold_elmask_deg <= o.ar_elmask_deg  # every fixed satellite is held


@pytest.mark.slow
def test_min_fix_sats_limits_the_satellites_a_fix_rests_on(nav, epochs) -> None:
    sols, _ = _run(nav, epochs, RtkOptions())
    n_sats = max(s.ns for s in sols)
    assert any(s.q == Q_FIX for s in sols)
    sols, _ = _run(nav, epochs, replace(RtkOptions(), min_fix_sats=n_sats + 1))
    assert not any(s.q == Q_FIX for s in sols)


def test_hold_elmask_deg_selects_the_held_satellites(nav, epochs) -> None:
    _, st = _run(nav, epochs, RtkOptions())
    assert st.held_prns.sum() >= 5
    _, st = _run(nav, epochs, replace(RtkOptions(), hold_elmask_deg=89.0))
    assert st.fix_count > RtkOptions().min_hold_epochs and not st.held_prns.any()


def test_an_epoch_whose_every_outlier_pass_rejects_is_counted_logged_and_keeps_its_time_update(
        nav, epochs, caplog: pytest.LogCaptureFixture) -> None:
    """A gate no innovation passes: every epoch after the first exhausts its passes; the state then stays at its
    time update (the position variance only grows), each such epoch is counted and logged."""
    o = replace(RtkOptions(), outlier_gate_sigma=1e-12, phase_outlier_floor_m=0.0, standstill=False)
    st = rtk_init(o)
    rov, bas = epochs
    with caplog.at_level(logging.INFO, logger="onboard.rtk.rtkpos"):
        rtk_pos(st, rov[0], bas[0], nav, BASE_ECEF_M)
        var0 = float(st.p[:3, :3].trace())
        sol = rtk_pos(st, rov[1], bas[1], nav, BASE_ECEF_M)
    assert st.rejected_updates >= 1
    assert float(st.p[:3, :3].trace()) >= var0  # no measurement shrank it
    assert sol.q != Q_FIX
    assert any("no measurement update" in r.getMessage() for r in caplog.records)
    _, clean = _run(nav, epochs, RtkOptions())
    assert clean.rejected_updates == 0


def test_an_epoch_without_a_position_carries_none(nav, epochs) -> None:
    """Q_NONE (no single-point solution: no ephemerides) has a NaN position, never 0,0,0 or a stale one."""
    rov, bas = epochs
    empty = Nav(EphemerisStore([]), None)
    sol = rtk_pos(rtk_init(RtkOptions()), rov[0], bas[0], empty, BASE_ECEF_M)
    assert sol.q == Q_NONE and sol.ns == 0 and np.isnan(sol.pos_ecef_m).all() and np.isnan(sol.cov_pos_m2).all()
    st = rtk_init(RtkOptions())
    rtk_pos(st, rov[0], bas[0], nav, BASE_ECEF_M)
    sol = rtk_pos(st, rov[1], bas[1], empty, BASE_ECEF_M)  # initialised, then an epoch without orbits
    assert sol.q == Q_NONE and np.isnan(sol.pos_ecef_m).all()


def test_a_base_position_its_own_single_point_solution_contradicts_is_refused(nav, epochs) -> None:
    rov, bas = epochs
    offset, n = base_spp_offset_m(bas, nav, BASE_ECEF_M, RtkOptions()) or (np.inf, 0)
    assert offset < 10.0 and n == len(bas)  # the simulated code has no ionosphere error, the model does
    wrong = BASE_ECEF_M + np.array([100.0, 0.0, 0.0])
    with pytest.raises(BasePositionRejected, match="check the base position") as err:
        postprocess(rov, bas, nav, wrong, RtkOptions())
    assert isinstance(err.value, ValueError) and 90.0 < err.value.offset_m < 110.0 and err.value.bound_m == 30.0
    sols, _ = postprocess(rov, bas, nav, wrong, replace(RtkOptions(), max_base_spp_offset_m=0.0))  # disabled
    assert len(sols) == len(rov)
    sols, _ = postprocess(rov, bas, nav, BASE_ECEF_M + np.array([5.0, 0.0, 0.0]), RtkOptions())  # within
    assert len(sols) == len(rov)


@pytest.mark.parametrize("bad", [[np.nan] * 3, [np.inf, 0.0, 0.0], [1.0, 2.0]])
def test_non_finite_base_or_take_off_positions_are_refused_at_the_entry(nav, epochs, bad) -> None:
    rov, bas = epochs
    with pytest.raises(ValueError, match="base position"):
        postprocess(rov, bas, nav, np.array(bad), RtkOptions())
    with pytest.raises(ValueError, match="take-off position"):
        postprocess(rov, bas, nav, BASE_ECEF_M, RtkOptions(), init_pos_ecef_m=np.array(bad))
    with pytest.raises(ValueError, match="take-off position"):
        rtk_init(RtkOptions(), np.array(bad))


def test_weak_signals_get_more_code_variance_on_each_side_of_the_single_difference() -> None:
    """code_cn0_ref_dbhz: each receiver's weak signal inflates its half of the SD code variance by
    10^((ref − C/N0)/10); a strong, unknown (NaN, or MSM's 0) C/N0, or a receiver without C/N0, counts as 1."""
    from onboard.rtk.rtkpos import _code_cn0_factor, _Receiver

    def rcv(cn0: np.ndarray | None) -> _Receiver:
        n = 4
        return _Receiver(np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n, np.uint8), None,  # type: ignore[arg-type]
                         np.ones(n, bool), cn0_dbhz=cn0)

    rov = rcv(np.array([50.0, 32.0, np.nan, 0.0]))
    f = _code_cn0_factor(42.0, rov, rcv(np.array([45.0, 45.0, 22.0, 45.0])))
    np.testing.assert_allclose(f, [1.0, (10.0 + 1.0) / 2, (1.0 + 100.0) / 2, 1.0])
    np.testing.assert_allclose(_code_cn0_factor(42.0, rcv(np.array([50.0, 32.0, 40.0, 0.0])), rcv(None)),
                               [1.0, 5.5, (10 ** 0.2 + 1) / 2, 1.0])
    assert not f.flags.writeable  # memoised on the rover epoch: shared, so read-only


def test_weak_signal_code_weighting_changes_the_float_only_for_u_blox_like_code(nav, epochs) -> None:
    """The option is wired: on noise-free data whose rover reports every signal at 30 dB-Hz (the base 45), the
    code rows of the float update carry 8.4× the variance ((10^1.2 + 1)/2 at 42 dB-Hz) once the code counts as
    u-blox-like (code_scatter_reference 0: taken as modelled), and none while it scatters as little as
    geodetic code; the solution stays on the truth either way (noise-free code is right whatever its weight)."""
    from onboard.rtk import rtkpos as R

    rov, bas = epochs
    weak = [replace(e, cn0_dbhz=np.full(len(e), 30.0)) for e in rov]
    seen: list[float] = []
    orig = R._ddres

    def spy(st, ctx, x, phase_ok, code_ok, with_doppler, jacobian=True):  # type: ignore[no-untyped-def]
        dd, e = orig(st, ctx, x, phase_ok, code_ok, with_doppler, jacobian)
        code = dd.kind == 1
        if code.any():
            seen.append(float(np.median(dd.r.diagonal()[code])))
        return dd, e

    truth = enu_to_ecef(ROVER_START_ENU_M, BASE_ECEF_M)

    def last_code_variances(**kw: float) -> np.ndarray:
        seen.clear()
        R._ddres = spy
        try:
            sols, _ = postprocess(weak, bas, nav, BASE_ECEF_M, replace(RtkOptions(), **kw), "forward")
        finally:
            R._ddres = orig
        assert np.linalg.norm(np.array(sols[-1].pos_ecef_m) - truth) < 0.01
        return np.array(seen[-5:])

    modelled = {"code_scatter_reference": 0.0}
    np.testing.assert_allclose(last_code_variances(code_cn0_ref_dbhz=42.0, **modelled)
                               / last_code_variances(code_cn0_ref_dbhz=0.0, **modelled),
                               (10.0 ** 1.2 + 1.0) / 2.0, rtol=1e-6)
    np.testing.assert_allclose(last_code_variances(code_cn0_ref_dbhz=42.0), last_code_variances(code_cn0_ref_dbhz=0.0))
