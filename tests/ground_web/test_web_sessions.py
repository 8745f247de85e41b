"""The web interface's session and CSRF layer, sign-in refusals, derived flight states and the adjustment
form's checks, through FastAPI's TestClient on a real SQLite file (the browser tests drive the same pages in
chromium)."""

from __future__ import annotations

import datetime as dt
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from ground.api.app import create_app
from ground.api.auth import Role, create_token, revoke_token
from ground.api.settings import ApiSettings
from ground.store import ApiToken, Flight, Job, Store, WebSession
from ground.web import flightinfo, sessions
from tests.ground_api import jobfuncs
from tests.ground_web.helpers import (
    client_cookies,
    csrf_of,
    error_of,
    sign_in,
    synthetic_files,
    upload_flight,
)

TOKEN = "web-boot-token-0123456789abcdef"
pytestmark = pytest.mark.timeout(120)


@pytest.fixture
def settings(tmp_path: Path) -> ApiSettings:
    return ApiSettings(data_dir=tmp_path / "data", token=TOKEN)


@pytest.fixture
def client(settings: ApiSettings) -> Iterator[TestClient]:
    app = create_app(settings, job_functions={"adjust": jobfuncs.works, "rtk": jobfuncs.works})
    with TestClient(app) as c:
        yield c


def _token(client: TestClient, role: Role, name: str) -> tuple[str, str]:
    return create_token(client.app.state.store, role, name)  # type: ignore[attr-defined]


# ------------------------------------------------------------------------------------------------ pure parts


def test_session_rows_expire_close_and_die_with_their_token(tmp_path: Path) -> None:
    store = Store(f"sqlite:///{tmp_path / 's.sqlite3'}")
    try:
        tid, _ = create_token(store, Role.ENGINEER, "eng")
        now = dt.datetime(2026, 5, 1, 12, tzinfo=dt.UTC)
        cookie, opened = sessions.open_session(store, tid, "eng", "engineer", 3600.0, now)
        assert sessions.find_session(store, cookie, now + dt.timedelta(seconds=3599)) == opened
        with store.session() as s:  # only the cookie's digest is stored
            [row] = s.query(WebSession).all()
            assert row.id_sha256 != cookie and cookie not in (row.csrf_token, row.token_id)
        assert sessions.find_session(store, cookie + "x", now) is None
        assert sessions.find_session(store, None, now) is None
        assert sessions.find_session(store, cookie, now + dt.timedelta(seconds=3600)) is None  # expired: deleted
        with store.session() as s:
            assert s.query(WebSession).count() == 0
        cookie, _ = sessions.open_session(store, tid, "eng", "engineer", 3600.0, now)
        sessions.close_session(store, cookie)
        assert sessions.find_session(store, cookie, now) is None
        cookie, _ = sessions.open_session(store, tid, "eng", "engineer", 3600.0, now)
        assert revoke_token(store, tid)
        assert sessions.find_session(store, cookie, now) is None  # revoked token: its sessions end
        tid2, _ = create_token(store, Role.ENGINEER, "eng2")
        cookie, _ = sessions.open_session(store, tid2, "eng2", "engineer", 3600.0, now)
        with store.session() as s:
            tok = s.get(ApiToken, tid2)
            assert tok is not None
            tok.role = "drone"
            s.commit()
        assert sessions.find_session(store, cookie, now) is None  # role changed since sign-in
    finally:
        store.close()


def test_csrf_comparison() -> None:
    assert sessions.csrf_matches("abc", "abc")
    assert not sessions.csrf_matches("abc", "abd")
    assert not sessions.csrf_matches("abc", "")
    assert not sessions.csrf_matches("", "")
    assert not sessions.csrf_matches(None, "abc")
    assert not sessions.csrf_matches("abc", None)
    assert sessions.sign_in_refusal("engineer") is None and sessions.sign_in_refusal("admin") is None
    assert "cannot sign in" in str(sessions.sign_in_refusal("drone"))
    assert "cannot sign in" in str(sessions.sign_in_refusal("worker"))


@pytest.mark.parametrize(("files", "jobs", "state"), [
    (["complete", "partial"], [], "uploading"),
    (["complete", "pending"], ["done"], "uploading"),
    (["complete"], [], "uploaded"),
    (["complete"], ["done", "queued"], "processing"),
    (["complete"], ["failed", "running"], "processing"),
    (["complete"], ["failed", "done"], "done"),
    (["complete"], ["done", "failed"], "failed"),
])
def test_flight_state(files: list[str], jobs: list[str], state: str) -> None:
    assert flightinfo.flight_state(files, jobs) == state


# ------------------------------------------------------------------------------------------------ sign-in


def test_pages_need_a_session(client: TestClient) -> None:
    r = client.get("/ui/flights?state=done", follow_redirects=False)
    assert r.status_code == 303 and r.headers["location"] == "/ui/login?next=/ui/flights%3Fstate%3Ddone"
    assert client.get("/ui/flights/abc/status").status_code == 401
    assert client.get("/", follow_redirects=False).headers["location"] == "/ui/flights"


def test_engineer_signs_in_and_out(client: TestClient) -> None:
    _, clear = _token(client, Role.ENGINEER, "alice")
    r = sign_in(client, clear)
    assert r.status_code == 303 and r.headers["location"] == "/ui/flights"
    cookie = next(h for h in r.headers.get_list("set-cookie") if h.startswith(sessions.SESSION_COOKIE + "="))
    assert "HttpOnly" in cookie and "SameSite=lax" in cookie and "Secure" not in cookie and "Max-Age=43200" in cookie
    page = client.get("/ui/flights")
    assert page.status_code == 200 and "alice (engineer)" in page.text
    assert clear not in page.text  # the token never comes back to the browser
    r = client.post("/ui/logout", data={"csrf_token": csrf_of(page.text)}, follow_redirects=False)
    assert r.status_code == 303 and r.headers["location"] == "/ui/login"
    assert client.get("/ui/flights", follow_redirects=False).status_code == 303
    with client.app.state.store.session() as s:  # type: ignore[attr-defined]
        assert s.query(WebSession).count() == 0


def test_session_cookie_is_secure_over_https(settings: ApiSettings) -> None:
    with TestClient(create_app(settings), base_url="https://ground.example") as c:
        r = sign_in(c, TOKEN)  # the bootstrap token is an admin
        assert r.status_code == 303
        cookie = next(h for h in r.headers.get_list("set-cookie") if h.startswith(sessions.SESSION_COOKIE + "="))
        assert "Secure" in cookie


@pytest.mark.parametrize("role", [Role.DRONE, Role.WORKER])
def test_machine_tokens_cannot_sign_in(client: TestClient, role: Role) -> None:
    _, clear = _token(client, role, f"m-{role.value}")
    r = sign_in(client, clear)
    assert r.status_code == 403
    assert f"a {role.value} token cannot sign in" in error_of(r.text)
    assert sessions.SESSION_COOKIE not in client_cookies(client)


def test_unknown_and_revoked_tokens_are_refused(client: TestClient) -> None:
    tid, clear = _token(client, Role.ENGINEER, "bob")
    r = sign_in(client, clear + "nope")
    assert r.status_code == 401 and "unknown or revoked token" in error_of(r.text)
    assert sign_in(client, clear).status_code == 303
    assert client.get("/ui/flights").status_code == 200
    revoke_token(client.app.state.store, tid)  # type: ignore[attr-defined]
    assert client.get("/ui/flights", follow_redirects=False).status_code == 303  # the session ended with it
    assert sign_in(client, clear).status_code == 401


def test_sign_in_without_its_csrf_cookie_is_refused(client: TestClient) -> None:
    page = client.get("/ui/login")
    client.cookies.delete(sessions.LOGIN_CSRF_COOKIE, path="/ui")
    r = client.post("/ui/login", data={"csrf_token": csrf_of(page.text), "token": TOKEN}, follow_redirects=False)
    assert r.status_code == 403 and "security token (CSRF)" in error_of(r.text)


# ------------------------------------------------------------------------------------------------ CSRF on POSTs


def test_every_post_needs_the_session_csrf_token(client: TestClient, tmp_path: Path) -> None:
    fid = upload_flight(client, TOKEN, "flight-20260501T101500Z", synthetic_files(tmp_path / "f"))
    assert sign_in(client, TOKEN).status_code == 303
    good = csrf_of(client.get(f"/ui/flights/{fid}").text)
    for path in (f"/ui/flights/{fid}/rtk", f"/ui/flights/{fid}/adjust", "/ui/logout"):
        for data in ({}, {"csrf_token": "forged"}, {"csrf_token": good[:-1]}):
            r = client.post(path, data=data, follow_redirects=False)
            assert r.status_code == 403, (path, data, r.status_code)
            assert "security token (CSRF)" in error_of(r.text)
    with client.app.state.store.session() as s:  # type: ignore[attr-defined]
        assert s.query(Job).count() == 0
    # another session's token does not open this one's forms
    with TestClient(client.app) as other:
        assert sign_in(other, TOKEN).status_code == 303
        theirs = csrf_of(other.get("/ui/flights").text)
    assert theirs != good
    assert client.post("/ui/logout", data={"csrf_token": theirs}, follow_redirects=False).status_code == 403


# ------------------------------------------------------------------------------------------------ pages


def test_flights_list_derives_columns_and_filters(client: TestClient, tmp_path: Path) -> None:
    _, drone = _token(client, Role.DRONE, "drone-07")
    fid = upload_flight(client, drone, "flight-20260501T101500Z", synthetic_files(tmp_path / "f"))
    partial = upload_flight(client, TOKEN, "flight-other", {"a.bin": (b"", None)} | {
        "b.bin": (b"", None)})
    assert sign_in(client, TOKEN).status_code == 303
    page = client.get("/ui/flights").text
    row = page[page.index(f'data-flight="{fid}"'):]
    row = row[:row.index("</tr>")]
    assert "drone-07" in row and "uploaded" in row
    from tests.ground_io.flightgen import START

    assert f">{START.to_utc().date().isoformat()}<" in row  # the trajectory's first epoch, not the name's 2026
    n = 400  # 80 s at 5 Hz; every 97th epoch (from the first) is float
    assert f">{100 * (n - len(range(0, n, 97))) / n:.1f} %<" in row
    assert ">1 min 20 s<" in row  # last − first epoch: 79.8 s, rounded
    assert client.get("/ui/flights?drone=DRONE-0").text.count("data-flight=") == 1
    assert client.get("/ui/flights?state=uploading").text.count("data-flight=") == 0
    day = START.to_utc().date().isoformat()
    only = client.get(f"/ui/flights?date_from={day}&date_to={day}").text
    assert only.count("data-flight=") == 1 and f'data-flight="{fid}"' in only
    today = dt.datetime.now(dt.UTC).date().isoformat()  # flight-other has no trajectory: the day it arrived
    assert f'data-flight="{partial}"' in client.get(f"/ui/flights?date_from={today}").text
    assert client.get("/ui/flights?state=uploaded").text.count("data-flight=") == 2
    r = client.get("/ui/flights?date_from=yesterday")
    assert r.status_code == 422 and "YYYY-MM-DD" in error_of(r.text)
    r = client.get("/ui/flights?state=lost")
    assert r.status_code == 422 and "one of uploading" in error_of(r.text)


def test_missing_flight_is_said_in_words(client: TestClient) -> None:
    assert sign_in(client, TOKEN).status_code == 303
    for path in ("/ui/flights/0123", "/ui/flights/0123/adjust", "/ui/flights/0123/report"):
        r = client.get(path)
        assert r.status_code == 404 and "no flight" in error_of(r.text), path
    r = client.get("/ui/flights/0123/status")
    assert r.status_code == 404 and "no flight" in r.json()["detail"]


def test_adjust_form_checks_before_it_queues(client: TestClient, tmp_path: Path) -> None:
    files = synthetic_files(tmp_path / "f")
    fid = upload_flight(client, TOKEN, "flight-20260501T101500Z", files)
    assert sign_in(client, TOKEN).status_code == 303
    csrf = csrf_of(client.get(f"/ui/flights/{fid}/adjust").text)
    poses = (tmp_path / "f" / "poses.csv").read_bytes()
    gcp = (tmp_path / "f" / "gcp.csv").read_bytes()

    def post(data: dict[str, str], up: dict[str, tuple[str, bytes]]) -> str:
        r = client.post(f"/ui/flights/{fid}/adjust", data={"csrf_token": csrf, **data},
                        files={k: (n, b, "application/octet-stream") for k, (n, b) in up.items()},
                        follow_redirects=False)
        assert r.status_code == 422, r.text[:300]
        return r.text

    assert "missing uploaded orientations" in post({}, {})  # none uploaded or held
    assert "lever arm y (m): &#39;abc&#39; is not a number" in post(
        {"lever_mode": "fixed", "lever_x": "0.1", "lever_y": "abc", "lever_z": "0"}, {"orientations": ("poses.csv", poses)})
    assert "lever arm σ -1.0: must be &gt; 0" in post({"lever_mode": "prior", "lever_x": "0", "lever_y": "0",
                                                  "lever_z": "0", "lever_sigma": "-1"},
                                                 {"orientations": ("poses.csv", poses)})
    text = post({}, {"orientations": ("poses.csv", b"image,x,y\nIMG_1.JPG,1,2\n")})
    assert "orientations: poses.csv" in text and str(tmp_path) not in text
    assert "GCP file: gcp.csv:1: header must be" in post({}, {"orientations": ("poses.csv", poses),
                                                              "gcp": ("gcp.csv", b"name,x\nA,1\n")})
    assert "export CRS &#39;EPSG:99999999&#39;: unknown CRS" in post({"crs": "EPSG:99999999"}, {"orientations": ("poses.csv", poses)})
    assert "rename it" in post({}, {"orientations": (".hidden.csv", poses)})
    with client.app.state.store.session() as s:  # type: ignore[attr-defined]
        flight = s.get(Flight, fid)
        assert flight is not None and sorted(f.name for f in flight.files) == ["SOL.pos", "events.csv"]
        assert s.query(Job).count() == 0
    # a good form: files added through the upload path, the job queued with the form's parameters
    r = client.post(f"/ui/flights/{fid}/adjust", data={
        "csrf_token": csrf, "lever_mode": "prior", "lever_x": "0.05", "lever_y": "-0.12", "lever_z": "-0.08",
        "lever_sigma": "0.02", "delay_mode": "fixed", "delay_ms": "65", "crs": "EPSG:32630"},
        files={"orientations": ("poses.csv", poses, "text/csv"), "gcp": ("gcp.csv", gcp, "text/csv")},
        follow_redirects=False)
    assert r.status_code == 303 and r.headers["location"] == f"/ui/flights/{fid}#jobs"
    with client.app.state.store.session() as s:  # type: ignore[attr-defined]
        flight = s.get(Flight, fid)
        assert flight is not None and flight.status == "complete"
        held = {f.name: (f.role, f.status) for f in flight.files}
        assert held["poses.csv"] == ("orientations", "complete") and held["gcp.csv"] == ("gcp", "complete")
        assert (client.app.state.settings.flights_dir / fid / "poses.csv").read_bytes() == poses  # type: ignore[attr-defined]
        [job] = s.query(Job).all()  # the form's job only: no automatic one
        assert job.kind == "adjust" and job.params["lever_arm"] == [0.05, -0.12, -0.08]
        assert job.params["delay"] == pytest.approx(0.065) and job.params["estimate"] == []
        assert job.params["orientations"] == "poses.csv" and job.params["crs"] == "EPSG:32630"
    deadline = time.monotonic() + 60
    while client.get(f"/ui/flights/{fid}/status").json()["jobs"][0]["status"] in ("queued", "running"):
        assert time.monotonic() < deadline
        time.sleep(0.2)
    status = client.get(f"/ui/flights/{fid}/status").json()
    assert status["jobs"][0]["status"] == "done" and status["state"] == "done"


def test_rtk_button_without_base_data_says_why(client: TestClient, tmp_path: Path) -> None:
    fid = upload_flight(client, TOKEN, "flight-20260501T101500Z", synthetic_files(tmp_path / "f"))
    assert sign_in(client, TOKEN).status_code == 303
    csrf = csrf_of(client.get(f"/ui/flights/{fid}").text)
    r = client.post(f"/ui/flights/{fid}/rtk", data={"csrf_token": csrf})
    assert r.status_code == 422 and "nothing queued" in error_of(r.text) and "base_obs" in error_of(r.text)


def test_upload_progress_and_both_rtk_solutions(client: TestClient, tmp_path: Path) -> None:
    """A file half sent shows as such (page and live JSON); a flight with an uploaded real-time trajectory and a
    finished RTK job's SOL.pos shows both solutions with their own figures."""
    import hashlib

    blob = bytes(range(256)) * 40
    headers = {"Authorization": f"Bearer {TOKEN}"}
    r = client.post("/flights", headers=headers, json={"name": "flight-half", "files": [
        {"name": "000000.ubx", "size": len(blob), "sha256": hashlib.sha256(blob).hexdigest(), "role": "raw"}]})
    half_id = r.json()["id"]
    part = blob[:4000]
    assert client.put(f"/flights/{half_id}/files/000000.ubx", params={"offset": 0}, content=part,
                      headers={**headers, "X-Chunk-SHA256": hashlib.sha256(part).hexdigest()}).status_code == 200
    assert sign_in(client, TOKEN).status_code == 303
    status = client.get(f"/ui/flights/{half_id}/status").json()
    assert status["state"] == "uploading"
    assert status["files"] == [{"name": "000000.ubx", "received": 4000, "size": len(blob), "status": "partial"}]
    page = client.get(f"/ui/flights/{half_id}").text
    assert f'<progress max="{len(blob)}" value="4000">' in page and "4000 B" in page

    files = synthetic_files(tmp_path / "f")
    fid = upload_flight(client, TOKEN, "flight-20260501T101500Z", files)
    # what a finished RTK job leaves: its row done and SOL.pos in its output folder (here: all epochs fixed)
    settings: ApiSettings = client.app.state.settings  # type: ignore[attr-defined]
    with client.app.state.store.session() as s:  # type: ignore[attr-defined]
        job = Job(flight_id=fid, kind="rtk", status="done", params={}, message="done")
        s.add(job)
        s.commit()
        job_id = job.id
    out = settings.data_dir / "outputs" / fid / job_id
    out.mkdir(parents=True)
    lines = []
    for line in files["SOL.pos"][0].decode().splitlines():
        cols = line.split()
        if not line.startswith("%") and len(cols) > 5:
            cols[5] = "1"  # Q: fix
            line = " ".join(cols)
        lines.append(line)
    fixed = ("\n".join(lines) + "\n").encode()
    (out / "SOL.pos").write_bytes(fixed)
    page = client.get(f"/ui/flights/{fid}").text
    rtk = page[page.index('id="rtk-table"'):page.index("</table>", page.index('id="rtk-table"'))]
    assert "real-time (uploaded)" in rtk and "post-processed (RTK job)" in rtk
    assert "395 (98.8 %)" in rtk and "400 (100.0 %)" in rtk
    assert page.count('alt="real-time (uploaded) trajectory') == 1
    assert page.count('alt="post-processed (RTK job) trajectory') == 1
    row = client.get("/ui/flights").text
    row = row[row.index(f'data-flight="{fid}"'):]
    assert ">100.0 %<" in row[:row.index("</tr>")]  # the list's fix ratio is the post-processed one
