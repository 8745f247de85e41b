"""bench/error_stats.py's code_by_arc on series whose code error is known: it sits in the arcs' first 30 s."""

from __future__ import annotations

import math

import numpy as np

from onboard.rtk.types import LLI_SLIP
from tests.bench.bench_modules import load_bench

mod = load_bench("error_stats")


def _series(errors: dict[int, list[float]], slips: dict[int, set[int]], cn0: float = 50.0):
    s = mod.Series()
    for prn, err in errors.items():
        for t, e in enumerate(err):
            s.t_s.append(float(t))
            s.prn.append(prn)
            s.rng_m.append(2.0e7 + prn)
            s.pr_m.append(2.0e7 + prn + e + 100.0)  # + a clock common to the epoch's satellites
            s.cp_cyc.append(0.0)
            s.cn0.append(cn0)
            s.el.append(1.0)
            s.lli.append(LLI_SLIP if t in slips.get(prn, set()) else 0)
            s.t_tag_s.append(float(t))
    return s


def test_an_error_in_the_first_30_s_of_each_arc_shows_there_and_only_there() -> None:
    n = 200
    # PRN 1 slips at 100 s: two arcs of 100 s, each with a 2 m error in its first 30 s; five clean satellites
    err1 = [2.0 if (t % 100) < 30 else 0.0 for t in range(n)]
    rover = _series({1: err1, **{p: [0.0] * n for p in range(2, 7)}}, {1: {100}})
    base = _series({p: [0.0] * n for p in range(1, 7)}, {})
    row = mod.code_by_arc(rover, base)["45-60"]
    assert row["n"] == 6 * n
    assert row["later"] == 0.0  # after 30 s the arcs are clean
    # in the first 30 s: 60 of PRN 1's samples at 2 m among its and the others' (30 each: their arc starts at 0)
    assert math.isclose(row["first 30 s"], math.sqrt(60 * 4.0 / (60 + 5 * 30)), rel_tol=1e-9)
    assert math.isnan(row["arc < 60 s"]) and row["arc >= 60 s"] == row["all"]
    assert np.isnan(mod.code_by_arc(rover, base)["30-35"]["all"])  # no sample in that band
