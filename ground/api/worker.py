"""`python -m ground worker`: a stateless processing worker on the PostgreSQL job queue (procrastinate).

A worker holds no flight data of its own: for each job the queue hands it, it claims the job through the API,
fetches the flight's files (and an earlier job's trajectory) through the API into a local cache, each verified
by SHA-256, runs the job in a child process with the job's time limit (`ground.api.jobs.run_job_process`, the
same as the in-process runner), then posts the output folder (one tar, installed atomically by the server) and
the final status through the API. Adding a machine that reaches the API and the database adds capacity.

At-least-once: procrastinate marks a job `doing` with the worker's id, and every worker sends a heartbeat every
`heartbeat_s`. Each worker also looks, every `heartbeat_s`, for jobs `doing` on a worker whose heartbeat is
older than `stalled_after_s` (procrastinate's `get_stalled_jobs`) and puts them back to `todo`
(`retry_job`), so a worker killed mid-job (SIGKILL, power cut, lost machine) has its job run again by another
— after at most about `stalled_after_s + heartbeat_s`. The defaults are procrastinate's own (10 s and 30 s):
three missed heartbeats before a live but slow worker is taken for dead (a duplicate run is harmless: jobs are
deterministic and their outputs are replaced as a whole), and a job of minutes loses well under a minute.
An API or network failure raises in the task and procrastinate retries it with exponential back-off; a 4xx
answer (job gone, refused archive) is final.
"""

from __future__ import annotations

import asyncio
import hashlib
import logging
import os
import shutil
import socket
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx

from ground.api.job_outputs import pack_outputs
from ground.api.jobs import JobFunction, run_job_process
from ground.api.queue import QUEUE_NAME, TASK_NAME, procrastinate_app
from ground.api.routes.worker_jobs import CONTENT_SHA_HEADER
from ground.api.schemas import JobInputFile, JobSpec
from ground.api.settings import ApiSettings
from onboard.formats.digest import sha256_file

log = logging.getLogger(__name__)

#: attempts of one job when the API or the network fails (then the job waits for `requeue_unfinished`)
MAX_ATTEMPTS = 8
#: base of the exponential back-off between those attempts (s): 2, 4, 8, … 256 s
BACKOFF_BASE_S = 2


@dataclass(frozen=True)
class WorkerOptions:
    """A worker's configuration: API base URL, its token, the queue's libpq DSN, local cache folder, and the
    heartbeat period / stalled-worker age (s) of the at-least-once mechanism."""

    api_url: str
    token: str
    dsn: str
    cache_dir: Path
    heartbeat_s: float = 10.0
    stalled_after_s: float = 30.0
    name: str = ""

    def __post_init__(self) -> None:
        if not self.stalled_after_s > 2 * self.heartbeat_s > 0:
            raise ValueError(f"stalled_after_s ({self.stalled_after_s:g} s) must exceed two heartbeats "
                             f"({self.heartbeat_s:g} s each): a live worker would be taken for dead")


class JobGone(Exception):
    """The API answered that the job does not exist or refused what the worker sent (4xx): do not retry."""


class ApiJobClient:
    """The worker's side of the API's worker routes (`ground.api.routes.worker_jobs`)."""

    def __init__(self, api_url: str, token: str, client: httpx.Client | None = None) -> None:
        self.http = client or httpx.Client(base_url=api_url, headers={"Authorization": f"Bearer {token}"},
                                           timeout=httpx.Timeout(60.0, connect=10.0))

    def _check(self, r: httpx.Response) -> httpx.Response:
        if 400 <= r.status_code < 500:
            raise JobGone(f"{r.request.method} {r.request.url.path}: {r.status_code} {r.text[:300]}")
        r.raise_for_status()  # 5xx: an HTTPStatusError, retried by the queue
        return r

    def claim(self, flight_id: str, job_id: str) -> JobSpec | None:
        """The job's spec (the job is now `running`), or None when it already ended."""
        r = self.http.post(f"/flights/{flight_id}/jobs/{job_id}/claim")
        if r.status_code == 409:
            return None
        return JobSpec.model_validate(self._check(r).json())

    def fetch(self, flight_id: str, f: JobInputFile, dest: Path) -> None:
        """`f` into `dest`, unless `dest` already holds exactly those bytes; streamed to a temporary name,
        SHA-256 checked, then renamed (a corrupted download never sits under the final name)."""
        if dest.is_file() and dest.stat().st_size == f.size and sha256_file(dest) == f.sha256:
            return
        path = (f"/flights/{flight_id}/jobs/{f.job_id}/outputs/{f.name}" if f.job_id
                else f"/flights/{flight_id}/files/{f.name}/content")
        dest.parent.mkdir(parents=True, exist_ok=True)
        tmp = dest.with_name(f".{dest.name}.{os.getpid()}.part")
        h = hashlib.sha256()
        try:
            with self.http.stream("GET", path) as r:
                self._check(r)
                with open(tmp, "wb") as fh:
                    for block in r.iter_bytes(1 << 20):
                        h.update(block)
                        fh.write(block)
            if h.hexdigest() != f.sha256:
                raise OSError(f"{f.name}: downloaded SHA-256 differs from the API's {f.sha256[:12]}…")
            os.replace(tmp, dest)
        finally:
            tmp.unlink(missing_ok=True)

    def put_outputs(self, flight_id: str, job_id: str, archive: bytes) -> list[dict[str, Any]]:
        """Post the output folder's tar; the server's listing of what it installed."""
        r = self.http.put(f"/flights/{flight_id}/jobs/{job_id}/outputs", content=archive,
                          headers={CONTENT_SHA_HEADER: hashlib.sha256(archive).hexdigest(),
                                   "Content-Type": "application/x-tar"})
        listing: list[dict[str, Any]] = self._check(r).json()
        return listing

    def finish(self, flight_id: str, job_id: str, status: str, message: str) -> None:
        """The job's final status and message."""
        self._check(self.http.post(f"/flights/{flight_id}/jobs/{job_id}/finish",
                                   json={"status": status, "message": message}))

    def close(self) -> None:
        """Close the connection pool."""
        self.http.close()


def run_one_job(api: ApiJobClient, flight_id: str, job_id: str, cache_dir: Path, token: str,
                functions: Mapping[str, JobFunction]) -> str | None:
    """Claim, fetch, run (child process, time limit), post outputs and status. The job's status ("done" or
    "failed"), or None when the job had already ended."""
    spec = api.claim(flight_id, job_id)
    if spec is None:
        log.info("job %s already ended: nothing to do", job_id)
        return None
    flight_dir = cache_dir / "flights" / flight_id
    for f in spec.files:
        api.fetch(flight_id, f, flight_dir / f.name)
    # a fresh scratch folder laid out like the server's outputs/<flight>/, so the job finds an earlier
    # job's trajectory as a sibling folder exactly as it does in-process
    work = cache_dir / "jobs" / job_id
    shutil.rmtree(work, ignore_errors=True)
    siblings = work / "outputs"
    for f in spec.earlier_outputs:
        api.fetch(flight_id, f, siblings / str(f.job_id) / f.name)
    out_dir = siblings / job_id
    out_dir.mkdir(parents=True)
    func = functions.get(spec.kind)
    if func is None:
        status, message = "failed", f"unknown job kind {spec.kind!r} on this worker"
    else:
        settings = ApiSettings(data_dir=work, token=token, job_timeout_s=spec.time_limit_s)
        files = {f.name: f.role for f in spec.files}
        status, message = run_job_process(func, (settings, spec.params, files, flight_dir, out_dir),
                                          spec.time_limit_s)
    if status == "done":
        try:
            api.put_outputs(flight_id, job_id, pack_outputs(out_dir))
        except JobGone as exc:
            status, message = "failed", f"the API refused the outputs: {exc}"
    api.finish(flight_id, job_id, status, message)
    shutil.rmtree(work, ignore_errors=True)
    log.info("job %s %s: %s", job_id, status, message[:200])
    return status


async def _retry_stalled_jobs(app: Any, options: WorkerOptions) -> None:
    """Every heartbeat: jobs `doing` on a worker silent for `stalled_after_s` go back to `todo`."""
    from procrastinate.exceptions import ConnectorException

    while True:
        try:
            stalled = await app.job_manager.get_stalled_jobs(queue=QUEUE_NAME,
                                                             seconds_since_heartbeat=options.stalled_after_s)
            for job in stalled:
                try:
                    await app.job_manager.retry_job(job)
                    log.warning("job %s (%s) of a silent worker: queued again", job.id, job.task_kwargs)
                except ConnectorException:  # another worker retried it first
                    pass
        except Exception:  # the database restarting: try again at the next beat
            log.warning("cannot look for stalled jobs now", exc_info=log.isEnabledFor(logging.DEBUG))
        await asyncio.sleep(options.heartbeat_s)


async def serve_async(options: WorkerOptions, functions: Mapping[str, JobFunction] | None = None) -> None:
    """Run jobs from the queue until SIGINT/SIGTERM (a running job is finished first)."""
    from procrastinate import RetryStrategy

    if functions is None:
        from ground.api.app import default_job_functions

        functions = default_job_functions()
    options.cache_dir.mkdir(parents=True, exist_ok=True)
    api = ApiJobClient(options.api_url, options.token)
    app = procrastinate_app(options.dsn, sync=False)
    retry = RetryStrategy(max_attempts=MAX_ATTEMPTS, exponential_wait=BACKOFF_BASE_S,
                          retry_exceptions={httpx.HTTPError, OSError})

    @app.task(name=TASK_NAME, queue=QUEUE_NAME, retry=retry)
    def run_job(job_id: str, flight_id: str) -> None:
        try:
            run_one_job(api, flight_id, job_id, options.cache_dir, options.token, functions)
        except JobGone as exc:  # a refused request (a flight file gone, …): the job fails saying why
            log.error("job %s: %s (not retried)", job_id, exc)
            try:
                api.finish(flight_id, job_id, "failed", f"the worker could not run it: {exc}")
            except (JobGone, httpx.HTTPError):
                log.error("job %s: cannot record the failure either", job_id)

    name = options.name or f"{socket.gethostname()}-{os.getpid()}"
    async with app.open_async():
        watcher = asyncio.create_task(_retry_stalled_jobs(app, options))
        try:
            await app.run_worker_async(queues=[QUEUE_NAME], concurrency=1, name=name,
                                       update_heartbeat_interval=options.heartbeat_s,
                                       stalled_worker_timeout=options.stalled_after_s)
        finally:
            watcher.cancel()
            api.close()


def serve(options: WorkerOptions, functions: Mapping[str, JobFunction] | None = None) -> None:
    """Blocking `serve_async`."""
    asyncio.run(serve_async(options, functions))
