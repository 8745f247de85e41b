"""Background job runner: each job runs in a child process watched by a worker thread; its status lives in
the store (queued → running → done|failed).

A job is a function `(settings, params, files, flight files dir, output dir) -> message`. It runs in a fresh
(spawned) process so that whatever it does — raise any exception, `SystemExit` and `KeyboardInterrupt`
included, die, or run past `settings.job_timeout_s` (then it is killed) — the job ends `failed` with a message
and the server keeps serving. Jobs left `queued`/`running` by a stopped server run again at the next start.
"""

from __future__ import annotations

import datetime as dt
import logging
import multiprocessing as mp
import traceback
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from ground.api.job_outputs import job_output_dir
from ground.api.settings import ApiSettings
from ground.store import Flight, Job, Store

log = logging.getLogger(__name__)

#: kind → function(settings, job params, flight files {name: role}, flight files dir, output dir) → message
JobFunction = Callable[[ApiSettings, dict[str, Any], dict[str, str | None], Path, Path], str]

#: seconds a killed job process gets to exit after SIGTERM before SIGKILL
KILL_GRACE_S = 5.0


def _now() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


def _child(conn: Connection, func: JobFunction, args: tuple[Any, ...]) -> None:
    """Child-process body: run the job, send ("done"|"failed", message) back, whatever happens."""
    try:
        message = func(*args)
        conn.send(("done", str(message)))
    except BaseException as exc:  # noqa: BLE001 - SystemExit/KeyboardInterrupt too: every end is a job status
        conn.send(("failed", f"{type(exc).__name__}: {exc}".rstrip(": "), traceback.format_exc()))
    finally:
        conn.close()


def run_job_process(func: JobFunction, args: tuple[Any, ...], timeout_s: float) -> tuple[str, str]:
    """Run `func(*args)` in a spawned process; (status, message) with status "done" or "failed"."""
    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(child, func, args), daemon=True)
    proc.start()
    child.close()
    try:
        if parent.poll(timeout_s):
            try:
                reply = parent.recv()
            except EOFError:
                reply = None
        else:
            reply = ("failed", f"exceeded the time limit of {timeout_s:g} s: stopped")
            proc.terminate()
        proc.join(KILL_GRACE_S)
        if proc.is_alive():
            proc.kill()
            proc.join()
    finally:
        parent.close()
    if reply is None:
        return "failed", f"the job process ended without a result (exit code {proc.exitcode})"
    if len(reply) > 2:
        log.debug("job traceback:\n%s", reply[2])
    return str(reply[0]), str(reply[1])


class JobRunner:
    """Runs queued jobs, one child process each, on a small pool of watcher threads; a failure is recorded on
    the job, never raised to the server."""

    def __init__(self, settings: ApiSettings, store: Store, functions: dict[str, JobFunction]) -> None:
        self.settings = settings
        self.store = store
        self.functions = functions
        self._pool = ThreadPoolExecutor(max_workers=settings.job_workers, thread_name_prefix="directgeo-job")
        self.futures: dict[str, Future[None]] = {}

    def submit(self, job_id: str) -> None:
        """Queue a job that already exists in the store."""
        self.futures[job_id] = self._pool.submit(self.run, job_id)

    def requeue_unfinished(self) -> int:
        """At start: jobs left queued or running by a previous process are run again. Returns how many."""
        with self.store.session() as s:
            ids = [j.id for j in s.query(Job).filter(Job.status.in_(("queued", "running"))).all()]
        for job_id in ids:
            self.submit(job_id)
        return len(ids)

    def run(self, job_id: str) -> None:
        """Run one job to completion, recording status, timings and message."""
        try:
            status, message = self._run(job_id)
        except Exception as exc:  # the runner itself failed (store, disk): the job says so
            log.exception("job %s: the runner failed", job_id)
            status, message = "failed", f"{type(exc).__name__}: {exc}"
        if status == "failed":
            log.warning("job %s failed: %s", job_id, message)
        with self.store.session() as s:
            job = s.get(Job, job_id)
            if job is not None:
                job.status, job.message, job.finished_at = status, message[:4000], _now()
                s.commit()

    def _run(self, job_id: str) -> tuple[str, str]:
        with self.store.session() as s:
            job = s.get(Job, job_id)
            if job is None:
                return "failed", "job vanished"
            flight = s.get(Flight, job.flight_id)
            assert flight is not None  # foreign key
            job.status, job.started_at, job.message = "running", _now(), ""
            s.commit()
            kind, params = job.kind, dict(job.params)
            files = {f.name: f.role for f in flight.files if f.status == "complete"}
            flight_id = flight.id
        func = self.functions.get(kind)
        if func is None:
            return "failed", f"unknown job kind {kind!r}"
        out_dir = job_output_dir(self.settings.data_dir, flight_id, job_id)
        out_dir.mkdir(parents=True, exist_ok=True)
        args = (self.settings, params, files, self.settings.flights_dir / flight_id, out_dir)
        return run_job_process(func, args, self.settings.job_timeout_s)

    def shutdown(self) -> None:
        """Wait for running jobs and stop the pool."""
        self._pool.shutdown(wait=True, cancel_futures=True)
