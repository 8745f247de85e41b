"""A radio gap (no base data for 20 s) while the hil_sim drone manoeuvres: the rover's phase is still watched,
so the gap neither fakes slips on every satellite nor hides one."""

from __future__ import annotations

import numpy as np
import pytest

from onboard.rtk.ephemeris import EphemerisStore
from onboard.rtk.options import RtkOptions
from onboard.rtk.postpro import pair_epochs
from onboard.rtk.rtkpos import Nav, rtk_init, rtk_pos
from onboard.rtk.types import Q_FIX
from tests.conftest import shared_file

GAP = range(150, 170)  # s after start, in flight


@pytest.fixture(scope="module")
def flight():
    shared_file("gnss/broadcast-nav-20100701/brdc1820.10n")
    from hil_sim.scenario import Scenario
    from hil_sim.world import World

    world = World(Scenario.default("m8t", duration_s=300.0))
    rover = [world.observe("rover", world.start.add_s(k)) for k in range(200)]
    base = [world.observe("base", world.start.add_s(k)) for k in range(200)]
    return world, rover, base


def _run(world, rover, base, slip_prn: int | None = None):
    if slip_prn is not None:  # the rover slips 5 cycles inside the gap, LLI not set
        for ep in rover[GAP.start + 5:]:
            ep.cp_cyc[ep.sv_id == slip_prn] += 5.0
    base = [b for k, b in enumerate(base) if k not in GAP]
    nav = Nav(EphemerisStore(world.ephemerides()), world.iono_params())
    st = rtk_init(RtkOptions(max_age_s=5.0))
    out = []
    for r, b in zip(rover, pair_epochs(rover, base, 0.025, 5.0)):
        before = st.slips
        s = rtk_pos(st, r, b, nav, world.base_ecef_m)
        err = float(np.linalg.norm(s.pos_ecef_m - world.truth(s.time)["antenna_ecef_m"]))
        out.append((s.q, err, st.slips - before))
    return out


def test_radio_gap_fakes_no_slips_and_the_fix_returns(flight):
    world, rover, base = flight
    out = _run(world, [r for r in rover], base)
    assert sum(x[2] for x in out[GAP.stop:]) == 0  # the gap's end resets no ambiguity
    assert any(x[0] == Q_FIX for x in out[GAP.stop:GAP.stop + 20])
    assert all(x[1] <= 0.10 for x in out if x[0] == Q_FIX)


def test_rover_slip_inside_a_radio_gap_is_caught(flight):
    import copy

    world, rover, base = flight
    rover = copy.deepcopy(rover)
    prn = int(rover[GAP.start].sv_id[0])
    out = _run(world, rover, base, slip_prn=prn)
    assert sum(x[2] for x in out[GAP.stop:GAP.stop + 1]) == 1  # that satellite's ambiguity, and only it
    assert all(x[1] <= 0.10 for x in out if x[0] == Q_FIX)
