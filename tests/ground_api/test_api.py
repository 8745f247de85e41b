"""The ground API against a live uvicorn server and a real SQLite file: auth, names, limits, corruption, resume,
jobs. Each test says what the server must do with the bad input and that nothing is lost or written."""

from __future__ import annotations

import hashlib
import json
import os
import sqlite3
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from ground.api.settings import ApiSettings
from onboard.logger.journal import Manifest, SegmentInfo
from onboard.upload.client import Uploader, UploaderOptions, UploadError, build_upload_manifest
from tests.ground_api.conftest import TOKEN, LiveServer, start_server

pytestmark = pytest.mark.timeout(120)


def _sha(b: bytes) -> str:
    return hashlib.sha256(b).hexdigest()


def _create(c: httpx.Client, files: dict[str, bytes], name: str = "flight-20240501T101500Z",
            roles: dict[str, str] | None = None) -> dict[str, Any]:
    body = {"name": name, "files": [{"name": n, "size": len(b), "sha256": _sha(b), "role": (roles or {}).get(n)}
                                    for n, b in files.items()]}
    r = c.post("/flights", json=body)
    assert r.status_code == 201, r.text
    return r.json()


def _put(c: httpx.Client, fid: str, name: str, offset: int, chunk: bytes, sha: str | None = None) -> httpx.Response:
    return c.put(f"/flights/{fid}/files/{name}", params={"offset": offset}, content=chunk,
                 headers={"X-Chunk-SHA256": sha or _sha(chunk)})


def test_unauthenticated_requests_are_refused(live: LiveServer) -> None:
    """No token or a wrong token: 401 on every flight route, nothing created; health and OpenAPI stay public."""
    with live.client(token=None) as anon, live.client(token="wrong-token-0123456789") as wrong, live.client() as ok:
        fid = _create(ok, {"a.ubx": b"x" * 10})["id"]
        for c in (anon, wrong):
            assert c.get("/flights").status_code == 401
            assert c.post("/flights", json={"name": "f2", "files": []}).status_code == 401
            assert c.get(f"/flights/{fid}").status_code == 401
            assert c.head(f"/flights/{fid}/files/a.ubx").status_code == 401
            assert _put(c, fid, "a.ubx", 0, b"x" * 10).status_code == 401
            assert c.get(f"/flights/{fid}/report").status_code == 401
            assert c.post(f"/flights/{fid}/jobs", json={"kind": "adjust"}).status_code == 401
        assert ok.head(f"/flights/{fid}/files/a.ubx").headers["Upload-Offset"] == "0"  # the 401 PUTs wrote nothing
        assert len(ok.get("/flights").json()) == 1
        assert anon.get("/health").json() == {"status": "ok"}
        spec = anon.get("/openapi.json").json()
        assert "/flights/{flight_id}/files/{name}" in spec["paths"]
        assert "put" in spec["paths"]["/flights/{flight_id}/files/{name}"]


@pytest.mark.parametrize("bad", ["../evil.ubx", "..", ".", ".hidden", "a/../../b.ubx", "a//b.ubx", "a/.partial/b",
                                 "a\\b.ubx", "nul\x00.ubx", "/etc/passwd", "C:evil", ""])
def test_manifest_with_bad_names_is_refused(live: LiveServer, bad: str) -> None:
    """A manifest naming a file outside the flight directory (or hidden/odd) is refused with 400; no flight made."""
    with live.client() as c:
        r = c.post("/flights", json={"name": "f", "files": [{"name": bad, "size": 1, "sha256": "0" * 64}]})
        assert r.status_code in (400, 422), r.text
        assert c.get("/flights").json() == []


def test_path_traversing_upload_names_are_refused(live: LiveServer, tmp_path: Path) -> None:
    """Percent-encoded ../ and names not in the manifest: 400/404, and no file appears outside the flight dir."""
    with live.client() as c:
        fid = _create(c, {"a.ubx": b"abc"})["id"]
        for raw in ("..%2F..%2F..%2Fevil", "..%2Fevil", "%2E%2E", "a.ubx%00", "sub%2Fa.ubx", "..%5Cevil"):
            r = c.put(f"/flights/{fid}/files/{raw}", params={"offset": 0}, content=b"abc",
                      headers={"X-Chunk-SHA256": _sha(b"abc")})
            assert r.status_code in (400, 404), (raw, r.status_code, r.text)
        assert _put(c, fid, "b.ubx", 0, b"abc").status_code == 404  # not in the manifest
    data = live.settings.data_dir
    written = sorted(p.relative_to(data).as_posix() for p in data.rglob("*") if p.is_file())
    assert all(p == "directgeo.sqlite3" or p.startswith(f"flights/{fid}/") for p in written), written
    assert not (data / "evil").exists() and not (data.parent / "evil").exists()


@pytest.mark.slow
def test_sub_folder_files_upload_byte_identical_and_stay_inside(live: LiveServer, tmp_path: Path) -> None:
    """A flight with the radio/ corrections journal: every file, sub-folder included, reaches the server
    byte-identical (SHA-256 confirmed), with roles by place; `radio/../` or `radio/.partial/` names write nothing."""
    folder = _flight_folder(tmp_path / "onboard")
    radio = folder / "radio"
    radio.mkdir()
    corrections = os.urandom(70_000)
    (radio / "000000.ubx").write_bytes(corrections)
    m = Manifest(flight="radio", created_wall_ns=1, segments=[SegmentInfo("000000.ubx", 70_000, _sha(corrections))],
                 closed=True)
    (radio / "manifest.json").write_text(json.dumps(m.to_json()))
    (radio / "000000.ubx.tmp").write_bytes(b"temporary")  # never uploaded
    name, entries = build_upload_manifest(folder)
    roles = {e.name: e.role for e in entries}
    assert name == folder.name and "radio/000000.ubx.tmp" not in roles
    assert roles["radio/000000.ubx"] == "base_obs" and roles["000000.ubx"] == "rover_obs"
    assert roles["radio/manifest.json"] == "manifest" and roles["000000.idx"] == "index"
    rep = Uploader(live.url, TOKEN, UploaderOptions(chunk_bytes=30_000), sleep=lambda s: None).upload_flight(folder)
    assert set(rep.sha256) == set(roles)
    held = live.settings.flights_dir / rep.flight_id
    for rel, digest in rep.sha256.items():
        assert _sha((held / rel).read_bytes()) == digest == _sha((folder / rel).read_bytes()), rel
    with live.client() as c:
        assert c.get(f"/flights/{rep.flight_id}/files/radio/000000.ubx/content").content == corrections
        assert c.get(f"/flights/{rep.flight_id}/files/radio%2F000000.ubx").json()["status"] == "complete"
        for raw in ("radio/..%2F..%2Fevil", "radio/%2E%2E/evil", "radio/.partial/000000.ubx", "radio//000000.ubx"):
            r = c.put(f"/flights/{rep.flight_id}/files/{raw}", params={"offset": 0}, content=b"abc",
                      headers={"X-Chunk-SHA256": _sha(b"abc")})
            assert r.status_code in (400, 404), (raw, r.status_code, r.text)
        r = c.post("/flights", json={"name": "clash", "files": [{"name": n, "size": 1, "sha256": "0" * 64}
                                                                 for n in ("radio", "radio/000000.ubx")]})
        assert r.status_code == 400 and "also the folder" in r.text
    data = live.settings.data_dir
    assert not (data / "evil").exists() and not (data.parent / "evil").exists()
    assert not (held / "radio" / ".partial" / "000000.ubx").exists()
    (radio / "000000.ubx").write_bytes(corrections[:-1] + bytes([corrections[-1] ^ 1]))  # the sub-journal's manifest
    with pytest.raises(UploadError, match="damaged"):                                  # is checked too
        build_upload_manifest(folder)


def test_oversized_files_and_chunks_are_refused(live: LiveServer) -> None:
    """File over the limit at manifest time, chunk over the chunk limit, chunk past the promised size: 413."""
    s = live.settings
    with live.client() as c:
        r = c.post("/flights", json={"name": "big", "files": [{"name": "a.ubx", "size": s.max_file_bytes + 1,
                                                                "sha256": "0" * 64}]})
        assert r.status_code == 413
        data = os.urandom(s.max_chunk_bytes + 10)
        fid = _create(c, {"a.ubx": data})["id"]
        assert _put(c, fid, "a.ubx", 0, data).status_code == 413
        small = _create(c, {"s.ubx": b"12345"}, name="small")["id"]
        assert _put(c, small, "s.ubx", 0, b"123456").status_code == 413
        assert c.get(f"/flights/{small}/files/s.ubx").json()["received"] == 0


def test_corrupted_chunk_rejected_and_bad_offset_conflicts(live: LiveServer) -> None:
    """A chunk whose bytes do not match its SHA-256 is rejected (422) and not stored; a wrong offset gets 409."""
    data = os.urandom(100_000)
    with live.client() as c:
        fid = _create(c, {"a.ubx": data})["id"]
        assert _put(c, fid, "a.ubx", 0, data[:40_000]).status_code == 200
        damaged = bytearray(data[40_000:80_000])
        damaged[123] ^= 0x40
        r = _put(c, fid, "a.ubx", 40_000, bytes(damaged), sha=_sha(data[40_000:80_000]))
        assert r.status_code == 422 and "corrupted" in r.text
        assert c.head(f"/flights/{fid}/files/a.ubx").headers["Upload-Offset"] == "40000"
        r = _put(c, fid, "a.ubx", 30_000, data[30_000:70_000])
        assert r.status_code == 409
        assert _put(c, fid, "a.ubx", 40_000, data[40_000:40_010], sha="not-hex").status_code == 400
        assert _put(c, fid, "a.ubx", 40_000, data[40_000:]).json()["status"] == "complete"
        got = c.get(f"/flights/{fid}/files/a.ubx/content")
        assert got.content == data


def test_whole_file_hash_mismatch_restarts_the_file(live: LiveServer) -> None:
    """Chunks all well-formed but the file is not the one promised: 422 at the end, data discarded, offset 0."""
    promised, sent = b"A" * 1000, b"B" * 1000
    with live.client() as c:
        fid = _create(c, {"a.ubx": promised})["id"]
        r = _put(c, fid, "a.ubx", 0, sent)
        assert r.status_code == 422 and "differs from the manifest" in r.text
        st = c.get(f"/flights/{fid}/files/a.ubx").json()
        assert st["received"] == 0 and st["status"] == "pending"
        assert _put(c, fid, "a.ubx", 0, promised).json()["status"] == "complete"
        assert c.get(f"/flights/{fid}").json()["status"] == "complete"


def _flight_folder(root: Path, sizes: tuple[int, ...] = (300_000, 200_000)) -> Path:
    """A recorder-style flight folder: segments + index files + events.jsonl + manifest.json (journal format)."""
    d = root / "flight-20240501T101500Z"
    d.mkdir(parents=True)
    rng = np.random.default_rng(3)
    segs = []
    for i, n in enumerate(sizes):
        b = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        (d / f"{i:06d}.ubx").write_bytes(b)
        (d / f"{i:06d}.idx").write_bytes(b"\x00" * 64)
        segs.append(SegmentInfo(name=f"{i:06d}.ubx", bytes=n, sha256=_sha(b)))
    (d / "events.jsonl").write_text('{"type":"mark","week":2300,"tow_ns":1}\n')
    m = Manifest(flight=d.name, created_wall_ns=1, segments=segs, closed=True)
    (d / "manifest.json").write_text(json.dumps(m.to_json()))
    return d


class _Unplug(httpx.HTTPTransport):
    """Network edge fault: after `n` chunk PUTs every request fails as if the link were gone."""

    def __init__(self, n: int) -> None:
        super().__init__()
        self.n, self.puts = n, 0

    def handle_request(self, request: httpx.Request) -> httpx.Response:
        if request.method == "PUT":
            self.puts += 1
        if self.puts > self.n:
            raise httpx.ConnectError("link down (test)", request=request)
        return super().handle_request(request)


RESUME_OPTIONS = UploaderOptions(chunk_bytes=50_000, max_retries=2, backoff_initial_s=0.0)


def interrupt_upload(settings: ApiSettings, folder: Path) -> None:
    """Upload `folder` to a fresh server whose link dies after 3 requests, then stop that server."""
    srv = start_server(settings)
    try:
        client = httpx.Client(base_url=srv.url, transport=_Unplug(3), timeout=30)
        up = Uploader(srv.url, TOKEN, RESUME_OPTIONS, client=client, sleep=lambda s: None)
        with pytest.raises(UploadError, match="failed after 3 attempts"):
            up.upload_flight(folder)
        up.close()
    finally:
        srv.stop()


def resume_upload(srv: Any, settings: ApiSettings, folder: Path) -> Any:
    """Resume the interrupted upload on a restarted server; checks it sent only the rest, byte-identical."""
    with srv.client() as c:
        flights = c.get("/flights").json()
        # files go in name order: 000000.idx (64 B, one PUT), then two 50 kB chunks of 000000.ubx
        assert len(flights) == 1 and flights[0]["bytes_received"] == 64 + 100_000
    up = Uploader(srv.url, TOKEN, RESUME_OPTIONS, sleep=lambda s: None)
    rep = up.upload_flight(folder)
    up.close()
    total = sum(p.stat().st_size for p in folder.iterdir())
    assert rep.bytes_sent == total - 100_064
    for p in folder.iterdir():
        assert (settings.flights_dir / rep.flight_id / p.name).read_bytes() == p.read_bytes(), p.name
    return rep


@pytest.mark.slow
def test_interrupted_upload_resumes_to_byte_identical_files(api_settings: ApiSettings, tmp_path: Path) -> None:
    """Link lost after 3 chunks, server restarted on the same SQLite file: the next run sends only the rest."""
    folder = _flight_folder(tmp_path / "onboard")
    interrupt_upload(api_settings, folder)
    srv = start_server(api_settings)  # a new process would see the same: state is in SQLite and on disk
    try:
        rep = resume_upload(srv, api_settings, folder)
        assert not list((api_settings.flights_dir / rep.flight_id / ".partial").iterdir())
        # a third run finds everything complete and sends nothing
        again = Uploader(srv.url, TOKEN, RESUME_OPTIONS, sleep=lambda s: None).upload_flight(folder)
        assert again.bytes_sent == 0 and again.flight_id == rep.flight_id
    finally:
        srv.stop()
    db = sqlite3.connect(api_settings.data_dir / "directgeo.sqlite3")
    try:
        rows = db.execute("select name, received, size, status from flight_files").fetchall()
        assert all(r[1] == r[2] and r[3] == "complete" for r in rows) and len(rows) == 6
        sessions = db.execute("select count(*), sum(bytes_received) from upload_sessions").fetchone()
        assert sessions[0] >= 2 and sessions[1] == sum(p.stat().st_size for p in folder.iterdir())
    finally:
        db.close()


def test_uploader_refuses_a_damaged_local_segment(tmp_path: Path) -> None:
    """A segment whose bytes no longer match the recorder's manifest is never uploaded as good."""
    folder = _flight_folder(tmp_path)
    seg = folder / "000001.ubx"
    b = bytearray(seg.read_bytes())
    b[10] ^= 1
    seg.write_bytes(bytes(b))
    with pytest.raises(UploadError, match="damaged"):
        build_upload_manifest(folder)
    seg.unlink()
    with pytest.raises(UploadError, match="missing"):
        build_upload_manifest(folder)


def _wait_job(c: httpx.Client, fid: str, timeout_s: float = 90.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        jobs = c.get(f"/flights/{fid}").json()["jobs"]
        if jobs and jobs[-1]["status"] in ("done", "failed"):
            return jobs[-1]
        time.sleep(0.2)
    raise AssertionError("job did not finish")


@pytest.mark.slow
def test_uploaded_orientations_trigger_the_adjustment(live: LiveServer, tmp_path: Path) -> None:
    """Trajectory + events + orientations (+ GCP) uploaded with roles: the adjustment job runs by itself and its
    results and report are served; the recovered lever arm and delay match the synthetic truth."""
    pytest.importorskip("ground.adjust.solve")
    from tests.ground_io.flightgen import write_synthetic_flight

    folder = tmp_path / "flight-synthetic"
    truth = write_synthetic_flight(folder)
    roles = {"SOL.pos": "trajectory", "events.csv": "events", "poses.csv": "orientations", "gcp.csv": "gcp"}
    up = Uploader(live.url, TOKEN, UploaderOptions(chunk_bytes=60_000), sleep=lambda s: None)
    rep = up.upload_flight(folder, roles)
    up.close()
    with live.client() as c:
        job = _wait_job(c, rep.flight_id)
        assert job["status"] == "done", job["message"]
        assert job["kind"] == "adjust"
        res = c.get(f"/flights/{rep.flight_id}/results").json()
        np.testing.assert_allclose(res["lever_arm_m"], truth.lever_arm_m, atol=0.01)
        assert res["delay_s"] == pytest.approx(truth.delay_s, abs=0.005)
        html = c.get(f"/flights/{rep.flight_id}/report")
        assert html.headers["content-type"].startswith("text/html")
        assert 'id="parameters"' in html.text and "data:image/png;base64," in html.text
        exports = c.get(f"/flights/{rep.flight_id}/exports").json()
        assert {"geo.txt", "pix4d.csv", "metashape.txt", "opk.csv"} <= set(exports)
        geo = c.get(f"/flights/{rep.flight_id}/exports/geo.txt").text.splitlines()
        assert geo[0] == "EPSG:4979" and len(geo) == truth.n_images + 1
        assert c.get(f"/flights/{rep.flight_id}/exports/..%2Fresults.json").status_code in (400, 404)
        # an explicit job with a bad parameter is refused at submission (422) with a message
        r = c.post(f"/flights/{rep.flight_id}/jobs", json={"kind": "adjust", "params": {"estimate": ["scale"]}})
        assert r.status_code == 422 and "estimate" in r.json()["detail"]
        # no base data uploaded: the RTK job is refused saying so
        r = c.post(f"/flights/{rep.flight_id}/jobs", json={"kind": "rtk"})
        assert r.status_code == 422 and "base_obs" in r.json()["detail"]


@pytest.mark.slow
def test_base_data_triggers_rtk_reprocessing(live: LiveServer, tmp_path: Path) -> None:
    """Real rover + base RINEX (Yamatogawa, u-blox L1 rover, 26 m base) uploaded with roles: the RTK job runs by
    itself and writes a .pos trajectory of every rover epoch; a corrupt rover file fails the job with a message."""
    from tests.conftest import shared_file

    src = {"rover.obs.gz": "rover_obs", "master.obs.gz": "base_obs", "brdc0060.10n.gz": "nav"}
    folder = tmp_path / "flight-yamatogawa"
    folder.mkdir()
    for name, orig in zip(src, ("yamatogawa_rover.obs.gz", "yamatogawa_master.obs.gz", "brdc0060.10n.gz")):
        (folder / name).write_bytes(shared_file(f"gnss/ublox-yamatogawa-20100106/{orig}").read_bytes())
    rep = Uploader(live.url, TOKEN, UploaderOptions(chunk_bytes=60_000), sleep=lambda s: None).upload_flight(
        folder, src)
    with live.client() as c:
        job = _wait_job(c, rep.flight_id)
        assert job["kind"] == "rtk" and job["status"] == "done", job["message"]
        assert "203 epochs" in job["message"]
    sol = live.settings.data_dir / "outputs" / rep.flight_id / job["id"] / "SOL.pos"
    from ground.io.trajectory import read_trajectory

    traj = read_trajectory(str(sol), accept_single=True)
    assert len(traj.t_ns) == 203 and traj.vel_ecef_m_s is not None
    assert len(read_trajectory(str(sol)).t_ns) == 193  # the 10 single-point rows are read only when asked
    (folder / "rover.obs.gz").write_bytes(b"\x1f\x8b garbage")
    folder.rename(tmp_path / "flight-broken")
    rep2 = Uploader(live.url, TOKEN, UploaderOptions(chunk_bytes=60_000), sleep=lambda s: None).upload_flight(
        tmp_path / "flight-broken", src)
    with live.client() as c:
        bad = _wait_job(c, rep2.flight_id)
        assert bad["kind"] == "rtk" and bad["status"] == "failed" and bad["message"]


@pytest.mark.slow
def test_unfinished_jobs_survive_a_restart_and_flight_names_are_unique(api_settings: ApiSettings,
                                                                       tmp_path: Path) -> None:
    """A job left queued when the server stopped runs at the next start; a second manifest under an existing
    flight name with other files is refused (409) rather than mixed in."""
    from ground.store import Job, Store
    from tests.ground_io.flightgen import write_synthetic_flight

    folder = tmp_path / "flight-restart"
    write_synthetic_flight(folder, n_lines=2)
    srv = start_server(api_settings)
    try:
        rep = Uploader(srv.url, TOKEN, UploaderOptions(chunk_bytes=60_000), sleep=lambda s: None).upload_flight(folder)
        with srv.client() as c:
            assert c.get(f"/flights/{rep.flight_id}").json()["jobs"] == []  # no roles: nothing automatic
            other = {"name": folder.name, "files": [{"name": "x.ubx", "size": 1, "sha256": "0" * 64}]}
            assert c.post("/flights", json=other).status_code == 409
    finally:
        srv.stop()
    store = Store(api_settings.db_url)
    with store.session() as s:
        s.add(Job(flight_id=rep.flight_id, kind="adjust", status="queued", message="", params={
            "trajectory": "SOL.pos", "events": "events.csv", "orientations": "poses.csv", "gcp": "gcp.csv"}))
        s.commit()
    store.close()
    srv = start_server(api_settings)
    try:
        with srv.client() as c:
            job = _wait_job(c, rep.flight_id)
            assert job["status"] == "done", job["message"]
            assert c.get(f"/flights/{rep.flight_id}/results").json()["n_images"] > 30
    finally:
        srv.stop()


@pytest.mark.slow
def test_uploader_adapts_to_the_server_chunk_limit(live: LiveServer, tmp_path: Path) -> None:
    """Uploader configured for 1 MiB chunks, server limit 64 KiB: chunks are halved until accepted."""
    folder = _flight_folder(tmp_path, sizes=(400_000,))
    up = Uploader(live.url, TOKEN, UploaderOptions(chunk_bytes=1 << 20), sleep=lambda s: None)
    rep = up.upload_flight(folder)
    assert up.chunk_bytes <= live.settings.max_chunk_bytes
    fdir = live.settings.flights_dir / rep.flight_id
    assert (fdir / "000000.ubx").read_bytes() == (folder / "000000.ubx").read_bytes()


def _drone_flight(root: Path) -> Path:
    """A flight folder as the companion closes it, from a real M8P capture (Galway, static, 0.33 m baseline):
    the rover's UBX journal (first ~5 min of the log, two segments, a torn tail) at the top, the base's RTCM3
    stream as received in the radio/ sub-journal (1005 position, MSM7; no navigation: the rover's own
    ephemerides), events.jsonl and a real-time solution.pos."""
    import gzip

    from onboard.hw.ports import SystemClock
    from onboard.logger.journal import Journal, JournalOptions
    from tests.conftest import shared_file

    d = "gnss/ublox-m8p-galway-2018/"
    rover = gzip.decompress(shared_file(d + "raw/rover-20181004-1237.ubx.gz").read_bytes())
    rover = rover[:len(rover) // 4]
    rtcm = gzip.decompress(shared_file(d + "rtcm3/base-20181004-1236.rtcm3.gz").read_bytes())
    flight = root / "flight-20181004T123800Z"
    for folder, data, block in ((flight, rover, 4096), (flight / "radio", rtcm, 1024)):
        journal = Journal(folder, SystemClock(), JournalOptions(segment_max_bytes=len(data) // 2 + 1))
        for i in range(0, len(data), block):
            journal.append(data[i:i + block], time.monotonic_ns(), time.time_ns())
        journal.close("landed")
    (flight / "events.jsonl").write_text('{"type": "flight", "event": "closed"}\n')
    (flight / "solution.pos").write_text("% real-time solution (not read by this test)\n")
    return flight


@pytest.mark.slow
def test_a_drone_flight_is_rtk_processed_as_uploaded(live: LiveServer, tmp_path: Path) -> None:
    """The companion's flight uploaded as it is: roles by place (rover journal, radio/ corrections), the RTK job
    queues by itself and reads the journal folders (299 rover epochs, mostly fixed on this 0.33 m baseline); a
    second job with static_start says so in SOL.pos; a job naming no journal folder is refused (422)."""
    from ground.io.trajectory import read_trajectory

    flight = _drone_flight(tmp_path)
    rep = Uploader(live.url, TOKEN, UploaderOptions(chunk_bytes=200_000), sleep=lambda s: None).upload_flight(flight)
    with live.client() as c:
        files = {f["name"]: f["role"] for f in c.get(f"/flights/{rep.flight_id}").json()["files"]}
        assert files["000000.ubx"] == files["000001.ubx"] == "rover_obs"
        assert files["radio/000000.ubx"] == files["radio/000001.ubx"] == "base_obs"
        assert files["solution.pos"] == "realtime_trajectory" and files["events.jsonl"] == "events"
        auto = _wait_job(c, rep.flight_id)
        assert auto["kind"] == "rtk" and auto["status"] == "done", auto["message"]
        assert auto["message"].startswith("299 epochs: fix ")
        fixed = float(auto["message"].split("(")[1].split(" %")[0])
        assert fixed > 50.0, auto["message"]
        r = c.post(f"/flights/{rep.flight_id}/jobs", json={"kind": "rtk", "params": {"base_obs": "nowhere"}})
        assert r.status_code == 422 and "nowhere" in r.text
        job = c.post(f"/flights/{rep.flight_id}/jobs", json={"kind": "rtk", "params": {
            "rover_obs": ".", "base_obs": "radio", "static_start": True}}).json()
        deadline = time.monotonic() + 90
        while job["status"] not in ("done", "failed") and time.monotonic() < deadline:
            time.sleep(0.3)
            job = c.get(f"/flights/{rep.flight_id}/jobs/{job['id']}").json()
        assert job["status"] == "done", job["message"]
    sol = live.settings.data_dir / "outputs" / rep.flight_id / job["id"] / "SOL.pos"
    text = sol.read_text()
    assert "pos mode  : kinematic (static start)" in text and "inp file  : radio" in text
    traj = read_trajectory(str(sol), accept_single=True)
    # the base position came from the stream's RTCM 1005 (the README's survey-in ECEF), the rover is 0.33 m away
    assert np.linalg.norm(np.median(traj.pos_ecef_m, axis=0) - [3774088.9931, -601661.8217, 5089321.3853]) < 0.05


@pytest.mark.slow
def test_office_files_added_to_a_drone_flight(live: LiveServer, tmp_path: Path) -> None:
    """Uploader.add_files: the office's files join the drone's flight (POST /flights/{id}/files, then the same
    resumable PUT), byte-identical with their roles; a file named like the flight's radio/ folder is refused."""
    folder = _flight_folder(tmp_path / "onboard")
    (folder / "radio").mkdir()
    (folder / "radio" / "000000.ubx").write_bytes(os.urandom(5_000))
    up = Uploader(live.url, TOKEN, UploaderOptions(chunk_bytes=40_000), sleep=lambda s: None)
    rep = up.upload_flight(folder)
    office = tmp_path / "office"
    office.mkdir()
    images, gcp = office / "images.txt", office / "gcp.csv"
    images.write_bytes(os.urandom(90_000))
    gcp.write_text("name,role,x_rel,y_rel,z_rel,X,Y,Z\n")
    added = up.add_files(rep.flight_id, {"images.txt": images, "office/gcp.csv": gcp},
                         {"images.txt": "orientations", "office/gcp.csv": "gcp"})
    assert added.flight_id == rep.flight_id and added.bytes_sent == 90_000 + gcp.stat().st_size
    held = live.settings.flights_dir / rep.flight_id
    assert (held / "images.txt").read_bytes() == images.read_bytes()
    assert (held / "office" / "gcp.csv").read_bytes() == gcp.read_bytes()
    with live.client() as c:
        flight = c.get(f"/flights/{rep.flight_id}").json()
        roles = {f["name"]: f["role"] for f in flight["files"]}
        assert roles["images.txt"] == "orientations" and roles["office/gcp.csv"] == "gcp"
        assert roles["radio/000000.ubx"] == "base_obs" and flight["status"] == "complete"
    clash = tmp_path / "radio"
    clash.write_bytes(b"x")
    with pytest.raises(UploadError, match="HTTP 400.*also the folder"):
        up.add_files(rep.flight_id, {"radio": clash})
    up.close()
