"""Two recorder features combined: a base station that also logs its own real-time RTK against a second base.

    world base emulator (pty) → recorder + BaseStationFeature (the second base) → radio link (ptys) ─┐
    world rover emulator (pty) → `onboard base`'s composition (`base_recorder`, rtk.base_stream set):  │
                                 recorder + BaseStationFeature (RTCM3 out to its own radio)           │
                                          + RtkFeature (corrections in) ◄─────────────────────────────┘

Checked on the one recorder that runs both: its radio carries MSM4/1006 of its own journal's epochs (base.json
counts them), its RTK solves against the second base with fixes near the truth (solution.pos, rtk.json), and
neither feature counted an error.
"""

from __future__ import annotations

import asyncio
import json
import threading
from pathlib import Path
from types import MappingProxyType

import numpy as np
import pytest

from onboard.base.cli import base_recorder
from onboard.base.station import BASE_STATUS_NAME, BaseOptions, BaseStationFeature
from onboard.formats.pos import read_pos
from onboard.hw.fake import FakeByteStream
from onboard.hw.serial_port import SerialByteStream
from onboard.logger.journal import iter_journal_bytes
from onboard.realtime.service import RADIO_DIR, RTK_STATUS_NAME, SOLUTION_NAME, RtkFeature
from onboard.receiver.decode import iter_journal
from onboard.receiver.framing import Protocol, StreamFramer
from onboard.recorder.daemon import Recorder, RecorderDeps
from onboard.rtk.types import Q_FIX, ObsEpoch
from tests.conftest import shared_file
from tests.daemon.helpers import make_settings, status, wait_until

pytestmark = [pytest.mark.timeout(240), pytest.mark.slow]
SPEED = 6.0


class _Running:
    def __init__(self, rec: Recorder) -> None:
        self.rec = rec
        self.rc: int | None = None
        self.thread = threading.Thread(target=lambda: setattr(self, "rc", asyncio.run(rec.run())), daemon=True)
        self.thread.start()

    def stop(self) -> int | None:
        loop = self.rec._loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(self.rec.request_stop, "test stop", 0)
        self.thread.join(30)
        return self.rc


def test_a_base_station_that_also_solves_its_own_rtk(tmp_path: Path) -> None:
    shared_file("gnss/broadcast-nav-20100701/brdc1820.10n")
    from hil_sim.pty_server import ReceiverEmulator
    from hil_sim.radio import RadioLink, RadioOptions
    from hil_sim.receiver import ReceiverOptions
    from hil_sim.scenario import Scenario
    from hil_sim.world import World

    world = World(Scenario.default(model="m8t", duration_s=400.0))
    emu_opts = ReceiverOptions(time_valid_after_s=1.0)
    own_emu = ReceiverEmulator("m8t", emu_opts, world, speed=SPEED, receiver="rover")
    second_emu = ReceiverEmulator("m8t", emu_opts, world, speed=SPEED, receiver="base")
    link = RadioLink(RadioOptions(mean_interval_s=1e6, seed=0), speed=SPEED)  # no dropout in this run
    own_port, second_port = own_emu.start(), second_emu.start()
    tx, rx = link.start()
    receiver = MappingProxyType({"ack_timeout_s": 0.5, "retries": 1, "meas_rate_ms": 1000})
    second_settings = make_settings(tmp_path / "second", port_baud=9600, receiver_options=receiver)
    own_settings = make_settings(tmp_path / "own", port_baud=9600, receiver_options=receiver,
                                 rtk_base_stream=f"serial:{rx}@57600")
    second = Recorder(second_settings, RecorderDeps(open_port=lambda: SerialByteStream(second_port, 9600, 0.05)),
                      features=[BaseStationFeature(BaseOptions(station_id=5, position_ecef_m=tuple(world.base_ecef_m),
                                                               radio_budget_bytes_s=1200.0),
                                                   lambda: SerialByteStream(tx, 57600, 0.05))])
    own_radio = FakeByteStream()
    # this recorder's antenna position as its base feature sends it in 1006 (where the antenna stands at start)
    own_position = tuple(float(v) for v in world.truth(world.start)["antenna_ecef_m"])
    own = base_recorder(own_settings, RecorderDeps(open_port=lambda: SerialByteStream(own_port, 9600, 0.05)),
                        BaseOptions(station_id=9, position_ecef_m=own_position), lambda: own_radio)
    base_feature, rtk_feature = own.features
    assert isinstance(base_feature, BaseStationFeature) and isinstance(rtk_feature, RtkFeature)
    runs = [_Running(second), _Running(own)]
    try:
        for s in (second_settings, own_settings):
            st = wait_until(lambda: (x := status(s.status_path)).get("config_state") in ("verified", "failed")  # noqa: B023
                            and x, timeout_s=60, what="configuration")
            assert st["config_state"] == "verified", st.get("config_error")
        wait_until(lambda: rtk_feature.rtk.snapshot()["fixed"] >= 20 and
                   base_feature.core.counts()["sent"].get("obs", 0) >= 20, timeout_s=150,
                   what="20 fixes and 20 epochs of corrections sent")
    finally:
        codes = [r.stop() for r in runs]
        link.stop()
        own_emu.stop()
        second_emu.stop()
    assert codes == [0, 0]
    flight = Path(own.status.flight_dir or "")

    # the base feature: what went to its radio is its own journal's epochs, as MSM4 (the default; one 1074 per
    # epoch of the GPS world) + 1006, all CRC-valid
    framer = StreamFramer()
    frames = framer.feed(bytes(own_radio.written)) + framer.flush()
    assert frames and all(f.protocol is Protocol.RTCM3 for f in frames) and framer.skipped_bytes == 0
    numbers = [f.msg_id for f in frames]
    assert numbers.count(1074) >= 20 and 1006 in numbers
    assert (flight / "radio-tx.rtcm3").read_bytes() == bytes(own_radio.written)
    journal_epochs = [e for e in iter_journal(flight) if isinstance(e, ObsEpoch)]
    assert numbers.count(1074) <= len(journal_epochs)
    base_snap = json.loads(own_settings.status_path.with_name(BASE_STATUS_NAME).read_text())
    assert base_snap["sent"]["obs"] == numbers.count(1074) and base_snap["sent_bytes"] == len(own_radio.written)

    # the RTK feature: corrections from the second base journaled as received, fixes on the truth
    assert b"".join(iter_journal_bytes(flight / RADIO_DIR))
    track = read_pos(flight / SOLUTION_NAME)
    fixed = track.q == Q_FIX
    assert fixed.sum() >= 20
    err = np.array([np.linalg.norm(p - world.truth(t)["antenna_ecef_m"]) for t, p in zip(track.time, track.pos_ecef_m)])
    assert err[fixed].max() < 0.10  # no wrong fix
    rtk_snap = json.loads(own_settings.status_path.with_name(RTK_STATUS_NAME).read_text())
    assert rtk_snap["fixed"] == int(fixed.sum()) and rtk_snap["base_epochs"] > 0
    assert rtk_snap["base_position_ecef_m"] == pytest.approx(list(world.base_ecef_m), abs=1e-3)
    assert json.loads(own_settings.status_path.read_text())["feature_errors"] == {}
