"""Combined post-processing refutes a held run as a whole (RtkOptions.combined_contest_distance_m).

GPS alone under trees (hil_sim's harsh rover, M8T, seed 2): the forward pass fixes a wrong set 6.4 m off at a
cold start, standing still, and holds it for 63 s, into the flight. The backward pass fixes the standstill
right and so contradicts that run there, but has no fix over the 18 s of flight after: the epoch-by-epoch
combination took the forward's wrong fix there. The run is one held integer set; refuted at one epoch, it is
not taken at any.
"""

from __future__ import annotations

import numpy as np
import pytest

from hil_sim.rtk_scenarios import HARSH_RADIO_LOSS, SimCase, simulate
from onboard.rtk import postpro
from onboard.rtk.options import RtkOptions
from onboard.rtk.types import Q_FIX


@pytest.mark.slow
def test_a_run_the_other_pass_refutes_is_not_taken_where_that_pass_has_no_fix() -> None:
    data = simulate(SimCase("harsh", "", harsh=True, radio_loss=HARSH_RADIO_LOSS, seed=2), "m8t")
    opts = RtkOptions()
    rover = sorted(data.rover, key=lambda e: e.time)
    paired = postpro.pair_epochs(rover, data.base, opts.pair_tolerance_s, opts.max_age_s)
    fwd, _ = postpro.run_filter(rover, paired, data.nav, data.base_pos_ecef_m, opts, False)
    bwd, _ = postpro.run_filter(rover, paired, data.nav, data.base_pos_ecef_m, opts, True, None, None,
                                postpro.handover_anchors(fwd, opts.handover_min_run_s))
    truth = np.array([data.truth(s.time)["antenna_ecef_m"] for s in fwd])

    def wrong_and_fixed(sols: list) -> tuple[int, int]:
        fixed = np.array([s.q == Q_FIX for s in sols])
        err = np.linalg.norm(np.array([s.pos_ecef_m for s in sols]) - truth, axis=1)
        return int(np.count_nonzero(fixed & (err > 0.10))), int(np.count_nonzero(fixed))

    assert wrong_and_fixed(fwd)[0] > 30  # the forward pass's wrong cold-start run (63 epochs when measured)
    wrong, fixed = wrong_and_fixed(postpro.combine_passes(fwd, bwd, opts.combined_contest_distance_m))
    assert wrong == 0 and fixed > 200
    # epoch by epoch, the wrong run survives where the backward pass has no fix
    assert wrong_and_fixed(postpro.combine_passes(fwd, bwd, 0.0))[0] > 0
