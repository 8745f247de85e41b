"""Acceptance: the whole real-time chain over real ptys, against the hil_sim World's truth.

    base emulator (pty) → `onboard base` (recorder + BaseStationFeature: journal + RTCM3 within budget) → radio
    link (two ptys, 5-20 s dropouts, air budget) → recorder with real-time RTK (RtkFeature) ← rover emulator (pty)

Both recorders configure their receivers (rover 2 Hz, base 1 Hz). Checked: no wrong fix (Q=1 > 10 cm 3D from
the true antenna), float or a held fix (never single) on the ageing corrections of a 12-20 s dropout, fixes
after it, the radio journal equals what the radio delivered, solution.pos and rtk.json written, no rover
epoch dropped.
"""

from __future__ import annotations

import asyncio
import json
import threading
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

import numpy as np
import pytest

from onboard.base.station import BaseOptions, BaseStationFeature
from onboard.formats.pos import read_pos
from onboard.hw.serial_port import SerialByteStream
from onboard.logger.journal import iter_journal_bytes
from onboard.realtime.service import RADIO_DIR, RTK_STATUS_NAME, SOLUTION_NAME, RtkFeature, RtkServiceOptions
from onboard.recorder.daemon import Recorder, RecorderDeps
from onboard.rtk.types import Q_FIX, Q_FLOAT
from tests.conftest import shared_file
from tests.daemon.helpers import make_settings, status, wait_until

pytestmark = [pytest.mark.timeout(240), pytest.mark.slow]
SPEED = 4.0
GAP_WINDOW_S = (60.0, 110.0)  # the one dropout starts and ends inside this window of link time


def _seed_with_one_gap(options_cls, channel_cls) -> tuple[int, tuple[float, float]]:
    """A radio seed whose first dropout falls after the first fixes and ends with time left to re-fix."""
    for seed in range(500):
        ch = channel_cls(options_cls(mean_interval_s=60.0, gap_min_s=5.0, gap_max_s=20.0, seed=seed))
        gaps = ch.gaps_until(170.0)
        if GAP_WINDOW_S[0] <= gaps[0][0] and gaps[0][1] <= GAP_WINDOW_S[1] and gaps[1][0] > 170.0 \
                and gaps[0][1] - gaps[0][0] >= 12.0:
            return seed, gaps[0]
    raise AssertionError("no seed found")


class _Running:
    def __init__(self, rec: Recorder) -> None:
        self.rec = rec
        self.rc: int | None = None
        self.thread = threading.Thread(target=self._main, daemon=True)
        self.thread.start()

    def _main(self) -> None:
        self.rc = asyncio.run(self.rec.run())

    def stop(self) -> int | None:
        loop = self.rec._loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(self.rec.request_stop, "test stop", 0)
        self.thread.join(30)
        return self.rc


@dataclass
class ChainRun:
    world: object
    flight: Path
    track: object
    err_m: np.ndarray
    rtk_status: dict
    radio: object
    codes: list


@pytest.fixture(scope="module")
def chain(tmp_path_factory: pytest.TempPathFactory) -> ChainRun:
    """Run the whole chain once (about 35 s) for the tests below."""
    tmp_path = tmp_path_factory.mktemp("chain")
    shared_file("gnss/broadcast-nav-20100701/brdc1820.10n")
    from hil_sim.pty_server import ReceiverEmulator
    from hil_sim.radio import RadioChannel, RadioLink, RadioOptions
    from hil_sim.receiver import ReceiverOptions
    from hil_sim.scenario import Scenario
    from hil_sim.world import World

    seed, gap = _seed_with_one_gap(RadioOptions, RadioChannel)
    world = World(Scenario.default(model="m8t", duration_s=400.0))
    emu_opts = ReceiverOptions(time_valid_after_s=1.0)
    rover_emu = ReceiverEmulator("m8t", emu_opts, world, speed=SPEED, receiver="rover")
    base_emu = ReceiverEmulator("m8t", emu_opts, world, speed=SPEED, receiver="base")
    radio = RadioLink(RadioOptions(air_baud=19200, mean_interval_s=60.0, gap_min_s=5.0, gap_max_s=20.0, seed=seed),
                      speed=SPEED)
    rover_port, base_port = rover_emu.start(), base_emu.start()
    tx, rx = radio.start()

    def settings(name: str, rate_ms: int):  # type: ignore[no-untyped-def]
        return make_settings(tmp_path / name, port_baud=9600, receiver_options=MappingProxyType(
            {"ack_timeout_s": 0.5, "retries": 1, "meas_rate_ms": rate_ms}))

    base_settings, rover_settings = settings("base", 1000), settings("rover", 500)
    base = Recorder(base_settings, RecorderDeps(open_port=lambda: SerialByteStream(base_port, 9600, 0.05)),
                    features=[BaseStationFeature(BaseOptions(station_id=5, position_ecef_m=tuple(world.base_ecef_m),
                                                             radio_budget_bytes_s=1200.0),
                                                 lambda: SerialByteStream(tx, 57600, 0.05))])
    rtk_opts = RtkServiceOptions()
    rover = Recorder(rover_settings, RecorderDeps(open_port=lambda: SerialByteStream(rover_port, 9600, 0.05)),
                     features=[RtkFeature(rtk_opts, lambda: SerialByteStream(rx, 57600, 0.05))])
    runs = [_Running(base), _Running(rover)]
    try:
        for s in (base_settings, rover_settings):
            st = wait_until(lambda: (x := status(s.status_path)).get("config_state") in ("verified", "failed")  # noqa: B023
                            and x, timeout_s=60, what="configuration")
            assert st["config_state"] == "verified", st.get("config_error")
        wait_until(lambda: radio.elapsed_s() > gap[1] + 40.0, timeout_s=120, what="the dropout and 40 s after")
    finally:
        codes = [r.stop() for r in runs]
        radio.stop()
        rover_emu.stop()
        base_emu.stop()
    flight = Path(rover.status.flight_dir or "")
    track = read_pos(flight / SOLUTION_NAME)
    err = np.array([np.linalg.norm(p - world.truth(t)["antenna_ecef_m"]) for t, p in zip(track.time, track.pos_ecef_m)])
    snap = json.loads(rover_settings.status_path.with_name(RTK_STATUS_NAME).read_text())
    return ChainRun(world, flight, track, err, snap, radio, codes)


def test_real_time_rtk_through_a_radio_dropout(chain: ChainRun) -> None:
    track, radio = chain.track, chain.radio
    assert chain.codes == [0, 0]
    assert len(track.q) > 150
    fixed = track.q == Q_FIX
    assert fixed.sum() > 20
    # the dropout (≤ 20 s): the ageing corrections are still used, float or held fix, and fixes after it
    gap_rows = np.flatnonzero(track.age_s >= 4.0)
    assert gap_rows.size, "the dropout did not show in the age of corrections"
    assert track.age_s.max() <= 30.0 and set(track.q[gap_rows].tolist()) <= {Q_FIX, Q_FLOAT}
    assert np.any(fixed[gap_rows.max() + 1:]), "no fix after the dropout"
    snap = chain.rtk_status
    assert snap["dropped_epochs"] == 0 and snap["ttff_s"] is not None and snap["baseline_m"] > 0
    assert snap["epochs"] >= len(track.q)
    # every byte the radio delivered is in the rover's radio journal
    assert len(b"".join(iter_journal_bytes(chain.flight / RADIO_DIR))) == radio.channel.bytes_out
    assert radio.channel.bytes_lost_dropout > 0 and radio.channel.bytes_lost_budget == 0


def test_real_time_rtk_never_fixes_wrong(chain: ChainRun) -> None:
    fixed = chain.track.q == Q_FIX
    bad = [(str(t), round(float(e), 3)) for t, e, f in zip(chain.track.time, chain.err_m, fixed) if f and e > 0.10]
    assert not bad, bad
