"""Flights: create from a manifest, resumable checksummed file upload, jobs, results and report.

Upload protocol (every route needs `Authorization: Bearer <token>` of a role the route lets through, see
`ground.api.auth`: a drone token creates flights and uploads the files of its own flights, nothing else):

1. `POST /flights` {name, files: [{name, size, sha256, role?}]} → 201 with the flight id (200 with the same
   flight when name and files are identical: an uploader restarted from scratch resumes; 409 when the name
   exists with other files). Names are relative paths of the flight folder (`events.jsonl`, `radio/000000.ubx`:
   components of letters, digits, `._+-`, no `..`, `\\`, NUL, leading dot or empty component).
2. `HEAD /flights/{id}/files/{name}` → `Upload-Offset` (bytes held, where to resume) and `Upload-Length`.
3. `PUT /flights/{id}/files/{name}?offset=N` body = the next bytes, header `X-Chunk-SHA256` = their SHA-256:
   200 with the new state; 409 if N is not `Upload-Offset`; 422 if the chunk's hash differs (not stored);
   413 for a chunk over the limit or past the promised size; 507 when the disk cannot take it. When the last
   byte arrives the whole file's SHA-256 is checked: the file moves into place (`complete`), or it is discarded
   and restarts at 0 (422).
   `POST /flights/{id}/files` {files: [...]} adds entries (office files: orientations, GCPs) to an existing
   flight, validated as the manifest; their bytes then go by the same PUT.
4. Once every file is complete, jobs are queued by role: `rtk` when `rover_obs` + `base_obs` are present,
   `adjust` when `events` + `orientations` (+ `trajectory`, or the RTK job's) are; or `POST /flights/{id}/jobs`.
   `GET /flights/{id}/results` and `/report` serve the latest finished adjustment.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import logging
import os
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, Any, BinaryIO

from fastapi import APIRouter, Depends, HTTPException, Query, Request, Response, status
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse
from sqlalchemy import select

from ground.api.auth import Principal, Role, check_flight_owner, require_role
from ground.api.deps import SettingsDep, StoreDep
from ground.api.job_kinds import check_job
from ground.api.job_outputs import job_output_dir
from ground.api.queue import JobQueue
from ground.api.schemas import (
    FileOut,
    FilesAdd,
    FlightCreate,
    FlightOut,
    FlightSummary,
    JobCreate,
    JobOut,
    ManifestFile,
)
from ground.api.settings import ApiSettings
from ground.api.upload import (
    Limits,
    UploadRejected,
    check_chunk,
    check_file_name,
    check_file_path,
    check_manifest_files,
    check_sha256,
)
from ground.store import Flight, FlightFile, Job, Store, UploadSession
from onboard.errors import InputError

log = logging.getLogger(__name__)

router = APIRouter(prefix="/flights", tags=["flights"])

#: who may call what (ADMIN passes every check); a drone only ever sees the flights it created
Uploader = Annotated[Principal, Depends(require_role(Role.DRONE, Role.ENGINEER))]
FlightReader = Annotated[Principal, Depends(require_role(Role.DRONE, Role.ENGINEER, Role.WORKER))]
FileReader = Annotated[Principal, Depends(require_role(Role.ENGINEER, Role.WORKER))]
JobReader = Annotated[Principal, Depends(require_role(Role.ENGINEER, Role.WORKER))]
Engineer = Annotated[Principal, Depends(require_role(Role.ENGINEER))]

CHUNK_SHA_HEADER = "X-Chunk-SHA256"
OFFSET_HEADER = "Upload-Offset"
LENGTH_HEADER = "Upload-Length"



class FileLocks:
    """One lock per (flight, file), so chunk appends to one file are serialised (one per app, on app.state)."""

    def __init__(self) -> None:
        self._locks: dict[tuple[str, str], threading.Lock] = {}
        self._guard = threading.Lock()

    def get(self, flight_id: str, name: str) -> threading.Lock:
        """The lock of this file (created on first use)."""
        with self._guard:
            return self._locks.setdefault((flight_id, name), threading.Lock())


#: partial uploads live here, apart from the final names (a manifest name can never start with a dot)
PARTIAL_DIR = ".partial"


def partial_path(path: Path) -> Path:
    """Where the bytes of a file being uploaded accumulate until its SHA-256 is verified."""
    return path.parent / PARTIAL_DIR / path.name


def _limits(s: ApiSettings) -> Limits:
    return Limits(s.max_file_bytes, s.max_flight_bytes, s.max_chunk_bytes, s.max_files_per_flight)


def flight_dir(settings: ApiSettings, flight_id: str) -> Path:
    """Directory of a flight's raw files."""
    return settings.flights_dir / flight_id


def safe_path(settings: ApiSettings, flight_id: str, name: str) -> Path:
    """Path of a flight file (`check_file_path`: a sub-folder such as `radio/` allowed); the result must stay
    inside the flight directory, also through a symbolic link on the server's disk."""
    check_file_path(name)
    base = flight_dir(settings, flight_id).resolve()
    p = (base / name).resolve()
    if not p.is_relative_to(base) or p.relative_to(base).as_posix() != name:
        raise UploadRejected(400, f"file name {name!r} escapes the flight directory")
    return p


def _http(exc: UploadRejected) -> HTTPException:
    return HTTPException(status_code=exc.status, detail=exc.detail)


def _file_out(f: FlightFile) -> FileOut:
    return FileOut(name=f.name, role=f.role, size=f.size, sha256=f.sha256, received=f.received,
                   status=f.status)  # type: ignore[arg-type]


def job_out(j: Job) -> JobOut:
    """Schema of a job row."""
    return JobOut(id=j.id, kind=j.kind, status=j.status, params=j.params, message=j.message,  # type: ignore[arg-type]
                  created_at=j.created_at, started_at=j.started_at, finished_at=j.finished_at)


def _creator(f: Flight) -> str | None:
    return f.creator.name if f.creator is not None else None


def _flight_out(f: Flight) -> FlightOut:
    return FlightOut(id=f.id, name=f.name, status=f.status, created_at=f.created_at, created_by=_creator(f),
                     files=[_file_out(x) for x in sorted(f.files, key=lambda x: x.name)],  # as loaded, also
                     jobs=[job_out(j) for j in f.jobs])  # right after files were appended in this session


def _flight_of(s: Any, flight_id: str, principal: Principal) -> Flight:
    """The flight, 404 when absent, 403 when a drone token did not create it."""
    flight = s.get(Flight, flight_id)
    if flight is None:
        raise HTTPException(status_code=404, detail=f"no flight {flight_id}")
    check_flight_owner(principal, flight.created_by)
    return flight


def _get_flight(store: Store, flight_id: str, principal: Principal) -> Flight:
    with store.session() as s:
        f = _flight_of(s, flight_id, principal)
        f.files, f.jobs  # noqa: B018 - load relationships before the session closes
        return f


def _entry_triples(files: list[ManifestFile], limits: Limits,
                   held: Sequence[tuple[str, int, str]] = ()) -> list[tuple[str, int, str]]:
    """(name, size, sha256) of manifest entries, checked by the manifest's rules (names, duplicates, sizes),
    and with the files a flight already `held` against the per-flight limits."""
    triples = [(f.name, f.size, check_sha256(f.sha256)) for f in files]
    check_manifest_files(triples, limits)
    if held:
        check_manifest_files([*held, *triples], limits)
    return triples


def _register_files(settings: ApiSettings, s: Any, flight: Flight, files: list[ManifestFile]) -> None:
    """Add rows for new manifest entries to `flight` (in session `s`) and verify the empty ones at once."""
    new = [FlightFile(name=f.name, size=f.size, sha256=f.sha256.strip().lower(), role=f.role,
                      status="pending" if f.size else "partial") for f in files]
    flight.files.extend(new)
    if any(f.size for f in new):
        flight.status = "uploading"
    s.add(flight)
    s.flush()  # the flight's id exists from here
    flight_dir(settings, flight.id).mkdir(parents=True, exist_ok=True)
    for ff in new:
        if ff.size == 0:  # nothing to send: verify the empty file's hash now
            _finish_file(settings, s, flight, ff, safe_path(settings, flight.id, ff.name))


@router.post("", response_model=FlightOut, status_code=status.HTTP_201_CREATED,
             responses={200: {"model": FlightOut, "description": "identical flight already exists (resume)"},
                        400: {}, 409: {}, 413: {}, 422: {}})
def create_flight(body: FlightCreate, response: Response, settings: SettingsDep,
                  store: StoreDep, principal: Uploader) -> FlightOut:
    """Create a flight from its upload manifest; the same name and files again returns the existing flight
    (409 when it exists with other files, or was created by another drone token)."""
    try:
        check_file_name(body.name)
        triples = _entry_triples(body.files, _limits(settings))
    except UploadRejected as exc:
        raise _http(exc) from exc
    with store.session() as s:
        existing = s.scalar(select(Flight).where(Flight.name == body.name))
        if existing is not None:
            same = sorted((f.name, f.size, f.sha256) for f in existing.files) == sorted(triples)
            if not same:
                raise HTTPException(status_code=409, detail=f"flight {body.name!r} exists with other files")
            if principal.role is Role.DRONE and existing.created_by != principal.token_id:
                raise HTTPException(status_code=409, detail=f"flight {body.name!r} exists, created by another token")
            response.status_code = status.HTTP_200_OK
            existing.files, existing.jobs  # noqa: B018
            return _flight_out(existing)
        flight = Flight(name=body.name, manifest=body.model_dump(), created_by=principal.token_id)
        _register_files(settings, s, flight, body.files)
        s.commit()
        log.info("flight %s (%s) created with %d files", flight.id, flight.name, len(flight.files))
        return _flight_out(flight)


def add_files(settings: ApiSettings, store: Store, flight_id: str, files: list[ManifestFile],
              principal: Principal) -> FlightOut:
    """Add manifest entries to an existing flight (office files: orientations, GCPs, …); the bytes then go by
    `PUT /flights/{id}/files/{name}` (or `_append_chunk`). Checked as the manifest at creation, together with
    the files held for the per-flight limits; an entry identical (name, size, SHA-256) to one held is kept as
    it is; a held name with another size or hash → `HTTPException(409)`; bad entries → 400/413/422; 404/403
    as the flight routes. The flight goes back to `uploading` until the new files are complete."""
    with store.session() as s:
        flight = _flight_of(s, flight_id, principal)
        held = {f.name: f for f in flight.files}
        try:
            _entry_triples(files, _limits(settings))
            for f in files:
                h = held.get(f.name)
                if h is not None and (h.size, h.sha256) != (f.size, check_sha256(f.sha256)):
                    raise UploadRejected(409, f"{f.name!r} is already in this flight with another size or "
                                              "SHA-256")
            new = [f for f in files if f.name not in held]
            if new:  # with the files held: the flight's file count and total size
                _entry_triples(new, _limits(settings), [(h.name, h.size, h.sha256) for h in held.values()])
        except UploadRejected as exc:
            raise _http(exc) from exc
        if new:
            _register_files(settings, s, flight, new)
            s.commit()
            log.info("flight %s: %d files added by %s", flight.id, len(new), principal.name)
        flight.files, flight.jobs  # noqa: B018
        return _flight_out(flight)


@router.post("/{flight_id}/files", response_model=FlightOut, responses={400: {}, 404: {}, 409: {}, 413: {}, 422: {}})
def add_flight_files(flight_id: str, body: FilesAdd, settings: SettingsDep, store: StoreDep,
                     principal: Uploader) -> FlightOut:
    """Add file entries (name, size, SHA-256, role) to an existing flight, e.g. the bundle adjustment's
    orientations and the GCP file; then upload their bytes with PUT. Identical entries again change nothing;
    a name held with another size or SHA-256 → 409."""
    return add_files(settings, store, flight_id, body.files, principal)


@router.get("", response_model=list[FlightSummary])
def list_flights(store: StoreDep, _: Engineer) -> list[FlightSummary]:
    """All flights, newest first."""
    with store.session() as s:
        rows = s.scalars(select(Flight).order_by(Flight.created_at.desc())).all()
        return [FlightSummary(id=f.id, name=f.name, status=f.status, created_at=f.created_at,
                              created_by=_creator(f), files=len(f.files),
                              bytes_total=sum(x.size for x in f.files), bytes_received=sum(x.received for x in f.files))
                for f in rows]


@router.get("/{flight_id}", response_model=FlightOut)
def get_flight(flight_id: str, store: StoreDep, principal: FlightReader) -> FlightOut:
    """A flight with its files and jobs (a drone token: only a flight it created)."""
    return _flight_out(_get_flight(store, flight_id, principal))


def _lookup_file(s: Any, flight_id: str, name: str, principal: Principal) -> tuple[Flight, FlightFile]:
    flight = _flight_of(s, flight_id, principal)
    f = s.scalar(select(FlightFile).where(FlightFile.flight_id == flight_id, FlightFile.name == name))
    if f is None:
        raise HTTPException(status_code=404, detail=f"{name!r} is not in this flight's manifest")
    return flight, f


@router.get("/{flight_id}/files/{name:path}/content", response_class=FileResponse)
def download_file(flight_id: str, name: str, settings: SettingsDep,
                  store: StoreDep, principal: FileReader) -> FileResponse:
    """The bytes of a completely uploaded file."""
    try:
        path = safe_path(settings, flight_id, name)
    except UploadRejected as exc:
        raise _http(exc) from exc
    with store.session() as s:
        _, f = _lookup_file(s, flight_id, name, principal)
        if f.status != "complete":
            raise HTTPException(status_code=409, detail=f"{name} is not completely uploaded")
    return FileResponse(path, media_type="application/octet-stream", filename=path.name)


@router.head("/{flight_id}/files/{name:path}")
def file_offset_head(flight_id: str, name: str, settings: SettingsDep,
                     store: StoreDep, principal: FlightReader) -> Response:
    """Upload-Offset (bytes received, where to resume) and Upload-Length (promised size) as headers."""
    out = file_status(flight_id, name, settings, store, principal)
    return Response(status_code=200, headers={OFFSET_HEADER: str(out.received), LENGTH_HEADER: str(out.size)})


@router.get("/{flight_id}/files/{name:path}", response_model=FileOut)
def file_status(flight_id: str, name: str, settings: SettingsDep,
                store: StoreDep, principal: FlightReader) -> FileOut:
    """Upload state of one file (received bytes = where an interrupted upload resumes)."""
    try:
        safe_path(settings, flight_id, name)
    except UploadRejected as exc:
        raise _http(exc) from exc
    with store.session() as s:
        _, f = _lookup_file(s, flight_id, name, principal)
        return _file_out(f)


async def _read_body_capped(request: Request, limit: int) -> bytes:
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > limit:
        raise HTTPException(status_code=413, detail=f"chunk of {declared} bytes > limit {limit}")
    buf = bytearray()
    async for part in request.stream():
        buf.extend(part)
        if len(buf) > limit:
            raise HTTPException(status_code=413, detail=f"chunk larger than the limit {limit}")
    return bytes(buf)


@router.put("/{flight_id}/files/{name:path}", response_model=FileOut,
            responses={400: {}, 404: {}, 409: {}, 413: {}, 422: {}, 507: {}},
            openapi_extra={"requestBody": {"content": {"application/octet-stream": {"schema": {
                "type": "string", "format": "binary"}}}, "required": True}})
async def put_chunk(
    flight_id: str,
    name: str,
    request: Request,
    settings: SettingsDep,
    store: StoreDep,
    principal: Uploader,
    offset: Annotated[int, Query(ge=0, description="byte offset of this chunk in the file (= bytes received so far)")],
) -> FileOut:
    """Append one chunk at `offset`. Header `X-Chunk-SHA256` (hex) must match the body or the chunk is refused.

    409 when `offset` is not the received length (resume from HEAD's Upload-Offset); 413 for an oversized chunk
    or one past the promised size; 422 when the completed file's SHA-256 differs from the manifest (the partial
    data is discarded and the file restarts at 0).
    """
    try:
        path = safe_path(settings, flight_id, name)
    except UploadRejected as exc:
        raise _http(exc) from exc
    body = await _read_body_capped(request, settings.max_chunk_bytes)
    claimed = request.headers.get(CHUNK_SHA_HEADER)
    if claimed is None:
        raise HTTPException(status_code=400, detail=f"missing {CHUNK_SHA_HEADER} header")
    client = request.client.host if request.client else ""
    return await run_in_threadpool(_append_chunk, settings, store, flight_id, name, path, offset, body,
                                   claimed, client, request.app.state.jobs, request.app.state.file_locks, principal)


def _append_chunk(settings: ApiSettings, store: Store, flight_id: str, name: str, path: Path, offset: int,
                  body: bytes, claimed: str, client: str, jobs: JobQueue | None, locks: FileLocks,
                  principal: Principal) -> FileOut:
    """Store one chunk (the PUT route's work); the flight's automatic jobs are queued on `jobs` when this chunk
    completes the flight (`jobs` None: the caller queues its own job, e.g. the web adjustment form)."""
    with locks.get(flight_id, name), store.session() as s:
        flight, f = _lookup_file(s, flight_id, name, principal)
        if f.status == "complete":
            raise HTTPException(status_code=409, detail=f"{name} is already complete")
        part = partial_path(path)
        on_disk = part.stat().st_size if part.exists() else 0
        if on_disk != f.received:  # a crash between write and commit: the disk is the truth
            log.warning("%s/%s: received %d in DB but %d on disk; using the disk", flight_id, name, f.received,
                        on_disk)
            f.received = on_disk
        sess = s.scalar(select(UploadSession).where(UploadSession.file_id == f.id, UploadSession.client == client)
                        .order_by(UploadSession.id.desc()))
        if sess is None or sess.start_offset + sess.bytes_received != offset:
            sess = UploadSession(file_id=f.id, client=client, start_offset=offset, bytes_received=0, chunks=0,
                                 rejected_chunks=0)
            s.add(sess)
        try:
            check_sha256(claimed)
            if hashlib.sha256(body).hexdigest() != claimed.strip().lower():
                raise UploadRejected(422, f"chunk at offset {offset} is corrupted: SHA-256 mismatch, not stored")
            check_chunk(offset, f.received, len(body), f.size, _limits(settings))
        except UploadRejected as exc:
            sess.rejected_chunks += 1
            s.commit()
            raise _http(exc) from exc
        part.parent.mkdir(parents=True, exist_ok=True)
        try:
            with open(part, "ab") as fh:
                fh.write(body)
                fh.flush()
                os.fsync(fh.fileno())
        except OSError as exc:
            # full disk, quota, file-size limit: cut back to the last whole chunk so nothing half-written stays
            with open(part, "ab") as fh:
                fh.truncate(offset)
            sess.rejected_chunks += 1
            s.commit()
            log.error("%s/%s: cannot store chunk at %d: %s", flight_id, name, offset, exc)
            raise HTTPException(status_code=507, detail=f"cannot store the chunk ({exc.strerror}); "
                                                        f"resume from {offset} when space is back") from exc
        f.received = offset + len(body)
        f.status = "partial"
        sess.bytes_received += len(body)
        sess.chunks += 1
        sess.updated_at = dt.datetime.now(dt.UTC)
        if f.received == f.size:
            _finish_file(settings, s, flight, f, path)
        s.commit()
        out = _file_out(f)
        if f.status != "complete" and f.received == 0:
            raise HTTPException(status_code=422, detail=f"{name}: whole-file SHA-256 differs from the manifest; "
                                                        "the data was discarded, upload again from offset 0")
    if flight.status == "complete" and jobs is not None:
        _maybe_auto_adjust(store, flight_id, jobs)
    return out


def write_file_bytes(settings: ApiSettings, store: Store, jobs: JobQueue | None, locks: FileLocks, flight_id: str,
                     name: str, source: BinaryIO, principal: Principal, client: str = "web") -> FileOut:
    """Store the whole content of a file the flight lists (e.g. added by `add_files` from a web form), read
    from `source` at the server's offset (an interrupted earlier write resumes), in chunks of the chunk limit,
    each through the same path as `PUT …/files/{name}` (locks, checks, whole-file SHA-256, automatic jobs;
    `jobs` None: none, the caller queues the job it was asked for, as the web adjustment form does).
    Returns the file's state; `HTTPException` as the PUT route (422: the bytes' SHA-256 differs from the listed
    one, or `source` ends before the listed size; 413: it runs past it)."""
    path = safe_path(settings, flight_id, name)
    with store.session() as s:
        _, f = _lookup_file(s, flight_id, name, principal)
        out = _file_out(f)
    source.seek(out.received)
    while out.status != "complete":
        chunk = source.read(settings.max_chunk_bytes)
        if not chunk:
            raise HTTPException(status_code=422, detail=f"{name}: {out.received} bytes given, {out.size} listed")
        out = _append_chunk(settings, store, flight_id, name, path, out.received, chunk,
                            hashlib.sha256(chunk).hexdigest(), client, jobs, locks, principal)
    return out


def _finish_file(settings: ApiSettings, s: Any, flight: Flight, f: FlightFile, path: Path) -> None:
    """Verify the whole file's SHA-256 and move it into place; on mismatch discard it and restart at 0."""
    part = partial_path(path)
    part.parent.mkdir(parents=True, exist_ok=True)
    part.touch()
    h = hashlib.sha256()
    with open(part, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    if h.hexdigest() != f.sha256:
        log.warning("%s/%s: final SHA-256 mismatch; discarding %d bytes", flight.id, f.name, f.received)
        part.unlink()
        f.received = 0
        f.status = "pending"
        return
    os.replace(part, path)
    f.status = "complete"
    if all(x.status == "complete" for x in flight.files):
        flight.status = "complete"


# ------------------------------------------------------------------------------------------------- jobs

ADJUST_ROLES = ("events", "orientations")
RTK_ROLES = ("rover_obs", "base_obs")


def _maybe_auto_adjust(store: Store, flight_id: str, jobs: JobQueue) -> None:
    """Once every file is in, queue the automatic jobs (only on a flight that has none yet):
    RTK re-processing when rover and base observations were uploaded, then the adjustment when events and
    orientations were uploaded with a trajectory (uploaded, or the one the RTK job will write)."""
    with store.session() as s:
        flight = s.get(Flight, flight_id)
        if flight is None or flight.jobs:
            return
        roles = {f.role for f in flight.files}
        queued: list[Job] = []
        if all(r in roles for r in RTK_ROLES):
            queued.append(Job(flight_id=flight_id, kind="rtk", params={}))
        if all(r in roles for r in ADJUST_ROLES) and ("trajectory" in roles or queued):
            queued.append(Job(flight_id=flight_id, kind="adjust", params={}))
        s.add_all(queued)
        s.commit()
        ids = [(j.id, j.kind) for j in queued]
    for job_id, kind in ids:  # one worker by default: the RTK job runs before the adjustment
        log.info("flight %s complete: %s job %s queued", flight_id, kind, job_id)
        jobs.submit(job_id)


def validate_and_queue_job(store: Store, jobs: JobQueue, flight_id: str, kind: str, params: dict[str, Any],
                           principal: Principal) -> JobOut:
    """Check a job against the flight (404 no flight, 403 not the caller's, 409 upload not complete, 422 bad
    parameters or missing files: HTTPException with the reason in words), record it `queued` and hand it to
    the job queue."""
    with store.session() as s:
        flight = _flight_of(s, flight_id, principal)
        if flight.status != "complete":
            raise HTTPException(status_code=409, detail="the flight's upload is not complete")
        try:
            check_job(kind, params, {f.name: f.role for f in flight.files if f.status == "complete"})
        except InputError as exc:
            raise HTTPException(status_code=422, detail=f"{kind} job: {exc}") from exc
        job = Job(flight_id=flight_id, kind=kind, params=params)
        s.add(job)
        s.commit()
        out = job_out(job)
    jobs.submit(out.id)
    return out


@router.post("/{flight_id}/jobs", response_model=JobOut, status_code=status.HTTP_202_ACCEPTED,
             responses={404: {}, 409: {}, 413: {}, 422: {}})
def create_job(flight_id: str, body: JobCreate, request: Request, store: StoreDep, principal: Engineer) -> JobOut:
    """Queue a processing job (runs in the background; poll its status)."""
    return validate_and_queue_job(store, request.app.state.jobs, flight_id, body.kind, body.params, principal)


@router.get("/{flight_id}/jobs/{job_id}", response_model=JobOut)
def get_job(flight_id: str, job_id: str, store: StoreDep, _: JobReader) -> JobOut:
    """A job's status and message."""
    with store.session() as s:
        job = s.get(Job, job_id)
        if job is None or job.flight_id != flight_id:
            raise HTTPException(status_code=404, detail=f"no job {job_id} on flight {flight_id}")
        return job_out(job)


def latest_output(settings: ApiSettings, store: Store, flight_id: str, filename: str) -> Path:
    """A file of the latest finished adjustment of the flight (404 in words when there is none or it lacks it)."""
    with store.session() as s:
        flight = s.get(Flight, flight_id)
        if flight is None:
            raise HTTPException(status_code=404, detail=f"no flight {flight_id}")
        done = [j for j in flight.jobs if j.kind == "adjust" and j.status == "done"]
    if not done:
        raise HTTPException(status_code=404, detail="no finished adjustment for this flight")
    path = job_output_dir(settings.data_dir, flight_id, done[-1].id) / filename
    if not path.is_file():
        raise HTTPException(status_code=404, detail=f"{filename} missing from the last adjustment")
    return path


@router.get("/{flight_id}/results", response_class=JSONResponse)
def get_results(flight_id: str, settings: SettingsDep,
                store: StoreDep, _: Engineer) -> Response:
    """`results.json` of the latest finished adjustment."""
    path = latest_output(settings, store, flight_id, "results.json")
    return Response(content=path.read_bytes(), media_type="application/json")


@router.get("/{flight_id}/report", response_class=HTMLResponse)
def get_report(flight_id: str, settings: SettingsDep,
               store: StoreDep, _: Engineer) -> Response:
    """The self-contained HTML report of the latest finished adjustment."""
    path = latest_output(settings, store, flight_id, "report.html")
    return HTMLResponse(content=path.read_text(encoding="utf-8"))


def export_names(settings: ApiSettings, store: Store, flight_id: str) -> list[str]:
    """Names of the export files of the latest finished adjustment (404 when there is none)."""
    folder = latest_output(settings, store, flight_id, "results.json").parent / "exports"
    return sorted(p.name for p in folder.iterdir() if p.is_file()) if folder.is_dir() else []


def export_path(settings: ApiSettings, store: Store, flight_id: str, name: str) -> Path:
    """One export file of the latest finished adjustment (400 for a bad name, 404 when absent)."""
    try:
        check_file_name(name)
    except UploadRejected as exc:
        raise _http(exc) from exc
    path = latest_output(settings, store, flight_id, "results.json").parent / "exports" / name
    if not path.is_file():
        raise HTTPException(status_code=404, detail=f"no export {name!r}")
    return path


@router.get("/{flight_id}/exports", response_model=list[str])
def list_exports(flight_id: str, settings: SettingsDep, store: StoreDep, _: Engineer) -> list[str]:
    """Geotag/orientation export files of the latest finished adjustment (geo.txt, pix4d.csv, …)."""
    return export_names(settings, store, flight_id)


@router.get("/{flight_id}/exports/{name}", response_class=FileResponse)
def get_export(flight_id: str, name: str, settings: SettingsDep, store: StoreDep, _: Engineer) -> FileResponse:
    """One export file of the latest finished adjustment."""
    return FileResponse(export_path(settings, store, flight_id, name), media_type="text/plain", filename=name)
