"""The uploader's loop against a live ground API (in process, SQLite) with a drone token: oldest first, byte-identical, never while
armed (also stopping mid-flight-upload when the vehicle arms, then resuming without sending a byte twice),
backoff when the server is unreachable, deletion only when configured and after the server confirmed every
SHA-256, a damaged local copy set aside, upload.json with the keys the pre-flight page reads."""

from __future__ import annotations

import hashlib
import json
import os
import socket
import threading
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from ground.api.auth import Role, create_token
from ground.api.settings import ApiSettings, database_url
from ground.store import Store
from onboard.hw.ports import SystemClock
from onboard.logger.journal import Journal, JournalOptions
from onboard.recorder.settings import Settings
from onboard.upload.daemon import UploadService, armed_hold, http_uploader_for
from onboard.upload.queue import UploadQueue
from tests.ground_api.conftest import TOKEN, LiveServer, start_server

pytestmark = pytest.mark.timeout(120)
PAGE_KEYS = {"queued", "uploading", "done", "last_result", "last_error", "last_success_wall_ns", "bytes_sent"}


@pytest.fixture
def live(tmp_path: Path) -> Iterator[LiveServer]:
    srv = start_server(ApiSettings(data_dir=tmp_path / "ground", token=TOKEN, max_chunk_bytes=64 * 1024,
                                   max_file_bytes=8 * 1024 * 1024, max_flight_bytes=32 * 1024 * 1024))
    try:
        yield srv
    finally:
        srv.stop()


def _journal(d: Path, size: int, seed: int) -> None:
    journal = Journal(d, SystemClock(), JournalOptions(segment_max_bytes=size // 2 + 1))
    rnd = __import__("random").Random(seed)
    for _ in range(size // 4096):
        journal.append(rnd.randbytes(4096), time.monotonic_ns(), time.time_ns())
    journal.close("test")


def make_flight(data: Path, name: str, size: int, seed: int, radio_bytes: int = 0) -> Path:
    """A closed flight as the recorder leaves it: two segments, manifest, events.jsonl, queued ready; with
    `radio_bytes`, also the corrections sub-journal radio/ (two segments and its own manifest)."""
    d = data / name
    _journal(d, size, seed)
    if radio_bytes:
        _journal(d / "radio", radio_bytes, seed + 100)
    (d / "events.jsonl").write_text('{"type": "flight", "event": "closed"}\n')
    UploadQueue(data).enqueue(name, True, 0)
    return d


def drone_token_file(tmp_path: Path) -> Path:
    """The companion's drone token (what a drone is given: create flights, upload their files), made once in
    the store the live server uses (tmp_path/ground)."""
    token = tmp_path / "token"
    if not token.exists():
        (tmp_path / "ground").mkdir(exist_ok=True)
        store = Store(database_url(tmp_path / "ground"))
        try:
            token.write_text(create_token(store, Role.DRONE, "companion")[1] + "\n")
        finally:
            store.close()
    return token


def settings_for(tmp_path: Path, url: str, **kw: Any) -> Settings:
    token = drone_token_file(tmp_path)
    base: dict[str, Any] = {"data_dir": tmp_path / "data", "status_path": tmp_path / "run" / "status.json",
                            "upload_url": url, "upload_token_file": str(token), "upload_chunk_mib": 0.0625,
                            "upload_backoff_min_s": 0.5, "upload_backoff_max_s": 2.0, "upload_poll_s": 0.2}
    base.update(kw)
    (tmp_path / "run").mkdir(exist_ok=True)
    return Settings(**base)


def service_for(settings: Settings) -> UploadService:
    stop = threading.Event()
    token = Path(str(settings.upload_token_file)).read_text().strip()
    return UploadService(settings, http_uploader_for(settings, token, stop), stop)


def server_files(live: LiveServer) -> dict[str, dict[str, str]]:
    """flight name → {file name: sha256 of the bytes the server stored}."""
    out: dict[str, dict[str, str]] = {}
    with live.client() as c:
        for f in c.get("/flights").json():
            flight = c.get(f"/flights/{f['id']}").json()
            out[flight["name"]] = {x["name"]: hashlib.sha256(c.get(f"/flights/{f['id']}/files/{x['name']}/content")
                                                             .content).hexdigest() for x in flight["files"]}
    return out


def local_files(d: Path) -> dict[str, str]:
    """relative name (sub-folders with /) → SHA-256 of every file of a flight folder but hidden and .tmp ones."""
    return {p.relative_to(d).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(d.rglob("*"))
            if p.is_file() and not p.name.startswith(".") and not p.name.endswith(".tmp")}


def write_autopilot(settings: Settings, **snap: Any) -> None:
    settings.status_path.with_name("autopilot.json").write_text(json.dumps(snap))


@pytest.mark.slow
def test_oldest_first_byte_identical_and_status(tmp_path: Path, live: LiveServer) -> None:
    data = tmp_path / "data"
    newer = make_flight(data, "flight-20260501T120000Z", 300_000, 2)
    older = make_flight(data, "flight-20260501T100000Z", 200_000, 1)
    expected = {older.name: local_files(older), newer.name: local_files(newer)}
    s = settings_for(tmp_path, live.url)
    svc = service_for(s)
    assert svc.step() == 0.0
    assert list(server_files(live)) == [older.name]  # the older one went first
    assert svc.step() == 0.0
    assert server_files(live) == expected  # every file, byte-identical by SHA-256
    svc.step()
    svc.write_status()
    status = json.loads(s.status_path.with_name("upload.json").read_text())
    assert PAGE_KEYS <= set(status)
    assert status["queued"] == 0 and status["done"] == 2 and status["uploading"] is None
    assert status["last_result"] == f"uploaded {newer.name}" and status["last_error"] is None
    assert isinstance(status["last_success_wall_ns"], int)
    assert status["bytes_sent"] == sum(p.stat().st_size for d in (older, newer) for p in d.iterdir()
                                       if p.is_file() and not p.name.startswith("."))
    assert older.is_dir() and local_files(older) == expected[older.name]  # kept: delete_after_upload false
    done = UploadQueue(data).done()
    assert done[older.name]["files"] == expected[older.name] and done[older.name]["deleted"] == []


@pytest.mark.slow
def test_never_while_armed_and_paused_when_arming_mid_upload(tmp_path: Path, live: LiveServer) -> None:
    data = tmp_path / "data"
    flight = make_flight(data, "flight-20260501T100000Z", 400_000, 3)
    s = settings_for(tmp_path, live.url, autopilot_link="udpin:127.0.0.1:14550")
    svc = service_for(s)
    assert svc.step() > 0 and svc.status.held_reason == "autopilot state unknown (no autopilot.json)"
    write_autopilot(s, armed=True, link_up=True)
    assert svc.step() > 0 and svc.status.state == "held" and svc.status.held_reason == "armed"
    assert svc.status.bytes_sent == 0 and server_files(live) == {}
    write_autopilot(s, armed=False, link_up=True)
    chunks: list[int] = []
    original = svc._on_chunk

    def arm_after_three(n: int) -> None:  # the pilot arms while the upload runs
        original(n)
        chunks.append(n)
        if len(chunks) == 3:
            write_autopilot(s, armed=True, link_up=True)

    svc.uploader.on_chunk = arm_after_three
    svc.step()
    assert svc.status.last_result == "paused: armed" and len(chunks) == 3
    sent_before = svc.status.bytes_sent
    assert sent_before == sum(chunks) > 0 and max(chunks) == 65536
    write_autopilot(s, armed=False, link_up=True)
    assert svc.step() == 0.0
    total = sum(p.stat().st_size for p in flight.iterdir() if p.is_file())
    assert svc.status.bytes_sent == total  # the resumed upload sent only what the server lacked
    assert server_files(live)[flight.name] == local_files(flight)


def test_armed_hold_rules() -> None:
    assert armed_hold(None, None, False) is None  # no autopilot link: nothing can arm as far as we know
    assert armed_hold({"armed": False, "link_up": True}, 1.0, True) is None
    assert armed_hold({"armed": True, "link_up": True}, 1.0, True) == "armed"
    assert armed_hold({"armed": False, "link_up": False}, 1.0, True) == "autopilot link down: armed state unknown"
    assert armed_hold({"armed": None, "link_up": True}, 1.0, True) == "armed state unknown"
    assert "old" in (armed_hold({"armed": False, "link_up": True}, 30.0, True) or "")


def test_backoff_when_the_server_is_unreachable(tmp_path: Path) -> None:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]  # closed again: nothing listens there
    make_flight(tmp_path / "data", "flight-20260501T100000Z", 50_000, 4)
    s = replace(settings_for(tmp_path, f"http://127.0.0.1:{port}"), upload_backoff_min_s=0.5,
                upload_backoff_max_s=1.5)
    svc = service_for(s)
    svc.uploader.sleep = lambda _s: None  # the per-request retries: no wait
    waits = [svc.step() for _ in range(4)]
    assert waits == [0.5, 1.0, 1.5, 1.5]
    assert svc.status.state == "backoff" and "ConnectError" in (svc.status.last_error or "")
    assert UploadQueue(tmp_path / "data").next_ready() is not None  # still queued


@pytest.mark.slow
def test_delete_after_upload_only_confirmed_files(tmp_path: Path, live: LiveServer) -> None:
    data = tmp_path / "data"
    flight = make_flight(data, "flight-20260501T100000Z", 100_000, 5, radio_bytes=30_000)
    (flight / "radio" / "000002.ubx.tmp").write_bytes(b"radio")  # a temporary file is never uploaded: never deleted
    files = local_files(flight)
    names = sorted(files)
    assert {"radio/000000.ubx", "radio/000001.ubx", "radio/manifest.json"} <= set(names)
    svc = service_for(settings_for(tmp_path, live.url, upload_delete_after_upload=True))
    assert svc.step() == 0.0
    assert server_files(live)[flight.name] == files  # radio/ too, byte-identical by SHA-256
    # each closed manifest stays with what is left in its folder, so that the recorder never takes the folder for
    # an unclosed flight (nor the radio journal for a torn one)
    left = sorted(p.relative_to(flight).as_posix() for p in flight.rglob("*") if p.is_file())
    assert left == ["manifest.json", "radio/000002.ubx.tmp", "radio/manifest.json"]
    assert sorted(UploadQueue(data).done()[flight.name]["deleted"]) == [
        n for n in names if n not in ("manifest.json", "radio/manifest.json")]


@pytest.mark.slow
def test_delete_after_upload_removes_the_whole_flight(tmp_path: Path, live: LiveServer) -> None:
    data = tmp_path / "data"
    flight = make_flight(data, "flight-20260501T100000Z", 100_000, 8, radio_bytes=20_000)
    files = local_files(flight)
    names = sorted(files)
    svc = service_for(settings_for(tmp_path, live.url, upload_delete_after_upload=True))
    assert svc.step() == 0.0
    assert server_files(live)[flight.name] == files
    assert not flight.exists()
    assert sorted(UploadQueue(data).done()[flight.name]["deleted"]) == names
    assert svc.step() == 0.2 and svc.status.state == "idle"  # nothing queued, nothing failed


@pytest.mark.slow
def test_a_damaged_local_copy_is_set_aside(tmp_path: Path, live: LiveServer) -> None:
    data = tmp_path / "data"
    bad = make_flight(data, "flight-20260501T100000Z", 50_000, 6)
    good = make_flight(data, "flight-20260501T110000Z", 50_000, 7)
    seg = bad / "000000.ubx"
    raw = bytearray(seg.read_bytes())
    raw[100] ^= 0xFF
    seg.write_bytes(bytes(raw))
    svc = service_for(settings_for(tmp_path, live.url))
    assert svc.step() == 0.0 and svc.status.last_result == f"failed: {bad.name}"
    assert (data / "upload" / "failed" / f"{bad.name}.json").is_file()
    assert svc.step() == 0.0
    assert list(server_files(live)) == [good.name]
    assert os.path.exists(seg)  # never deleted
