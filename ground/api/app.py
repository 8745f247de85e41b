"""`create_app(settings) -> FastAPI`: the ground API (flights, upload, jobs, reports). Nothing happens at import."""

from __future__ import annotations

import json
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from ground.api.auth import document_roles
from ground.api.jobs import JobFunction, JobRunner
from ground.api.queue import make_job_queue
from ground.api.routes import flights, tokens, worker_jobs
from ground.api.settings import ApiSettings
from ground.store import Store
from ground.web import routes as web

log = logging.getLogger(__name__)


def default_job_functions() -> dict[str, JobFunction]:
    """The processing jobs the API offers (kind → function)."""
    from ground.api.job_kinds import adjust_job, rtk_job

    return {"adjust": adjust_job, "rtk": rtk_job}


def _streams_files(scope: Scope) -> bool:
    """The web adjustment form's multipart POST: its files stream to disk and the route caps them itself."""
    return bool(scope["method"] == "POST" and scope["path"].startswith(web.PREFIX + "/flights/")
                and scope["path"].endswith("/adjust"))


class BodyLimit:
    """ASGI middleware: a request body other than an upload chunk (`PUT …/files/…`), a worker's outputs
    archive (`PUT …/outputs`) or the web adjustment form (each capped by its route) larger than `limit`
    bytes is answered 413 before the application parses it."""

    def __init__(self, app: ASGIApp, limit: int) -> None:
        self.app = app
        self.limit = limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] in ("GET", "HEAD") or (
                scope["method"] == "PUT" and ("/files/" in scope["path"] or scope["path"].endswith("/outputs"))
        ) or _streams_files(scope):
            await self.app(scope, receive, send)
            return
        declared = dict(scope["headers"]).get(b"content-length", b"")
        if declared.isdigit() and int(declared) > self.limit:
            await self._refuse(send, int(declared))
            return
        chunks: list[bytes] = []
        size = 0
        more = True
        while more:
            message = await receive()
            if message["type"] != "http.request":
                await self.app(scope, receive, send)  # disconnect: let the app see it
                return
            body = message.get("body", b"")
            size += len(body)
            if size > self.limit:
                await self._refuse(send, size)
                return
            chunks.append(body)
            more = bool(message.get("more_body", False))
        replay = [{"type": "http.request", "body": b"".join(chunks), "more_body": False}]

        async def replayed() -> Message:
            return replay.pop() if replay else await receive()

        await self.app(scope, replayed, send)

    async def _refuse(self, send: Send, size: int) -> None:
        body = json.dumps({"detail": f"request body of {size}+ bytes > limit {self.limit}"}).encode()
        await send({"type": "http.response.start", "status": 413,
                    "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]})
        await send({"type": "http.response.body", "body": body})


def create_app(settings: ApiSettings, job_functions: dict[str, JobFunction] | None = None) -> FastAPI:
    """Build the app: store opened, job queue (`settings.job_queue`: in-process runner or PostgreSQL workers)
    opened and unfinished jobs re-queued in the lifespan."""

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        settings.flights_dir.mkdir(parents=True, exist_ok=True)
        store = Store(settings.db_url)
        functions = job_functions if job_functions is not None else default_job_functions()
        runner = make_job_queue(settings, store, lambda: JobRunner(settings, store, functions))
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
        "Every route but /health needs `Authorization: Bearer <token>` of a role it lets through (its "
        "`x-roles`: drone, engineer, worker; admin passes every check): `python -m ground token create`.",
        lifespan=lifespan,
    )
    app.state.settings = settings
    app.state.file_locks = flights.FileLocks()
    app.add_middleware(BodyLimit, limit=settings.max_json_bytes)
    app.include_router(flights.router)
    app.include_router(worker_jobs.router)
    app.include_router(tokens.router)
    web.install(app)  # the web interface under /ui (its own routes, outside the OpenAPI schema)

    @app.get("/health", tags=["health"])
    def health() -> dict[str, str]:
        """Liveness probe (no flight data, no authentication)."""
        return {"status": "ok"}

    document_roles(app)  # last: every route is in place
    return app
