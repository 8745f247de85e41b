"""The stand-in's parts the demo needs for corrections over MAVLink: live RTCM injected message by message as a
ground station does (180·k-byte messages, dropped fragments), and the go gate before arming."""

from __future__ import annotations

import time
from typing import Any

import pytest

from hil_sim.autopilot import AutopilotCore, AutopilotSim, AutopilotSimOptions, MissionFlight
from onboard.autopilot.rtcm_reassembly import GpsRtcmReassembler
from tests.autopilot.rtcm_frames import rtcm_frame

SIZES = [100, 180, 360, 540, 720, 250, 181, 359, 60]


def _gps_rtcm(frames: list[bytes]) -> list[Any]:
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    parser = mavlink.MAVLink(None)
    msgs = []
    for frame in frames:
        msgs += [m for m in parser.parse_buffer(frame) or [] if m.get_type() == "GPS_RTCM_DATA"]
    return msgs


def _reassemble(msgs: list[Any]) -> list[bytes]:
    r = GpsRtcmReassembler()
    out: list[bytes] = []
    for m in msgs:
        out += r.feed(m.flags, bytes(m.data[:m.len]))
    return out


def test_live_messages_are_injected_whole_including_180k_bytes() -> None:
    core = AutopilotCore(AutopilotSimOptions(gcs_heartbeat=False))
    messages = [rtcm_frame(n, i) for i, n in enumerate(SIZES)]
    for m in messages:
        core.inject_rtcm(m)
    frames = core.step(0.1)
    gps = _gps_rtcm(frames)
    # 180, 360 and 540 bytes end with an empty fragment; 720 is four full ones
    assert [m.len for m in gps if m.flags & 1 and m.len == 0] == [0, 0, 0]
    assert all(m.get_srcSystem() == 255 for m in gps)  # the ground station's inject, forwarded
    assert _reassemble(gps) == messages  # the last (60 B) is unfragmented: whole at once
    assert core.report()["rtcm_live"] == {"messages": 9, "intact": 9, "broken": 0, "bytes": sum(SIZES), "too_long": 0}


def test_dropped_fragments_lose_messages_never_mix_them() -> None:
    core = AutopilotCore(AutopilotSimOptions(gcs_heartbeat=False, drop_fragment_rate=0.2, reorder_fragments=True,
                                             seed=3))
    messages = [rtcm_frame(n, i) for i, n in enumerate(SIZES * 8)]
    frames: list[bytes] = []
    for k, m in enumerate(messages):
        core.inject_rtcm(m)
        frames += core.step(0.1 * k)
    got = _reassemble(_gps_rtcm(frames))
    live = core.report()["rtcm_live"]
    assert live["broken"] > 5 and live["intact"] + live["broken"] == len(messages)
    it = iter(messages)
    assert all(any(g == m for m in it) for g in got)  # in order, each one byte-identical to a message sent
    assert len(got) in (live["intact"], live["intact"] - 1)


def test_over_720_bytes_is_counted_not_sent() -> None:
    core = AutopilotCore(AutopilotSimOptions(gcs_heartbeat=False))
    core.inject_rtcm(rtcm_frame(800, 1))
    assert _gps_rtcm(core.step(0.1)) == []
    assert core.report()["rtcm_live"]["too_long"] == 1


def test_the_script_waits_for_the_go_then_flies_from_it() -> None:
    core = AutopilotCore(AutopilotSimOptions(hold_until_go=True, arm_at_s=10.0, gcs_heartbeat=False))
    assert core.phase(5.0)[0] is False and core.phase(40.0) == (False, 1, 5)  # held on the ground, LOITER
    core.give_go(30.0)
    assert core.phase(29.0)[0] is False
    assert core.phase(30.5)[0] is True and core.phase(30.5)[1] == 1  # armed at the go, spooling on the ground
    assert core.phase(30.0 + 2.0 + 4.0 + 1.0)[1] == 2  # in the air after spool (2 s) and take-off (4 s)
    assert core.report()["go_late_s"] is None


def test_the_mission_cannot_wait_a_late_go_is_reported() -> None:
    from hil_sim.scenario import Scenario

    mission = MissionFlight(Scenario.default())
    arm = mission.arm_s
    core = AutopilotCore(AutopilotSimOptions(hold_until_go=True, gcs_heartbeat=False), mission)
    assert core.phase(arm + 1.0)[0] is False
    core.give_go(arm - 5.0)
    assert core.phase(arm - 1.0)[0] is False and core.phase(arm + 1.0)[0] is True
    assert core.report()["go_late_s"] == 0.0
    late = AutopilotCore(AutopilotSimOptions(hold_until_go=True, gcs_heartbeat=False), mission)
    late.give_go(arm + 7.5)
    assert late.report()["go_late_s"] == 7.5


class _Chunks:
    """A ByteStream giving the bytes in awkward chunks, with noise between messages, then nothing."""

    def __init__(self, data: bytes) -> None:
        self.chunks = [data[i:i + 77] for i in range(0, len(data), 77)]

    def read(self, max_bytes: int) -> bytes:
        if self.chunks:
            return self.chunks.pop(0)
        time.sleep(0.01)
        return b""

    def write(self, data: bytes) -> int:
        return 0

    def close(self) -> None:
        pass


@pytest.mark.timeout(30)
def test_shell_reads_a_live_stream_and_a_go_file(tmp_path: Any) -> None:
    messages = [rtcm_frame(n, i) for i, n in enumerate(SIZES)]
    stream = b"".join(b"\x00noise" + m for m in messages)
    go = tmp_path / "go"
    sim = AutopilotSim(AutopilotSimOptions(hold_until_go=True, arm_at_s=1.0), speed=10.0,
                       rtcm_stream=lambda: _Chunks(stream), go_file=go)
    sim.start()
    try:
        deadline = time.monotonic() + 10
        while sim.core.rtcm_live["messages"] < len(messages) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert sim.core.rtcm_live["messages"] == len(messages) and sim.rtcm_stream_bytes == len(stream)
        time.sleep(0.3)
        assert sim.core.go_s is None
        go.touch()
        deadline = time.monotonic() + 5
        while sim.core.go_s is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert sim.core.go_s is not None
    finally:
        sim.stop()


@pytest.mark.slow
@pytest.mark.timeout(60)
def test_cli_injects_a_live_tcp_stream_and_waits_for_the_go_file(tmp_path: Any) -> None:
    """`python -m hil_sim autopilot --rtcm-stream tcp://... --go-file F`: a caster's messages are injected as they
    come, and the vehicle stays disarmed until F appears."""
    import json
    import os
    import signal
    import socket
    import subprocess
    import sys
    from pathlib import Path

    messages = [rtcm_frame(n, i) for i, n in enumerate(SIZES)]
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    port = server.getsockname()[1]
    go, report = tmp_path / "go", tmp_path / "report.json"
    project = Path(__file__).resolve().parents[2]
    proc = subprocess.Popen([sys.executable, "-m", "hil_sim", "autopilot", "--speed", "10", "--arm-at", "2",
                             "--rtcm-stream", f"tcp://127.0.0.1:{port}", "--go-file", str(go), "--report",
                             str(report)], cwd=project, env=dict(os.environ, PYTHONPATH=str(project)),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)

    def read() -> dict[str, Any]:
        try:
            return dict(json.loads(report.read_text()))
        except (OSError, ValueError):
            return {}

    try:
        server.settimeout(20)
        conn, _ = server.accept()
        conn.sendall(b"".join(messages))
        deadline = time.monotonic() + 20
        while read().get("rtcm_live", {}).get("messages", 0) < len(messages) and time.monotonic() < deadline:
            time.sleep(0.1)
        first = read()
        assert first["rtcm_live"]["messages"] == len(messages) and first["rtcm_stream_bytes"] == sum(SIZES)
        assert first["go_s"] is None and first["sim_time_s"] > 2.0  # past --arm-at, still waiting for the go
        go.touch()
        deadline = time.monotonic() + 10
        while read().get("go_s") is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert read()["go_s"] is not None
        conn.close()
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=30)
        server.close()
    assert proc.returncode == 0
