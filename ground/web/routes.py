"""The web interface's pages, under `/ui` (the API keeps `/flights…`): sign-in, flights list, flight page,
adjustment form, report and exports. Every page needs a signed-in session (`ground.web.sessions`); every POST
form carries the session's CSRF token and is refused (403, in words) without it. The pages call the same core
functions as the API routes: `validate_and_queue_job` (validate and queue a job, as `POST /flights/{id}/jobs`), `add_files` and
`write_file_bytes` (office files into a flight), `latest_output` / `export_path` (results).

Routes (none in the OpenAPI schema: they are for browsers, not API clients):

- `GET /` → `/ui/flights`; `GET /ui/login`, `POST /ui/login`, `POST /ui/logout`
- `GET /ui/flights` (filters `state`, `drone`, `date_from`, `date_to`)
- `GET /ui/flights/{id}`, `GET /ui/flights/{id}/status` (JSON for the page's live status)
- `GET|POST /ui/flights/{id}/adjust`, `POST /ui/flights/{id}/rtk`
- `GET /ui/flights/{id}/report`, `GET /ui/flights/{id}/exports/{name}`, `GET /ui/flights/{id}/files/{name}`
"""

from __future__ import annotations

import datetime as dt
import hashlib
import logging
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any
from urllib.parse import quote, urlsplit

from fastapi import APIRouter, Depends, FastAPI, HTTPException, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.exception_handlers import http_exception_handler, request_validation_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, RedirectResponse, Response
from fastapi.staticfiles import StaticFiles
from fastapi.templating import Jinja2Templates
from sqlalchemy import select
from starlette.datastructures import FormData, UploadFile
from starlette.exceptions import HTTPException as StarletteHTTPException

from ground.api.auth import Principal, Role, authenticate
from ground.api.routes.flights import (
    add_files,
    export_names,
    export_path,
    latest_output,
    validate_and_queue_job,
    write_file_bytes,
)
from ground.api.schemas import ManifestFile
from ground.api.settings import ApiSettings
from ground.api.upload import UploadRejected, check_file_name
from ground.store import Flight, Store
from ground.web import flightinfo
from ground.web.sessions import (
    CSRF_FIELD,
    LOGIN_CSRF_COOKIE,
    SESSION_COOKIE,
    SignedIn,
    close_session,
    csrf_matches,
    find_session,
    new_secret,
    open_session,
    sign_in_refusal,
)
from onboard.errors import InputError

log = logging.getLogger(__name__)

PREFIX = "/ui"
HERE = Path(__file__).parent
templates = Jinja2Templates(directory=HERE / "templates")
router = APIRouter(include_in_schema=False)


def _duration(seconds: float | None) -> str:
    if seconds is None:
        return "—"
    m, s = divmod(round(seconds), 60)
    return f"{m // 60} h {m % 60:02d} min" if m >= 60 else f"{m} min {s:02d} s"


def _size(n: int | None) -> str:
    if n is None:
        return "—"
    if n < 1024:
        return f"{n} B"
    value = float(n)
    for unit in ("KiB", "MiB", "GiB"):
        value /= 1024
        if value < 1024 or unit == "GiB":
            break
    return f"{value:.1f} {unit}"


def _pct(ratio: float | None) -> str:
    return "—" if ratio is None else f"{100 * ratio:.1f} %"


def _utc(t: dt.datetime | None) -> str:
    if t is None:
        return ""
    t = t if t.tzinfo is not None else t.replace(tzinfo=dt.UTC)
    return t.astimezone(dt.UTC).strftime("%Y-%m-%d %H:%M:%S")


templates.env.filters.update(duration=_duration, size=_size, pct=_pct, utc=_utc)


def _now() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


class SignInNeeded(Exception):
    """No live session: a page redirects to the sign-in form, the JSON status route answers 401."""


def _settings(request: Request) -> ApiSettings:
    settings: ApiSettings = request.app.state.settings
    return settings


def _store(request: Request) -> Store:
    store: Store = request.app.state.store
    return store


def signed_in(request: Request) -> SignedIn:
    """The session of the request's cookie, else `SignInNeeded`."""
    user = find_session(_store(request), request.cookies.get(SESSION_COOKIE), _now())
    if user is None:
        raise SignInNeeded
    return user


User = Annotated[SignedIn, Depends(signed_in)]


def _principal(user: SignedIn) -> Principal:
    return Principal(token_id=user.token_id, name=user.name, role=Role(user.role))


async def checked_form(request: Request, user: SignedIn) -> FormData:
    """The POSTed form when its CSRF field is the session's token; 403 in words otherwise."""
    form = await request.form()
    if not csrf_matches(user.csrf_token, form.get(CSRF_FIELD)):
        raise HTTPException(status_code=403, detail="this form was refused: its security token (CSRF) is missing or "
                            "does not belong to your session. Reload the page and send it again.")
    return form


def _page(request: Request, name: str, user: SignedIn | None, status_code: int = 200, **context: Any) -> HTMLResponse:
    ctx = {"user": user, "csrf_field": CSRF_FIELD, "prefix": PREFIX, **context}
    return templates.TemplateResponse(request, name, ctx, status_code=status_code)


def _cookie_secure(request: Request) -> bool:
    return request.url.scheme == "https"


def _safe_next(target: str | None) -> str:
    """Where to go after sign-in: a path of this interface only (never another site)."""
    if target and target.startswith(PREFIX + "/") and not target.startswith("//") and not urlsplit(target).netloc:
        return target
    return f"{PREFIX}/flights"


# ------------------------------------------------------------------------------------------------ sign-in


@router.get("/", response_class=RedirectResponse)
def root() -> RedirectResponse:
    """The web interface's start page."""
    return RedirectResponse(f"{PREFIX}/flights", status_code=303)


def _login_page(request: Request, error: str | None = None, status_code: int = 200, next_: str | None = None) -> HTMLResponse:
    token = new_secret()
    resp = _page(request, "login.html", None, status_code, error=error, login_csrf=token, next=_safe_next(next_))
    resp.set_cookie(LOGIN_CSRF_COOKIE, token, httponly=True, samesite="lax", secure=_cookie_secure(request),
                    path=PREFIX, max_age=3600)
    return resp


@router.get(f"{PREFIX}/login", response_class=HTMLResponse)
def login_form(request: Request, next: str | None = None) -> HTMLResponse:
    """The sign-in form (a user token: engineer or admin)."""
    return _login_page(request, next_=next)


@router.post(f"{PREFIX}/login", response_class=HTMLResponse)
async def login(request: Request) -> Response:
    """Check the token and its role, open a session (cookie) and go on; refusals in words on the form."""
    form = await request.form()
    next_ = str(form.get("next") or "")
    if not csrf_matches(request.cookies.get(LOGIN_CSRF_COOKIE), form.get(CSRF_FIELD)):
        return _login_page(request, "the sign-in form was refused: its security token (CSRF) is missing or stale. "
                           "Try again.", 403, next_)
    token = str(form.get("token") or "").strip()
    principal = authenticate(_store(request), _settings(request), token) if token else None
    if principal is None:
        return _login_page(request, "unknown or revoked token: check it and try again.", 401, next_)
    role = str(getattr(principal.role, "value", principal.role))
    refusal = sign_in_refusal(role)
    if refusal is not None:
        return _login_page(request, refusal, 403, next_)
    close_session(_store(request), request.cookies.get(SESSION_COOKIE))  # a new id at every sign-in
    cookie, _ = open_session(_store(request), principal.token_id, principal.name, role,
                             _settings(request).web_session_s, _now())
    resp = RedirectResponse(_safe_next(next_), status_code=303)
    resp.set_cookie(SESSION_COOKIE, cookie, httponly=True, samesite="lax", secure=_cookie_secure(request),
                    path="/", max_age=int(_settings(request).web_session_s))
    resp.delete_cookie(LOGIN_CSRF_COOKIE, path=PREFIX)
    log.info("web sign-in: %s (%s)", principal.name, role)
    return resp


@router.post(f"{PREFIX}/logout")
async def logout(request: Request, user: User) -> RedirectResponse:
    """Sign out: the session is deleted from the store and the cookie cleared."""
    await checked_form(request, user)
    close_session(_store(request), request.cookies.get(SESSION_COOKIE))
    resp = RedirectResponse(f"{PREFIX}/login", status_code=303)
    resp.delete_cookie(SESSION_COOKIE, path="/")
    return resp


# ------------------------------------------------------------------------------------------------ flights


def _dirs(settings: ApiSettings, flight_id: str) -> tuple[Path, Path]:
    return settings.flights_dir / flight_id, settings.data_dir / "outputs" / flight_id


def _load(store: Store, flight_id: str) -> Flight:
    with store.session() as s:
        flight = s.get(Flight, flight_id)
        if flight is None:
            raise HTTPException(status_code=404, detail=f"there is no flight {flight_id!r} (deleted, or a wrong link)")
        flight.files, flight.jobs  # noqa: B018 - load the relationships before the session closes
        return flight


def _date(text: str | None, what: str) -> dt.date | None:
    if not text:
        return None
    try:
        return dt.date.fromisoformat(text)
    except ValueError:
        raise HTTPException(status_code=422, detail=f"{what} {text!r}: give a date as YYYY-MM-DD") from None


@router.get(f"{PREFIX}/flights", response_class=HTMLResponse)
def flights_page(request: Request, user: User, state: str | None = None, drone: str | None = None,
                 date_from: str | None = None, date_to: str | None = None) -> HTMLResponse:
    """Every flight, newest first, with the filters of the query."""
    if state and state not in flightinfo.STATES:
        raise HTTPException(status_code=422, detail=f"state {state!r}: one of {', '.join(flightinfo.STATES)}")
    filt = flightinfo.FlightFilter(state or None, (drone or "").strip() or None, _date(date_from, "from date"),
                                   _date(date_to, "to date"))
    settings = _settings(request)
    with _store(request).session() as s:
        flights = s.scalars(select(Flight).order_by(Flight.created_at.desc())).all()
        rows = [flightinfo.flight_row(f, *_dirs(settings, f.id)) for f in flights]
    shown = [r for r in rows if filt.keeps(r)]
    return _page(request, "flights.html", user, rows=shown, total=len(rows), filt=filt, states=flightinfo.STATES,
                 drones=sorted({r.drone for r in rows if r.drone}))


def _plots(flight: Flight, settings: ApiSettings) -> list[dict[str, Any]]:
    out = []
    for label, source, path, key in flightinfo.trajectories(flight, *_dirs(settings, flight.id)):
        stats = flightinfo.track_stats(path, key)
        plot = flightinfo.trajectory_plot(path, key) if isinstance(stats, flightinfo.TrackStats) else None
        out.append({"label": label, "source": source, "stats": stats, "plot": plot})
    return out


def _flight_context(flight: Flight, settings: ApiSettings, store: Store) -> dict[str, Any]:
    files_dir, outputs_dir = _dirs(settings, flight.id)
    events = None
    for f in flight.files:
        if f.role == "events" and f.status == "complete":
            events = flightinfo.event_summary(files_dir / f.name, f.sha256)
            break
    try:
        exports = export_names(settings, store, flight.id)
        has_report = latest_output(settings, store, flight.id, "report.html").is_file()
    except HTTPException:
        exports, has_report = [], False
    return {"flight": flight, "row": flightinfo.flight_row(flight, files_dir, outputs_dir),
            "plots": _plots(flight, settings), "events": events, "exports": exports, "has_report": has_report,
            "jobs": list(reversed(flight.jobs))}


def _flight_page(request: Request, user: SignedIn, flight_id: str, error: str | None = None,
                 status_code: int = 200) -> HTMLResponse:
    flight = _load(_store(request), flight_id)
    return _page(request, "flight.html", user, status_code, error=error,
                 **_flight_context(flight, _settings(request), _store(request)))


@router.get(f"{PREFIX}/flights/{{flight_id}}", response_class=HTMLResponse)
def flight_page(request: Request, user: User, flight_id: str) -> HTMLResponse:
    """A flight: files and upload progress, trajectories by fix status, events, jobs, results."""
    return _flight_page(request, user, flight_id)


@router.get(f"{PREFIX}/flights/{{flight_id}}/status")
def flight_status(request: Request, user: User, flight_id: str) -> dict[str, Any]:
    """The live part of the flight page as JSON (the page's script polls it with the session cookie)."""
    flight = _load(_store(request), flight_id)
    return {
        "state": flightinfo.flight_state([f.status for f in flight.files], [j.status for j in flight.jobs]),
        "files": [{"name": f.name, "received": f.received, "size": f.size, "status": f.status} for f in flight.files],
        "jobs": [{"id": j.id, "kind": j.kind, "status": j.status, "message": j.message} for j in flight.jobs],
    }


@router.post(f"{PREFIX}/flights/{{flight_id}}/rtk", response_class=HTMLResponse)
async def rtk_submit(request: Request, user: User, flight_id: str) -> Response:
    """Queue an RTK re-processing job of the flight's uploaded rover and base observations."""
    await checked_form(request, user)
    try:
        await run_in_threadpool(validate_and_queue_job, _store(request), request.app.state.jobs, flight_id, "rtk",
                                {}, _principal(user))
    except HTTPException as exc:
        if exc.status_code == 404:
            raise
        return await run_in_threadpool(_flight_page, request, user, flight_id, f"nothing queued: {exc.detail}",
                                       exc.status_code)
    return RedirectResponse(f"{PREFIX}/flights/{flight_id}#jobs", status_code=303)


# ------------------------------------------------------------------------------------------------ adjustment

#: lever-arm and delay modes of the form → how AdjustParams reads them
MODES = ("free", "fixed", "prior")


@dataclass
class AdjustForm:
    """The adjustment form's values as typed (re-shown with the errors when refused)."""

    lever_mode: str = "free"
    lever_x: str = ""
    lever_y: str = ""
    lever_z: str = ""
    lever_sigma: str = ""
    delay_mode: str = "free"
    delay_ms: str = ""
    delay_sigma_ms: str = ""
    crs: str = "EPSG:4979"
    gcp_crs: str = "EPSG:4978"
    events_kind: str = "trigger"
    trajectory: str = ""
    relative_control: bool = False
    accept_single: bool = False
    accept_blunder: bool = False
    errors: list[str] = field(default_factory=list)

    @classmethod
    def from_form(cls, form: FormData) -> AdjustForm:
        """The typed values (text), checkboxes as booleans."""
        def text(k: str, default: str = "") -> str:
            v = form.get(k)
            return v.strip() if isinstance(v, str) else default

        return cls(lever_mode=text("lever_mode", "free"), lever_x=text("lever_x"), lever_y=text("lever_y"),
                   lever_z=text("lever_z"), lever_sigma=text("lever_sigma"), delay_mode=text("delay_mode", "free"),
                   delay_ms=text("delay_ms"), delay_sigma_ms=text("delay_sigma_ms"),
                   crs=text("crs", "EPSG:4979") or "EPSG:4979", gcp_crs=text("gcp_crs", "EPSG:4978") or "EPSG:4978",
                   events_kind=text("events_kind", "trigger"), trajectory=text("trajectory"),
                   relative_control=form.get("relative_control") == "on", accept_single=form.get("accept_single") == "on",
                   accept_blunder=form.get("accept_blunder") == "on")

    def params(self) -> dict[str, Any]:
        """The `adjust` job's parameters (AdjustParams fields); ValueError in words for a field that is not a
        number. Lever arm in m (camera frame), delay typed in ms and given to the job in s."""
        p: dict[str, Any] = {"crs": self.crs, "gcp_crs": self.gcp_crs, "events_kind": self.events_kind,
                             "relative_control": self.relative_control, "accept_single": self.accept_single,
                             "accept_blunder": self.accept_blunder}
        estimate = []
        if self.lever_mode not in MODES or self.delay_mode not in MODES:
            raise ValueError(f"lever-arm and delay modes: one of {', '.join(MODES)}")
        if self.lever_mode == "free":
            estimate.append("lever-arm")
        else:
            p["lever_arm"] = [_number(v, f"lever arm {a} (m)") for a, v in
                              zip("xyz", (self.lever_x, self.lever_y, self.lever_z))]
            if self.lever_mode == "prior":
                p["lever_arm_sigma"] = _number(self.lever_sigma, "lever arm σ (m)")
        if self.delay_mode == "free":
            estimate.append("delay")
        else:
            p["delay"] = _number(self.delay_ms, "delay (ms)") / 1000.0
            if self.delay_mode == "prior":
                p["delay_sigma"] = _number(self.delay_sigma_ms, "delay σ (ms)") / 1000.0
        p["estimate"] = estimate
        if self.trajectory:
            p["trajectory"] = self.trajectory
        return p


def _number(text: str, what: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"{what}: {text!r} is not a number" if text else f"{what}: missing") from None


#: the form's file fields → the manifest role of the file (and the job parameter naming it)
UPLOAD_FIELDS = (("orientations", "orientations"), ("gcp", "gcp"), ("gcp_rel", "gcp_rel"))


@dataclass(frozen=True)
class Upload:
    """A file of the form, saved in a temporary folder under its own (checked) name."""

    role: str
    name: str
    path: Path
    size: int
    sha256: str


async def _save_uploads(form: FormData, folder: Path, max_bytes: int, errors: list[str]) -> list[Upload]:
    out: list[Upload] = []
    for field_name, role in UPLOAD_FIELDS:
        up = form.get(field_name)
        if not isinstance(up, UploadFile) or not up.filename:
            continue
        name = Path(up.filename).name
        try:
            check_file_name(name)
        except UploadRejected as exc:
            errors.append(f"{role} file: {exc.detail}; rename it and upload again")
            continue
        if any(u.name == name for u in out):
            errors.append(f"{name}: given twice (as {role} too); each file once")
            continue
        h = hashlib.sha256()
        size = 0
        path = folder / name
        with path.open("wb") as fh:
            while block := await up.read(1 << 20):
                size += len(block)
                if size > max_bytes:
                    break
                h.update(block)
                fh.write(block)
        if size > max_bytes:
            errors.append(f"{name}: larger than the limit of {max_bytes} bytes per file")
            continue
        out.append(Upload(role, name, path, size, h.hexdigest()))
    return out


def _importer_error(exc: Exception, folder: Path) -> str:
    """An importer's error in words, without the temporary folder's path."""
    return str(exc).replace(str(folder) + "/", "")


def _check_uploads(uploads: list[Upload], p: dict[str, Any], folder: Path, held: dict[str, Path],
                   errors: list[str]) -> None:
    """Parse the uploaded orientation and GCP files with the adjustment's importers (what the job will read)."""
    from ground.io import crs as crsmod
    from ground.io.orientations import read_orientations
    from ground.pipeline import read_control

    for key in ("crs", "gcp_crs"):
        try:
            crsmod.parse_crs(p[key])
        except (InputError, ValueError) as exc:
            errors.append(f"{'export CRS' if key == 'crs' else 'GCP CRS'} {p[key]!r}: {exc}")
    by_role = {u.role: u for u in uploads}
    if "orientations" in by_role:
        try:
            n = len(read_orientations(by_role["orientations"].path).poses)
            if n == 0:
                errors.append(f"{by_role['orientations'].name}: no camera pose in it")
        except (InputError, OSError, ValueError) as exc:
            errors.append(f"orientations: {_importer_error(exc, folder)}")
    if "gcp" in by_role:
        rel = by_role["gcp_rel"].path if "gcp_rel" in by_role else held.get(str(p.get("gcp_rel")))
        try:
            read_control(by_role["gcp"].path, rel, p["gcp_crs"])
        except (InputError, OSError, ValueError) as exc:
            errors.append(f"GCP file: {_importer_error(exc, folder)}")
    elif "gcp_rel" in by_role:
        errors.append("a relative GCP file without a GCP file: upload the GCP file too")


def _adjust_page(request: Request, user: SignedIn, flight: Flight, form: AdjustForm, status_code: int = 200) -> HTMLResponse:
    return _page(request, "adjust.html", user, status_code, flight=flight, form=form, modes=MODES,
                 trajectories=[f.name for f in flight.files if f.role == "trajectory" and f.status == "complete"],
                 held={role: [f.name for f in flight.files if f.role == role and f.status == "complete"]
                       for role, _ in UPLOAD_FIELDS})


def _check_add_and_queue(request: Request, user: SignedIn, flight: Flight, params: dict[str, Any],
                         uploads: list[Upload], folder: Path, errors: list[str]) -> int | None:
    """The adjustment form's checks (uploaded files parsed by the importers, then `check_job` with them), then
    the files added to the flight (`add_files` + `write_file_bytes`, no automatic job) and the job queued.
    Returns None when queued, else the HTTP status of the refusal, `errors` saying why in words; nothing is
    added when a check fails."""
    from ground.api.job_kinds import check_job

    settings, store = _settings(request), _store(request)
    complete = {f.name: f for f in flight.files if f.status == "complete"}
    for u in uploads:
        params[u.role] = u.name
        held = complete.get(u.name)
        if held is not None and held.sha256 != u.sha256:
            errors.append(f"{u.name}: the flight already holds another file of that name; rename yours")
    if not errors:
        _check_uploads(uploads, params, folder, {n: settings.flights_dir / flight.id / n for n in complete}, errors)
    if not errors:
        roles = {n: f.role for n, f in complete.items()} | {u.name: u.role for u in uploads}
        try:
            check_job("adjust", params, roles)
        except InputError as exc:
            errors.append(f"adjust job: {exc}")
    if errors:
        return 422
    principal = _principal(user)
    new = [u for u in uploads if u.name not in complete]
    try:
        if new:
            add_files(settings, store, flight.id, [ManifestFile(name=u.name, size=u.size, sha256=u.sha256,
                                                                role=u.role) for u in new], principal)
        for u in new:  # no automatic job (jobs None): the form's job is queued below
            with u.path.open("rb") as fh:
                write_file_bytes(settings, store, None, request.app.state.file_locks, flight.id, u.name, fh,
                                 principal)
    except HTTPException as exc:
        errors.append(f"the files could not be added: {exc.detail}")
        return exc.status_code
    try:
        validate_and_queue_job(store, request.app.state.jobs, flight.id, "adjust", params, principal)
    except HTTPException as exc:
        errors.append(f"nothing queued: {exc.detail}")
        return exc.status_code
    return None


@router.get(f"{PREFIX}/flights/{{flight_id}}/adjust", response_class=HTMLResponse)
def adjust_form(request: Request, user: User, flight_id: str) -> HTMLResponse:
    """The adjustment form: orientation and GCP files, lever-arm and delay modes, export CRS."""
    return _adjust_page(request, user, _load(_store(request), flight_id), AdjustForm())


@router.post(f"{PREFIX}/flights/{{flight_id}}/adjust", response_class=HTMLResponse)
async def adjust_submit(request: Request, user: User, flight_id: str) -> Response:
    """Validate everything (values, the files' formats, the job's check), then add the files to the flight and
    queue the job; on any error the form comes back with the errors in words and nothing is added or queued."""
    settings, store = _settings(request), _store(request)
    declared = request.headers.get("content-length", "")
    if declared.isdigit() and int(declared) > settings.max_flight_bytes:
        raise HTTPException(status_code=413, detail=f"the form's files ({declared} bytes) exceed the flight limit "
                            f"of {settings.max_flight_bytes} bytes")
    form = await checked_form(request, user)
    flight = _load(store, flight_id)
    values = AdjustForm.from_form(form)
    errors = values.errors
    try:
        params = values.params()
    except ValueError as exc:
        errors.append(str(exc))
        params = {}
    with tempfile.TemporaryDirectory(prefix="directgeo-web-") as tmp:
        uploads = await _save_uploads(form, Path(tmp), settings.max_file_bytes, errors)
        # parsing the files and the store's writes are blocking work: off the event loop
        status_code = await run_in_threadpool(_check_add_and_queue, request, user, flight, params, uploads,
                                              Path(tmp), errors)
    if status_code is not None:
        return await run_in_threadpool(_adjust_page, request, user, _load(store, flight_id), values, status_code)
    return RedirectResponse(f"{PREFIX}/flights/{flight_id}#jobs", status_code=303)


# ------------------------------------------------------------------------------------------------ downloads


@router.get(f"{PREFIX}/flights/{{flight_id}}/report", response_class=HTMLResponse)
def report(request: Request, user: User, flight_id: str) -> HTMLResponse:
    """The HTML report of the latest finished adjustment."""
    path = latest_output(_settings(request), _store(request), flight_id, "report.html")
    return HTMLResponse(path.read_text(encoding="utf-8"))


@router.get(f"{PREFIX}/flights/{{flight_id}}/exports/{{name}}", response_class=FileResponse)
def export(request: Request, user: User, flight_id: str, name: str) -> FileResponse:
    """An export file of the latest finished adjustment (geo.txt, …), as a download."""
    path = export_path(_settings(request), _store(request), flight_id, name)
    return FileResponse(path, media_type="text/plain", filename=name)


@router.get(f"{PREFIX}/flights/{{flight_id}}/files/{{name}}", response_class=FileResponse)
def flight_file(request: Request, user: User, flight_id: str, name: str) -> FileResponse:
    """A completely uploaded file of the flight."""
    flight = _load(_store(request), flight_id)
    f = next((x for x in flight.files if x.name == name), None)
    if f is None or f.status != "complete":
        raise HTTPException(status_code=404, detail=f"{name!r} is not a completely uploaded file of this flight")
    return FileResponse(_settings(request).flights_dir / flight_id / f.name, media_type="application/octet-stream",
                        filename=f.name)


# ------------------------------------------------------------------------------------------------ mounting


def _is_web(request: Request) -> bool:
    return request.url.path == "/" or request.url.path.startswith(PREFIX + "/")


def install(app: FastAPI) -> None:
    """Mount the web interface on the app: its routes, static files, and error pages in words for its paths
    (the API's paths keep their JSON errors)."""
    app.include_router(router)
    app.mount(f"{PREFIX}/static", StaticFiles(directory=HERE / "static"), name="web-static")

    async def sign_in_needed(request: Request, exc: Exception) -> Response:
        if request.url.path.endswith("/status"):
            return JSONResponse({"detail": "signed out: sign in again"}, status_code=401)
        target = request.url.path + (f"?{request.url.query}" if request.url.query else "")
        if request.method != "GET":
            target = f"{PREFIX}/flights"
        return RedirectResponse(f"{PREFIX}/login?next={quote(target)}", status_code=303)

    async def http_error(request: Request, exc: Exception) -> Response:
        assert isinstance(exc, StarletteHTTPException)
        if not _is_web(request) or request.url.path.endswith("/status"):
            return await http_exception_handler(request, exc)
        user = find_session(_store(request), request.cookies.get(SESSION_COOKIE), _now())
        return _page(request, "error.html", user, exc.status_code, status=exc.status_code, detail=exc.detail)

    async def validation_error(request: Request, exc: Exception) -> Response:
        assert isinstance(exc, RequestValidationError)
        if not _is_web(request):
            return await request_validation_exception_handler(request, exc)
        words = "; ".join(f"{'.'.join(str(x) for x in e['loc'][1:])}: {e['msg']}" for e in exc.errors())
        return _page(request, "error.html", None, 422, status=422, detail=words)

    app.add_exception_handler(SignInNeeded, sign_in_needed)
    app.add_exception_handler(StarletteHTTPException, http_error)
    app.add_exception_handler(RequestValidationError, validation_error)
