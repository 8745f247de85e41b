"""End to end: the real daemon (`python -m onboard run`, a subprocess) against the hil_sim receiver emulator
over a real pseudo-terminal, for the LEA-6T and the M8T.

The emulator starts at the factory 9600 Bd while the daemon opens the port at 115200 Bd, so the run also
covers baud probing and the CFG-PRT rate change. The camera misses some flashes and bounces others (seeded),
and the trigger pulse is wired to EXTINT1. Truth is the emulator's own World: every camera event in the
recorded window must come out of `events.jsonl` paired, with the simulator's delay to ±1 µs, or flagged.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from onboard.logger.events import read_events
from onboard.logger.journal import iter_journal_bytes, iter_journal_frames, read_manifest
from onboard.receiver.decode import iter_journal
from onboard.rtk.types import ObsEpoch
from onboard.timepulse.marks import BOUNCE, MISSED_FLASH, PULSE_WITHOUT_FLASH, parse_records
from tests.conftest import shared_file
from tests.daemon.helpers import reap, status, wait_until

hil_scenario = pytest.importorskip("hil_sim.scenario")
from hil_sim.faults import FaultOptions
from hil_sim.pty_server import ReceiverEmulator
from hil_sim.receiver import ReceiverOptions
from hil_sim.world import World

PROJECT = Path(__file__).resolve().parents[2]
NAV = "gnss/broadcast-nav-20100701/brdc1820.10n"  # the World's real broadcast orbits (Scenario.default)


@pytest.fixture(autouse=True)
def _needs_broadcast_orbits() -> None:
    """Every test here simulates the default scenario: skip with the reason when ../shared is absent."""
    shared_file(NAV)

SPEED = 4.0  # simulated seconds per real second
VALID_AFTER_S = 4.0  # simulated time to the first fix (no camera pulses before)
RECORD_SIM_S = 48.0  # simulated seconds recorded after configuration: ~24 camera pulses at 2 s
pytestmark = [pytest.mark.timeout(180), pytest.mark.slow]


def start_daemon(tmp_path: Path, port: str | Path) -> tuple[subprocess.Popen[bytes], Path, Path]:
    cfg = tmp_path / "recorder.toml"
    cfg.write_text(
        "[receiver]\ncamera_period_s = 2.0\ntrigger = \"extint1\"\nmeas_rate_ms = 500\naid_eph_poll_s = 5.0\n"
        "[journal]\ndisk_floor_mb = 1.0\n"
    )
    data_dir, status_path = tmp_path / "data", tmp_path / "run" / "status.json"
    env = dict(os.environ, PYTHONPATH=str(PROJECT))
    env.pop("NOTIFY_SOCKET", None)
    proc = subprocess.Popen(
        [sys.executable, "-m", "onboard", "run", "--config", str(cfg), "--port", str(port), "--baud", "115200",
         "--data-dir", str(data_dir), "--status", str(status_path)],
        cwd=PROJECT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
    )
    return proc, data_dir, status_path


def stop_cleanly(proc: subprocess.Popen[bytes]) -> None:
    """SIGTERM the daemon and require a clean exit (0), showing its output when it is not."""
    proc.send_signal(signal.SIGTERM)
    out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0, out.decode(errors="replace")[-3000:]


def kill_leftovers(proc: subprocess.Popen[bytes], emu: ReceiverEmulator) -> None:
    """After a test, whatever happened: no daemon left running, the emulator stopped."""
    reap(proc)
    emu.stop()


@pytest.mark.parametrize("model", ["lea6t", "m8t"])
def test_daemon_against_emulator(tmp_path: Path, model: str) -> None:
    scenario = hil_scenario.Scenario.default(
        model=model,
        camera=hil_scenario.CameraPlan(valid_after_s=VALID_AFTER_S, missed_flash_probability=0.15,
                                       bounce_probability=0.15),
    )
    world = World(scenario)
    emu = ReceiverEmulator(model, ReceiverOptions(trigger_extint=True, time_valid_after_s=VALID_AFTER_S), world,
                           speed=SPEED, t_start=scenario.start)
    port = emu.start()
    proc, data_dir, status_path = start_daemon(tmp_path, port)
    try:
        st = wait_until(lambda: (s := status(status_path)).get("config_state") in ("verified", "failed") and s,
                        timeout_s=60, what="configuration result")
        assert st["config_state"] == "verified", st["config_error"]
        configured_at = emu.sim_time()
        wait_until(lambda: emu.sim_time().diff_s(configured_at) > RECORD_SIM_S, timeout_s=60, what="recording")
        stop_cleanly(proc)
        end = emu.sim_time()
    finally:
        kill_leftovers(proc, emu)
    assert emu.error is None

    # --- configuration verified by poll-back, receiver identified
    st = status(status_path)
    assert st["state"] == "stopped" and st["receiver_model"] == model
    report = st["config_report"]
    assert report["ok"] and report["baud"] == 115200
    assert any(m["polled_back"] for m in report["messages"])
    assert all(m["status"] in ("ok", "altered", "sent", "replaced") for m in report["messages"]), report
    flight = next(data_dir.glob("flight-*"))
    manifest = read_manifest(flight)
    assert manifest is not None and manifest.closed and manifest.config_report is not None
    assert manifest.receiver is not None and manifest.receiver["model"] == model

    # --- raw epochs recorded (2 Hz for the recorded span, allowing the configuration time)
    recorded = b"".join(iter_journal_bytes(flight))
    assert len(recorded) == st["bytes_recorded"] == manifest.to_json()["total_bytes"]
    epochs = [e for e in iter_journal(flight) if isinstance(e, ObsEpoch)]
    assert len(epochs) >= 0.8 * RECORD_SIM_S * 2
    assert st["epochs"] == len(epochs)
    assert all(len(e.sv_id) >= 4 for e in epochs)

    # --- the AID-EPH backup path: polled after the fix and every 5 s (host time), answered with ephemerides
    # once the emulated receiver has seen subframes 1-3 (every 30 s of simulated time)
    assert st["aid_eph_polls"] >= 3
    aid = [f for f in iter_journal_frames(flight) if (f.msg_class, f.msg_id) == (0x0B, 0x31)]
    assert sum(len(f.payload) == 104 for f in aid) >= 4  # full ephemerides, not only "none" replies

    # --- every camera event in the recorded window paired or flagged, delays to ±1 µs
    marks, pairings, other = parse_records(read_events(flight / "events.jsonl").records)
    assert any(r.get("kind") == "timepulse" for r in other)
    with_pulse = [p for p in pairings if p.pulse_time is not None]
    assert with_pulse, "no trigger pulse was recorded"
    first = min(p.pulse_time.total_ns for p in with_pulse)  # type: ignore[union-attr]
    last = max(p.pulse_time.total_ns for p in with_pulse)  # type: ignore[union-attr]
    truth = [ev for ev in world.camera_events(scenario.start, end)
             if first - 1_000_000 <= ev.pulse_time.total_ns <= last + 1_000_000]  # marks carry ns noise
    assert len(truth) >= 15
    by_pulse = {round(p.pulse_time.total_ns / 1e6): p for p in with_pulse}  # type: ignore[union-attr]
    kinds = {"clean": 0, "missed": 0, "bounced": 0}
    for ev in truth:
        p = by_pulse.get(round(ev.pulse_time.total_ns / 1e6))
        assert p is not None, f"pulse at {ev.pulse_time} not recorded"
        assert abs(p.pulse_time.diff_ns(ev.pulse_time)) <= 1_000  # type: ignore[union-attr]
        if ev.flash_time is None:
            assert PULSE_WITHOUT_FLASH in p.flags, p
            kinds["missed"] += 1
        elif ev.bounce_time is not None:
            assert BOUNCE in p.flags or MISSED_FLASH in p.flags, p
            kinds["bounced"] += 1
        else:
            assert p.flags == (), p
            assert p.delay_ns is not None
            assert abs(p.delay_ns - round(ev.delay_s * 1e9)) <= 1_000, (p, ev)
            kinds["clean"] += 1
    assert kinds["missed"] >= 1 and kinds["bounced"] >= 1 and kinds["clean"] >= 10, kinds
    # nothing invented: no pairing outside the truth
    assert len(with_pulse) == len(truth)
    assert all(m.source == "tim-tm2" for m in marks)


def test_port_disappears_and_returns_configuration_reapplied(tmp_path: Path) -> None:
    """The emulator's pty vanishes for 8 simulated seconds (USB re-enumeration) and comes back under the same
    stable link: the daemon keeps the flight open, reconnects, re-detects and re-applies the configuration."""
    unplug_at_s, unplug_for_s = 30.0, 8.0
    scenario = hil_scenario.Scenario.default(model="m8t", camera=hil_scenario.CameraPlan(valid_after_s=VALID_AFTER_S))
    world = World(scenario)
    link = tmp_path / "gps0"
    emu = ReceiverEmulator(
        "m8t",
        ReceiverOptions(trigger_extint=True, time_valid_after_s=VALID_AFTER_S,
                        faults=FaultOptions(unplug_windows_s=((unplug_at_s, unplug_for_s),))),
        world, speed=SPEED, t_start=scenario.start, link=link,
    )
    emu.start()
    proc, data_dir, status_path = start_daemon(tmp_path, link)
    try:
        wait_until(lambda: status(status_path).get("config_state") == "verified", timeout_s=60, what="first config")
        wait_until(lambda: status(status_path).get("state") == "port_lost", timeout_s=60, what="port lost")
        lost = status(status_path)
        assert not lost["port_open"] and lost["port_error"]
        wait_until(lambda: (s := status(status_path)).get("port_reconnects", 0) >= 1
                   and s.get("config_state") == "verified", timeout_s=60, what="reconnect and re-configuration")
        back_at = emu.sim_time()
        wait_until(lambda: emu.sim_time().diff_s(back_at) > 10.0, timeout_s=30, what="recording after return")
        stop_cleanly(proc)
    finally:
        kill_leftovers(proc, emu)
    assert emu.reopen_count >= 1
    flights = list(data_dir.glob("flight-*"))
    assert len(flights) == 1
    configs = [r for r in read_events(flights[0] / "events.jsonl").records if r.get("kind") == "config"]
    assert len(configs) >= 2 and all(c["ok"] for c in configs)
    epochs = [e for e in iter_journal(flights[0]) if isinstance(e, ObsEpoch)]
    gap_start = scenario.start.add_s(unplug_at_s)
    after = [e for e in epochs if e.time.diff_s(gap_start) > unplug_for_s]
    before = [e for e in epochs if e.time.diff_s(gap_start) < 0]
    assert len(before) >= 10 and len(after) >= 10  # recorded on both sides of the outage, in one flight


def test_silent_receiver_every_byte_recorded_status_names_the_problem(tmp_path: Path) -> None:
    """An emulated receiver that never answers configuration (factory NMEA only): the daemon records every byte
    sent after it opened the port, keeps recording, and the status names MON-VER as the failing message."""
    scenario = hil_scenario.Scenario.default(model="m8t")
    world = World(scenario)
    emu = ReceiverEmulator("m8t", ReceiverOptions(silent=True), world, speed=SPEED, t_start=scenario.start,
                           initial_baud=115200)
    port = emu.start()
    proc, data_dir, status_path = start_daemon(tmp_path, port)
    try:
        wait_until(lambda: status(status_path).get("port_open"), timeout_s=30, what="port open")
        sent_before_open = emu.bytes_out  # an upper bound of what pyserial's open() flushed
        st = wait_until(lambda: (s := status(status_path)).get("config_state") == "failed" and s,
                        timeout_s=60, what="configuration failure")
        assert "MON-VER" in st["config_error"] and "no answer" in st["config_error"]
        time.sleep(2.0)
        emu.stop()  # the receiver goes away: nothing more is sent
        wait_until(lambda: status(status_path).get("state") == "port_lost", timeout_s=30, what="port lost")
        sent_total = emu.bytes_out
        stop_cleanly(proc)
    finally:
        kill_leftovers(proc, emu)
    assert emu.port.tx_overrun_bytes == 0
    flight = next(data_dir.glob("flight-*"))
    recorded = b"".join(iter_journal_bytes(flight))
    assert sent_total - sent_before_open <= len(recorded) <= sent_total
    assert recorded.count(b"$GNGGA") + recorded.count(b"$GPGGA") >= 3  # the factory NMEA is all there
    st = status(status_path)
    assert st["state"] == "stopped" and st["config_state"] == "failed" and st["bytes_recorded"] == len(recorded)


def test_lost_flash_reports_flagged_as_missed_flashes_end_to_end(tmp_path: Path) -> None:
    """The emulator loses some EXTINT0 TIM-TM2 reports (`drop_flash_mark_rate`: the flash was taken, its mark
    never arrived). The real daemon must flag that image `pulse_without_flash` and charge the `count` jump
    to the next flash (`missed_flash`, `lost_edges` = reports lost in a row); every other image is clean
    with the simulator's delay to ±1 µs."""
    scenario = hil_scenario.Scenario.default(model="m8t", camera=hil_scenario.CameraPlan(valid_after_s=VALID_AFTER_S))
    world = World(scenario)
    emu = ReceiverEmulator(
        "m8t",
        ReceiverOptions(trigger_extint=True, time_valid_after_s=VALID_AFTER_S,
                        faults=FaultOptions(seed=5, drop_flash_mark_rate=0.25)),
        world, speed=SPEED, t_start=scenario.start,
    )
    port = emu.start()
    proc, data_dir, status_path = start_daemon(tmp_path, port)
    try:
        wait_until(lambda: status(status_path).get("config_state") == "verified", timeout_s=60, what="configuration")
        configured_at = emu.sim_time()
        wait_until(lambda: emu.sim_time().diff_s(configured_at) > 36.0, timeout_s=60, what="recording")
        stop_cleanly(proc)
        end = emu.sim_time()
    finally:
        kill_leftovers(proc, emu)
    assert emu.error is None
    flight = next(data_dir.glob("flight-*"))
    _marks, pairings, _ = parse_records(read_events(flight / "events.jsonl").records)
    with_pulse = sorted((p for p in pairings if p.pulse_time is not None),
                        key=lambda p: p.pulse_time.total_ns)  # type: ignore[union-attr]
    first, last = with_pulse[0].pulse_time, with_pulse[-1].pulse_time
    assert first is not None and last is not None
    truth = [ev for ev in world.camera_events(scenario.start, end)
             if first.total_ns - 1_000_000 <= ev.pulse_time.total_ns <= last.total_ns + 1_000_000]
    assert len(truth) == len(with_pulse) >= 12
    lost_falls = [r.falling for r in emu.core.dropped_flash_reports if r.new_falling and r.falling is not None]
    assert lost_falls, "the seeded fault lost no flash report in the recorded window"

    def was_lost(ev: object) -> bool:
        return any(abs(t.diff_ns(ev.flash_time)) < 1_000 for t in lost_falls)  # type: ignore[attr-defined]

    lost_in_a_row = 0
    seen = {"lost": 0, "missed_flash": 0, "clean": 0}
    for ev, p in zip(truth, with_pulse, strict=True):
        assert abs(p.pulse_time.diff_ns(ev.pulse_time)) <= 1_000  # type: ignore[union-attr]
        if was_lost(ev):
            assert PULSE_WITHOUT_FLASH in p.flags and p.flash_time is None, p
            lost_in_a_row += 1
            seen["lost"] += 1
            continue
        assert p.delay_ns is not None and abs(p.delay_ns - round(ev.delay_s * 1e9)) <= 1_000, (p, ev)
        if lost_in_a_row and p is not with_pulse[0]:
            assert p.flags == (MISSED_FLASH,) and p.lost_edges == lost_in_a_row, p
            seen["missed_flash"] += 1
        else:
            assert p.flags == () and p.lost_edges == 0, p
            seen["clean"] += 1
        lost_in_a_row = 0
    assert seen["lost"] >= 1 and seen["missed_flash"] >= 1 and seen["clean"] >= 6, seen
