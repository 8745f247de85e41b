"""The simulated GNSS world: observation equations closed independently, clocks, arcs, error statistics."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from hil_sim.scenario import DEFAULT_NAV_PATH, ErrorModel, FlightPlan, ReceiverModel, Scenario
from hil_sim.world import OutsideSimulatedSpan, World
from onboard.errors import InputError
from onboard.gnsstime import GpsTime
from onboard.rtk import lnav
from onboard.rtk.consts import CLIGHT_M_S, LAMBDA_L1_M, OMEGA_E_RAD_S
from onboard.rtk.ephemeris import eph_position, eph_position_velocity
from onboard.rtk.geodesy import azimuth_elevation, ecef_to_llh
from onboard.rtk.models import klobuchar_m, saastamoinen_m
from onboard.rtk.types import LLI_HALF_CYCLE, LLI_SLIP

C_1MS_M = CLIGHT_M_S * 1e-3


def make_world(**overrides: object) -> World:
    nav = DEFAULT_NAV_PATH
    model = str(overrides.pop("model", "m8t"))
    return World(Scenario.default(model, nav_path=nav, **overrides))


@pytest.fixture(scope="module")
def clean_world() -> World:
    return make_world(errors=ErrorModel.noise_free())


def nominal(world: World, dt_s: float) -> GpsTime:
    return world.start.add_s(dt_s)


def independent_model(world: World, receiver: str, t_nom: GpsTime) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pseudorange and phase·λ predicted with onboard functions only (no World internals beyond the timing).

    Returns (sv ids, predicted pr without ambiguity, predicted phase range without ambiguity).
    """
    timing = world.epoch_timing(receiver, t_nom)
    t = timing.t_true
    b = timing.tag.diff_s(t)  # receiver clock bias as defined by its tag
    rcv = world.truth(t)["antenna_ecef_m"] if receiver == "rover" else world.base_ecef_m
    lat, lon, h = ecef_to_llh(rcv)
    alpha, beta = world.iono_params()
    svs, pr, ph = [], [], []
    ephs = {e.prn: e for e in world.ephemerides()}
    epoch = world.observe(receiver, t_nom)
    for prn in epoch.sv_id:
        eph = ephs[int(prn)]
        tau = 0.07
        for _ in range(4):
            pos, clk = eph_position(eph, t.add_s(-tau))
            th = OMEGA_E_RAD_S * tau
            rot = np.array([[math.cos(th), math.sin(th), 0], [-math.sin(th), math.cos(th), 0], [0, 0, 1]])
            pos_r = rot @ pos
            rho = float(np.linalg.norm(pos_r - rcv))
            tau = rho / CLIGHT_M_S
        az, el = azimuth_elevation(rcv, pos_r[None])
        trop = saastamoinen_m(lat, h, el)[0]
        ion = klobuchar_m(t.tow_s, lat, lon, az, el, alpha, beta)[0]
        dts = clk - eph.tgd_s
        svs.append(int(prn))
        pr.append(rho + CLIGHT_M_S * (b - dts) + trop + ion)
        ph.append(rho + CLIGHT_M_S * (b - dts) + trop - ion)
    return np.array(svs), np.array(pr), np.array(ph)


@pytest.mark.parametrize("receiver,dt_s", [("rover", 5.0), ("base", 5.0), ("rover", 400.0), ("base", 900.0)])
def test_noise_free_observables_close_to_within_a_millimetre(clean_world: World, receiver: str, dt_s: float) -> None:
    t_nom = nominal(clean_world, dt_s)
    epoch = clean_world.observe(receiver, t_nom)
    svs, pr_model, ph_model = independent_model(clean_world, receiver, t_nom)
    assert list(svs) == list(epoch.sv_id) and len(svs) >= 8
    np.testing.assert_allclose(epoch.pr_m - pr_model, 0.0, atol=1e-3)
    # Phase: the same range except for the ambiguity, an integer number of cycles.
    n_cyc = epoch.cp_cyc - ph_model / LAMBDA_L1_M
    np.testing.assert_allclose(n_cyc - np.round(n_cyc), 0.0, atol=1e-3 / LAMBDA_L1_M)


def test_code_minus_carrier_is_twice_the_iono_plus_a_constant_integer_per_arc(clean_world: World) -> None:
    cmc: dict[int, list[float]] = {}
    for k in range(0, 120, 4):
        t_nom = nominal(clean_world, k)
        ep = clean_world.observe("base", t_nom)
        comp = clean_world.components("base", t_nom)
        resid = (ep.pr_m - ep.cp_cyc * LAMBDA_L1_M - 2 * comp["iono_m"]) / LAMBDA_L1_M
        for sv, r in zip(ep.sv_id, resid):
            cmc.setdefault(int(sv), []).append(float(r))
    for sv, vals in cmc.items():
        arr = np.array(vals)
        assert np.ptp(arr) < 1e-3, f"PRN {sv}: code-minus-carrier not constant"
        assert abs(arr[0] - round(arr[0])) < 1e-3
        assert abs(arr[0]) <= 500  # phase starts near code/λ, as u-blox's
    # And the iono really is there (metres by day), so the test is not trivially passing.
    assert np.all(clean_world.components("base", nominal(clean_world, 0))["iono_m"] > 1.0)


@pytest.mark.parametrize("receiver,dt_s", [("base", 30.0), ("rover", 200.0), ("rover", 420.0)])
def test_doppler_is_minus_range_rate_over_lambda(clean_world: World, receiver: str, dt_s: float) -> None:
    """Doppler against the central difference of the pseudorange (includes clock drifts and rover motion)."""
    t = nominal(clean_world, dt_s)
    e0, e1, e2 = (clean_world.observe(receiver, t.add_s(d)) for d in (-0.2, 0.0, 0.2))
    assert e0.time.diff_s(e2.time) == pytest.approx(-0.4, abs=1e-9)  # no clock step inside
    rate = (e2.pr_m - e0.pr_m) / e2.time.diff_s(e0.time)
    np.testing.assert_allclose(e1.dop_hz, -rate / LAMBDA_L1_M, atol=0.03)  # code also has +dI/dt
    # Doppler is the carrier phase rate: against the phase the match is ~1 mHz (atmospheric rates included).
    phase_rate_cyc_s = (e2.cp_cyc - e0.cp_cyc) / e2.time.diff_s(e0.time)
    np.testing.assert_allclose(e1.dop_hz, -phase_rate_cyc_s, atol=0.003)
    assert np.max(np.abs(e1.dop_hz)) > 500  # real satellite dynamics present


def test_zero_baseline_double_differences_are_integers() -> None:
    rx = ReceiverModel.m8t()
    world = make_world(errors=ErrorModel.noise_free(), base_offset_enu_m=(0.0, 0.0, 0.0),
                       flight=FlightPlan(fly=False), rover_receiver=rx, base_receiver=rx)
    for dt in (0.0, 123.4, 700.0):
        t = nominal(world, dt)
        rov, bas = world.observe("rover", t), world.observe("base", t)
        assert rov.time == bas.time
        assert list(rov.sv_id) == list(bas.sv_id)
        sd_cp = rov.cp_cyc - bas.cp_cyc
        dd_cp = sd_cp[1:] - sd_cp[0]
        np.testing.assert_allclose(dd_cp - np.round(dd_cp), 0.0, atol=1e-6)
        assert np.any(np.abs(dd_cp) >= 1)  # ambiguities differ between receivers: integers, not zeros
        sd_pr = rov.pr_m - bas.pr_m
        np.testing.assert_allclose(sd_pr, 0.0, atol=1e-6)


def test_ephemerides_are_the_real_broadcast_set_and_encodable(clean_world: World) -> None:
    ephs = clean_world.ephemerides()
    assert len(ephs) >= 28 and all(e.health == 0 for e in ephs)
    assert all(abs(clean_world.start.diff_s(e.toe)) < 7200 for e in ephs)
    alpha, beta = clean_world.iono_params()
    assert alpha is not None and beta is not None and alpha[0] == pytest.approx(4.657e-09)
    for e in ephs:
        assert len(lnav.encode_subframes(e, 0.0)) == 3


def test_default_scenario_sees_eight_to_ten_satellites_above_15_deg(clean_world: World) -> None:
    comp = clean_world.components("base", nominal(clean_world, 0))
    n15 = int(np.sum(comp["el_rad"] > math.radians(15)))
    assert 8 <= n15 <= 10
    assert np.all(comp["el_rad"] >= math.radians(5))  # the receiver's mask


def test_lea6t_tags_999_then_998_ms_and_the_step_moves_pr_and_phase_together() -> None:
    world = make_world(model="lea6t", errors=ErrorModel.noise_free())
    rx = world.scenario.rover_receiver
    # The oscillator offset reaches +1 ms after (1 ms − bias0) / drift seconds.
    t_jump = (1e-3 - rx.clock_bias0_s) / rx.clock_drift_s_s
    assert 0 < t_jump < world.scenario.duration_s
    before, after = nominal(world, math.floor(t_jump) - 1), nominal(world, math.ceil(t_jump) + 1)
    e0, e1 = world.observe("rover", before), world.observe("rover", after)
    assert e0.time.tow_ns % 1_000_000_000 == 999_000_000
    assert e1.time.tow_ns % 1_000_000_000 == 998_000_000
    assert not e0.clock_reset and e1.clock_reset
    assert abs(world.epoch_timing("rover", before).clock_bias_s) < 1e-3
    sv = np.intersect1d(e0.sv_id, e1.sv_id)
    i0, i1 = np.searchsorted(e0.sv_id, sv), np.searchsorted(e1.sv_id, sv)
    d_pr = e1.pr_m[i1] - e0.pr_m[i0]
    d_cp_m = (e1.cp_cyc[i1] - e0.cp_cyc[i0]) * LAMBDA_L1_M
    dt = after.diff_s(before)
    # Both drop by c·1 ms (plus at most the range change over dt); phase follows code to < 1 cm.
    assert np.all(np.abs(d_pr + C_1MS_M) < 1000.0 * dt)
    np.testing.assert_allclose(d_pr - d_cp_m, 0.0, atol=0.01)
    # The step is exactly 1 575 420 cycles in phase: nothing fractional was introduced.
    c0 = world.components("rover", before)["ambiguity_cyc"]
    c1 = world.components("rover", after)["ambiguity_cyc"]
    np.testing.assert_array_equal(c0[i0], c1[i1])


def test_m8t_clock_drifts_with_992_ms_tags_and_steps_occasionally() -> None:
    world = make_world(errors=ErrorModel.noise_free())
    rx = world.scenario.rover_receiver
    tags, biases = [], []
    for k in range(0, 1200, 20):
        timing = world.epoch_timing("rover", nominal(world, k))
        tags.append(timing.tag.tow_ns % 1_000_000_000 // 1_000_000)
        biases.append(timing.clock_bias_s)
    assert tags[0] == 992 and set(tags) <= {992, 993} and 993 in tags  # one 1-ms step in 20 min
    jumps = [i for i in range(1, len(tags)) if tags[i] != tags[i - 1]]
    assert len(jumps) == 1
    b = np.array(biases[: jumps[0]])
    slope = np.polyfit(np.arange(len(b)) * 20.0, b, 1)[0]
    assert slope == pytest.approx(rx.clock_drift_s_s, rel=1e-3)  # free-running, not steered
    assert biases[jumps[0]] - biases[jumps[0] - 1] == pytest.approx(1e-3 + 20 * rx.clock_drift_s_s, abs=1e-8)


@pytest.mark.slow
def test_observables_reproduce_from_the_seed_in_any_call_order() -> None:
    w1, w2, w3 = make_world(seed=7), make_world(seed=7), make_world(seed=8)
    ts = [nominal(w1, x) for x in (10.0, 11.0, 300.0)]
    a = [w1.observe("rover", t) for t in ts]
    b = [w2.observe("rover", t) for t in reversed(ts)][::-1]
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x.pr_m, y.pr_m)
        np.testing.assert_array_equal(x.cp_cyc, y.cp_cyc)
    c = w3.observe("rover", ts[0])
    assert np.max(np.abs(c.pr_m - a[0].pr_m)) > 0.1


def _only(**fields: float) -> ErrorModel:
    return dataclasses.replace(ErrorModel.noise_free(), **fields)


@pytest.mark.slow
def test_white_noise_statistics_match_the_error_model() -> None:
    clean = make_world(errors=ErrorModel.noise_free())
    noisy = make_world(errors=_only(code_sigma_zenith_m=0.5, phase_sigma_zenith_m=0.003,
                                    doppler_sigma_zenith_hz=0.05, cn0_sigma_dbhz=1.0))
    code, phase, dop, cn0_res = [], [], [], []
    for k in range(150):
        t = nominal(clean, 2.0 * k)
        a, b = clean.observe("base", t), noisy.observe("base", t)
        s = np.sin(clean.components("base", t)["el_rad"])
        code.append((b.pr_m - a.pr_m) * s)
        phase.append((b.cp_cyc - a.cp_cyc) * LAMBDA_L1_M * s)
        dop.append((b.dop_hz - a.dop_hz) * s)
        cn0_res.append(b.cn0_dbhz - a.cn0_dbhz)
    code_a, phase_a, dop_a, cn0_a = (np.concatenate(x) for x in (code, phase, dop, cn0_res))
    n = code_a.size
    tol = 4.0 / math.sqrt(2 * n)  # relative sampling error of a σ estimate, 4σ
    assert n > 1000
    assert np.std(code_a) == pytest.approx(0.5, rel=tol)
    assert np.std(phase_a) == pytest.approx(0.003, rel=tol)
    assert np.std(dop_a) == pytest.approx(0.05, rel=tol)
    assert np.std(cn0_a) == pytest.approx(1.0, rel=tol)
    assert abs(np.mean(code_a)) < 4 * 0.5 / math.sqrt(n)


def test_cn0_follows_elevation_between_35_and_50_dbhz() -> None:
    world = make_world()
    cn0, el = [], []
    for k in range(0, 1200, 30):
        t = nominal(world, k)
        cn0.append(world.observe("base", t).cn0_dbhz)
        el.append(world.components("base", t)["el_rad"])
    c, e = np.concatenate(cn0), np.concatenate(el)
    model = 35.0 + 15.0 * np.sin(e)
    assert np.all((c > 31.0) & (c < 54.0))
    assert np.std(c - model) == pytest.approx(1.0, rel=0.2)
    assert np.corrcoef(c, e)[0, 1] > 0.8


@pytest.mark.slow
def test_multipath_is_first_order_gauss_markov_with_its_sigma_and_time_constant() -> None:
    clean = make_world(errors=ErrorModel.noise_free())
    mp = make_world(errors=_only(mp_code_sigma_zenith_m=0.5, mp_phase_sigma_zenith_m=0.001, mp_tau_s=30.0))
    step = 5.0
    series: dict[int, list[float]] = {}
    phase_series: dict[int, list[float]] = {}
    for k in range(int(1200 / step)):
        t = nominal(clean, step * k)
        a, b = clean.observe("base", t), mp.observe("base", t)
        s = np.sin(clean.components("base", t)["el_rad"])
        for sv, d, dp, si in zip(a.sv_id, b.pr_m - a.pr_m, (b.cp_cyc - a.cp_cyc) * LAMBDA_L1_M, s):
            series.setdefault(int(sv), []).append(d * si)
            phase_series.setdefault(int(sv), []).append(dp * si)
    long = [np.array(v) for v in series.values() if len(v) > 100]
    allv = np.concatenate(long)
    assert np.std(allv) == pytest.approx(0.5, rel=0.2)
    lag1 = np.mean([np.corrcoef(v[:-1], v[1:])[0, 1] for v in long])
    assert lag1 == pytest.approx(math.exp(-step / 30.0), abs=0.05)
    lag12 = np.mean([np.corrcoef(v[:-12], v[12:])[0, 1] for v in long])  # 60 s = 2τ
    assert lag12 == pytest.approx(math.exp(-2.0), abs=0.15)
    pv = np.concatenate([np.array(v) for v in phase_series.values() if len(v) > 100])
    assert np.std(pv) == pytest.approx(0.001, rel=0.2)


@pytest.mark.slow
def test_common_errors_cancel_between_receivers_and_iono_gradient_is_about_1_mm_per_km() -> None:
    """Orbit, satellite clock, iono model error and tropo residual are common: single differences of the
    same epoch see only the iono gradient (and geometry)."""
    common = _only(orbit_sigma_m=0.3, sat_clock_sigma_m=0.3, iono_model_error_fraction=0.2,
                   tropo_residual_zenith_sigma_m=0.02)
    grad = _only(iono_gradient_mm_per_km=1.0)
    clean = make_world(errors=ErrorModel.noise_free(), flight=FlightPlan(fly=False))
    w_common = make_world(errors=common, flight=FlightPlan(fly=False))
    w_grad = make_world(errors=grad, flight=FlightPlan(fly=False))
    t = nominal(clean, 100.0)
    sd = {}
    for name, w in (("clean", clean), ("common", w_common), ("grad", w_grad)):
        r, b = w.observe("rover", t), w.observe("base", t)
        sd[name] = r.pr_m - b.pr_m
    zero_diff = w_common.observe("base", t).pr_m - clean.observe("base", t).pr_m
    assert np.max(np.abs(zero_diff)) > 0.2  # the common errors are there (decimetres) …
    np.testing.assert_allclose(sd["common"] - sd["clean"], 0.0, atol=2e-3)  # … and cancel over 1 km
    d_iono = sd["grad"] - sd["clean"]
    comp = clean.components("base", t)
    obliquity = 1.0 + 16.0 * (0.53 - comp["el_rad"] / math.pi) ** 3
    per_km = np.abs(d_iono) / obliquity / (clean.scenario.baseline_m / 1000.0)
    assert np.all(per_km <= 1.0e-3 + 1e-6)
    assert np.max(per_km) > 0.5e-3


@pytest.mark.slow
def test_cycle_slips_with_and_without_lli() -> None:
    errors = _only(slip_lli_rate_per_h=8.0, slip_undetected_rate_per_h=8.0, slip_undetected_max_cyc=3)
    world = make_world(errors=errors, flight=FlightPlan(fly=False))
    prev: dict[int, tuple[float, float, float]] = {}
    seen_lli = seen_undetected = 0
    for k in range(900):
        ep, comp = world.observe_detailed("base", nominal(world, float(k)))
        cmc = (ep.pr_m - ep.cp_cyc * LAMBDA_L1_M - 2 * comp["iono_m"]) / LAMBDA_L1_M
        for i, sv in enumerate(ep.sv_id):
            sv = int(sv)
            if sv in prev:
                p_cmc, p_lock, _ = prev[sv]
                jump = cmc[i] - p_cmc
                if ep.lli[i] & LLI_SLIP:
                    seen_lli += 1
                    assert ep.lock_ms[i] < 1000.0 + 1e-6  # lock time restarted
                elif ep.lock_ms[i] > p_lock:
                    assert abs(jump - round(jump)) < 1e-6  # integer only …
                    if round(jump) != 0:
                        seen_undetected += 1
                        assert 1 <= abs(round(jump)) <= 3  # … a small undetected slip with no flag
            prev[sv] = (cmc[i], ep.lock_ms[i], 0.0)
    assert seen_lli >= 3 and seen_undetected >= 3


@pytest.mark.slow
def test_half_cycle_flag_after_acquisition_then_subtracted() -> None:
    errors = _only(slip_lli_rate_per_h=20.0, half_cycle_probability=1.0, half_cycle_resolve_s=2.0)
    world = make_world(errors=errors, flight=FlightPlan(fly=False))
    checked = 0
    for k in range(900):
        ep, comp = world.observe_detailed("base", nominal(world, float(k)))
        for i in range(len(ep)):
            if ep.lock_ms[i] < 2000.0:
                assert ep.lli[i] & LLI_HALF_CYCLE and comp["half_cycle_cyc"][i] == 0.5
                assert ep.half_cyc_sub[i] == 0
                checked += 1
            else:
                assert not ep.lli[i] & LLI_HALF_CYCLE and comp["half_cycle_cyc"][i] == 0.0
                assert ep.half_cyc_sub[i] == 1
    assert checked >= 4


def test_missing_navigation_file_is_a_clear_error(tmp_path) -> None:  # type: ignore[no-untyped-def]
    missing = tmp_path / "nope.10n"
    with pytest.raises(InputError, match="nope.10n"):
        World(Scenario.default(nav_path=missing))
    bad = tmp_path / "bad.10n"
    bad.write_text("not a rinex file\n")
    with pytest.raises(InputError, match="not a RINEX"):
        World(Scenario.default(nav_path=bad))


def test_scenario_time_without_ephemerides_and_bad_queries_are_rejected(clean_world: World) -> None:
    with pytest.raises(InputError, match="no healthy GPS ephemeris"):
        World(Scenario.default(nav_path=DEFAULT_NAV_PATH, start=GpsTime(1600, 0)))
    with pytest.raises(OutsideSimulatedSpan, match="outside the simulated span"):
        clean_world.observe("rover", clean_world.start.add_s(-3600))
    with pytest.raises(ValueError, match="unknown receiver"):
        clean_world.observe("plane", clean_world.start)
    with pytest.raises(ValueError, match="unknown receiver model"):
        Scenario.default("zed-f9p")


def test_velocity_truth_matches_position_difference(clean_world: World) -> None:
    for dt in (61.0, 100.0, 300.0):
        t = nominal(clean_world, dt)
        p0 = clean_world.truth(t.add_s(-0.01))["antenna_ecef_m"]
        p1 = clean_world.truth(t.add_s(0.01))["antenna_ecef_m"]
        v = clean_world.truth(t)["antenna_vel_ecef_m_s"]
        np.testing.assert_allclose((p1 - p0) / 0.02, v, atol=2e-3)


def test_satellite_velocity_model_agrees_with_ephemeris(clean_world: World) -> None:
    """Range rate in the components equals the projection of the ephemeris velocity (static base)."""
    t = nominal(clean_world, 50.0)
    comp = clean_world.components("base", t)
    ephs = {e.prn: e for e in clean_world.ephemerides()}
    for sv, rr, t_tx in zip(comp["sv_id"], comp["rho_dot_m_s"], comp["t_tx"]):
        pos, vel, _, _ = eph_position_velocity(ephs[int(sv)], t_tx)
        los = pos - clean_world.base_ecef_m
        los /= np.linalg.norm(los)
        assert rr == pytest.approx(float(los @ vel), abs=0.5)  # Earth-rotation terms are < 0.5 m/s


# SPP ignores the atmospheric delay rates the Doppler carries (a few mm/s): hence 2 cm/s noise-free.
@pytest.mark.parametrize("errors,pos_tol_m,vel_tol_m_s", [(ErrorModel.noise_free(), 0.01, 0.02),
                                                         (ErrorModel(), 15.0, 0.5)])
def test_single_point_positioning_of_the_simulated_rover_finds_the_truth(
    errors: ErrorModel, pos_tol_m: float, vel_tol_m_s: float,
) -> None:
    """End to end through the consumer's side: onboard SPP on the world's epochs recovers the antenna
    position, velocity and receiver clock at the true measurement instant (climb, line and turn)."""
    from onboard.rtk.ephemeris import EphemerisStore, satellite_states
    from onboard.rtk.pntpos import pntpos

    world = make_world(errors=errors)
    store = EphemerisStore(world.ephemerides())
    for dt in (70.0, 150.0, 212.0):
        ep = world.observe("rover", nominal(world, dt))
        sats = satellite_states(store, ep.sv_id, ep.time, ep.pr_m)
        sol = pntpos(ep.pr_m, sats, ep.time.tow_s, math.radians(5), dop_hz=ep.dop_hz, iono=world.iono_params())
        timing = world.epoch_timing("rover", nominal(world, dt))
        truth = world.truth(timing.t_true)
        assert sol.ok
        assert np.linalg.norm(sol.pos_ecef_m - truth["antenna_ecef_m"]) < pos_tol_m
        assert np.linalg.norm(sol.vel_ecef_m_s - truth["antenna_vel_ecef_m_s"]) < vel_tol_m_s
        assert sol.clock_bias_m == pytest.approx(CLIGHT_M_S * timing.clock_bias_s, abs=max(pos_tol_m, 0.01) * 3)


@pytest.mark.parametrize("baseline_m", [0.0, 1000.0, 5000.0, 12000.0])
def test_baseline_is_configurable(baseline_m: float) -> None:
    offset = Scenario.base_offset_for(baseline_m, azimuth_deg=60.0, up_m=0.0)
    world = make_world(base_offset_enu_m=offset, errors=ErrorModel.noise_free())
    d = np.linalg.norm(world.base_ecef_m - world.trajectory.origin_ecef_m)
    assert d == pytest.approx(baseline_m, abs=1e-6)
    rov, bas = world.observe("rover", world.start), world.observe("base", world.start)
    assert len(np.intersect1d(rov.sv_id, bas.sv_id)) >= 8


def test_epoch_arrays_have_the_obsepoch_layout_the_encoders_expect() -> None:
    world = make_world()
    ep = world.observe("rover", nominal(world, 1.0))
    n = len(ep)
    assert ep.gnss_id.dtype == np.int8 and ep.sv_id.dtype == np.int16 and ep.lli.dtype == np.uint8
    assert ep.half_cyc_sub.dtype == np.uint8
    for arr in (ep.gnss_id, ep.pr_m, ep.cp_cyc, ep.dop_hz, ep.cn0_dbhz, ep.lock_ms, ep.lli, ep.half_cyc_sub,
                ep.pr_std_m, ep.cp_std_cyc):
        assert arr.shape == (n,)
    assert np.all(np.diff(ep.sv_id) > 0) and np.all(np.isfinite(ep.cp_cyc))
    assert np.all((ep.pr_m > 1.9e7) & (ep.pr_m < 2.7e7 + 3e5))  # ranges ± 1 ms of clock
    assert np.all(ep.pr_std_m > 0.5)
    # cpStdev is the receiver's own tracking-noise estimate from C/N0: mm-level, falling as C/N0 rises
    assert np.all((ep.cp_std_cyc > 0.001) & (ep.cp_std_cyc < 0.03))
    order = np.argsort(ep.cn0_dbhz)
    assert np.all(np.diff(ep.cp_std_cyc[order]) <= 1e-12)
    assert ep.leap_s == 15 and not ep.clock_reset
