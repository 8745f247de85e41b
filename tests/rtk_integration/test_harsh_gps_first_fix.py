"""GPS alone under trees (hil_sim's harsh rover, M8T): no first fix on a small full set's two wins.

With the C/N0 deviation simulated as the signal's attenuation (the code noisier where the signal is weak, for
tens of seconds), seed 3 built a float 1.3-1.6 m off whose full set of 6-7 double differences won the ratio
test (3.0-5.6); confirmed by two consecutive wins it was fixed, 4 epochs wrong (docs/rtk-defaults.md,
`full_set_min_dd`). With the per-arc code error simulated as well (docs/hil-sim-error-model.md), seed 18 is the
flight where the rule makes the difference.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hil_sim.rtk_scenarios import HARSH_RADIO_LOSS, SimCase, SimData, simulate
from onboard.rtk import postpro
from onboard.rtk.options import RtkOptions
from onboard.rtk.slots import slot_layout
from onboard.rtk.types import Q_FIX


def _wrong_fixed_epochs(data: SimData, options: RtkOptions) -> tuple[int, int]:
    rover = sorted(data.rover, key=lambda e: e.time)
    paired = postpro.pair_epochs(rover, data.base, options.pair_tolerance_s, options.max_age_s,
                                 frozenset(slot_layout("G").first_slot))
    sols, _ = postpro.run_filter(rover, paired, data.nav, data.base_pos_ecef_m, options, False)
    err = np.array([np.linalg.norm(s.pos_ecef_m - data.truth(s.time)["antenna_ecef_m"]) for s in sols])
    fixed = np.array([s.q == Q_FIX for s in sols])
    return int(np.count_nonzero(fixed & (err > 0.10))), int(np.count_nonzero(fixed))


@pytest.mark.slow
def test_gps_alone_under_trees_does_not_fix_a_small_full_set_on_two_wins() -> None:
    data = simulate(SimCase("harsh", "", harsh=True, radio_loss=HARSH_RADIO_LOSS, seed=18), "m8t")
    wrong, fixed = _wrong_fixed_epochs(data, RtkOptions())
    assert wrong == 0 and fixed > 50
    # the rule is what keeps them out: without it the same flight fixes the wrong full sets
    wrong_without, _ = _wrong_fixed_epochs(data, replace(RtkOptions(), full_set_min_dd=0))
    assert wrong_without > 0
