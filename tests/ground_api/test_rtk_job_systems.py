"""The ground's RTK job with the engine's constellations: an M8P walk under trees re-processed with GPS alone and
with GPS+GLONASS, through the pipeline the API's jobs run (run_rtk), and the systems checked at submission."""

from __future__ import annotations

from pathlib import Path

import pytest

from ground.pipeline import RtkInputs, RtkJobOptions, run_rtk
from onboard.formats.pos import read_pos
from tests.conftest import shared_file

M8P = "gnss/ublox-m8p-galway-2018/rinex/"
BASE_ECEF_M = (3774085.6456, -601662.5769, 5089316.3970)


def test_systems_are_checked_and_normalised() -> None:
    assert RtkJobOptions().systems == "auto"
    assert RtkJobOptions(systems="gr").systems == "GR"
    assert RtkJobOptions(systems="GRGR").systems == "GR"
    for bad in ("", "GX", "L1"):
        with pytest.raises(ValueError, match="letters of G, R, E, C, J"):
            RtkJobOptions(systems=bad)


@pytest.mark.slow
def test_the_walk_fixes_with_glonass_where_gps_alone_cannot(tmp_path: Path) -> None:
    """Under the trees GPS alone does not fix (0 epochs of 1180, combined: the job's default direction); with
    GLONASS beside it the job fixes over 90 % of the walk (95.3 % when measured; forward 76.8 %), and
    says in its .pos and its message which constellations it used. By default (auto) the job takes every
    constellation both receivers observed: GPS and GLONASS here."""
    inputs = RtkInputs(rover=shared_file(M8P + "rover-20181004-1532.obs.gz"),
                       base=shared_file(M8P + "base-20181004-1452.rawx.obs.gz"),
                       nav=(shared_file(M8P + "rover-20181004-1532.nav.gz"),))
    gps = run_rtk(inputs, RtkJobOptions(base_pos_ecef_m=BASE_ECEF_M, systems="G"), tmp_path / "g.pos")
    both = run_rtk(inputs, RtkJobOptions(base_pos_ecef_m=BASE_ECEF_M, systems="GR"), tmp_path / "gr.pos")
    assert gps.n_fix < 0.01 * gps.n_epochs and both.n_fix > 0.90 * both.n_epochs
    text = (tmp_path / "gr.pos").read_text()
    assert "ground rtk job (L1, systems GR)" in text and "systems G)" in (tmp_path / "g.pos").read_text()
    assert int((read_pos(tmp_path / "gr.pos").q == 1).sum()) == both.n_fix
    assert "; systems GR; " in both.summary() and "; systems G; " in gps.summary()
    # the message says where the two passes' fixes disagreed and were written as float (8 epochs when measured)
    assert both.n_disputed > 0 and f"; {both.n_disputed} fixes written as float: the forward and backward passes " \
        "disagree there;" in both.summary()
    auto = run_rtk(inputs, RtkJobOptions(base_pos_ecef_m=BASE_ECEF_M), tmp_path / "auto.pos")
    assert auto.systems == "GR" and auto.n_fix == both.n_fix
    assert "systems GR (auto: both receivers')" in (tmp_path / "auto.pos").read_text()
