"""End to end: the real recorder daemon (`python -m onboard run`) with `python -m hil_sim receiver` on a pty and
`python -m hil_sim autopilot` on a raw pty, the uploader (`python -m onboard upload-daemon`) and a live ground
server (`python -m ground serve`, SQLite, a generated token), every one a process of its own; nobody runs an
upload command. Short settle times; the stand-in flies at 4× real time, the receiver at 6×."""

from __future__ import annotations

import hashlib
import json
import secrets
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import pytest

from ground.api.auth import Role, create_token
from ground.api.settings import database_url
from ground.store import Store
from onboard.hw.ports import SystemClock
from onboard.logger.events import read_events
from onboard.logger.journal import Journal, JournalOptions, iter_journal_bytes, list_segments, read_manifest
from onboard.receiver.framing import StreamFramer
from onboard.recorder.feature import is_rollover
from onboard.upload.priority import io_class
from onboard.upload.queue import UploadQueue
from tests.autopilot.test_e2e import autopilot_json, env, start_standin
from tests.daemon.helpers import reap, wait_until

PROJECT = Path(__file__).resolve().parents[2]
pytestmark = [pytest.mark.timeout(300), pytest.mark.slow]


def free_tcp_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Ground:
    """`python -m ground serve` on a fixed port (restartable on the same data and port), started with a
    bootstrap admin token; the companion uploads with a drone token (`token_file`), the test reads with an
    engineer token (`token`)."""

    def __init__(self, tmp: Path) -> None:
        self.admin_token_file = tmp / "ground-admin.token"
        self.admin_token_file.write_text(secrets.token_hex(16) + "\n")
        self.port = free_tcp_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.data = tmp / "ground"
        self.data.mkdir(parents=True, exist_ok=True)
        store = Store(database_url(self.data))
        try:
            drone = create_token(store, Role.DRONE, "companion")[1]
            self.token = create_token(store, Role.ENGINEER, "office")[1]
        finally:
            store.close()
        self.token_file = tmp / "ground-drone.token"
        self.token_file.write_text(drone + "\n")
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self) -> None:
        self.proc = subprocess.Popen([sys.executable, "-m", "ground", "serve", "--port", str(self.port),
                                      "--data-dir", str(self.data), "--token-file", str(self.admin_token_file)],
                                     cwd=PROJECT, env=env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 60
        while True:
            try:
                if httpx.get(f"{self.url}/health", timeout=1).status_code == 200:
                    return
            except httpx.TransportError:
                pass
            assert time.monotonic() < deadline and self.proc.poll() is None, "ground server did not start"
            time.sleep(0.1)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            self.proc.wait(timeout=30)

    def flights(self) -> dict[str, dict[str, Any]]:
        """name → the server's flight record (files with status, size, sha256)."""
        h = {"Authorization": f"Bearer {self.token}"}
        out = {}
        for f in httpx.get(f"{self.url}/flights", headers=h, timeout=10).json():
            out[f["name"]] = httpx.get(f"{self.url}/flights/{f['id']}", headers=h, timeout=10).json()
        return out

    def stored_sha256(self, name: str) -> dict[str, str]:
        """SHA-256 of the bytes the server stored for each file of flight `name` (read from its data folder)."""
        flight = self.flights()[name]
        return {f["name"]: hashlib.sha256((self.data / "flights" / flight["id"] / f["name"]).read_bytes()).hexdigest()
                for f in flight["files"]}


def local_sha256(d: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(d.iterdir())
            if p.is_file() and not p.name.startswith(".")}


def write_config(tmp: Path, ground: Ground | None, autopilot: str | None, settle_s: float,
                 upload: str = "") -> Path:
    cfg = tmp / "recorder.toml"
    text = "[journal]\ndisk_floor_mb = 1.0\n[status]\ninterval_s = 0.2\n"
    if autopilot:
        text += f'[autopilot]\nlink = "{autopilot}"\nlink_timeout_s = 2.0\nsettle_s = {settle_s}\n'
    if ground is not None:
        text += (f'[upload]\nurl = "{ground.url}"\ntoken_file = "{ground.token_file}"\nbackoff_min_s = 0.5\n'
                 f"backoff_max_s = 2.0\npoll_s = 0.2\n{upload}")
    cfg.write_text(text)
    return cfg


def start_daemon(tmp: Path, cfg: Path, port: str) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [sys.executable, "-m", "onboard", "run", "--config", str(cfg), "--port", port, "--baud", "9600",
         "--no-configure", "--data-dir", str(tmp / "data"), "--status", str(tmp / "run" / "status.json")],
        cwd=PROJECT, env=env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT)


def start_uploader(tmp: Path, cfg: Path) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [sys.executable, "-m", "onboard", "upload-daemon", "--config", str(cfg), "--data-dir", str(tmp / "data"),
         "--status", str(tmp / "run" / "status.json")], cwd=PROJECT, env=env(), stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT)


def start_receiver(tmp: Path) -> tuple[subprocess.Popen[bytes], str]:
    proc = subprocess.Popen([sys.executable, "-m", "hil_sim", "receiver", "--model", "m8t", "--speed", "6"],
                            cwd=PROJECT, env=env(), stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    assert proc.stdout is not None
    path = proc.stdout.readline().decode().strip()
    assert path, "hil_sim receiver printed no pty"
    return proc, path


def upload_json(tmp: Path) -> dict[str, Any]:
    try:
        return json.loads((tmp / "run" / "upload.json").read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return {}


def sigterm(proc: subprocess.Popen[bytes]) -> str:
    proc.send_signal(signal.SIGTERM)
    out, _ = proc.communicate(timeout=60)
    text = (out or b"").decode(errors="replace")
    assert proc.returncode == 0, text[-3000:]
    return text


def autopilot_events(flight: Path) -> list[str]:
    return [r["event"] for r in read_events(flight / "events.jsonl").records if r.get("type") == "autopilot"]


def _holds_bytes(flights: list[Path]) -> bool:
    """One flight folder is given and its journal segments hold at least one byte."""
    return len(flights) == 1 and any(p.stat().st_size > 0 for p in list_segments(flights[0]))


def test_closed_after_landing_uploaded_next_flight_without_a_gap(tmp_path: Path) -> None:
    """Two flights: each closed 2 s after its disarm (a roll-over: recording goes on), uploaded by the uploader
    started at boot, byte-identical on the server; the receiver's stream split between the flights loses and
    repeats nothing."""
    ground = Ground(tmp_path)
    ground.start()
    receiver, rx_pty = start_receiver(tmp_path)
    standin, ap_pty, _ = start_standin(tmp_path, "--arm-at", "8", "--survey", "8", "--repeat-after", "40")
    cfg = write_config(tmp_path, ground, f"serial:{ap_pty}@921600", 2.0)
    daemon = start_daemon(tmp_path, cfg, rx_pty)
    uploader = start_uploader(tmp_path, cfg)
    data = tmp_path / "data"
    status_path = tmp_path / "run" / "status.json"
    violations: list[dict[str, Any]] = []
    sampling = threading.Event()

    def sample() -> None:  # the uploader must never be sending while the autopilot says armed
        while not sampling.is_set():
            ap, up = autopilot_json(status_path), upload_json(tmp_path)
            if ap.get("armed") and up.get("state") == "uploading":
                violations.append({"autopilot": ap.get("armed"), "upload": up})
            time.sleep(0.05)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    try:
        wait_until(lambda: autopilot_json(status_path).get("link_up"), 30, "autopilot link up")
        wait_until(lambda: autopilot_json(status_path).get("flights_closed") == 1, 40, "first flight closed")
        wait_until(lambda: upload_json(tmp_path).get("done") == 1, 40, "first flight uploaded")
        wait_until(lambda: autopilot_json(status_path).get("armed"), 40, "second flight armed")
        wait_until(lambda: autopilot_json(status_path).get("flights_closed") == 2, 60, "second flight closed")
        wait_until(lambda: upload_json(tmp_path).get("done") == 2, 40, "second flight uploaded")
        # the flight opened at the second roll-over records the receiver before the stop: stopped first, it would
        # rightly hold no byte (CI once stopped it within its first second)
        wait_until(lambda: _holds_bytes(sorted(data.glob("flight-*"))[2:]), 20, "third flight recording")
        sampling.set()
        status_before_stop = json.loads(status_path.read_text())
        sigterm(daemon)
        wait_until(lambda: upload_json(tmp_path).get("done") == 3, 40, "the flight closed at stop uploaded")
        sigterm(uploader)
        flights = sorted(data.glob("flight-*"))
        assert len(flights) == 3
        manifests = [read_manifest(f) for f in flights]
        assert all(m is not None and m.closed for m in manifests)
        assert is_rollover(manifests[0].close_reason) and is_rollover(manifests[1].close_reason)  # type: ignore[union-attr]
        assert manifests[2].close_reason == "signal SIGTERM"  # type: ignore[union-attr]
        assert autopilot_events(flights[0]) == ["armed", "takeoff", "landed", "disarmed", "flight_over"]
        assert autopilot_events(flights[1]) == ["armed", "takeoff", "landed", "disarmed", "flight_over"]
        assert autopilot_events(flights[2]) == []
        closed = [r for r in read_events(flights[0] / "events.jsonl").records if r.get("type") == "flight"]
        assert closed[-1]["event"] == "closed" and closed[-1]["next_flight"] == flights[1].name
        # the receiver's bytes: every one read is in exactly one flight, in order, and they frame without a seam
        parts = [b"".join(iter_journal_bytes(f)) for f in flights]
        assert all(len(p) > 0 for p in parts)
        status = json.loads(status_path.read_text())
        assert sum(len(p) for p in parts) == status["bytes_recorded"] >= status_before_stop["bytes_recorded"]
        framer = StreamFramer()
        frames = framer.feed(b"".join(parts))
        assert len(frames) > 50 and framer.skipped_bytes == status["skipped_bytes"]
        for f in flights:  # each flight's tlog holds its share of the autopilot's packets
            assert (f / "autopilot.tlog").stat().st_size > 0
        on_server = ground.flights()
        assert sorted(on_server) == [f.name for f in flights]
        for f in flights:
            assert ground.stored_sha256(f.name) == local_sha256(f), f.name  # byte-identical
            assert all(x["status"] == "complete" for x in on_server[f.name]["files"])
        done = UploadQueue(data).done()
        assert [done[f.name]["files"] == local_sha256(f) for f in flights] == [True] * 3
        assert violations == []
    finally:
        sampling.set()
        for p in (daemon, uploader):
            reap(p)
        for p in (standin, receiver):
            p.send_signal(signal.SIGTERM)
            p.communicate(timeout=30)
        ground.stop()


def test_rearming_during_the_settle_time_keeps_one_flight(tmp_path: Path) -> None:
    """The stand-in lands, disarms and re-arms 1 s later (4 simulated s), inside a 3 s settle time: no close;
    after its second landing the flight closes once, with both flights' events in it."""
    standin, ap_pty, _ = start_standin(tmp_path, "--arm-at", "8", "--survey", "4", "--repeat-after", "4")
    cfg = write_config(tmp_path, None, f"serial:{ap_pty}@921600", 3.0)
    daemon = start_daemon(tmp_path, cfg, str(tmp_path / "no-receiver"))
    status_path = tmp_path / "run" / "status.json"
    settling: list[float] = []
    try:
        wait_until(lambda: autopilot_json(status_path).get("link_up"), 30, "autopilot link up")

        def second_disarm() -> bool:
            snap = autopilot_json(status_path)
            if snap.get("settling_s") is not None:
                settling.append(snap["settling_s"])
            return snap.get("flights_closed") == 1

        wait_until(second_disarm, 60, "the flight closed after the second landing")
        time.sleep(1.0)
        sigterm(daemon)
    finally:
        reap(daemon)
        standin.send_signal(signal.SIGTERM)
        standin.communicate(timeout=30)
    flights = sorted((tmp_path / "data").glob("flight-*"))
    assert len(flights) == 2
    assert autopilot_events(flights[0]) == ["armed", "takeoff", "landed", "disarmed"] * 2 + ["flight_over"]
    assert autopilot_events(flights[1]) == []
    assert settling and max(settling) < 3.0


def test_battery_pull_mid_flight_resumed_then_closed_on_the_ground(tmp_path: Path) -> None:
    """SIGKILL mid-flight (a battery pull): the next boot resumes the flight (torn tails listed, recovered)
    and, the autopilot found disarmed on the ground, closes it after the settle time and goes on in a new one."""
    receiver, rx_pty = start_receiver(tmp_path)
    standin, ap_pty, _ = start_standin(tmp_path, "--arm-at", "4", "--survey", "400")
    cfg = write_config(tmp_path, None, f"serial:{ap_pty}@921600", 2.0)
    status_path = tmp_path / "run" / "status.json"
    daemon = start_daemon(tmp_path, cfg, rx_pty)
    try:
        wait_until(lambda: autopilot_json(status_path).get("landed_state") == "in_air", 40, "in the air")
        time.sleep(1.0)
        daemon.kill()  # the battery goes
        daemon.wait(timeout=30)
        standin.send_signal(signal.SIGTERM)
        standin.communicate(timeout=30)
        (flight,) = (tmp_path / "data").glob("flight-*")
        assert not read_manifest(flight).closed  # type: ignore[union-attr]
        # power back: the autopilot boots on the ground, disarmed
        standin, ap_pty, _ = start_standin(tmp_path, "--arm-at", "1000")
        cfg = write_config(tmp_path, None, f"serial:{ap_pty}@921600", 2.0)
        daemon = start_daemon(tmp_path, cfg, rx_pty)
        wait_until(lambda: autopilot_json(status_path).get("flights_closed") == 1, 60, "resumed flight closed")
        sigterm(daemon)
    finally:
        reap(daemon)
        for p in (standin, receiver):
            p.send_signal(signal.SIGTERM)
            p.communicate(timeout=30)
    flights = sorted((tmp_path / "data").glob("flight-*"))
    assert flights[0] == flight and len(flights) == 2
    m = read_manifest(flight)
    assert m is not None and m.closed and m.restarts == 1 and is_rollover(m.close_reason or "")
    assert any(s.recovered for s in m.segments)  # the segment cut by the kill, listed with its true size/hash
    assert autopilot_events(flight)[:2] == ["armed", "takeoff"] and autopilot_events(flight)[-1] == "flight_over"
    assert sorted(p.name for p in flight.glob("autopilot*.tlog")) == ["autopilot-2.tlog", "autopilot.tlog"]


def make_big_flight(data: Path, name: str, mb: int) -> Path:
    """A closed flight of `mb` MB of journal (as the recorder leaves one), queued ready."""
    d = data / name
    journal = Journal(d, SystemClock(), JournalOptions(segment_max_bytes=32_000_000))
    block = bytes(range(256)) * 256
    for i in range(mb * 1_000_000 // len(block)):
        journal.append(block[i % 256:] + block[:i % 256], time.monotonic_ns(), time.time_ns())
    journal.close("test")
    UploadQueue(data).enqueue(name, True, 0)
    return d


def server_held(ground: Ground, name: str) -> int:
    """Bytes the server holds for flight `name` (all files, complete or not)."""
    h = {"Authorization": f"Bearer {ground.token}"}
    flight = ground.flights()[name]
    total = 0
    for f in flight["files"]:
        r = httpx.get(f"{ground.url}/flights/{flight['id']}/files/{f['name']}", headers=h, timeout=10)
        total += int(r.json()["received"])
    return total


def test_upload_resumes_after_the_server_was_down_and_after_a_reboot(tmp_path: Path) -> None:
    """A 96 MB flight: the server stopped mid-upload (the uploader backs off, then resumes when it is back), then
    the uploader SIGKILLed mid-upload and started again (it completes; it sends exactly what the server lacks)."""
    ground = Ground(tmp_path)
    ground.start()
    data = tmp_path / "data"
    flight = make_big_flight(data, "flight-20260501T100000Z", 96)
    total = sum(p.stat().st_size for p in flight.iterdir() if p.is_file())
    (tmp_path / "run").mkdir()
    cfg = write_config(tmp_path, ground, None, 2.0, upload="chunk_mib = 1.0\n")
    uploader = start_uploader(tmp_path, cfg)
    try:
        wait_until(lambda: upload_json(tmp_path).get("bytes_sent", 0) > total * 0.2, 60, "a fifth sent")
        ground.stop()  # the network goes
        wait_until(lambda: upload_json(tmp_path).get("last_error"), 30, "the failure seen")
        assert upload_json(tmp_path)["state"] == "backoff" and upload_json(tmp_path)["uploading"] is None
        ground.start()
        wait_until(lambda: upload_json(tmp_path).get("bytes_sent", 0) > total * 0.6, 60, "resumed past 60 %")
        uploader.kill()  # a reboot mid-upload
        uploader.wait(timeout=30)
        held = server_held(ground, flight.name)
        assert 0 < held < total
        uploader = start_uploader(tmp_path, cfg)
        wait_until(lambda: upload_json(tmp_path).get("pid") == uploader.pid, 30, "the new uploader's status")
        # low priority, as the kernel sees the running process: nice (field 19 of /proc/PID/stat) and I/O class
        assert int(Path(f"/proc/{uploader.pid}/stat").read_text().rsplit(")", 1)[1].split()[16]) >= 10
        assert io_class(uploader.pid) == "idle" and upload_json(tmp_path)["priority"]["io_class"] == "idle"
        wait_until(lambda: upload_json(tmp_path).get("done") == 1, 90, "upload complete after the restart")
        second_run = upload_json(tmp_path)
        sigterm(uploader)
    finally:
        reap(uploader)
    try:
        assert second_run["bytes_sent"] == total - held  # nothing the server held was sent again
        assert ground.stored_sha256(flight.name) == local_sha256(flight)
        assert UploadQueue(data).done()[flight.name]["files"] == local_sha256(flight)
    finally:
        ground.stop()


def test_a_reboot_of_the_companion_mid_upload(tmp_path: Path) -> None:
    """A real reboot: the recorder daemon and the uploader both SIGKILLed while a closed 96 MB flight is partly on
    the server and the next flight is being recorded in the air, then both started again as systemd would (same
    config, same data folder), the autopilot back on the ground. The upload resumes from the server's offset, the
    cut flight is recovered (torn tail) and closes on the ground, every closed flight is byte-identical on the
    server and nothing is sent twice."""
    ground = Ground(tmp_path)
    ground.start()
    data = tmp_path / "data"
    big = make_big_flight(data, "flight-20260501T100000Z", 96)
    big_total = sum(p.stat().st_size for p in big.iterdir() if p.is_file())
    go = tmp_path / "go"
    receiver, rx_pty = start_receiver(tmp_path)
    standin, ap_pty, _ = start_standin(tmp_path, "--go-file", str(go), "--arm-at", "1", "--survey", "400")
    cfg = write_config(tmp_path, ground, f"serial:{ap_pty}@921600", 2.0, upload="chunk_mib = 1.0\n")
    status_path = tmp_path / "run" / "status.json"
    daemon = start_daemon(tmp_path, cfg, rx_pty)
    uploader = start_uploader(tmp_path, cfg)
    try:
        wait_until(lambda: autopilot_json(status_path).get("link_up"), 30, "autopilot link up")
        wait_until(lambda: upload_json(tmp_path).get("bytes_sent", 0) > big_total * 0.2, 60, "a fifth sent")
        go.touch()  # take-off: the uploader pauses while armed
        wait_until(lambda: autopilot_json(status_path).get("landed_state") == "in_air", 40, "in the air")
        time.sleep(1.0)
        for p in (daemon, uploader):  # the battery goes: no clean stop for either
            p.kill()
            p.wait(timeout=30)
        standin.send_signal(signal.SIGTERM)
        standin.communicate(timeout=30)
        held = server_held(ground, big.name)
        assert 0 < held < big_total
        (cut,) = [f for f in data.glob("flight-*") if f != big]
        assert not read_manifest(cut).closed  # type: ignore[union-attr]
        # power back: the autopilot boots on the ground, disarmed; the companion's two services start again
        standin, ap_pty, _ = start_standin(tmp_path, "--arm-at", "1000")
        cfg = write_config(tmp_path, ground, f"serial:{ap_pty}@921600", 2.0, upload="chunk_mib = 1.0\n")
        daemon = start_daemon(tmp_path, cfg, rx_pty)
        uploader = start_uploader(tmp_path, cfg)
        wait_until(lambda: upload_json(tmp_path).get("pid") == uploader.pid, 30, "the new uploader's status")
        wait_until(lambda: autopilot_json(status_path).get("flights_closed") == 1, 60, "the cut flight closed")
        wait_until(lambda: upload_json(tmp_path).get("done") == 2, 90, "both closed flights uploaded")
        second_run = upload_json(tmp_path)
        sigterm(uploader)
        sigterm(daemon)
    finally:
        for p in (daemon, uploader):
            reap(p)
        for p in (standin, receiver):
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
                p.communicate(timeout=30)
    try:
        m = read_manifest(cut)
        assert m is not None and m.closed and m.restarts == 1 and is_rollover(m.close_reason or "")
        assert any(s.recovered for s in m.segments)  # the torn tail, listed with its true size and hash
        assert autopilot_events(cut)[:2] == ["armed", "takeoff"] and autopilot_events(cut)[-1] == "flight_over"
        cut_total = sum(p.stat().st_size for p in cut.iterdir() if p.is_file() and not p.name.startswith("."))
        # resumed from the server's offset: the second run sent what the server lacked of the big flight and the
        # whole cut flight, not a byte more
        assert second_run["bytes_sent"] == big_total - held + cut_total
        on_server = ground.flights()
        assert big.name in on_server and cut.name in on_server
        newest = max(data.glob("flight-*"))
        assert set(on_server) == {big.name, cut.name} and newest not in (big, cut)  # the open flight stays local
        for f in (big, cut):
            assert ground.stored_sha256(f.name) == local_sha256(f), f.name
            assert all(x["status"] == "complete" for x in on_server[f.name]["files"])
            assert UploadQueue(data).done()[f.name]["files"] == local_sha256(f)
    finally:
        ground.stop()
