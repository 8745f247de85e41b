"""Where the API puts the jobs it accepts: the `JobQueue` seam and its PostgreSQL task-queue implementation.

Two implementations, chosen once by `make_job_queue` (called by `create_app`, the composition root):

- `inprocess` (`ground.api.jobs.JobRunner`, the default): jobs run in child processes of the API server itself —
  SQLite, no broker, `ground serve` alone works on a laptop.
- `postgres` (`PostgresJobQueue`): jobs are deferred to a procrastinate queue in the same PostgreSQL database as
  the flight store and run by `python -m ground worker` processes (any machine that reaches the API and the
  database). Procrastinate was chosen over Celery/Dramatiq + Redis because we already run PostgreSQL: no second
  server to operate, jobs deferred in a transaction of the database that holds the flights, and a maintained
  worker heartbeat that lets a surviving worker retry the job of a dead one (see `ground.api.worker`).

The store's `jobs` row stays the job's status for users (queued → running → done|failed, with its message);
the procrastinate job only carries "run job X" to a worker.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Protocol

from ground.api.settings import ApiSettings
from ground.store import Job, Store

log = logging.getLogger(__name__)

#: the procrastinate task a worker runs: `run_job(job_id=..., flight_id=...)`
TASK_NAME = "directgeo.run_job"
#: the procrastinate queue of processing jobs
QUEUE_NAME = "directgeo-jobs"
#: attempts to defer a job when the database connection fails, and the wait before the n-th retry (n × s)
DEFER_ATTEMPTS = 5
DEFER_RETRY_S = 0.5


class JobQueue(Protocol):
    """What the API needs of a job queue."""

    def submit(self, job_id: str) -> None:
        """Queue a job that already exists in the store (status `queued`)."""

    def requeue_unfinished(self) -> int:
        """At start: queue again the jobs a stopped server left unfinished; returns how many."""

    def shutdown(self) -> None:
        """Stop (the in-process runner waits for its running jobs)."""


def libpq_dsn(database_url: str) -> str:
    """The libpq connection string of a SQLAlchemy PostgreSQL URL (`postgresql+psycopg://…` → `postgresql://…`)."""
    scheme, sep, rest = database_url.partition("://")
    if not sep or scheme.split("+")[0] not in ("postgresql", "postgres"):
        raise ValueError(f"not a PostgreSQL URL: {database_url.split('@')[-1]}")
    return f"postgresql://{rest}"


def procrastinate_app(dsn: str, *, sync: bool):  # type: ignore[no-untyped-def]
    """A procrastinate App on `dsn` (sync connector for the API's defers, async for a worker)."""
    import procrastinate

    connector = (procrastinate.SyncPsycopgConnector(conninfo=dsn) if sync
                 else procrastinate.PsycopgConnector(conninfo=dsn))
    return procrastinate.App(connector=connector)


class PostgresJobQueue:
    """Defers each job to the procrastinate queue; `python -m ground worker` processes run them.

    Jobs of one flight share the procrastinate `lock` (the flight id): they run one after the other in the order
    they were queued (the RTK re-processing before the adjustment that uses its trajectory), whatever the number
    of workers. The `queueing_lock` (the job id) keeps a job from being waiting twice."""

    def __init__(self, settings: ApiSettings, store: Store) -> None:
        from sqlalchemy import inspect

        if not settings.database_url:
            raise ValueError("the postgres job queue needs DATABASE_URL (a PostgreSQL database)")
        self.store = store
        self.app = procrastinate_app(libpq_dsn(settings.database_url), sync=True)
        self.app.open()
        if not inspect(store.engine).has_table("procrastinate_jobs"):
            log.info("creating the procrastinate schema in the flight store's database")
            self.app.schema_manager.apply_schema()

    def submit(self, job_id: str) -> None:
        """Defer `run_job(job_id)` under the flight's lock; a job already waiting is not queued twice."""
        from procrastinate.exceptions import AlreadyEnqueued, ConnectorException

        with self.store.session() as s:
            job = s.get(Job, job_id)
            if job is None:
                raise KeyError(f"no job {job_id}")
            flight_id = job.flight_id
        task = self.app.configure_task(name=TASK_NAME, queue=QUEUE_NAME, lock=flight_id, queueing_lock=job_id)
        for attempt in range(DEFER_ATTEMPTS):
            try:
                task.defer(job_id=job_id, flight_id=flight_id)
                return
            except AlreadyEnqueued:
                log.info("job %s is already waiting in the queue", job_id)
                return
            except ConnectorException:  # the database restarted: the pool hands out a fresh connection next
                if attempt == DEFER_ATTEMPTS - 1:
                    raise
                log.warning("job %s: cannot reach the queue, retrying", job_id, exc_info=True)
                time.sleep(DEFER_RETRY_S * (attempt + 1))

    def requeue_unfinished(self) -> int:
        """Store jobs queued/running with no procrastinate job waiting or running (a server stopped between the
        commit and the defer, or a job whose retries ran out while the API was down) are deferred again."""
        with self.store.session() as s:
            ids = [j.id for j in s.query(Job).filter(Job.status.in_(("queued", "running"))).all()]
        n = 0
        for job_id in ids:
            live = [j for j in self.app.job_manager.list_jobs(queueing_lock=job_id)
                    if j.status in ("todo", "doing")]
            if not live:
                self.submit(job_id)
                n += 1
        return n

    def shutdown(self) -> None:
        """Close the connection pool (waiting and running jobs stay in the database)."""
        self.app.close()


def make_job_queue(settings: ApiSettings, store: Store, runner_factory: Callable[[], JobQueue]) -> JobQueue:
    """The queue `settings.job_queue` names: `runner_factory()` (the in-process runner) or PostgreSQL."""
    if settings.job_queue == "postgres":
        return PostgresJobQueue(settings, store)
    return runner_factory()
