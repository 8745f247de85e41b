"""The real entry points: `python -m ground serve` (token from the environment or a file, refusal without one)
and `python -m onboard.upload` against it; plus concurrent chunk writers and an empty file."""

from __future__ import annotations

import concurrent.futures
import hashlib
import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from onboard.logger.journal import Manifest, SegmentInfo
from tests.ground_api.conftest import LiveServer

ROOT = Path(__file__).resolve().parents[2]
TOKEN = "serve-token-0123456789abcdef"

pytestmark = pytest.mark.timeout(120)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("DIRECTGEO_TOKEN", "DATABASE_URL")}
    env.update(extra)
    return env


@pytest.mark.slow
def test_serve_refuses_to_start_without_a_token(tmp_path: Path) -> None:
    out = subprocess.run([sys.executable, "-m", "ground", "serve", "--data-dir", str(tmp_path)], cwd=ROOT,
                         env=_env(), capture_output=True, text=True, timeout=60, check=False)
    assert out.returncode == 2 and "DIRECTGEO_TOKEN" in out.stderr
    (tmp_path / "short").write_text("abc\n")
    out = subprocess.run([sys.executable, "-m", "ground", "serve", "--token-file", str(tmp_path / "short")],
                         cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=60, check=False)
    assert out.returncode == 2 and "at least 16" in out.stderr


@pytest.mark.slow
def test_serve_and_uploader_command_lines(tmp_path: Path) -> None:
    """Server from `python -m ground serve --token-file`, flight sent by `python -m onboard.upload` (token from
    the environment), SQLite file in the data dir; a second uploader run sends nothing."""
    token_file = tmp_path / "token"
    token_file.write_text(TOKEN + "\n")
    port = _free_port()
    data = tmp_path / "data"
    srv = subprocess.Popen([sys.executable, "-m", "ground", "serve", "--port", str(port), "--data-dir", str(data),
                            "--token-file", str(token_file)], cwd=ROOT, env=_env(), stdout=subprocess.DEVNULL,
                           stderr=subprocess.PIPE, text=True)
    try:
        url = f"http://127.0.0.1:{port}"
        deadline = time.monotonic() + 30
        while True:
            try:
                if httpx.get(f"{url}/health", timeout=1).status_code == 200:
                    break
            except httpx.TransportError:
                pass
            assert time.monotonic() < deadline and srv.poll() is None, "server did not start"
            time.sleep(0.1)
        assert httpx.get(f"{url}/flights").status_code == 401
        flight = tmp_path / "flight-20240501T120000Z"
        flight.mkdir()
        seg = os.urandom(150_000)
        (flight / "000000.ubx").write_bytes(seg)
        m = Manifest(flight.name, 1, [SegmentInfo("000000.ubx", len(seg), hashlib.sha256(seg).hexdigest())])
        (flight / "manifest.json").write_text(json.dumps(m.to_json()))
        cmd = [sys.executable, "-m", "onboard.upload.client", "--url", url, "--chunk-mib", "0.05", str(flight)]
        up = subprocess.run(cmd, cwd=ROOT, env=_env(DIRECTGEO_TOKEN=TOKEN), capture_output=True, text=True,
                            timeout=60, check=False)
        assert up.returncode == 0, up.stderr
        assert "complete" in up.stdout
        again = subprocess.run(cmd, cwd=ROOT, env=_env(DIRECTGEO_TOKEN=TOKEN), capture_output=True, text=True,
                               timeout=60, check=False)
        assert again.returncode == 0 and " 0 bytes sent" in again.stdout
        bad = subprocess.run(cmd, cwd=ROOT, env=_env(DIRECTGEO_TOKEN="wrong-token-0123456789"),
                             capture_output=True, text=True, timeout=60, check=False)
        assert bad.returncode == 1 and "401" in bad.stderr
        flights = httpx.get(f"{url}/flights", headers={"Authorization": f"Bearer {TOKEN}"}).json()
        fid = flights[0]["id"]
        assert (data / "flights" / fid / "000000.ubx").read_bytes() == seg
        assert (data / "directgeo.sqlite3").is_file()
    finally:
        srv.terminate()
        srv.wait(timeout=20)


def test_concurrent_writers_at_one_offset_one_wins(live: LiveServer) -> None:
    """Two clients send different chunks at the same offset at once: exactly one is stored, the other gets 409."""
    a, b = os.urandom(50_000), os.urandom(50_000)
    whole = a + os.urandom(10)
    with live.client() as c:
        body = {"name": "race", "files": [{"name": "x.ubx", "size": len(whole),
                                           "sha256": hashlib.sha256(whole).hexdigest()}]}
        fid = c.post("/flights", json=body).json()["id"]

    def put(chunk: bytes) -> int:
        with live.client() as cc:
            return cc.put(f"/flights/{fid}/files/x.ubx", params={"offset": 0}, content=chunk,
                          headers={"X-Chunk-SHA256": hashlib.sha256(chunk).hexdigest()}).status_code

    with concurrent.futures.ThreadPoolExecutor(2) as pool:
        codes = sorted(pool.map(put, [a, b]))
    assert codes == [200, 409]
    with live.client() as c:
        assert c.get(f"/flights/{fid}/files/x.ubx").json()["received"] == 50_000


def test_empty_file_completes_at_creation(live: LiveServer) -> None:
    """A 0-byte file (e.g. an events.jsonl with no mark) is verified at once; the flight can complete."""
    with live.client() as c:
        body = {"name": "empty", "files": [{"name": "events.jsonl", "size": 0,
                                            "sha256": hashlib.sha256(b"").hexdigest()}]}
        r = c.post("/flights", json=body)
        assert r.status_code == 201
        assert r.json()["files"][0]["status"] == "complete" and r.json()["status"] == "complete"
        assert c.get(f"/flights/{r.json()['id']}/files/events.jsonl/content").content == b""


_LIMITED_SERVER = """
import resource, signal, sys
from pathlib import Path
import uvicorn
from ground.api.app import create_app
from ground.api.settings import ApiSettings
limit = int(sys.argv[3])
if limit:
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit then fails with EFBIG
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
settings = ApiSettings(data_dir=Path(sys.argv[1]), token=sys.argv[4], max_chunk_bytes=100_000)
uvicorn.run(create_app(settings), host="127.0.0.1", port=int(sys.argv[2]), log_level="warning")
"""


def _start_limited(data: Path, limit: int) -> tuple[subprocess.Popen[str], str]:
    port = _free_port()
    proc = subprocess.Popen([sys.executable, "-c", _LIMITED_SERVER, str(data), str(port), str(limit), TOKEN],
                            cwd=ROOT, env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, text=True)
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 30
    while True:
        try:
            if httpx.get(f"{url}/health", timeout=1).status_code == 200:
                return proc, url
        except httpx.TransportError:
            pass
        assert time.monotonic() < deadline and proc.poll() is None, "server did not start"
        time.sleep(0.1)


@pytest.mark.slow
def test_full_disk_rejects_the_chunk_and_keeps_what_was_stored(tmp_path: Path) -> None:
    """The server process may not write files past 350 kB (RLIMIT_FSIZE, like a full disk): the chunk that does
    not fit gets 507, the partial file is cut back to the last whole chunk, and after a restart with space the
    upload resumes from there to a byte-identical file."""
    data = tmp_path / "data"
    blob = os.urandom(500_000)
    headers = {"Authorization": f"Bearer {TOKEN}"}
    proc, url = _start_limited(data, 350_000)
    try:
        with httpx.Client(base_url=url, headers=headers, timeout=30) as c:
            body = {"name": "full", "files": [{"name": "a.ubx", "size": len(blob),
                                               "sha256": hashlib.sha256(blob).hexdigest()}]}
            fid = c.post("/flights", json=body).json()["id"]
            codes = []
            for off in range(0, len(blob), 100_000):
                chunk = blob[off:off + 100_000]
                r = c.put(f"/flights/{fid}/files/a.ubx", params={"offset": off}, content=chunk,
                          headers={"X-Chunk-SHA256": hashlib.sha256(chunk).hexdigest()})
                codes.append(r.status_code)
                if r.status_code != 200:
                    break
            assert codes == [200, 200, 200, 507]
            assert c.head(f"/flights/{fid}/files/a.ubx").headers["Upload-Offset"] == "300000"
        assert (data / "flights" / fid / ".partial" / "a.ubx").stat().st_size == 300_000
    finally:
        proc.terminate()
        proc.wait(timeout=20)
    proc, url = _start_limited(data, 0)
    try:
        with httpx.Client(base_url=url, headers=headers, timeout=30) as c:
            off = int(c.head(f"/flights/{fid}/files/a.ubx").headers["Upload-Offset"])
            while off < len(blob):
                chunk = blob[off:off + 100_000]
                r = c.put(f"/flights/{fid}/files/a.ubx", params={"offset": off}, content=chunk,
                          headers={"X-Chunk-SHA256": hashlib.sha256(chunk).hexdigest()})
                assert r.status_code == 200
                off = r.json()["received"]
            assert r.json()["status"] == "complete"
        assert (data / "flights" / fid / "a.ubx").read_bytes() == blob
    finally:
        proc.terminate()
        proc.wait(timeout=20)


def test_serve_refuses_an_unusable_database_url(tmp_path: Path) -> None:
    """A DATABASE_URL whose driver is missing or whose file cannot be created: exit 2 with the reason."""
    for url in ("postgresql+nosuchdriver://u@db/flights", f"sqlite:///{tmp_path}/missing/dir/x.sqlite3"):
        out = subprocess.run([sys.executable, "-m", "ground", "serve", "--data-dir", str(tmp_path / "d")],
                             cwd=ROOT, env=_env(DIRECTGEO_TOKEN=TOKEN, DATABASE_URL=url), capture_output=True,
                             text=True, timeout=60, check=False)
        assert out.returncode == 2 and "cannot open the flight store" in out.stderr, out.stderr
