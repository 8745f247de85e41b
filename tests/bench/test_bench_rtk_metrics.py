"""bench/bench_rtk.py's pure helpers: the fix/wrong-fix metrics, the references by time, the tables and
RTKLIB's navsys mask (the benchmark itself needs RTKLIB's bindings and the real datasets: not run here)."""

from __future__ import annotations

import sys
from types import SimpleNamespace

import numpy as np
import pytest

from onboard.rtk.geodesy import enu_to_ecef
from tests.bench.bench_modules import load_bench

REF = np.array([3774088.9931, -601661.8217, 5089321.3853])


bench_rtk = load_bench("bench_rtk")
rtklib_driver = load_bench("rtklib_driver")


def _rows(offsets_enu_m: list[tuple[float, float, float]], q: list[int], tow0: float = 1000.0) -> np.ndarray:
    """Solution rows (week, tow, x, y, z, q) 1 s apart at the given ENU offsets from REF."""
    return np.array([(2021, tow0 + k, *enu_to_ecef(np.array(d), REF), qk)
                     for k, (d, qk) in enumerate(zip(offsets_enu_m, q))])


def test_score_counts_fixes_first_fix_and_the_three_kinds_of_wrong_fix():
    offsets = [(1.0, 0, 0), (0.5, 0, 0), (0.02, 0, 0), (0, 0, 0.12), (0, 0.11, 0), (0.04, 0, 0.04)]
    sol = _rows(offsets, [2, 2, 1, 1, 1, 1])
    r = bench_rtk.score(sol, bench_rtk._static(tuple(REF)))
    assert r["epochs"] == 6 and r["fixed"] == 4 and r["fix"] == pytest.approx(100 * 4 / 6)
    assert r["ttff"] == pytest.approx(2.0)  # first fix 2 s after the first epoch
    assert r["checked"] == 4
    assert r["wrong"] == 2  # 12 cm up, 11 cm north: > 10 cm in 3D
    assert r["wrong_h"] == 1  # only the 11 cm north one horizontally
    assert r["off5"] == 3  # 12, 11 and 5.7 cm (0.04, 0.04) are beyond 5 cm; 2 cm is not
    h = np.sqrt(np.mean([0.02**2, 0, 0.11**2, 0.04**2]))
    assert r["h"] == pytest.approx(100 * h, rel=1e-6)
    assert r["pseudo_checked"] == 0


def test_score_against_a_reference_of_few_epochs_and_a_pseudo_reference():
    sol = _rows([(0, 0, 0), (0.2, 0, 0), (0.0, 0, 0), (0.0, 0, 0)], [1, 1, 1, 2])
    # the reference covers only the first two epochs; the pseudo-reference (a solution's fixed epochs) the last
    # three, the second of them float (not used) and the first 30 cm off the tested one
    ref = bench_rtk.nearest_ref(np.array([(1000.0, *REF), (1001.0, *REF)]), 0.06)
    pseudo_rows = _rows([(9, 9, 9), (0.5, 0, 0), (0.3, 0, 0), (0, 0, 0)], [5, 1, 2, 1])
    r = bench_rtk.score(sol, ref, bench_rtk.solution_ref(pseudo_rows))
    assert r["checked"] == 2 and r["wrong"] == 1 and r["wrong_h"] == 1
    assert r["pseudo_checked"] == 1 and r["pseudo_wrong"] == 1  # epoch 1001: 0.2 vs 0.5 m east; 1002 float there


def test_score_counts_the_epochs_beyond_5_cm_where_the_pseudo_reference_agrees_with_the_solution():
    # reference: REF at every epoch; the solution's fixes 0, 8, 8, 12 cm east and a float at 8 cm; the
    # pseudo-reference fixed 1, 7, 30 cm east at the first three epochs and float at the fourth
    sol = _rows([(0, 0, 0), (0.08, 0, 0), (0.08, 0, 0), (0.12, 0, 0), (0.08, 0, 0)], [1, 1, 1, 1, 2])
    ref = bench_rtk._static(tuple(REF))
    pseudo_rows = _rows([(0.01, 0, 0), (0.07, 0, 0), (0.30, 0, 0), (0.12, 0, 0), (0.08, 0, 0)], [1, 1, 1, 2, 1])
    r = bench_rtk.score(sol, ref, bench_rtk.solution_ref(pseudo_rows))
    assert r["off5"] == 3  # 8, 8 and 12 cm
    # 1001: 8 vs 7 cm (1 cm apart) agrees; 1002: 8 vs 30 cm does not; 1003: no fixed pseudo-reference there; the
    # float at 1004 is not counted; 1000 is within 5 cm of the reference
    assert r["off5_pseudo_near"] == 1
    assert bench_rtk.score(sol, ref)["off5_pseudo_near"] == 0  # without a pseudo-reference


def test_score_of_an_empty_solution():
    r = bench_rtk.score(np.zeros((0, 6)), bench_rtk._static(tuple(REF)))
    assert r["epochs"] == 0 and r["fixed"] == 0 and np.isnan(r["fix"])


def test_nearest_ref_tolerance_and_an_empty_reference():
    ref = bench_rtk.nearest_ref(np.array([(10.0, 1, 2, 3), (12.0, 4, 5, 6)]), 0.06)
    out = ref(np.array([9.97, 11.0, 12.05, 13.0]))
    assert out[0].tolist() == [1, 2, 3] and out[2].tolist() == [4, 5, 6]
    assert np.isnan(out[1]).all() and np.isnan(out[3]).all()
    assert np.isnan(bench_rtk.nearest_ref(np.zeros((0, 4)), 0.06)(np.array([1.0]))).all()


def test_markdown_and_text_tables():
    md = bench_rtk.markdown_table(["a", "b|c"], [["1", "x|y"]]).splitlines()
    assert md == ["| a | b\\|c |", "|---|---|", "| 1 | x\\|y |"]
    cells = bench_rtk.table_row(["set", "GPS", "demo5", 10, 9, 90.0, 90.0, float("nan"), 1.25, 2.0, 9, 0, 0, 1, "",
                                 "", "", 0.5, 50000.0, ""])
    assert len(cells) == len(bench_rtk.COLUMNS)
    assert cells[3:8] == ["10", "9", "90.0", "90.0", "-"] and cells[8] == "1.2"
    assert len(bench_rtk.text_table([cells]).splitlines()) == 2


def test_systems_label_and_navsys_mask():
    assert bench_rtk.systems_label("GEJ") == "GPS+GAL+QZSS"
    mod = SimpleNamespace(SYS_GPS=1, SYS_GLO=4, SYS_GAL=8, SYS_QZS=16, SYS_CMP=32)
    assert rtklib_driver.navsys_mask(mod, "GR") == 5
    assert rtklib_driver.navsys_mask(mod, "GEJ") == 25


def test_multi_constellation_runs_only_demo5_and_ours(tmp_path):
    ds = next(d for d in bench_rtk.DATASETS if "GR" in d.systems)
    cmds = bench_rtk.engine_commands(ds, "GR", tmp_path)
    assert set(cmds) == {"demo5", "ours", "demo5-combined", "ours-combined"}
    assert all("--systems=GR" in c for c in cmds.values())
    assert set(bench_rtk.engine_commands(ds, "G", tmp_path)) == set(bench_rtk.ENGINES)
    combined = bench_rtk.pseudo_ref_command(ds, tmp_path)
    assert "--combined" in combined and str(tmp_path / "demo5-combined.pos") == combined[4]
    assert combined == cmds["demo5-combined"]


def test_combined_runs_write_their_own_files_in_their_own_direction(tmp_path):
    ds = next(d for d in bench_rtk.DATASETS if "GR" in d.systems)
    cmds = bench_rtk.engine_commands(ds, "GR", tmp_path)
    ours = cmds["ours-combined"]
    assert "--direction=combined" in ours and ours[-2:] == ["-o", str(tmp_path / "ours-combined.pos")]
    assert "--direction=combined" not in cmds["ours"] and "--combined" not in cmds["demo5"]
    assert len({bench_rtk._out_file(c) for c in cmds.values()}) == 4


def _fake_engine(tmp_path, script: str) -> list[str]:
    """A command `run_set` runs as an engine: `script` writes its .pos (one week/tow/ECEF/Q line) to the path
    after -o (sys.argv[-1])."""
    return [sys.executable, "-c", script, "-o", str(tmp_path / "fake.pos")]


LINE = "2021 100.0 -3976219.1873 3382371.6051 3652511.1423 "


def test_repeat_keeps_the_least_cpu_and_refuses_an_engine_that_changes_its_answer(tmp_path, monkeypatch):
    ds = bench_rtk.DATASETS[0]
    steady = _fake_engine(tmp_path, f"import sys; open(sys.argv[-1], 'w').write('{LINE}1\\n')")
    real_child = bench_rtk.run_child
    cpu = iter([0.5, 0.2, 0.4])
    monkeypatch.setattr(bench_rtk, "run_child", lambda cmd: (next(cpu), 0.0, real_child(cmd)[2]))
    monkeypatch.setattr(bench_rtk, "engine_commands", lambda *a, **k: {"ours": steady})
    rows, us = bench_rtk.run_set(ds, "G", ("ours",), None, repeat=3)
    assert len(rows) == 1 and us == {"ours": pytest.approx(0.2e6)}  # one epoch: the least of 0.5, 0.2, 0.4 s
    # an engine whose solution changes from one run to the next is not timed as if it were one job
    counter = tmp_path / "runs"
    flaky = _fake_engine(tmp_path, f"import sys, pathlib; c = pathlib.Path({str(counter)!r}); "
                                   "n = int(c.read_text()) if c.exists() else 0; c.write_text(str(n + 1)); "
                                   f"open(sys.argv[-1], 'w').write('{LINE}' + str(1 + n) + chr(10))")
    cpu = iter([0.5, 0.2])
    monkeypatch.setattr(bench_rtk, "engine_commands", lambda *a, **k: {"ours": flaky})
    with pytest.raises(RuntimeError, match="gave another solution"):
        bench_rtk.run_set(ds, "G", ("ours",), None, repeat=2)
