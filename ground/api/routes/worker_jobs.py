"""Jobs run by `python -m ground worker`, and every job's output files.

A worker (role worker) runs one queued job through these routes, never touching the server's disk:

1. `POST /flights/{id}/jobs/{job}/claim` → the job's spec (kind, parameters, time limit, the flight files and
   earlier outputs to fetch with their SHA-256); the job becomes `running`. 409 when it already ended (a
   duplicate delivery: nothing to do).
2. fetch the files: `GET /flights/{id}/files/{name}/content`, `GET /flights/{id}/jobs/{other}/outputs/{name}`.
3. `PUT /flights/{id}/jobs/{job}/outputs` body = the output folder as a tar (`ground.api.job_outputs`), header
   `X-Content-SHA256`: checked, unpacked beside the job's folder and renamed into place (all or nothing). A
   retried job posting the same archive leaves the same bytes.
4. `POST /flights/{id}/jobs/{job}/finish` {status: done|failed, message}: the first final word is kept.

Engineers list and download any job's outputs (`GET …/outputs`, `GET …/outputs/{name}`, e.g. the RTK job's
`SOL.pos`).
"""

from __future__ import annotations

import datetime as dt
import hashlib
import logging
import os
from pathlib import Path

from fastapi import APIRouter, Depends, HTTPException, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse

from ground.api.auth import Role, require_role
from ground.api.deps import SettingsDep, StoreDep
from ground.api.job_kinds import reprocessed_trajectory
from ground.api.job_outputs import (
    OutputFile,
    install_outputs,
    job_output_dir,
    list_outputs,
    staging_path,
)
from ground.api.routes.flights import job_out
from ground.api.schemas import JobFinish, JobInputFile, JobOut, JobSpec, OutputFileOut
from ground.store import Flight, Job, Store
from onboard.errors import InputError
from onboard.formats.digest import sha256_file

log = logging.getLogger(__name__)

CONTENT_SHA_HEADER = "X-Content-SHA256"
#: who may call: workers run jobs (admin passes every check); engineers and workers read outputs (a worker
#: fetches an earlier job's trajectory)
WORKER_ONLY = [Depends(require_role(Role.WORKER))]
READERS = [Depends(require_role(Role.ENGINEER, Role.WORKER))]

router = APIRouter(prefix="/flights", tags=["jobs"])


def _job(s: object, flight_id: str, job_id: str) -> Job:
    job = s.get(Job, job_id)  # type: ignore[attr-defined]
    if job is None or job.flight_id != flight_id:
        raise HTTPException(status_code=404, detail=f"no job {job_id} on flight {flight_id}")
    return job  # type: ignore[no-any-return]


def _out(f: OutputFile) -> OutputFileOut:
    return OutputFileOut(name=f.name, size=f.size, sha256=f.sha256)


@router.post("/{flight_id}/jobs/{job_id}/claim", response_model=JobSpec, dependencies=WORKER_ONLY,
             responses={404: {}, 409: {"description": "the job already ended"}})
def claim_job(flight_id: str, job_id: str, settings: SettingsDep, store: StoreDep) -> JobSpec:
    """A worker takes the job: it becomes `running` and its spec is returned (also to a worker retrying the
    job of a dead one)."""
    out_dir = job_output_dir(settings.data_dir, flight_id, job_id)
    with store.session() as s:
        job = _job(s, flight_id, job_id)
        if job.status in ("done", "failed"):
            raise HTTPException(status_code=409, detail=f"job {job_id} already ended ({job.status})")
        flight = s.get(Flight, flight_id)
        assert flight is not None  # foreign key
        files = [JobInputFile(name=f.name, role=f.role, size=f.size, sha256=f.sha256)
                 for f in flight.files if f.status == "complete"]
        job.status, job.started_at, job.message, job.finished_at = "running", dt.datetime.now(dt.UTC), "", None
        s.commit()
        kind, params = job.kind, dict(job.params)
    earlier: list[JobInputFile] = []
    if kind == "adjust":  # the trajectory an earlier RTK job wrote (the same rule as the in-process runner)
        sol = reprocessed_trajectory(out_dir)
        if sol is not None:
            earlier.append(JobInputFile(name=sol.name, size=sol.stat().st_size, sha256=sha256_file(sol),
                                        job_id=sol.parent.name))
    log.info("job %s (%s, flight %s) claimed by a worker", job_id, kind, flight_id)
    return JobSpec(job_id=job_id, flight_id=flight_id, kind=kind, params=params,
                   time_limit_s=settings.job_timeout_s, files=files, earlier_outputs=earlier)


async def _spool_body(request: Request, path: Path, limit: int) -> str:
    """Write the request body to `path` (at most `limit` bytes, else 413); its SHA-256 (hex)."""
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > limit:
        raise HTTPException(status_code=413, detail=f"outputs archive of {declared} bytes > limit {limit}")
    h, size = hashlib.sha256(), 0
    fh = await run_in_threadpool(open, path, "wb")  # disk writes off the event loop
    try:
        async for part in request.stream():
            size += len(part)
            if size > limit:
                raise HTTPException(status_code=413, detail=f"outputs archive larger than the limit {limit}")
            h.update(part)
            await run_in_threadpool(fh.write, part)
    finally:
        fh.close()
    return h.hexdigest()


@router.put("/{flight_id}/jobs/{job_id}/outputs", response_model=list[OutputFileOut], dependencies=WORKER_ONLY,
            responses={400: {}, 404: {}, 413: {}, 422: {}},
            openapi_extra={"requestBody": {"content": {"application/x-tar": {"schema": {
                "type": "string", "format": "binary"}}}, "required": True}})
async def put_outputs(flight_id: str, job_id: str, request: Request, settings: SettingsDep,
                      store: StoreDep) -> list[OutputFileOut]:
    """The job's whole output folder as a tar (header X-Content-SHA256): installed atomically. On a job that
    already ended the folder is left as it is and listed (a late duplicate of a retried job)."""
    claimed = request.headers.get(CONTENT_SHA_HEADER, "").strip().lower()
    if len(claimed) != 64:
        raise HTTPException(status_code=400, detail=f"missing or malformed {CONTENT_SHA_HEADER} header")
    dest = job_output_dir(settings.data_dir, flight_id, job_id)
    with store.session() as s:
        ended = _job(s, flight_id, job_id).status in ("done", "failed")
    if ended:
        return [_out(f) for f in await run_in_threadpool(list_outputs, dest)]
    dest.parent.mkdir(parents=True, exist_ok=True)
    spool = staging_path(dest, "upload")
    try:
        if await _spool_body(request, spool, settings.max_output_bytes) != claimed:
            raise HTTPException(status_code=422, detail="outputs archive corrupted: SHA-256 mismatch, not stored")
        try:
            listing = await run_in_threadpool(install_outputs, spool, dest)
        except InputError as exc:
            raise HTTPException(status_code=422, detail=str(exc)) from exc
    finally:
        spool.unlink(missing_ok=True)
    log.info("job %s: %d output files installed", job_id, len(listing))
    return [_out(f) for f in listing]


@router.post("/{flight_id}/jobs/{job_id}/finish", response_model=JobOut, dependencies=WORKER_ONLY,
             responses={404: {}})
def finish_job(flight_id: str, job_id: str, body: JobFinish, store: StoreDep) -> JobOut:
    """The job's final status and message; a job that already ended keeps its first final word."""
    with store.session() as s:
        job = _job(s, flight_id, job_id)
        if job.status not in ("done", "failed"):
            job.status, job.message, job.finished_at = body.status, body.message[:4000], dt.datetime.now(dt.UTC)
            s.commit()
            (log.info if body.status == "done" else log.warning)("job %s %s: %s", job_id, body.status,
                                                                 body.message[:200])
        return job_out(job)


def _existing_job(store: Store, flight_id: str, job_id: str) -> None:
    with store.session() as s:
        _job(s, flight_id, job_id)


@router.get("/{flight_id}/jobs/{job_id}/outputs", response_model=list[OutputFileOut], dependencies=READERS,
            responses={404: {}})
def get_outputs(flight_id: str, job_id: str, settings: SettingsDep, store: StoreDep) -> list[OutputFileOut]:
    """The job's output files (relative names, sizes, SHA-256); empty while it has none."""
    _existing_job(store, flight_id, job_id)
    return [_out(f) for f in list_outputs(job_output_dir(settings.data_dir, flight_id, job_id))]


@router.get("/{flight_id}/jobs/{job_id}/outputs/{name:path}", response_class=FileResponse, dependencies=READERS,
            responses={400: {}, 404: {}})
def get_output(flight_id: str, job_id: str, name: str, settings: SettingsDep, store: StoreDep) -> FileResponse:
    """One output file of the job (e.g. `SOL.pos` of an RTK job, `exports/geo.txt` of an adjustment)."""
    _existing_job(store, flight_id, job_id)
    base = job_output_dir(settings.data_dir, flight_id, job_id).resolve()
    path = (base / name).resolve()
    if not path.is_relative_to(base) or path == base or any(p.startswith(".") for p in Path(name).parts):
        raise HTTPException(status_code=400, detail=f"output name {name!r} escapes the job's folder")
    if not path.is_file():
        raise HTTPException(status_code=404, detail=f"no output {name!r} of job {job_id}")
    return FileResponse(path, media_type="application/octet-stream", filename=os.path.basename(name))
