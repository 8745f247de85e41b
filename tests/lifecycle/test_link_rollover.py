"""The autopilot link's side of the lifecycle, in memory against the stand-in (no daemon): `flight_over` once
after the disarm and the settle time, and a tlog that moves to the next flight without losing a packet."""

from __future__ import annotations

import struct
import time
from pathlib import Path

import pytest

from hil_sim.autopilot import AutopilotSimOptions
from onboard.autopilot.feature import AutopilotOptions
from onboard.recorder.feature import is_rollover
from tests.autopilot.harness import Joined

pytestmark = pytest.mark.timeout(60)


def tlog_stamps(path: Path) -> list[int]:
    """The µs stamps of a tlog's records (8-byte stamp + a MAVLink 2 packet: 10 header bytes + payload + 2 CRC
    [+ 13 signature])."""
    data, out, i = path.read_bytes(), [], 0
    while i + 8 < len(data):
        (stamp,) = struct.unpack(">Q", data[i:i + 8])
        magic, length, incompat = data[i + 8], data[i + 9], data[i + 10]
        assert magic == 0xFD
        out.append(stamp)
        i += 8 + 10 + length + 2 + (13 if incompat & 1 else 0)
    assert i == len(data)
    return out


@pytest.mark.slow
def test_flight_over_once_and_tlog_moves(tmp_path: Path) -> None:
    f1, f2 = tmp_path / "f1", tmp_path / "f2"
    f1.mkdir()
    f2.mkdir()
    over: list[str] = []
    joined = Joined(f1, AutopilotSimOptions(arm_at_s=2, survey_s=2, gcs_heartbeat=False),
                    AutopilotOptions(link_timeout_s=1.5, rerequest_s=1.5, settle_s=0.5), speed=8.0)
    joined._t0 = time.monotonic()
    joined.link.start(f1, joined.events.append, over.append)
    joined._thread.start()
    try:
        deadline = time.monotonic() + 30
        while not over and time.monotonic() < deadline:
            time.sleep(0.05)
        assert len(over) == 1 and is_rollover(over[0])
        events = [e["event"] for e in joined.events]
        assert events == ["armed", "takeoff", "landed", "disarmed", "flight_over"]
        disarmed, flight_over = joined.events[3], joined.events[4]
        assert flight_over["monotonic_ns"] - disarmed["monotonic_ns"] >= 0.5e9
        joined.link.switch_flight(f2)
        time.sleep(1.0)
        assert len(over) == 1  # the next flight is not flown: no second close
        assert joined.link.snapshot()["tlog"] == "autopilot.tlog"
        assert joined.link.snapshot()["flights_closed"] == 1
    finally:
        joined._stop.set()
        joined._thread.join(timeout=5)
        joined.link.stop()
    first, second = tlog_stamps(f1 / "autopilot.tlog"), tlog_stamps(f2 / "autopilot.tlog")
    assert first and second and first[-1] <= second[0]
    assert second[0] - first[-1] < 300_000  # the stand-in sends at ≥ 4 Hz: no second without a packet
