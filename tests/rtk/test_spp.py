"""Satellite positions and single-point positioning on real data against surveyed coordinates."""

from __future__ import annotations

import numpy as np
import pytest

from onboard.formats.rinex_nav import read_rinex_nav
from onboard.formats.rinex_obs import read_rinex_obs
from onboard.rtk.ephemeris import EphemerisStore, satellite_states
from onboard.rtk.geodesy import ecef_to_enu, ecef_to_llh
from onboard.rtk.models import klobuchar_m, saastamoinen_m
from onboard.rtk.pntpos import pntpos
from tests.conftest import shared_file

ROVER_0759 = np.array([-3976219.1873, 3382371.6051, 3652511.1423])


@pytest.fixture(scope="module")
def geonet():
    nav = read_rinex_nav(shared_file("gnss/geonet-0759-3040-20050402/07590920.05n.gz"))
    obs = read_rinex_obs(shared_file("gnss/geonet-0759-3040-20050402/07590920.05o.gz"))
    return nav, obs


def test_broadcast_orbits_are_on_the_gps_shell_and_move_at_orbital_speed(geonet):
    nav, obs = geonet
    e = obs.epochs[0]
    sats = satellite_states(EphemerisStore(nav.ephemerides), e.sv_id, e.time, e.pr_m)
    assert sats.ok.all()
    r = np.linalg.norm(sats.pos_m, axis=1)
    a = np.array([next(x for x in nav.ephemerides if x.prn == p).sqrt_a ** 2 for p in e.sv_id])
    ecc = np.array([next(x for x in nav.ephemerides if x.prn == p).e for p in e.sv_id])
    assert np.all(np.abs(r - a) <= a * ecc + 2e3)  # r = a(1 − e cos E) + harmonic corrections < 2 km
    v = np.linalg.norm(sats.vel_m_s, axis=1)  # ECEF speed of a GPS satellite: 1.9–4.0 km/s
    assert np.all((v > 1500) & (v < 4200))
    assert np.all(np.abs(sats.clock_s) < 1e-3)


def test_spp_on_geonet_within_a_few_metres_of_the_surveyed_marker(geonet):
    nav, obs = geonet
    store = EphemerisStore(nav.ephemerides)
    errs = []
    for e in obs.epochs[::10]:
        sats = satellite_states(store, e.sv_id, e.time, e.pr_m)
        sol = pntpos(e.pr_m, sats, e.time.tow_s, np.radians(10), None, (nav.iono_alpha, nav.iono_beta))
        assert sol.ok, sol.message
        errs.append(ecef_to_enu(sol.pos_ecef_m, ROVER_0759))
        assert abs(sol.clock_bias_m) < 0.01 * 299792458.0  # receiver clock within its ±1 ms steering range
    errs = np.array(errs)
    assert np.sqrt(np.mean(errs[:, 0] ** 2 + errs[:, 1] ** 2)) < 4.0
    assert np.sqrt(np.mean(errs[:, 2] ** 2)) < 8.0


def test_spp_excludes_a_faulty_pseudorange(geonet):
    nav, obs = geonet
    store = EphemerisStore(nav.ephemerides)
    e = obs.epochs[0]
    pr = e.pr_m.copy()
    pr[2] += 300.0
    sats = satellite_states(store, e.sv_id, e.time, pr)
    sol = pntpos(pr, sats, e.time.tow_s, np.radians(5), None, (nav.iono_alpha, nav.iono_beta))
    assert sol.ok and not sol.used[2]
    assert np.linalg.norm(sol.pos_ecef_m - ROVER_0759) < 15.0


def test_spp_velocity_from_doppler_of_a_static_receiver():
    d = "gnss/ublox-m8p-galway-2018/rinex/"
    nav = read_rinex_nav(shared_file(d + "rover-20181004-1237.nav.gz"))
    obs = read_rinex_obs(shared_file(d + "rover-20181004-1237.obs.gz"))
    store = EphemerisStore(nav.ephemerides)
    e = obs.epochs[100].gps_only()
    sats = satellite_states(store, e.sv_id, e.time, e.pr_m)
    sol = pntpos(e.pr_m, sats, e.time.tow_s, np.radians(15), e.dop_hz, (nav.iono_alpha, nav.iono_beta))
    assert sol.ok
    assert np.linalg.norm(sol.vel_ecef_m_s) < 0.1
    ref = np.array([3774088.9931, -601661.8217, 5089321.3853])
    assert np.linalg.norm(sol.pos_ecef_m - ref) < 10.0


def test_atmosphere_models_have_textbook_magnitudes():
    lat = np.radians(35.0)
    zen = saastamoinen_m(lat, 0.0, np.array([np.pi / 2]))[0]
    assert 2.3 < zen < 2.6  # ≈2.3 m dry + wet at sea level
    low = saastamoinen_m(lat, 0.0, np.array([np.radians(15.0)]))[0]
    assert low == pytest.approx(zen / np.sin(np.radians(15.0)), rel=0.02)
    iono = klobuchar_m(50400.0, lat, np.radians(139.0), np.array([0.0]), np.array([np.pi / 2]), None, None)[0]
    assert 1.0 < iono < 30.0
    # at 02:00 local time (t = 60200 s GPST at 139° E) only the 5 ns night-time floor remains
    night = klobuchar_m(60200.0, lat, np.radians(139.0), np.array([0.0]), np.array([np.pi / 2]), None, None)
    assert night[0] == pytest.approx(5e-9 * 299792458.0, rel=1e-3)


def test_ecef_llh_sanity():
    lat, lon, h = ecef_to_llh(ROVER_0759)
    assert 35 < np.degrees(lat) < 36.5 and 139 < np.degrees(lon) < 141 and -50 < h < 500


@pytest.fixture(scope="module")
def shipped_store():
    """Broadcast orbits shipped with the simulator (2010-07-01): no ../shared needed."""
    from hil_sim.scenario import DEFAULT_NAV_PATH
    from tests.rtk._sim import T0

    return EphemerisStore(read_rinex_nav(DEFAULT_NAV_PATH).ephemerides), T0


@pytest.mark.parametrize("corrupt", [0.0, -1.0e6, np.inf, -np.inf, 1.0e12])
def test_spp_refuses_a_pseudorange_no_satellite_can_give_and_keeps_the_epoch(shipped_store, corrupt: float) -> None:
    """One impossible pseudorange (0 m, negative, infinite, 10⁹ km) is not a measurement: the epoch is still
    solved on the others, to the millimetre the solution without that satellite. (A 0-m pseudorange used to
    pull the iteration thousands of km away and the exclusion then lost the whole epoch.)"""
    from tests.rtk._sim import BASE_ECEF_M, SimReceiver, observe

    store, t0 = shipped_store
    e = observe(store, SimReceiver(clock_s=2e-4), BASE_ECEF_M, np.zeros(3), t0)
    assert len(e) >= 6
    pr = e.pr_m.copy()
    pr[1] = corrupt
    sats = satellite_states(store, e.sv_id, e.time, pr)
    sol = pntpos(pr, sats, e.time.tow_s, np.radians(10), e.dop_hz)
    assert sol.ok, sol.message
    assert not sol.used[1] and sol.used[0] and sol.used[2:].all()
    without = pr.copy()
    without[1] = np.nan
    alone = pntpos(without, sats, e.time.tow_s, np.radians(10), e.dop_hz)
    assert np.linalg.norm(sol.pos_ecef_m - alone.pos_ecef_m) < 0.001
    assert np.linalg.norm(sol.pos_ecef_m - BASE_ECEF_M) < 15.0  # the broadcast models' single-point metres


@pytest.mark.parametrize("corrupt_hz", [1.0e6, -3000.0, 200.0])
def test_doppler_velocity_leaves_out_a_doppler_far_off_the_others(shipped_store, corrupt_hz: float) -> None:
    """A static receiver with one corrupt Doppler (added: 1 MHz, −3 kHz, 200 Hz ≈ 38 m/s): the velocity is the
    others' (noise-free: zero), not moved by tens or thousands of m/s."""
    from tests.rtk._sim import BASE_ECEF_M, SimReceiver, observe

    store, t0 = shipped_store
    e = observe(store, SimReceiver(clock_s=2e-4, drift_s_s=1e-7), BASE_ECEF_M, np.zeros(3), t0)
    dop = e.dop_hz.copy()
    dop[2] += corrupt_hz
    sats = satellite_states(store, e.sv_id, e.time, e.pr_m)
    sol = pntpos(e.pr_m, sats, e.time.tow_s, np.radians(10), dop)
    assert sol.ok
    assert np.linalg.norm(sol.vel_ecef_m_s) < 0.01
    assert sol.clock_drift_m_s == pytest.approx(1e-7 * 299792458.0, abs=0.01)


def test_spp_of_a_real_gps_glonass_epoch_leaves_out_a_pseudorange_8000_km_off():
    """M8P static rover, GPS + GLONASS, epoch 30 with G03's pseudorange replaced by 3·10⁷ m (inside the physical
    bounds, 8 000 km off): from the batch's start position that residual misses the other GPS satellites' by
    thousands of km and is left out before the least squares. The exclusion by largest residual alone, at the
    position the bad value had pulled the solution to, left out good satellites until 4 remained: no solution."""
    from dataclasses import replace

    from onboard.postpro.inputs import load_rtk_inputs
    from onboard.rtk.options import RtkOptions
    from onboard.rtk.rtkpos import epoch_receivers, epoch_spp
    from onboard.rtk.slots import slot_layout

    m8p = "gnss/ublox-m8p-galway-2018/rinex/"
    inp = load_rtk_inputs(shared_file(m8p + "rover-20181004-1237.obs.gz"),
                          shared_file(m8p + "base-20181004-1236.rtcm.obs.gz"),
                          [shared_file(m8p + "rover-20181004-1237.nav.gz")], systems="GR")
    epochs = list(inp.rover[:40])
    e = epochs[30]
    g03 = (e.gnss_id == 0) & (e.sv_id == 3)
    assert g03.any()
    epochs[30] = replace(e, pr_m=np.where(g03, 3.0e7, e.pr_m))
    options = RtkOptions(systems="GR")
    layout = slot_layout("GR")
    rcvs = epoch_receivers(epochs, inp.nav.store, layout=layout, broadcast=inp.nav.broadcast)
    sols = epoch_spp(epochs, rcvs, inp.nav, options)
    assert sols[30].ok, sols[30].message
    assert not sols[30].used[layout.slots_of(np.array([0]), np.array([3]))[0]]
    assert np.count_nonzero(sols[30].used) >= np.count_nonzero(sols[29].used) - 1  # G03 alone left out
    assert np.linalg.norm(sols[30].pos_ecef_m - sols[29].pos_ecef_m) < 10.0
    # the real-time path: that epoch alone, from the previous epoch's solution
    r = rcvs[30]
    live = pntpos(np.where(r.has, r.pr_m, np.nan), r.sats, epochs[30].time.tow_s, options.elmask_rad, r.dop_hz,
                  inp.nav.iono, x0_ecef_m=sols[29].pos_ecef_m, clock0_m=sols[29].clock_bias_m,
                  clock_group=layout.group, lam_m=r.lam)
    assert live.ok and np.linalg.norm(live.pos_ecef_m - sols[30].pos_ecef_m) < 0.01


def test_gross_error_screen_of_one_epoch_equals_the_batch_one():
    """_gross_errors' two paths (one epoch in Python, many with numpy's nanmedian) flag the same values, with
    and without clock groups, on random residuals with gaps and values thousands of km off."""
    from onboard.rtk.pntpos import _gross_errors

    rng = np.random.default_rng(4)
    flagged = 0
    for trial in range(100):
        e, n = 20, 40
        pr = rng.normal(2.2e7, 3e5, (e, n))
        pr[rng.random((e, n)) < 0.4] = np.nan
        pr[rng.random((e, n)) < 0.05] += rng.choice([5e6, -3e6, 2e6])
        spos = np.zeros((e, n, 3))
        spos[..., 0] = 1.0
        group = rng.integers(0, 3, n).astype(np.int8) if trial % 2 else None
        args = (np.zeros((e, n)), np.zeros((e, 3)), np.isfinite(pr))
        batch = _gross_errors(pr, spos, args[0], args[1], args[2], group)
        single = np.vstack([_gross_errors(pr[k:k + 1], spos[k:k + 1], args[0][k:k + 1], args[1][k:k + 1],
                                          args[2][k:k + 1], group) for k in range(e)])
        assert np.array_equal(batch, single)
        flagged += int(batch.sum())
    assert flagged > 100
