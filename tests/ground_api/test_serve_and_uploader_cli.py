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
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from onboard.logger.journal import Manifest, SegmentInfo
from tests.ground_api.conftest import TOKEN as TOKEN_LIVE
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
    """Server from `python -m ground serve --token-file` (the bootstrap admin token), a drone and an engineer
    token made by `python -m ground token create` (stdout: the token alone), flight sent by
    `python -m onboard.upload` with the drone token (from the environment), read back with the engineer's;
    SQLite file in the data dir; a second uploader run sends nothing; a revoked drone token is refused."""
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

        def token(*args: str) -> str:
            out = subprocess.run([sys.executable, "-m", "ground", "token", *args, "--data-dir", str(data)],
                                 cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=60, check=True)
            return out.stdout.strip()

        drone, engineer = token("create", "--role", "drone", "--name", "drone-1"), token("create", "--role", "engineer")
        flight = tmp_path / "flight-20240501T120000Z"
        flight.mkdir()
        seg = os.urandom(150_000)
        (flight / "000000.ubx").write_bytes(seg)
        m = Manifest(flight.name, 1, [SegmentInfo("000000.ubx", len(seg), hashlib.sha256(seg).hexdigest())])
        (flight / "manifest.json").write_text(json.dumps(m.to_json()))
        cmd = [sys.executable, "-m", "onboard.upload.client", "--url", url, "--chunk-mib", "0.05", str(flight)]
        up = subprocess.run(cmd, cwd=ROOT, env=_env(DIRECTGEO_TOKEN=drone), capture_output=True, text=True,
                            timeout=60, check=False)
        assert up.returncode == 0, up.stderr
        assert "complete" in up.stdout
        again = subprocess.run(cmd, cwd=ROOT, env=_env(DIRECTGEO_TOKEN=drone), capture_output=True, text=True,
                               timeout=60, check=False)
        assert again.returncode == 0 and " 0 bytes sent" in again.stdout
        bad = subprocess.run(cmd, cwd=ROOT, env=_env(DIRECTGEO_TOKEN="wrong-token-0123456789"),
                             capture_output=True, text=True, timeout=60, check=False)
        assert bad.returncode == 1 and "401" in bad.stderr
        assert httpx.get(f"{url}/flights", headers={"Authorization": f"Bearer {drone}"}).status_code == 403
        token("revoke", "drone-1")
        revoked = subprocess.run(cmd, cwd=ROOT, env=_env(DIRECTGEO_TOKEN=drone), capture_output=True, text=True,
                                 timeout=60, check=False)
        assert revoked.returncode == 1 and "401" in revoked.stderr
        flights = httpx.get(f"{url}/flights", headers={"Authorization": f"Bearer {engineer}"}).json()
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


@pytest.mark.slow
def test_serve_refuses_an_unusable_database_url(tmp_path: Path) -> None:
    """A DATABASE_URL whose driver is missing or whose file cannot be created: exit 2 with the reason."""
    for url in ("postgresql+nosuchdriver://u@db/flights", f"sqlite:///{tmp_path}/missing/dir/x.sqlite3"):
        out = subprocess.run([sys.executable, "-m", "ground", "serve", "--data-dir", str(tmp_path / "d")],
                             cwd=ROOT, env=_env(DIRECTGEO_TOKEN=TOKEN, DATABASE_URL=url), capture_output=True,
                             text=True, timeout=60, check=False)
        assert out.returncode == 2 and "cannot open the flight store" in out.stderr, out.stderr


EMPTY_SHA256 = "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855"


def test_uploader_sends_zero_size_files_with_their_true_sha(live: LiveServer, tmp_path: Path) -> None:
    """An empty segment (a rotation right before the stop) and an empty events.jsonl go in the manifest with the
    SHA-256 of no bytes (the server refuses any other), and the flight completes, resumably: a second run sends
    nothing."""
    from onboard.upload.client import Uploader, build_upload_manifest

    flight = tmp_path / "flight-20240501T120000Z"
    flight.mkdir()
    seg = os.urandom(20_000)
    (flight / "000000.ubx").write_bytes(seg)
    (flight / "000001.ubx").write_bytes(b"")
    (flight / "events.jsonl").write_bytes(b"")
    m = Manifest(flight.name, 1, [SegmentInfo("000000.ubx", len(seg), hashlib.sha256(seg).hexdigest()),
                                  SegmentInfo("000001.ubx", 0, EMPTY_SHA256)])
    (flight / "manifest.json").write_text(json.dumps(m.to_json()))
    _, entries = build_upload_manifest(flight)
    by_name = {e.name: e for e in entries}
    assert by_name["000001.ubx"].sha256 == by_name["events.jsonl"].sha256 == EMPTY_SHA256
    assert by_name["000001.ubx"].size == 0
    up = Uploader(live.url, TOKEN_LIVE)
    try:
        report = up.upload_flight(flight)
        assert set(report.files) == set(by_name) and set(report.files.values()) == {"complete"}
        assert up.upload_flight(flight).bytes_sent == 0
    finally:
        up.close()
    with live.client() as c:
        held = {f["name"]: f for f in c.get(f"/flights/{report.flight_id}").json()["files"]}
    assert held["000001.ubx"]["sha256"] == held["events.jsonl"]["sha256"] == EMPTY_SHA256
    assert all(f["status"] == "complete" for f in held.values())


def test_uploader_refuses_a_segment_whose_manifest_sha_is_wrong(tmp_path: Path) -> None:
    """The recorder's manifest says the empty segment had other bytes: the local copy is damaged, not sent."""
    from onboard.upload.client import UploadError, build_upload_manifest

    flight = tmp_path / "flight-20240501T120000Z"
    flight.mkdir()
    (flight / "000000.ubx").write_bytes(b"")
    m = Manifest(flight.name, 1, [SegmentInfo("000000.ubx", 0, hashlib.sha256(b"x").hexdigest())])
    (flight / "manifest.json").write_text(json.dumps(m.to_json()))
    with pytest.raises(UploadError, match="local copy damaged"):
        build_upload_manifest(flight)


def _upload_main(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    from onboard.upload.client import main

    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's usage error
        code = int(exc.code or 0)
    return code, capsys.readouterr().err


@pytest.mark.parametrize(("args", "message"), [
    (["--chunk-mib", "nan"], "directgeo: upload: error: --chunk-mib nan: must be a finite number"),
    (["--chunk-mib", "inf"], "directgeo: upload: error: --chunk-mib inf: must be a finite number"),
    (["--chunk-mib", "-4"], "directgeo: upload: error: --chunk-mib -4: must be 0.01–1024 MiB"),
    (["--chunk-mib", "0"], "directgeo: upload: error: --chunk-mib 0: must be 0.01–1024 MiB"),
    (["--url", "ground:8600"], "directgeo: upload: error: --url ground:8600: must be an http:// or https:// URL"),
    (["--role", "poses.csv"], "directgeo: upload: error: --role poses.csv: must be NAME=ROLE"),
    (["--token-file", "/nonexistent/token"], ("directgeo: upload: error: --token-file /nonexistent/token: cannot "
                                             "read it: No such file or directory")),
])
def test_uploader_options_are_checked(tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str],
                                      message: str) -> None:
    """Before: `--chunk-mib nan` traced back (int(nan)), `--role x` too (dict of a 1-tuple)."""
    code, err = _upload_main(["--url", "http://127.0.0.1:9", *args, str(tmp_path)], capsys)
    assert code == 2 and message in err and "Traceback" not in err, err


def test_uploader_token_file_not_utf8(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "token").write_bytes(b"\xff\xfe token")
    code, err = _upload_main(["--url", "http://127.0.0.1:9", "--token-file", str(tmp_path / "token"),
                              str(tmp_path)], capsys)
    assert code == 2 and f"--token-file {tmp_path / 'token'}: cannot read it" in err, err


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(chunk=st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr), st.integers().map(str),
                       st.text(max_size=12)))
def test_uploader_chunk_mib_fuzz(tmp_path: Path, capsys: pytest.CaptureFixture[str], chunk: str) -> None:
    """50 drawn `--chunk-mib` values (non-finite, huge, negative, text, unicode): exit 2 naming the option, or —
    a valid size — the flight folder is looked at (exit 1 here: it is not a flight folder); never a traceback."""
    missing = tmp_path / "no-flight"
    (tmp_path / "token").write_text(TOKEN + "\n")
    code, err = _upload_main(["--url", "http://127.0.0.1:9", "--token-file", str(tmp_path / "token"),
                              f"--chunk-mib={chunk}", str(missing)], capsys)
    assert "Traceback" not in err
    try:
        valid = 0.01 <= float(chunk) <= 1024
    except ValueError:
        valid = False
    if valid:
        assert code == 1 and f"directgeo: upload: error: {missing}: {missing} is not a flight folder" in err, err
    else:
        assert code == 2 and "directgeo: upload: error: --chunk-mib" in err, err
