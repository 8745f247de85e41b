"""Background job runner: jobs run in worker threads, their status lives in the store (queued → running → done|failed)."""

from __future__ import annotations

import datetime as dt
import logging
import traceback
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

from ground.api.settings import ApiSettings
from ground.store import Flight, Job, Store

log = logging.getLogger(__name__)

#: kind → function(settings, flight, job params, flight files dir, output dir) → result message
JobFunction = Callable[[ApiSettings, dict[str, Any], dict[str, str | None], Path, Path], str]


def _now() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


class JobRunner:
    """Runs queued jobs on a small thread pool; a failure is recorded on the job, never raised to the server."""

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
        with self.store.session() as s:
            job = s.get(Job, job_id)
            if job is None:
                return
            flight = s.get(Flight, job.flight_id)
            assert flight is not None  # foreign key
            job.status, job.started_at, job.message = "running", _now(), ""
            s.commit()
            kind, params = job.kind, dict(job.params)
            files = {f.name: f.role for f in flight.files if f.status == "complete"}
            flight_id = flight.id
        out_dir = self.settings.data_dir / "outputs" / flight_id / job_id
        out_dir.mkdir(parents=True, exist_ok=True)
        func = self.functions.get(kind)
        try:
            if func is None:
                raise ValueError(f"unknown job kind {kind!r}")
            message = func(self.settings, params, files, self.settings.flights_dir / flight_id, out_dir)
            status = "done"
        except Exception as exc:  # noqa: BLE001 - any failure of a job is the job's status, not a server crash
            log.warning("job %s (%s) failed: %s", job_id, kind, exc)
            log.debug("%s", traceback.format_exc())
            message, status = f"{type(exc).__name__}: {exc}", "failed"
        with self.store.session() as s:
            job = s.get(Job, job_id)
            if job is not None:
                job.status, job.message, job.finished_at = status, message[:4000], _now()
                s.commit()

    def shutdown(self) -> None:
        """Wait for running jobs and stop the pool."""
        self._pool.shutdown(wait=True, cancel_futures=True)
