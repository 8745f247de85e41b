"""The World's common errors drift smoothly: what a 20-s-old base epoch misses is a steady drift, not noise."""

from __future__ import annotations

import dataclasses

import numpy as np

from hil_sim.flight import FlightPlan
from hil_sim.scenario import ErrorModel, Scenario
from hil_sim.world import World


def test_common_errors_drift_smoothly_over_a_radio_gap() -> None:
    # only the common errors (orbit, satellite clock, ionosphere model error, troposphere residual)
    common = dataclasses.replace(ErrorModel.noise_free(), orbit_sigma_m=0.3, sat_clock_sigma_m=0.3,
                                 iono_model_error_fraction=0.2, tropo_residual_zenith_sigma_m=0.02)
    sc = Scenario.default("m8t", duration_s=400.0, flight=FlightPlan(fly=False))
    noisy, clean = World(dataclasses.replace(sc, errors=common)), World(dataclasses.replace(sc, errors=ErrorModel.noise_free()))
    t0 = sc.start

    def err(k: int) -> dict[int, float]:  # the common errors in the base's phase (m), per PRN
        a, b = noisy.observe("base", t0.add_s(k)), clean.observe("base", t0.add_s(k))
        return {int(s): float(d) for s, d in zip(a.sv_id, (a.cp_cyc - b.cp_cyc) * 0.19029367279836487)}

    e = {k: err(k) for k in (100, 110, 120, 140)}
    prns = set.intersection(*(set(v) for v in e.values()))
    assert len(prns) >= 6
    change = np.array([e[140][p] - e[120][p] for p in prns])
    assert np.max(np.abs(change)) > 0.002  # the errors do move over 20 s …
    # … along a line: extrapolating the last 10 s rate over 20 s leaves millimetres
    miss = np.array([e[140][p] - (e[120][p] + 2.0 * (e[120][p] - e[110][p])) for p in prns])
    assert np.max(np.abs(miss)) < 0.005
