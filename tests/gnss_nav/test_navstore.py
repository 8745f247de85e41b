"""The multi-constellation broadcast store and satellite-state evaluation (onboard.rtk.navstore)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from onboard.formats.rinex_nav import read_rinex_nav
from onboard.rtk.ephemeris import eph_position, sisa_index_from_m, sisa_sigma_m
from onboard.rtk.glonass import glonass_position
from onboard.rtk.navstore import BroadcastNavigation, is_healthy, satellite_state
from onboard.rtk.types import GNSS_GALILEO, GNSS_GLONASS, GNSS_GPS, GNSS_QZSS
from tests.conftest import shared_file

pytestmark = pytest.mark.shared_data

SEPT_NAV = "gnss/geonet-3034-sept-20210922/SEPT2650.21P.gz"
GLO_NAV = "gnss/broadcast-nav-20121031/brdc3050.12g"


def test_sisa_index_and_sigma_round_trip() -> None:
    for k in (0, 1, 49, 50, 74, 75, 99, 100, 107, 125):
        assert sisa_index_from_m(sisa_sigma_m(k)) == k
    assert sisa_sigma_m(107) == pytest.approx(3.12)
    assert sisa_index_from_m(-1.0) == 255 and sisa_sigma_m(255) == 6144.0


def test_store_selects_nearest_inav_galileo_and_evaluates_each_system() -> None:
    nav = read_rinex_nav(shared_file(SEPT_NAV))
    store = BroadcastNavigation([*nav.ephemerides, *nav.galileo, *nav.qzss])
    assert len(store) == 49 + 253 + 19
    e08 = [e for e in nav.galileo if e.prn == 8]
    assert {e.code_on_l2 for e in e08} == {258, 517}  # F/NAV and I/NAV records
    t = e08[0].toe.add_s(700.0)
    sel = store.select(GNSS_GALILEO, 8, t)
    assert sel is not None and sel.code_on_l2 == 517  # I/NAV preferred for E1
    assert abs(sel.toe.diff_s(t)) == min(abs(e.toe.diff_s(t)) for e in e08 if e.code_on_l2 == 517)
    st = satellite_state(sel, t)
    pos, clk = eph_position(sel, t)
    np.testing.assert_array_equal(st.pos_m, pos)
    assert st.clock_s == pytest.approx(clk - sel.tgd2_s, abs=1e-18)  # E1: BGD(E1,E5b)
    assert st.healthy and st.var_m2 == pytest.approx(sisa_sigma_m(sel.ura_index) ** 2)
    assert np.linalg.norm(st.vel_m_s) == pytest.approx(3_000.0, rel=0.25)
    g = store.select(GNSS_GPS, nav.ephemerides[0].prn, nav.ephemerides[0].toe.add_s(3600))
    assert g is not None and satellite_state(g, g.toe).clock_s == pytest.approx(
        eph_position(g, g.toe)[1] - g.tgd_s, abs=1e-18)
    last_q = max(nav.qzss, key=lambda e: e.toe)
    assert store.select(GNSS_QZSS, last_q.prn, last_q.toe.add_s(7199)) == last_q
    assert store.select(GNSS_QZSS, last_q.prn, last_q.toe.add_s(7201)) is None  # QZSS: 2 h at most
    assert store.select(GNSS_GALILEO, 8, t.add_s(3 * 86400)) is None


def test_kepler_table_states_equal_the_per_satellite_evaluation() -> None:
    # Galileo (I/NAV preferred, SISA, BGD), QZSS (2 h age) and a BeiDou GEO row (the Galileo E08 orbit relabelled
    # C03: its −5° frame and rotation) through the batched table, against select + clock + satellite_state per
    # satellite and epoch, as the engine evaluated them before (transmission time rounded to the ns there)
    from onboard.rtk.consts import CLIGHT_M_S
    from onboard.rtk.ephemeris import EphemerisStore, eph_clock_s
    from onboard.rtk.slots import satellite_states_layout, slot_layout
    from onboard.rtk.types import GNSS_BEIDOU

    nav = read_rinex_nav(shared_file(SEPT_NAV))
    geo = [dataclasses.replace(e, gnss_id=GNSS_BEIDOU, prn=3) for e in nav.galileo if e.prn == 8]
    store = BroadcastNavigation([*nav.galileo, *nav.qzss, *geo])
    layout = slot_layout("ECJ")
    t_start = min(e.toe for e in nav.qzss)
    epochs = [t_start.add_s(s) for s in range(0, 4 * 3600, 600)]
    rng = np.random.default_rng(7)
    pr = rng.uniform(2.0e7, 2.6e7, (len(epochs), layout.n))
    pr[rng.random(pr.shape) < 0.2] = np.nan
    states = satellite_states_layout(layout, EphemerisStore(), store, [t.total_ns for t in epochs], pr)
    checked = 0
    for k, t in enumerate(epochs):
        for j in range(layout.n):
            g, sv = int(layout.gnss_id[j]), int(layout.sv_id[j])
            eph = None if np.isnan(pr[k, j]) else store.select(g, sv, t.add_s(-pr[k, j] / CLIGHT_M_S))
            want = None
            if eph is not None:
                t0 = t.add_s(-pr[k, j] / CLIGHT_M_S)
                want = satellite_state(eph, t0.add_s(-eph_clock_s(eph, t0)))
            s = states[k]
            if want is None or not want.healthy:
                assert not s.ok[j]
                continue
            assert s.ok[j]
            np.testing.assert_allclose(s.pos_m[j], want.pos_m, rtol=0, atol=1e-5)  # the ns rounding: ~2 µm
            # a 1 ms forward difference: the per-satellite Kepler loop stops at 1e-14 rad, ~0.3 µm of position
            np.testing.assert_allclose(s.vel_m_s[j], want.vel_m_s, rtol=0, atol=1e-3)
            assert s.clock_s[j] == pytest.approx(want.clock_s, abs=1e-13)
            assert s.drift_s_s[j] == pytest.approx(want.drift_s_s, abs=1e-15)
            assert s.var_m2[j] == want.var_m2
            checked += 1
    assert checked > 200
    assert {int(layout.gnss_id[j]) for k in range(len(epochs)) for j in np.flatnonzero(states[k].ok)} == {
        GNSS_GALILEO, GNSS_QZSS, GNSS_BEIDOU}


def test_store_glonass_age_channels_and_health() -> None:
    glo = read_rinex_nav(shared_file(GLO_NAV)).glonass
    store = BroadcastNavigation(glo)
    assert store.add(glo[0]) is False  # a repeat
    g = glo[0]
    # the first tb of the day of this slot: 30 min before it nothing, 29 min before it this one
    first = min((e for e in glo if e.slot == g.slot), key=lambda e: e.toe)
    assert store.select(GNSS_GLONASS, g.slot, first.toe.add_s(-1801)) is None
    assert store.select(GNSS_GLONASS, g.slot, first.toe.add_s(-1799)) == first
    chans = store.glonass_channels()
    assert len(chans) == 24 and set(chans.values()) <= set(range(-7, 7))
    st = satellite_state(g, g.toe.add_s(100))
    pos, _ = glonass_position(g, g.toe.add_s(100))
    np.testing.assert_array_equal(st.pos_m, pos)
    assert st.var_m2 == 25.0 and st.clock_s == pytest.approx(-g.tau_n_s + g.gamma_n * 100)
    assert not is_healthy(dataclasses.replace(g, health=1))


def test_glonass_orbits_interpolated_between_whole_steps_agree_with_integration_from_tb() -> None:
    """The store's GLONASS states (RK4 from tb in whole 60 s steps, quintic Hermite between them) at instants in
    any order over ±30 min of five ephemerides stay within 0.1 mm of RTKLIB's integration from tb to the instant
    (the last step shortened), the velocity (v + a·dt/2 against RTKLIB's forward difference) within 10 µm/s;
    on the whole steps they are RTKLIB's positions to the bit."""
    glo = read_rinex_nav(shared_file(GLO_NAV)).glonass
    rng = np.random.default_rng(5)
    for g in glo[:: max(1, len(glo) // 5)][:5]:
        store = BroadcastNavigation([g])
        worst_m = worst_v = 0.0
        for dt in rng.uniform(-1800.0, 1800.0, 150):
            t = g.toe.add_s(float(dt))
            carried = store.state(g, t)
            fresh = satellite_state(g, t)
            worst_m = max(worst_m, float(np.linalg.norm(carried.pos_m - fresh.pos_m)))
            worst_v = max(worst_v, float(np.linalg.norm(carried.vel_m_s - fresh.vel_m_s)))
            assert carried.clock_s == pytest.approx(fresh.clock_s, abs=1e-15)
        assert worst_m < 1e-4 and worst_v < 1e-5, (g.slot, worst_m, worst_v)
        for k in (-30, -7, 0, 1, 29):
            t = g.toe.add_s(60.0 * k)
            np.testing.assert_array_equal(store.state(g, t).pos_m, satellite_state(g, t).pos_m)


def test_glonass_states_of_a_slot_equal_the_per_epoch_selection_clock_and_state_to_the_bit() -> None:
    # the engine's batch of one slot (selection among the slot's ephemerides, the clock fixed point, the orbit
    # carried on) against select + glonass_clock_s + state called epoch by epoch on a store of its own
    from onboard.rtk.consts import CLIGHT_M_S
    from onboard.rtk.glonass import glonass_clock_s

    glo = read_rinex_nav(shared_file(GLO_NAV)).glonass
    slot = glo[len(glo) // 2].slot
    ephs = [e for e in glo if e.slot == slot]
    assert len(ephs) >= 3
    batch, single = BroadcastNavigation(ephs), BroadcastNavigation(ephs)
    t_first = ephs[-1].toe.add_s(-7200.0)  # through the slot's last ephemeris and an hour past its 30 min
    times = [t_first.add_s(s) for s in range(0, 3 * 3600, 13)]
    pr = np.random.default_rng(3).uniform(1.9e7, 2.5e7, len(times))
    t0 = np.array([t.add_s(-p / CLIGHT_M_S).total_ns for t, p in zip(times, pr, strict=True)], np.int64)
    out = (np.zeros((len(times), 3)), np.zeros((len(times), 3)), np.zeros(len(times)), np.zeros(len(times)),
           np.zeros(len(times)))
    ok = np.zeros(len(times), bool)
    batch.glonass_states(slot, t0, out, ok)
    for i, (t, p) in enumerate(zip(times, pr, strict=True)):
        t_tx0 = t.add_s(-p / CLIGHT_M_S)
        eph = single.select(GNSS_GLONASS, slot, t_tx0)
        if eph is None:
            assert not ok[i]
            continue
        want = single.state(eph, t_tx0.add_s(-glonass_clock_s(eph, t_tx0)))  # type: ignore[arg-type]
        assert ok[i] == want.healthy
        np.testing.assert_array_equal(out[0][i], want.pos_m)
        np.testing.assert_array_equal(out[1][i], want.vel_m_s)
        assert (out[2][i], out[3][i], out[4][i]) == (want.clock_s, want.drift_s_s, want.var_m2)
    assert 0.5 * len(times) < ok.sum() < 0.75 * len(times)  # the last hour has no ephemeris within 30 min
