"""Jobs on the PostgreSQL task queue run by real `ground worker` processes (a throw-away PostgreSQL cluster, a
live API, worker subprocesses): submitted through the API, run by a worker that fetches the files through the
API, outputs downloadable; a worker SIGKILLed mid-job has its job completed by another with byte-identical
outputs; a job over its time limit fails with a message. The in-process default is covered by test_api."""

from __future__ import annotations

import hashlib
import io
import subprocess
import tarfile
import time
from pathlib import Path

import httpx
import numpy as np
import pytest

from ground.api.job_outputs import install_outputs, list_outputs, pack_outputs
from ground.api.settings import ApiSettings
from onboard.errors import InputError
from onboard.upload.client import Uploader, UploaderOptions
from tests.ground_api.conftest import TOKEN, LiveServer, start_server
from tests.ground_api.fleet import (
    kill_worker,
    make_token,
    start_worker,
    stop_worker,
    wait_job,
    write_token_file,
)
from tests.postgres_cluster import PostgresCluster

psycopg = pytest.importorskip("psycopg", reason="psycopg (PostgreSQL driver) not installed: worker tests skipped")
pytestmark = pytest.mark.timeout(300)

ROLES = {"SOL.pos": "trajectory", "events.csv": "events", "poses.csv": "orientations", "gcp.csv": "gcp"}


def _server(cluster: PostgresCluster, tmp_path: Path, **kw: float) -> LiveServer:
    settings = ApiSettings(data_dir=tmp_path / "data", token=TOKEN, database_url=cluster.url, job_queue="postgres",
                           **kw)  # type: ignore[arg-type]
    return start_server(settings)


def _upload_synthetic(srv: LiveServer, tmp_path: Path, name: str = "flight-synthetic") -> tuple[str, object]:
    from tests.ground_io.flightgen import write_synthetic_flight

    truth = write_synthetic_flight(tmp_path / name)
    up = Uploader(srv.url, TOKEN, UploaderOptions(chunk_bytes=60_000), sleep=lambda s: None)
    rep = up.upload_flight(tmp_path / name, ROLES)
    up.close()
    return rep.flight_id, truth


def _only_job(c: httpx.Client, fid: str) -> str:
    jobs = c.get(f"/flights/{fid}").json()["jobs"]
    assert len(jobs) == 1, jobs
    return str(jobs[0]["id"])


def _worker_args(srv: LiveServer, cluster: PostgresCluster, token_file: Path, cache: Path, name: str) -> list[str]:
    return ["--api", srv.url, "--token-file", str(token_file), "--database-url", cluster.dsn,
            "--cache-dir", str(cache), "--name", name]


def _test_worker_args(srv: LiveServer, cluster: PostgresCluster, token_file: Path, cache: Path,
                      name: str) -> list[str]:
    return ["--api", srv.url, "--token-file", str(token_file), "--dsn", cluster.dsn, "--cache-dir", str(cache),
            "--name", name]


def _outputs(c: httpx.Client, fid: str, jid: str) -> dict[str, str]:
    r = c.get(f"/flights/{fid}/jobs/{jid}/outputs")
    assert r.status_code == 200, r.text
    return {o["name"]: o["sha256"] for o in r.json()}


def test_outputs_archive_round_trip_and_refusals(tmp_path: Path) -> None:
    """pack → install gives the same files (and the same archive twice); an archive with a name escaping the
    folder or a link is refused and leaves the previous outputs in place."""
    src = tmp_path / "src"
    (src / "exports").mkdir(parents=True)
    (src / "results.json").write_text('{"a": 1}\n')
    (src / "exports" / "geo.txt").write_text("EPSG:4979\n")
    archive = pack_outputs(src)
    assert pack_outputs(src) == archive  # deterministic
    tar = tmp_path / "a.tar"
    tar.write_bytes(archive)
    dest = tmp_path / "outputs" / "f" / "j"
    assert [o.name for o in install_outputs(tar, dest)] == ["exports/geo.txt", "results.json"]
    assert list_outputs(dest) == list_outputs(src)
    install_outputs(tar, dest)  # again: same bytes, nothing left beside
    assert sorted(p.name for p in dest.parent.iterdir()) == ["j"]
    for bad in ("../evil.txt", "/etc/evil.txt"):
        buf = io.BytesIO()
        with tarfile.open(fileobj=buf, mode="w") as t:
            info = tarfile.TarInfo(bad)
            info.size = 4
            t.addfile(info, io.BytesIO(b"evil"))
        tar.write_bytes(buf.getvalue())
        with pytest.raises(InputError):
            install_outputs(tar, dest)
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w") as t:
        link = tarfile.TarInfo("results.json")
        link.type, link.linkname = tarfile.SYMTYPE, "/etc/passwd"
        t.addfile(link)
    tar.write_bytes(buf.getvalue())
    with pytest.raises(InputError, match="not a regular file"):
        install_outputs(tar, dest)
    assert list_outputs(dest) == list_outputs(src)
    assert not (tmp_path / "outputs" / "evil.txt").exists()
    assert sorted(p.name for p in dest.parent.iterdir()) == ["j"]


def test_worker_and_queue_options_are_checked_before_starting(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    """Exit 2 with the reason: no queue database, a non-PostgreSQL one, a stalled age within two heartbeats,
    an unreachable database; `serve --queue postgres` on SQLite."""
    from ground.cli import EXIT_USAGE, main

    monkeypatch.delenv("DATABASE_URL", raising=False)
    token = write_token_file(tmp_path / "t", "w" * 32)
    base = ["worker", "--api", "http://127.0.0.1:9", "--token-file", str(token)]
    cases = [
        (base, "no queue database"),
        ([*base, "--database-url", "sqlite:///x.db"], "not a PostgreSQL URL"),
        ([*base, "--database-url", "postgresql://u@127.0.0.1:9/db", "--heartbeat-s", "10", "--stalled-after-s", "15"],
         "must exceed two heartbeats"),
        ([*base, "--database-url", "postgresql://u@127.0.0.1:9/db"], "cannot reach the queue database"),
        (["serve", "--data-dir", str(tmp_path / "d"), "--token-file", str(token), "--queue", "postgres"],
         "needs a PostgreSQL database URL"),
    ]
    for argv, reason in cases:
        assert main(argv) == EXIT_USAGE, argv
        assert reason in capsys.readouterr().err, argv


@pytest.mark.slow
def test_worker_runs_a_job_submitted_through_the_api(postgres_cluster: PostgresCluster, tmp_path: Path) -> None:
    """Upload → the adjustment is queued in PostgreSQL → `python -m ground worker` (role worker, its own cache)
    runs it → results, report and outputs are served by the API; an engineer downloads any output by name; a
    drone may not; an outputs archive with a wrong SHA-256 is refused; the job went through procrastinate."""
    srv = _server(postgres_cluster, tmp_path)
    worker = None
    try:
        token_file = write_token_file(tmp_path / "worker.token", make_token(srv.url, TOKEN, "worker", "w1"))
        engineer = make_token(srv.url, TOKEN, "engineer", "eng")
        drone = make_token(srv.url, TOKEN, "drone", "drone")
        worker = start_worker(_worker_args(srv, postgres_cluster, token_file, tmp_path / "cache", "w1"),
                              tmp_path / "w1.log")
        fid, truth = _upload_synthetic(srv, tmp_path)
        with srv.client(token=engineer) as c:
            jid = _only_job(c, fid)
            job = wait_job(c, fid, jid, procs=(worker,))
            assert job["status"] == "done", job["message"] + (tmp_path / "w1.log").read_text()[-3000:]
            res = c.get(f"/flights/{fid}/results").json()
            np.testing.assert_allclose(res["lever_arm_m"], truth.lever_arm_m, atol=0.01)  # type: ignore[attr-defined]
            outs = _outputs(c, fid, jid)
            assert {"results.json", "report.html", "exports/geo.txt"} <= set(outs)
            geo = c.get(f"/flights/{fid}/jobs/{jid}/outputs/exports/geo.txt")
            assert geo.status_code == 200 and geo.text.startswith("EPSG:4979")
            assert hashlib.sha256(geo.content).hexdigest() == outs["exports/geo.txt"]
            assert c.get(f"/flights/{fid}/exports/geo.txt").content == geo.content
            assert c.get(f"/flights/{fid}/jobs/{jid}/outputs/..%2F..%2Fdirectgeo.sqlite3").status_code in (400, 404)
            assert c.get(f"/flights/{fid}/jobs/{jid}/outputs/nope.txt").status_code == 404
        with srv.client(token=drone) as c:
            assert c.get(f"/flights/{fid}/jobs/{jid}/outputs").status_code == 403
            assert c.post(f"/flights/{fid}/jobs/{jid}/claim").status_code == 403
        with srv.client(token=engineer) as c:  # only a worker claims or posts
            assert c.post(f"/flights/{fid}/jobs/{jid}/finish", json={"status": "failed", "message": "x"}
                          ).status_code == 403
        with srv.client(token=token_file.read_text().strip()) as c:
            assert c.post(f"/flights/{fid}/jobs/{jid}/claim").status_code == 409  # already ended
            r = c.put(f"/flights/{fid}/jobs/{jid}/outputs", content=b"x" * 10240,
                      headers={"X-Content-SHA256": "0" * 64})
            assert r.status_code == 200  # ended: a late duplicate changes nothing
            assert _outputs(c, fid, jid) == outs
    finally:
        if worker is not None:
            stop_worker(worker)
        srv.stop()
    with psycopg.connect(postgres_cluster.dsn) as db:
        rows = db.execute("select status, queueing_lock, lock from procrastinate_jobs").fetchall()
    assert rows == [("succeeded", jid, fid)]


@pytest.mark.slow
def test_a_worker_killed_mid_job_is_replaced_and_the_outputs_are_identical(postgres_cluster: PostgresCluster,
                                                                           tmp_path: Path) -> None:
    """Two workers; the one running the job is SIGKILLed (with its job process) mid-job; the other takes the
    job over after the stalled-worker age and completes it; its outputs equal, byte for byte, those of a
    second, clean run of the same job."""
    srv = _server(postgres_cluster, tmp_path)
    workers: dict[str, subprocess.Popen[bytes]] = {}
    try:
        token_file = write_token_file(tmp_path / "worker.token", make_token(srv.url, TOKEN, "worker", "w"))
        for name in ("w1", "w2"):
            workers[name] = start_worker(_test_worker_args(srv, postgres_cluster, token_file,
                                                           tmp_path / f"cache-{name}", name),
                                         tmp_path / f"{name}.log", test_mode="slow")
        fid, _ = _upload_synthetic(srv, tmp_path)
        with srv.client() as c:
            jid = _only_job(c, fid)
            wait_job(c, fid, jid, statuses=("running",), procs=tuple(workers.values()))
            # the worker running it has the job's scratch folder in its cache (once the inputs are fetched)
            deadline = time.monotonic() + 30
            while not (holders := [n for n in workers if (tmp_path / f"cache-{n}" / "jobs" / jid).is_dir()]):
                assert time.monotonic() < deadline, "no worker started the job"
                time.sleep(0.05)
            assert len(holders) == 1, holders
            kill_worker(workers.pop(holders[0]))
            survivor = next(iter(workers.values()))
            job = wait_job(c, fid, jid, timeout_s=90, procs=(survivor,))
            assert job["status"] == "done", job["message"]
            retried = _outputs(c, fid, jid)
            second = c.post(f"/flights/{fid}/jobs", json={"kind": "adjust", "params": {}}).json()["id"]
            assert wait_job(c, fid, second, procs=(survivor,))["status"] == "done"
            clean = _outputs(c, fid, second)
        assert retried == clean and "exports/geo.txt" in clean
        with psycopg.connect(postgres_cluster.dsn) as db:
            attempts = db.execute("select attempts from procrastinate_jobs where queueing_lock = %s",
                                  (jid,)).fetchone()
        assert attempts is not None and attempts[0] >= 1  # it was put back once by the stalled-job check
        logs = "".join((tmp_path / f"{n}.log").read_text() for n in ("w1", "w2"))
        assert "of a silent worker: queued again" in logs
    finally:
        for p in workers.values():
            stop_worker(p)
        srv.stop()


@pytest.mark.slow
def test_a_job_over_its_time_limit_fails_with_a_message(postgres_cluster: PostgresCluster, tmp_path: Path) -> None:
    """A worker job running past the server's time limit is stopped and failed, saying so; the worker goes on."""
    srv = _server(postgres_cluster, tmp_path, job_timeout_s=2.0)
    worker = None
    try:
        token_file = write_token_file(tmp_path / "worker.token", make_token(srv.url, TOKEN, "worker", "w"))
        worker = start_worker(_test_worker_args(srv, postgres_cluster, token_file, tmp_path / "cache", "w1"),
                              tmp_path / "w1.log", test_mode="hang")
        fid, _ = _upload_synthetic(srv, tmp_path)
        with srv.client() as c:
            jid = _only_job(c, fid)
            job = wait_job(c, fid, jid, timeout_s=60, procs=(worker,))
            assert job["status"] == "failed" and "exceeded the time limit of 2 s" in job["message"], job
            assert _outputs(c, fid, jid) == {}
        assert worker.poll() is None
    finally:
        if worker is not None:
            stop_worker(worker)
        srv.stop()
