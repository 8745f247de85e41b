"""The scenario runner with several constellations: RXM-RAWX rover, MSM7 base per system, engine inputs."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hil_sim.rtk_scenarios import SimCase, scenario_for, simulate
from onboard.rtk.types import FCN_NONE, GNSS_GLONASS, GNSS_GPS


def test_gps_cases_keep_the_gps_world() -> None:
    sc = scenario_for(SimCase("nominal", ""), "m8t")
    assert sc.systems == "G" and sc.extra_nav_paths == () and sc.rover_environment is None


@pytest.mark.slow
def test_a_multi_constellation_case_reaches_the_engine_inputs_through_the_byte_paths() -> None:
    case = SimCase("multi", "", duration_s=60.0, systems="GREJ", world="gr-2012")
    data = simulate(case, "m8t")
    rov, bas = data.rover[10], data.base[10]
    for ep in (rov, bas):  # rover via RXM-RAWX + decoder, base via MSM7 1077/1087 + collect_rtcm
        assert {GNSS_GPS, GNSS_GLONASS} <= set(ep.gnss_id.tolist())
        glo = ep.gnss_id == GNSS_GLONASS
        assert np.all(ep.glo_fcn[glo] != FCN_NONE) and np.all(np.isfinite(ep.cp_cyc[glo]))
    assert data.nav.broadcast is not None
    assert {g for g, _ in data.nav.broadcast.satellites()} == {GNSS_GPS, GNSS_GLONASS}
    assert len(data.nav.store.prns()) >= 8
    # the base's GLONASS channels survive MSM7 (DF419) and agree with the broadcast set's
    common = [(int(s), int(k)) for g, s, k in zip(bas.gnss_id, bas.sv_id, bas.glo_fcn, strict=True) if g == GNSS_GLONASS]
    assert common and all(data.nav.broadcast.glonass_channels()[s] == k for s, k in common)


def test_the_lea6t_sees_gps_only_and_the_radio_loss_drops_seconds() -> None:
    case = SimCase("multi", "", duration_s=60.0, systems="GR", radio_loss=(0.5, 0.56))
    data = simulate(case, "lea6t")
    assert all(set(ep.gnss_id.tolist()) == {GNSS_GPS} for ep in data.rover)
    assert 0.3 < 1 - len(data.base) / len(data.rover) < 0.75 and data.lost_bytes > 0
    assert replace(case, systems="G").multi is False


@pytest.mark.slow
def test_a_base_with_few_gps_satellites_is_checked_on_every_constellation_it_tracks() -> None:
    """Five satellites, three or four of them GPS: the base's GPS-alone single points are rare and tens of
    metres off (GDOP ~37), so a check on GPS alone refused the right base position and the whole run; on GPS and
    GLONASS the right position passes, and a position 100 m off is still refused."""
    from onboard.rtk.options import RtkOptions
    from onboard.rtk.postpro import base_spp_offset_m, check_base_position
    from onboard.rtk.types import BasePositionRejected

    case = SimCase("5 satellites", "", max_sats=5, systems="GR", world="gr-2012", seed=1)
    data = simulate(case, "m8t")
    base_pos = np.asarray(data.base_pos_ecef_m)
    gps = base_spp_offset_m(data.base, data.nav, base_pos, RtkOptions(systems="G"))
    assert gps is not None and gps[0] > RtkOptions().max_base_spp_offset_m
    check_base_position(data.base, data.nav, base_pos, RtkOptions(systems="GR"))  # no refusal
    found = base_spp_offset_m(data.base, data.nav, base_pos, RtkOptions(systems="GR"))
    assert found is not None and found[1] > gps[1]
    try:
        check_base_position(data.base, data.nav, base_pos + [100.0, 0.0, 0.0], RtkOptions(systems="GR"))
    except BasePositionRejected:
        pass
    else:
        raise AssertionError("a base position 100 m off passed the check")
