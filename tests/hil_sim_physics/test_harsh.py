"""The harsh rover environment (walking under trees) against the statistics it was fitted to.

The simulated rover's observations go through the same estimator (hil_sim.obs_stats) as the real M8P walk; the
refit must land within the stated bounds of HARSH (the real walk's fit, docs/hil-sim-error-model.md).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from hil_sim.obs_stats import fit_environment, stream_losses, tracking_stats
from hil_sim.rtk_scenarios import HARSH_RADIO_LOSS, radio_drops
from hil_sim.scenario import HARSH, RoverEnvironment, Scenario
from hil_sim.world import World
from onboard.rtk.types import GNSS_GLONASS, GNSS_GPS

M8P = Path(__file__).resolve().parents[3] / "shared" / "data" / "gnss" / "ublox-m8p-galway-2018"
MEASURED_CODE_SIGMA_AT_45_M = 0.79
"""What the estimator returns on the real walk (HARSH.code_sigma_ref_m is the input that reproduces it)."""
MEASURED_GLONASS_CODE_FACTOR = 2.43
"""Likewise for GLONASS's code σ over GPS's (HARSH.glonass_code_factor is the input)."""
SET_AT_THE_TRUTH = ("arc_code_sigma_ref_m", "acq_code_sigma_ref_m", "acq_code_tau_s")
"""RoverEnvironment fields the rover-only estimator cannot measure: set from the walk's code at the M8P's own
RTK fixes (docs/hil-sim-error-model.md)."""


def _harsh_world(duration_s: float, seed: int = 5) -> World:
    return World(Scenario.multi("gr-2012", duration_s=duration_s, seed=seed, rover_environment=HARSH))


@pytest.mark.slow
def test_harsh_scenario_statistics_are_within_bounds_of_the_fitted_ones() -> None:
    world = _harsh_world(1200.0)
    sc = world.scenario
    n = 1190
    eps = [world.observe("rover", sc.start.add_s(k)) for k in range(n)]
    pos = np.array([world.truth(sc.start.add_s(k))["antenna_ecef_m"] for k in range(n)])
    stats = tracking_stats(eps, world.broadcast_navigation(), pos, (GNSS_GPS, GNSS_GLONASS))
    fit = fit_environment(stats, HARSH.phase_sigma_ref_m)
    assert fit.lli_slips_per_h == pytest.approx(HARSH.lli_slips_per_h, rel=0.35)
    assert HARSH.unflagged_slips_per_h / 2 <= fit.unflagged_slips_per_h <= 2 * HARSH.unflagged_slips_per_h
    assert fit.outage_mean_s == pytest.approx(HARSH.outage_mean_s, rel=0.3)
    assert fit.half_cycle_resolve_s == pytest.approx(HARSH.half_cycle_resolve_s, rel=0.3)
    for u_sim, u_fit in zip(fit.unavailability[:3], HARSH.unavailability[:3], strict=True):
        assert abs(u_sim - u_fit) < 0.05
    assert fit.cn0_horizon_dbhz == pytest.approx(HARSH.cn0_horizon_dbhz, abs=1.5)
    assert fit.cn0_zenith_dbhz == pytest.approx(HARSH.cn0_zenith_dbhz, abs=1.5)
    assert fit.cn0_sigma_dbhz == pytest.approx(HARSH.cn0_sigma_dbhz, abs=0.5)
    # the C/N0 deviation is a correlated attenuation, as on the walk (its GPS ACF 0.85 / 0.64 / 0.41 at 1 / 5 /
    # 20 s), not the white scatter of an estimate
    acf = stats[GNSS_GPS].cn0_acf
    assert acf[1] == pytest.approx(0.85, abs=0.1) and acf[5] == pytest.approx(0.64, abs=0.12)
    assert acf[20] == pytest.approx(0.41, abs=0.15)
    fast, slow = fit.cn0_tau_s
    assert 2.0 <= fast <= 10.0 and 30.0 <= slow <= 300.0
    assert fit.code_sigma_ref_m == pytest.approx(MEASURED_CODE_SIGMA_AT_45_M, rel=0.15)
    assert fit.glonass_code_factor == pytest.approx(MEASURED_GLONASS_CODE_FACTOR, rel=0.2)
    # the open-sky base is untouched by the rover's environment
    base = [world.observe("base", sc.start.add_s(k)) for k in range(0, n, 1)]
    base_st = tracking_stats(base, world.broadcast_navigation(), world.base_ecef_m, (GNSS_GPS,))[GNSS_GPS]
    assert base_st.lli_slips_per_h < 2.0 and base_st.avail_by_el["20-30"] == 1.0


def test_blockage_follows_the_unavailability_and_outage_length() -> None:
    env = RoverEnvironment(unavailability=(0.3, 0.3, 0.3, 0.3, 0.3), outage_mean_s=4.0)
    world = World(Scenario.default(duration_s=1200.0, rover_environment=env, seed=3))
    blocked = world._blocked["rover"][:, world.cols]
    el = world._el_grid_rover[:, world.cols]
    x = np.arange(blocked.shape[0]) * world._fast.dt_s / world._slow.dt_s
    el_f = np.stack([np.interp(x, np.arange(el.shape[0]), el[:, j]) for j in range(el.shape[1])], axis=1)
    up = np.degrees(el_f) >= 10.0
    assert blocked[up].mean() == pytest.approx(0.3, abs=0.03)
    assert not blocked[np.degrees(el_f) < 9.0].any()  # below the first band: never blocked
    runs = []
    for j in range(blocked.shape[1]):
        b = np.concatenate(([0], blocked[:, j].astype(int), [0]))
        edges = np.flatnonzero(np.diff(b))
        runs += list(edges[1::2] - edges[::2])
    assert np.mean(runs) == pytest.approx(4.0, rel=0.15)
    # every reacquisition is a new arc: the epoch after an outage starts its lock time afresh
    ep_prev = None
    restarts = 0
    for k in range(200, 320):
        ep = world.observe("rover", world.start.add_s(k))
        if ep_prev is not None:
            seen = set(ep_prev.sv_id.tolist())
            for i, sv in enumerate(ep.sv_id.tolist()):
                if sv not in seen and ep.lock_ms[i] < 1500.0:
                    restarts += 1
        ep_prev = ep
    assert restarts > 20


def test_radio_loss_model_reproduces_its_gilbert_parameters() -> None:
    lost = radio_drops(20_000, *HARSH_RADIO_LOSS, seed=2)
    st = stream_losses(np.flatnonzero(~lost).astype(float))
    assert st["p_loss_after_ok"] == pytest.approx(HARSH_RADIO_LOSS[0], abs=0.02)
    assert st["p_loss_after_loss"] == pytest.approx(HARSH_RADIO_LOSS[1], abs=0.02)


@pytest.mark.slow
@pytest.mark.skipif(not M8P.is_dir(), reason="needs ../shared/data/gnss/ublox-m8p-galway-2018 (not redistributable)")
def test_harsh_is_the_fit_of_the_real_walk() -> None:
    from hil_sim.constellations import read_navigation
    from onboard.formats.rinex_obs import read_rinex_obs
    from onboard.rtk.navstore import BroadcastNavigation

    walk = read_rinex_obs(M8P / "rinex/rover-20181004-1532.obs.gz")
    ephs, _, _ = read_navigation([M8P / p for p in ("rinex/rover-20181004-1532.nav.gz",
                                                    "rinex/base-20181004-1452.nav.gz", "cors-glw1/glw1277p.18n.gz",
                                                    "cors-glw1/glw1277p.18g.gz")])
    stats = tracking_stats(walk.epochs, BroadcastNavigation(ephs), walk.header.approx_pos_ecef_m,
                           (GNSS_GPS, GNSS_GLONASS))
    fit = fit_environment(stats, HARSH.phase_sigma_ref_m)
    for f in dataclasses.fields(RoverEnvironment):
        a, b = getattr(fit, f.name), getattr(HARSH, f.name)
        if f.name in SET_AT_THE_TRUTH:
            continue
        if f.name == "code_sigma_ref_m":
            assert a == pytest.approx(MEASURED_CODE_SIGMA_AT_45_M, abs=0.01)
        elif f.name == "glonass_code_factor":
            assert a == pytest.approx(MEASURED_GLONASS_CODE_FACTOR, abs=0.06)
        elif isinstance(b, tuple):
            assert np.allclose(a, b, atol=0.01 if f.name == "unavailability" else 0.05), f.name
        else:
            assert math.isclose(a, b, abs_tol=0.06), (f.name, a, b)


@pytest.mark.slow
def test_an_attenuated_signal_is_noisier() -> None:
    # with the C/N0 deviation correlated (HARSH.cn0_tau_s) it is the signal's attenuation and the code error
    # follows it; as a white scatter of the receiver's estimate it tells nothing about the error
    def code_error_by_cn0(env: RoverEnvironment) -> tuple[float, float]:
        world = World(Scenario.multi("gr-2012", duration_s=400.0, seed=7, rover_environment=env))
        err, cn0 = [], []
        for k in range(0, 360, 2):
            ep, d = world.observe_detailed("rover", world.start.add_s(k))
            gps = ep.gnss_id == GNSS_GPS
            err += (d["mp_code_m"] + d["eps_code_m"])[gps].tolist()
            cn0 += ep.cn0_dbhz[gps].tolist()
        e, c = np.array(err), np.array(cn0)
        return float(np.sqrt(np.mean(e[c < 38.0] ** 2))), float(np.sqrt(np.mean(e[c >= 45.0] ** 2)))

    weak, strong = code_error_by_cn0(HARSH)
    weak_w, strong_w = code_error_by_cn0(dataclasses.replace(HARSH, cn0_tau_s=()))
    # white: the weak ones are noisier only by their lower elevations; attenuated: by their own signal too
    assert weak / strong > 1.5 * (weak_w / strong_w)


@pytest.mark.slow
def test_the_rover_code_carries_an_error_per_arc_largest_at_acquisition() -> None:
    # the walk's code at the truth has a part constant over each arc and worst in its first seconds, which its
    # own code minus carrier cannot see (docs/hil-sim-error-model.md); HARSH draws one per arc
    world = _harsh_world(600.0, seed=11)
    early, late, steps = [], [], []
    prev: dict[tuple[int, int], tuple[float, float]] = {}
    for k in range(590):
        ep, d = world.observe_detailed("rover", world.start.add_s(k))
        # the C/N0 law of the epoch (the reported C/N0 is the attenuated signal's own): σ_ref at 45 dB-Hz
        v = d["arc_code_m"] / 10.0 ** ((HARSH.cn0_ref_dbhz - ep.cn0_dbhz) / 20.0)
        age = ep.lock_ms / 1000.0
        for j in range(len(ep)):
            key = (int(ep.gnss_id[j]), int(ep.sv_id[j]))
            if age[j] < 1.5:
                early.append(v[j])
            elif age[j] >= 75.0:
                late.append(v[j])
                last = prev.get(key)
                if last is not None and age[j] - last[1] == pytest.approx(1.0, abs=0.01):
                    steps.append(v[j] - last[0])
            prev[key] = (float(v[j]), float(age[j]))
    assert len(early) > 100 and len(late) > 300
    assert float(np.std(late)) == pytest.approx(HARSH.arc_code_sigma_ref_m, rel=0.3)
    assert float(np.std(early)) == pytest.approx(math.hypot(HARSH.arc_code_sigma_ref_m, HARSH.acq_code_sigma_ref_m),
                                                  rel=0.25)
    assert float(np.max(np.abs(steps))) < 0.01  # constant over the arc once the acquisition part has decayed
    # the open-sky environment has none
    plain = World(Scenario.multi("gr-2012", duration_s=120.0, seed=11, rover_environment=RoverEnvironment()))
    _, d = plain.observe_detailed("rover", plain.start.add_s(30))
    assert not np.any(d["arc_code_m"])
