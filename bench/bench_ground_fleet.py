"""The ground app under a fleet's load and faults, over loopback: today's in-process runner (SQLite) side by side
with PostgreSQL + `python -m ground worker` processes, in the same run.

1. Uploads: `--drones` drones upload at once with the real onboard uploader (`onboard.upload.client.Uploader`,
   one drone token each) to `python -m ground serve` (a subprocess): throughput, p95 latency of a chunk PUT,
   and every file checked server side (SHA-256 of the bytes on the server's disk against the drone's, status
   complete): corrupted / lost counts.
2. Processing: `--flights` flights queued (the adjustment on a small simulated flight: 1 line, ~17 images,
   trajectory + events + poses + GCP — a light but real job, spawned child process included) and processed
   by the in-process runner (1 job at a time, today's default), by 1 and by 2 workers: flights per hour from
   the first job start to the last job end; the 2-worker/1-worker scaling factor on this machine.
3. A worker SIGKILLed mid-job (with its job process) while a second worker runs: the job is completed by the
   second one, outputs compared byte for byte with a clean run of the same job; time to recovery.
4. PostgreSQL restarted (fast shutdown: sessions cut) while drones upload: the uploads resume and complete,
   files verified.
Throughout 1 and 2, another client polls `GET /flights` (engineer token): its p95 latency under that load.

Every loop is bounded (fixed counts, deadlines). Run:
`PYTHONPATH=. .venv/bin/python bench/bench_ground_fleet.py [--drones 20 --flights 50 --flight-mib 4]`
"""

from __future__ import annotations

import argparse
import hashlib
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx

from bench.bench_ground_api import _flight
from onboard.upload.client import Uploader, UploaderOptions
from tests.ground_api.fleet import (
    kill_worker,
    make_token,
    start_worker,
    stop_worker,
    wait_job,
    write_token_file,
)
from tests.postgres_cluster import PostgresCluster, free_port

TOKEN = "bench-token-0123456789abcdef"
ROLES = {"SOL.pos": "trajectory", "events.csv": "events", "poses.csv": "orientations", "gcp.csv": "gcp"}
REPO = Path(__file__).resolve().parents[1]


def p95(xs: list[float]) -> float:
    """95th percentile (s) of latencies; NaN for none."""
    if len(xs) < 2:
        return xs[0] if xs else float("nan")
    return statistics.quantiles(xs, n=20, method="inclusive")[-1]


@dataclass
class Server:
    """`python -m ground serve` in a subprocess."""

    url: str
    data_dir: Path
    proc: subprocess.Popen[bytes]

    def stop(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def serve(root: Path, tag: str, database_url: str | None = None, queue: str = "inprocess") -> Server:
    data = root / f"srv-{tag}"
    data.mkdir(parents=True)
    token_file = write_token_file(root / f"{tag}.token", TOKEN)
    port = free_port()
    args = [sys.executable, "-m", "ground", "serve", "--port", str(port), "--data-dir", str(data), "--token-file",
            str(token_file), "--queue", queue]
    if database_url:
        args += ["--database-url", database_url]
    with open(root / f"{tag}.log", "ab") as log:
        proc = subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT, cwd=REPO,
                                env={**os.environ, "PYTHONPATH": str(REPO)})
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 60
    while True:
        try:
            if httpx.get(f"{url}/health", timeout=2).status_code == 200:
                return Server(url, data, proc)
        except httpx.TransportError:
            pass
        if time.monotonic() > deadline or proc.poll() is not None:
            raise RuntimeError(f"server {tag} did not start: {(root / f'{tag}.log').read_text()[-2000:]}")
        time.sleep(0.2)


class TimedTransport(httpx.HTTPTransport):
    """Records the duration (s) of every chunk PUT."""

    def __init__(self, sink: list[float]) -> None:
        super().__init__()
        self.sink = sink

    def handle_request(self, request: httpx.Request) -> httpx.Response:
        t = time.perf_counter()
        r = super().handle_request(request)
        if request.method == "PUT":
            r.read()
            self.sink.append(time.perf_counter() - t)
        return r


class Poller(threading.Thread):
    """GET /flights every `period_s` until stopped; latencies (s) and failures."""

    def __init__(self, url: str, token: str, period_s: float = 0.1) -> None:
        super().__init__(daemon=True)
        self.client = httpx.Client(base_url=url, headers={"Authorization": f"Bearer {token}"}, timeout=60)
        self.period_s, self.lat, self.errors = period_s, [], 0
        self.halt = threading.Event()

    def run(self) -> None:
        while not self.halt.is_set():
            t = time.perf_counter()
            try:
                ok = self.client.get("/flights").status_code == 200
            except httpx.HTTPError:
                ok = False
            self.lat.append(time.perf_counter() - t)
            self.errors += not ok
            self.halt.wait(self.period_s)

    def stop(self) -> tuple[float, int, int]:
        """(p95 latency s, requests, failures)."""
        self.halt.set()
        self.join(timeout=120)
        self.client.close()
        return p95(self.lat), len(self.lat), self.errors


@dataclass
class UploadRun:
    seconds: float = 0.0
    bytes_sent: int = 0
    chunk_lat: list[float] = field(default_factory=list)
    retries: int = 0
    failures: list[str] = field(default_factory=list)
    flight_ids: list[str] = field(default_factory=list)


def upload_all(srv: Server, folders: list[Path], chunk_bytes: int, roles: dict[str, str] | None = None,
               on_chunk: Callable[[int], None] | None = None) -> UploadRun:
    """One thread per folder, each a drone with its own token, all started together."""
    run = UploadRun()
    tokens = [make_token(srv.url, TOKEN, "drone", f"drone-{f.name}") for f in folders]
    lock = threading.Lock()
    start = threading.Barrier(len(folders) + 1)

    def drone(folder: Path, token: str) -> None:
        lat: list[float] = []
        client = httpx.Client(base_url=srv.url, transport=TimedTransport(lat), timeout=60)
        up = Uploader(srv.url, token, UploaderOptions(chunk_bytes=chunk_bytes, max_retries=12, backoff_max_s=5),
                      client=client, on_chunk=on_chunk)
        start.wait()
        try:
            rep = up.upload_flight(folder, roles)
            with lock:
                run.bytes_sent += rep.bytes_sent
                run.retries += rep.retries
                run.flight_ids.append(rep.flight_id)
        except Exception as exc:  # noqa: BLE001 - any end of an upload is counted: a failed (lost) flight
            with lock:
                run.failures.append(f"{folder.name}: {exc}")
        finally:
            up.close()
            with lock:
                run.chunk_lat.extend(lat)

    threads = [threading.Thread(target=drone, args=(f, t)) for f, t in zip(folders, tokens)]
    for th in threads:
        th.start()
    start.wait()
    t0 = time.perf_counter()
    for th in threads:
        th.join(timeout=900)
    run.seconds = time.perf_counter() - t0
    return run


def verify_server_side(srv: Server, folders: list[Path], run: UploadRun) -> tuple[int, int]:
    """(corrupted, lost): files whose bytes on the server's disk differ from the drone's, or that are missing or
    not complete."""
    corrupted = lost = 0
    with httpx.Client(base_url=srv.url, headers={"Authorization": f"Bearer {TOKEN}"}, timeout=60) as c:
        by_name = {f["name"]: f["id"] for f in c.get("/flights").json()}
        for folder in folders:
            fid = by_name.get(folder.name)
            files = [p for p in sorted(folder.iterdir()) if p.is_file() and p.name != "manifest.json"]
            if fid is None:
                lost += len(files)
                continue
            held = {f["name"]: f for f in c.get(f"/flights/{fid}").json()["files"]}
            for p in files:
                on_server = srv.data_dir / "flights" / fid / p.name
                if held.get(p.name, {}).get("status") != "complete" or not on_server.is_file():
                    lost += 1
                elif hashlib.sha256(on_server.read_bytes()).hexdigest() != hashlib.sha256(p.read_bytes()).hexdigest():
                    corrupted += 1
    return corrupted, lost


def upload_phase(label: str, tag: str, srv: Server, root: Path, n: int, flight_mib: int, chunk_bytes: int) -> str:
    folders = [_flight(root / f"up-{tag}", flight_mib * 2**20, 2**20, f"flight-{tag}-{i:02d}") for i in range(n)]
    engineer = make_token(srv.url, TOKEN, "engineer", f"poller-{tag}")
    poller = Poller(srv.url, engineer)
    poller.start()
    run = upload_all(srv, folders, chunk_bytes)
    gp95, greq, gerr = poller.stop()
    corrupted, lost = verify_server_side(srv, folders, run)
    return (f"{label:26s} {run.bytes_sent / 2**20 / run.seconds:7.1f} MiB/s  chunk p95 {p95(run.chunk_lat) * 1e3:6.1f} ms "
            f"({len(run.chunk_lat)} PUTs, {run.retries} retried)  GET /flights p95 {gp95 * 1e3:6.1f} ms ({greq} req, {gerr} failed)  "
            f"corrupted {corrupted}  lost {lost}  failed uploads {len(run.failures)}")


def synthetic_flights(root: Path, label: str, n: int) -> list[Path]:
    from tests.ground_io.flightgen import write_synthetic_flight

    src = root / f"synthetic-{label}-src"
    write_synthetic_flight(src, n_lines=1)
    out = []
    for i in range(n):
        d = root / f"flight-{label}-{i:02d}"
        d.mkdir()
        for p in src.iterdir():
            os.link(p, d / p.name)
        out.append(d)
    return out


def _parse(ts: str) -> float:
    import datetime as dt

    return dt.datetime.fromisoformat(ts).timestamp()


def job_rows(srv: Server) -> list[dict[str, Any]]:
    with httpx.Client(base_url=srv.url, headers={"Authorization": f"Bearer {TOKEN}"}, timeout=60) as c:
        return [j for f in c.get("/flights").json() for j in c.get(f"/flights/{f['id']}").json()["jobs"]]


def wait_all_jobs(srv: Server, n: int, timeout_s: float, procs: tuple[subprocess.Popen[bytes], ...] = ()) -> list[dict[str, Any]]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        jobs = job_rows(srv)
        if len(jobs) >= n and all(j["status"] in ("done", "failed") for j in jobs):
            return jobs
        if any(p.poll() is not None for p in procs):
            raise RuntimeError("a worker exited")
        time.sleep(1.0)
    raise RuntimeError(f"{n} jobs not finished in {timeout_s} s")


def processing_phase(label: str, tag: str, root: Path, n: int, cluster: PostgresCluster | None,
                     workers: int) -> tuple[str, float]:
    """Upload n flights at once, each queueing its adjustment, processed as they arrive (in-process runner, or
    `workers` worker processes started before); (line, flights per hour from first job start to last end)."""
    if cluster is None:
        srv = serve(root, tag)
    else:
        db = f"bench_{tag}"
        import psycopg

        with psycopg.connect(cluster.dsn, autocommit=True) as conn:
            conn.execute(f"create database {db}")
        srv = serve(root, tag, cluster.url.rsplit("/", 1)[0] + f"/{db}", queue="postgres")
    procs: list[subprocess.Popen[bytes]] = []
    try:
        folders = synthetic_flights(root, tag, n)
        engineer = make_token(srv.url, TOKEN, "engineer", "poller")
        if cluster is not None:  # workers up first: jobs run while uploads go on, as in-process
            token_file = write_token_file(root / f"{tag}-worker.token", make_token(srv.url, TOKEN, "worker", "w"))
            dsn = cluster.dsn.rsplit("/", 1)[0] + f"/{db}"
            for k in range(workers):
                procs.append(start_worker(["--api", srv.url, "--token-file", str(token_file), "--database-url", dsn,
                                           "--cache-dir", str(root / f"{tag}-cache-{k}"), "--name", f"w{k}"],
                                          root / f"{tag}-w{k}.log"))
            time.sleep(3.0)  # workers registered and listening
        poller = Poller(srv.url, engineer, period_s=0.25)
        poller.start()
        upload_all(srv, folders, 256 * 1024, ROLES)
        jobs = wait_all_jobs(srv, n, timeout_s=60 * n, procs=tuple(procs))
        gp95, greq, gerr = poller.stop()
    finally:
        for p in procs:
            stop_worker(p)
        srv.stop()
    done = [j for j in jobs if j["status"] == "done"]
    span = max(_parse(j["finished_at"]) for j in jobs) - min(_parse(j["started_at"]) for j in jobs)
    rate = len(done) / span * 3600
    per_job = statistics.median(_parse(j["finished_at"]) - _parse(j["started_at"]) for j in jobs)
    line = (f"{label:26s} {len(done)}/{len(jobs)} done in {span:6.1f} s = {rate:7.0f} flights/h  "
            f"(median job {per_job:4.1f} s)  GET /flights p95 {gp95 * 1e3:6.1f} ms ({greq} req, {gerr} failed)")
    return line, rate


def kill_phase(root: Path, cluster: PostgresCluster) -> str:
    """Two real workers (2 s heartbeat, 6 s stalled age); the one running the job is SIGKILLed mid-job."""
    import psycopg

    with psycopg.connect(cluster.dsn, autocommit=True) as conn:
        conn.execute("create database bench_kill")
    srv = serve(root, "kill", cluster.url.rsplit("/", 1)[0] + "/bench_kill", queue="postgres")
    dsn = cluster.dsn.rsplit("/", 1)[0] + "/bench_kill"
    procs: dict[str, subprocess.Popen[bytes]] = {}
    try:
        token_file = write_token_file(root / "kill-worker.token", make_token(srv.url, TOKEN, "worker", "w"))
        for k in ("k1", "k2"):
            procs[k] = start_worker(["--api", srv.url, "--token-file", str(token_file), "--database-url", dsn,
                                     "--cache-dir", str(root / f"kill-cache-{k}"), "--name", k, "--heartbeat-s", "2",
                                     "--stalled-after-s", "6"], root / f"kill-{k}.log")
        (folder,) = synthetic_flights(root, "kill", 1)
        upload_all(srv, [folder], 256 * 1024, ROLES)
        with httpx.Client(base_url=srv.url, headers={"Authorization": f"Bearer {TOKEN}"}, timeout=60) as c:
            fid = c.get("/flights").json()[0]["id"]
            jid = c.get(f"/flights/{fid}").json()["jobs"][0]["id"]
            deadline = time.monotonic() + 120
            while not (holders := [k for k in procs if (root / f"kill-cache-{k}" / "jobs" / jid).is_dir()]):
                if time.monotonic() > deadline:
                    raise RuntimeError("no worker started the job")
                time.sleep(0.02)
            time.sleep(0.5)  # the job process is running (importing, reading, adjusting)
            t_kill = time.monotonic()
            kill_worker(procs.pop(holders[0]))
            survivor = next(iter(procs.values()))
            job = wait_job(c, fid, jid, timeout_s=180, procs=(survivor,))
            recovery = time.monotonic() - t_kill
            killed_mid_job = "SIGKILLed before the end" if not (root / f"kill-cache-{holders[0]}" / "jobs" / jid
                                                                / "outputs" / jid / "results.json").exists() else \
                "(it had finished computing, not posted)"
            first = {o["name"]: o["sha256"] for o in c.get(f"/flights/{fid}/jobs/{jid}/outputs").json()}
            second = c.post(f"/flights/{fid}/jobs", json={"kind": "adjust", "params": {}}).json()["id"]
            wait_job(c, fid, second, timeout_s=180, procs=(survivor,))
            clean = {o["name"]: o["sha256"] for o in c.get(f"/flights/{fid}/jobs/{second}/outputs").json()}
    finally:
        for p in procs.values():
            stop_worker(p)
        srv.stop()
    same = first == clean and bool(first)
    return (f"{'worker SIGKILLed mid-job':26s} job {job['status']} by the other worker {recovery:5.1f} s after the "
            f"kill ({killed_mid_job}); {len(first)} output files, identical to a clean run: {same}")


def restart_phase(root: Path, cluster: PostgresCluster, n: int, flight_mib: int, chunk_bytes: int) -> str:
    import psycopg

    with psycopg.connect(cluster.dsn, autocommit=True) as conn:
        conn.execute("create database bench_restart")
    srv = serve(root, "restart", cluster.url.rsplit("/", 1)[0] + "/bench_restart", queue="postgres")
    try:
        folders = [_flight(root / "up-restart", flight_mib * 2**20, 2**20, f"flight-restart-{i:02d}")
                   for i in range(n)]
        total_chunks = n * (flight_mib * 2**20 // chunk_bytes)
        sent = [0]
        restarted = threading.Event()
        restart_s = [0.0]

        def on_chunk(_: int) -> None:
            sent[0] += 1
            if sent[0] == total_chunks // 3 and not restarted.is_set():
                restarted.set()
                t = time.perf_counter()
                cluster.restart("fast")
                restart_s[0] = time.perf_counter() - t

        run = upload_all(srv, folders, chunk_bytes, on_chunk=on_chunk)
        corrupted, lost = verify_server_side(srv, folders, run)
    finally:
        srv.stop()
    return (f"{'PostgreSQL restarted':26s} after {total_chunks // 3}/{total_chunks} chunks (down {restart_s[0]:.1f} s): "
            f"{n - len(run.failures)}/{n} uploads completed, {run.retries} uploader retries, corrupted {corrupted}, "
            f"lost {lost}, {run.bytes_sent / 2**20:.0f} MiB sent for {n * flight_mib} MiB")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--drones", type=int, default=20)
    ap.add_argument("--flight-mib", type=int, default=4, help="size of each drone's flight (MiB, 1 MiB segments)")
    ap.add_argument("--chunk-kib", type=int, default=128)
    ap.add_argument("--flights", type=int, default=50, help="flights queued for processing")
    args = ap.parse_args()
    import logging

    logging.basicConfig(level=logging.ERROR)  # the uploaders' retry warnings: counted in the figures instead
    chunk = args.chunk_kib * 1024
    print(f"machine: {os.cpu_count()} cores; loopback; server = python -m ground serve (subprocess)")
    with tempfile.TemporaryDirectory(prefix="bench-fleet-") as tmp:
        root = Path(tmp)
        cluster = PostgresCluster()
        try:
            print(f"\n1. {args.drones} drones uploading {args.flight_mib} MiB each at once, {args.chunk_kib} KiB chunks")
            srv = serve(root, "sqlite")
            try:
                print(upload_phase("in-process, SQLite", "sqlite", srv, root, args.drones, args.flight_mib, chunk))
            finally:
                srv.stop()
            import psycopg

            with psycopg.connect(cluster.dsn, autocommit=True) as conn:
                conn.execute("create database bench_upload")
            srv = serve(root, "pg", cluster.url.rsplit("/", 1)[0] + "/bench_upload", queue="postgres")
            try:
                print(upload_phase("workers, PostgreSQL", "pg", srv, root, args.drones, args.flight_mib, chunk))
            finally:
                srv.stop()
            print(f"\n2. {args.flights} queued flights, adjustment of a simulated 1-line flight (~17 images + GCP)")
            line, _ = processing_phase("in-process (1 at a time)", "inproc", root, args.flights, None, 0)
            print(line)
            line, one = processing_phase("PostgreSQL, 1 worker", "w1", root, args.flights, cluster, 1)
            print(line)
            line, two = processing_phase("PostgreSQL, 2 workers", "w2", root, args.flights, cluster, 2)
            print(line)
            print(f"{'scaling 2 workers / 1':26s} x{two / one:.2f} on {os.cpu_count()} cores")
            print("\n3. fault: worker killed")
            print(kill_phase(root, cluster))
            print("\n4. fault: database restarted mid-upload (5 drones, 4 MiB each)")
            print(restart_phase(root, cluster, 5, 4, 64 * 1024))
        finally:
            cluster.stop()


if __name__ == "__main__":
    main()
