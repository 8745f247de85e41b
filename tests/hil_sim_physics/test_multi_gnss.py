"""Multi-constellation worlds: GLONASS FDMA carriers and inter-frequency biases, Galileo/QZSS, RXM-RAWX ids.

The double-difference checks run on noise-free worlds with a static rover: DD phase (m) minus the DD of the
geometric model (range, satellite clocks, troposphere, ionosphere on each carrier) minus the known integer
ambiguities × λ must vanish to the millimetre for two receivers of one IFB type, and leave the difference of the
two types' phase IFBs for a mixed pair.
"""

from __future__ import annotations

import dataclasses
from collections import Counter

import numpy as np
import pytest

from hil_sim import ubx_encode as enc
from hil_sim.constellations import IFB_TYPES, SatelliteLayout, glonass_ifb, parse_systems
from hil_sim.scenario import MULTI_WORLDS, ErrorModel, FlightPlan, ReceiverModel, Scenario
from hil_sim.world import World
from onboard.receiver.decode import decode_rxm_rawx
from onboard.rtk.consts import CLIGHT_M_S, DFREQ_G1_HZ, FREQ_G1_HZ, FREQ_L1_HZ
from onboard.rtk.types import FCN_NONE, GNSS_GALILEO, GNSS_GLONASS, GNSS_GPS, GNSS_QZSS


def _static_world(world: str, rover_ifb: str = "ublox-m8", base_ifb: str = "ublox-m8",
                  glonass_unit_code_sigma_m: float = 0.0, **over: object) -> World:
    errors = dataclasses.replace(ErrorModel.noise_free(), glonass_unit_code_sigma_m=glonass_unit_code_sigma_m)
    sc = Scenario.multi(world, duration_s=300.0, errors=errors, flight=FlightPlan(fly=False),
                        base_offset_enu_m=(600.0, -400.0, 3.0), **over)
    sc = dataclasses.replace(sc, rover_receiver=dataclasses.replace(sc.rover_receiver, ifb_type=rover_ifb),
                             base_receiver=dataclasses.replace(sc.base_receiver, ifb_type=base_ifb))
    return World(sc)


def _one_way(world: World, rcv: str, k: int) -> dict[tuple[int, int], tuple[float, float, float, float]]:
    """Per satellite: (phase m − ambiguity·λ, model m (ρ + c(b − dts) + T − I), phase IFB m, λ)."""
    ep, d = world.observe_detailed(rcv, world.start.add_s(k))
    lam = d["lambda_m"]
    model = d["rho_m"] + CLIGHT_M_S * (d["clock_bias_s"] - d["sat_clock_s"]) + d["tropo_m"] - d["iono_m"]
    phase = (ep.cp_cyc - d["ambiguity_cyc"] - d["half_cycle_cyc"]) * lam
    return {(int(g), int(s)): (float(phase[i]), float(model[i]), float(d["phase_ifb_m"][i]), float(lam[i]))
            for i, (g, s) in enumerate(zip(ep.gnss_id, ep.sv_id, strict=True))}


def _glonass_dd(world: World, k: int) -> tuple[np.ndarray, np.ndarray]:
    """GLONASS DD residuals (phase − model, m) against the first GLONASS satellite, and the DD of the phase IFBs."""
    rov, bas = _one_way(world, "rover", k), _one_way(world, "base", k)
    glo = sorted(s for s in rov if s[0] == GNSS_GLONASS and s in bas)
    assert len(glo) >= 4, glo
    ref = glo[0]

    def sd(s: tuple[int, int], j: int) -> float:
        return rov[s][j] - bas[s][j]

    res = np.array([(sd(s, 0) - sd(s, 1)) - (sd(ref, 0) - sd(ref, 1)) for s in glo[1:]])
    ifb = np.array([sd(s, 2) - sd(ref, 2) for s in glo[1:]])
    return res, ifb


def test_glonass_double_differences_of_one_receiver_type_match_the_geometric_model_to_the_millimetre() -> None:
    world = _static_world("gr-2012")
    for k in (0, 120, 250):
        res, ifb = _glonass_dd(world, k)
        assert np.all(ifb == 0.0)
        assert np.max(np.abs(res)) < 1e-3, res


def test_glonass_double_differences_of_mixed_receiver_types_carry_the_phase_ifb() -> None:
    world = _static_world("gr-2012", rover_ifb="ublox-m8", base_ifb="other")
    res, ifb = _glonass_dd(world, 60)
    assert np.max(np.abs(ifb)) > 5e-3  # 4 mm per channel step between the types: centimetres over the band
    assert np.max(np.abs(res - ifb)) < 1e-3, (res, ifb)
    # and the model does not cancel them: the same DD without the IFB term is off by them
    assert np.max(np.abs(res)) > 5e-3


def test_glonass_code_ifb_cancels_for_one_type_and_not_for_two() -> None:
    ks = np.arange(-7, 7)
    c1, p1 = glonass_ifb("ublox-m8", ks, (1, 10))
    c1b, p1b = glonass_ifb("ublox-m8", ks, (1, 10))
    c2, p2 = glonass_ifb("other", ks, (1, 10))
    assert np.array_equal(c1, c1b) and np.array_equal(p1, p1b)
    dc = c2 - c1
    assert np.ptp(dc) > 1.0  # decimetres to metres per channel step: metres across the band
    dp = (p2 - p1) * 1e3
    slope = np.polyfit(ks, dp, 1)[0]
    t1, t2 = IFB_TYPES["ublox-m8"], IFB_TYPES["other"]
    assert slope == pytest.approx(t2.phase_slope_mm_per_k - t1.phase_slope_mm_per_k, abs=0.5)


@pytest.mark.slow
def test_each_receiver_unit_carries_its_own_glonass_code_delay_per_channel() -> None:
    """Two u-blox units of one type: the type's code IFB cancels between them, each unit's own delay per channel
    (ErrorModel.glonass_unit_code_sigma_m) does not; GPS code carries none; noise_free() switches it off."""
    world = _static_world("gr-2012", glonass_unit_code_sigma_m=1.0)
    t = world.start.add_s(60)
    (rov, d_r), (bas, d_b) = world.observe_detailed("rover", t), world.observe_detailed("base", t)
    glo_r = {int(s): float(c) for g, s, c in zip(rov.gnss_id, rov.sv_id, d_r["code_ifb_m"], strict=True)
             if g == GNSS_GLONASS}
    glo_b = {int(s): float(c) for g, s, c in zip(bas.gnss_id, bas.sv_id, d_b["code_ifb_m"], strict=True)
             if g == GNSS_GLONASS}
    sd = np.array([glo_r[s] - glo_b[s] for s in sorted(glo_r.keys() & glo_b.keys())])
    assert sd.size >= 4
    assert 0.3 < float(np.std(sd)) < 3.0, sd  # metres between channels, as between the two real M8Ps
    assert np.all(d_r["code_ifb_m"][rov.gnss_id == GNSS_GPS] == 0.0)
    quiet = _static_world("gr-2012")
    (qr, q_r), (qb, q_b) = quiet.observe_detailed("rover", t), quiet.observe_detailed("base", t)
    assert np.array_equal(q_r["code_ifb_m"][qr.gnss_id == GNSS_GLONASS], q_b["code_ifb_m"][qb.gnss_id == GNSS_GLONASS])
    # the same units in another flight of the same seed: constant, a property of the hardware
    again = _static_world("gr-2012", glonass_unit_code_sigma_m=1.0).observe_detailed("rover", t)[1]["code_ifb_m"]
    assert np.array_equal(again, d_r["code_ifb_m"])


def test_fdma_wavelength_of_the_simulated_phase_doppler_times_lambda_is_the_range_rate() -> None:
    world = _static_world("gr-2012")
    ep, d = world.observe_detailed("rover", world.start.add_s(30))
    glo = ep.gnss_id == GNSS_GLONASS
    assert glo.sum() >= 4
    k = ep.glo_fcn[glo].astype(float)
    lam = CLIGHT_M_S / (FREQ_G1_HZ + k * DFREQ_G1_HZ)
    assert np.allclose(d["lambda_m"][glo], lam, rtol=0, atol=1e-15)
    assert len(set(k.tolist())) >= 3  # several different channels in view
    # Doppler·λ = −(range rate + clock rates): noise-free world, static rover
    rate = d["rho_dot_m_s"] + CLIGHT_M_S * (d["timing"].clock_drift_s_s - d["sat_drift_s_s"])
    assert np.max(np.abs(-ep.dop_hz[glo] * lam - rate[glo])) < 0.01
    # the phase rate is the Doppler: Δphase over 1 s in the channel's own cycles
    ep2 = world.observe("rover", world.start.add_s(31))
    common = [(i, j) for i in np.flatnonzero(glo) for j in range(len(ep2))
              if ep2.gnss_id[j] == GNSS_GLONASS and ep2.sv_id[j] == ep.sv_id[i]]
    dt = ep2.time.diff_s(ep.time)
    for i, j in common:
        mean_dop = (ep.cp_cyc[i] - ep2.cp_cyc[j]) / dt  # phase has the sign of range, Doppler the opposite
        assert mean_dop == pytest.approx((ep.dop_hz[i] + ep2.dop_hz[j]) / 2, abs=0.05)
    # a wrong wavelength (GPS L1's) would turn the same range rate into a visibly different Doppler
    assert np.max(np.abs(-ep.dop_hz[glo] * CLIGHT_M_S / FREQ_L1_HZ - rate[glo])) > 1.0


@pytest.mark.parametrize(("world", "expected"), [
    ("gr-2012", {GNSS_GPS: (6, 12), GNSS_GLONASS: (5, 10)}),
    ("gej-2021", {GNSS_GPS: (5, 12), GNSS_GALILEO: (4, 10), GNSS_QZSS: (3, 4)}),
])
def test_multi_constellation_world_has_satellites_of_each_system_above_the_mask(world: str,
                                                                               expected: dict) -> None:
    w = World(Scenario.multi(world, duration_s=120.0))
    ep, d = w.observe_detailed("base", w.start.add_s(10))
    mask = np.radians(w.scenario.base_receiver.elevation_mask_deg)
    assert np.all(d["el_rad"] >= mask - 1e-3)
    counts = Counter(ep.gnss_id.tolist())
    assert set(counts) == set(expected)
    for g, (lo, hi) in expected.items():
        assert lo <= counts[g] <= hi, (g, counts)
    # GLONASS entries carry their channel, others FCN_NONE; the signal is the L1 C/A-class one
    assert np.all((ep.glo_fcn != FCN_NONE) == (ep.gnss_id == GNSS_GLONASS))
    assert set(ep.signal.tolist()) == {"1C"}


def test_the_lea6t_tracks_gps_only_in_a_multi_constellation_world() -> None:
    w = World(Scenario.multi("gr-2012", model="lea6t", duration_s=120.0))
    assert set(w.observe("rover", w.start.add_s(5)).gnss_id.tolist()) == {GNSS_GPS}


def test_rxm_rawx_of_the_emulated_m8t_decodes_back_with_gnss_and_frequency_ids() -> None:
    for world in MULTI_WORLDS:
        w = World(Scenario.multi(world, duration_s=120.0))
        ep = w.observe("rover", w.start.add_s(3))
        frame = enc.rxm_rawx(ep)
        fcn: dict[int, int] = {}
        back = decode_rxm_rawx(frame[6:-2], fcn)
        assert back is not None
        assert back.gnss_id.tolist() == ep.gnss_id.tolist() and back.sv_id.tolist() == ep.sv_id.tolist()
        assert back.glo_fcn.tolist() == ep.glo_fcn.tolist()
        assert fcn == {int(s): int(k) for g, s, k in zip(ep.gnss_id, ep.sv_id, ep.glo_fcn, strict=True)
                       if g == GNSS_GLONASS}
        assert np.allclose(back.cp_cyc, ep.cp_cyc, rtol=0, atol=1e-6)
        assert back.signal.tolist() == ep.signal.tolist()


def test_system_strings_and_layout() -> None:
    assert parse_systems("JERG") == (GNSS_GPS, GNSS_GLONASS, GNSS_GALILEO, GNSS_QZSS)
    with pytest.raises(ValueError):
        parse_systems("GX")
    multi = SatelliteLayout(gps_only=False)
    cols = {multi.column(g, s) for g, n in ((0, 32), (6, 24), (2, 36), (5, 10), (3, 63)) for s in range(1, n + 1)}
    assert cols == set(range(multi.n_cols)) and multi.n_cols == 165
    assert SatelliteLayout(gps_only=True).column(GNSS_GPS, 7) == 6
    with pytest.raises(ValueError):
        SatelliteLayout(gps_only=True).column(GNSS_GLONASS, 1)


def test_gps_only_systems_select_the_gps_part_of_a_multi_world() -> None:
    w = World(Scenario.multi("gej-2021", systems="G", duration_s=120.0))
    assert {g for g, _ in w.satellites()} == {GNSS_GPS} and w.layout.gps_only
    assert ReceiverModel().ifb_type == "ublox-m8"
