"""`create_app(settings) -> FastAPI`: the ground API (flights, upload, jobs, reports). Nothing happens at import."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI

from ground.api.jobs import JobFunction, JobRunner
from ground.api.routes import flights
from ground.api.settings import ApiSettings
from ground.store import Store

log = logging.getLogger(__name__)


def default_job_functions() -> dict[str, JobFunction]:
    """The processing jobs the API offers (kind → function)."""
    from ground.cli import adjust_job, rtk_job

    return {"adjust": adjust_job, "rtk": rtk_job}


def create_app(settings: ApiSettings, job_functions: dict[str, JobFunction] | None = None) -> FastAPI:
    """Build the app: store opened, job runner started and unfinished jobs re-queued in the lifespan."""

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        settings.flights_dir.mkdir(parents=True, exist_ok=True)
        store = Store(settings.db_url)
        runner = JobRunner(settings, store, job_functions if job_functions is not None else default_job_functions())
        app.state.settings, app.state.store, app.state.jobs = settings, store, runner
        n = runner.requeue_unfinished()
        if n:
            log.info("re-queued %d unfinished jobs", n)
        try:
            yield
        finally:
            runner.shutdown()
            store.close()

    app = FastAPI(
        title="directgeo ground API",
        version="0.1.0",
        description="Flight store with resumable, checksummed upload (manifest with SHA-256, chunks with "
        "offsets and per-chunk SHA-256), processing jobs (RTK re-processing, final adjustment) and reports. "
        "Every /flights route needs `Authorization: Bearer <token>`.",
        lifespan=lifespan,
    )
    app.state.settings = settings
    app.state.file_locks = flights.FileLocks()
    app.include_router(flights.router)

    @app.get("/health", tags=["health"])
    def health() -> dict[str, str]:
        """Liveness probe (no flight data, no authentication)."""
        return {"status": "ok"}

    return app
