"""Tokens with roles (ground.api.auth): hashed storage, authenticate/revoke, the role of every OpenAPI operation
checked per role against a live server, a drone confined to its own flights, the old database migrated."""

from __future__ import annotations

import hashlib
import io
import json
import sqlite3
from pathlib import Path
from typing import Annotated, Any

import httpx
import pytest
from fastapi import APIRouter, Depends, FastAPI, HTTPException

from ground.api.auth import (
    OPENAPI_ROLES_KEY,
    Principal,
    Role,
    TokenNameTaken,
    authenticate,
    create_token,
    document_roles,
    hash_token,
    list_tokens,
    principal_for_id,
    require_role,
    revoke_token,
)
from ground.api.routes.flights import write_file_bytes
from ground.api.settings import ApiSettings
from ground.cli import main
from ground.store import Store
from onboard.errors import InputError
from tests.ground_api.conftest import TOKEN, LiveServer

pytestmark = pytest.mark.timeout(120)

#: the only operation open without a token
OPEN_OPERATIONS = {("get", "/health")}
CALLERS = ("no token", "revoked", *(r.value for r in Role))


def _sha(b: bytes) -> str:
    return hashlib.sha256(b).hexdigest()


def _settings(tmp_path: Path) -> ApiSettings:
    return ApiSettings(data_dir=tmp_path, token=TOKEN)


def _store(tmp_path: Path) -> Store:
    return Store(_settings(tmp_path).db_url)


def test_created_token_authenticates_with_its_role_until_revoked(tmp_path: Path) -> None:
    store, settings = _store(tmp_path), _settings(tmp_path)
    try:
        tid, clear = create_token(store, Role.DRONE, "drone-7")
        assert len(clear) >= 43  # 32 random bytes, URL-safe base64
        assert authenticate(store, settings, clear) == Principal(token_id=tid, name="drone-7", role=Role.DRONE)
        assert authenticate(store, settings, clear + "x") is None
        assert authenticate(store, settings, "") is None
        assert authenticate(store, settings, TOKEN) == Principal(token_id=None, name="bootstrap", role=Role.ADMIN)
        [info] = list_tokens(store)
        assert (info.id, info.name, info.role, info.revoked_at) == (tid, "drone-7", Role.DRONE, None)
        assert info.last_used_at is not None  # written by authenticate
        assert principal_for_id(store, tid) == authenticate(store, settings, clear)
        assert principal_for_id(store, "0" * 32) is None
        assert revoke_token(store, "drone-7") is True
        assert authenticate(store, settings, clear) is None
        assert principal_for_id(store, tid) is None
        assert revoke_token(store, tid) is False  # already revoked
        assert revoke_token(store, "nobody") is False
        assert list_tokens(store)[0].revoked_at is not None
    finally:
        store.close()


def test_token_names_are_unique_and_checked(tmp_path: Path) -> None:
    store = _store(tmp_path)
    try:
        create_token(store, Role.ENGINEER, "alice")
        with pytest.raises(TokenNameTaken):
            create_token(store, Role.DRONE, "alice")
        for bad in ("", "a b", "-x", "0123456789abcdef0123456789abcdef", "x" * 101):
            with pytest.raises(InputError):
                create_token(store, Role.DRONE, bad)
        with pytest.raises(ValueError):
            create_token(store, "pilot", "bob")  # type: ignore[arg-type]
        assert [t.name for t in list_tokens(store)] == ["alice"]
    finally:
        store.close()


def test_tokens_are_never_stored_in_clear(tmp_path: Path) -> None:
    """The SQLite file (read with sqlite3 and as raw bytes) holds each token's SHA-256, never the token."""
    store, settings = _store(tmp_path), _settings(tmp_path)
    clears = [create_token(store, role, f"t-{role.value}")[1] for role in Role]
    for c in clears:
        assert authenticate(store, settings, c) is not None
    store.close()
    db = tmp_path / "directgeo.sqlite3"
    con = sqlite3.connect(db)
    try:
        dump = "\n".join(con.iterdump())
        hashes = {row[0] for row in con.execute("SELECT token_sha256 FROM api_tokens")}
    finally:
        con.close()
    raw = b"".join(p.read_bytes() for p in tmp_path.glob("directgeo.sqlite3*"))
    assert hashes == {hash_token(c) for c in clears}
    for c in clears:
        assert c not in dump
        assert c.encode() not in raw
        assert hash_token(c).encode() in raw


def test_require_role_always_lets_admin_through() -> None:
    assert require_role(Role.DRONE).roles == {Role.DRONE, Role.ADMIN}
    assert require_role(Role.ADMIN).roles == {Role.ADMIN}
    with pytest.raises(ValueError):
        require_role()


def test_an_old_database_gets_the_new_columns(tmp_path: Path) -> None:
    """A store created before tokens (flights without `created_by`) opens, keeps its flights, gains the column."""
    db = tmp_path / "old.sqlite3"
    con = sqlite3.connect(db)
    con.execute("CREATE TABLE flights (id VARCHAR(32) PRIMARY KEY, name VARCHAR(255) UNIQUE, created_at DATETIME, "
                "status VARCHAR(32), manifest JSON)")
    con.execute("INSERT INTO flights VALUES ('f' , 'old-flight', '2024-05-01 10:00:00', 'complete', '{}')")
    con.commit()
    con.close()
    Store(f"sqlite:///{db}").close()
    con = sqlite3.connect(db)
    try:
        cols = [r[1] for r in con.execute("PRAGMA table_info(flights)")]
        assert "created_by" in cols
        assert con.execute("SELECT name, created_by FROM flights").fetchall() == [("old-flight", None)]
        assert con.execute("SELECT count(*) FROM api_tokens").fetchone() == (0,)
    finally:
        con.close()


# ------------------------------------------------------------------------------------------ against a live server

def _client(live: LiveServer, token: str | None) -> httpx.Client:
    return live.client(token=token)


def _tokens(live: LiveServer) -> dict[str, str]:
    """A token per caller of CALLERS, made through the admin API (the revoked one revoked through it too)."""
    out: dict[str, str] = {}
    with live.client() as admin:
        for role in Role:
            r = admin.post("/tokens", json={"role": role.value, "name": f"walk-{role.value}"})
            assert r.status_code == 201, r.text
            out[role.value] = r.json()["token"]
        r = admin.post("/tokens", json={"role": "engineer"})
        assert r.status_code == 201 and r.json()["name"].startswith("engineer-"), r.text
        out["revoked"] = r.json()["token"]
        assert admin.delete(f"/tokens/{r.json()['id']}").status_code == 204
        assert admin.delete(f"/tokens/{r.json()['id']}").status_code == 404
    return out


def _drone_flight(c: httpx.Client, name: str, files: dict[str, bytes]) -> dict[str, Any]:
    body = {"name": name, "files": [{"name": n, "size": len(b), "sha256": _sha(b)} for n, b in files.items()]}
    r = c.post("/flights", json=body)
    assert r.status_code == 201, r.text
    return r.json()  # type: ignore[no-any-return]


def _call(c: httpx.Client, method: str, path: str, op: dict[str, Any]) -> httpx.Response:
    """One call of an operation with plausible arguments (a bad body or query is answered 4xx by validation,
    which comes after authentication: only 401/403 matter here)."""
    kw: dict[str, Any] = {}
    if "requestBody" in op:
        content = op["requestBody"]["content"]
        if "application/json" in content:
            kw["json"] = {}
        else:
            kw["content"] = b"abc"
            kw["headers"] = {"X-Chunk-SHA256": _sha(b"abc")}
    if any(p["name"] == "offset" for p in op.get("parameters", [])):
        kw["params"] = {"offset": 0}
    return c.request(method.upper(), path, **kw)


class _Ids(dict[str, str]):
    """Path parameters: the walk's flight and file, any other id a made-up one (answered 404 after the check)."""

    def __missing__(self, key: str) -> str:
        return "0" * 32


@pytest.mark.slow
def test_every_operation_refuses_exactly_the_roles_outside_its_x_roles(live: LiveServer) -> None:
    """Walk the OpenAPI operations: for every caller (no token, revoked, each role) the answer is 401/403
    exactly when the caller is outside the operation's `x-roles`, and never 401/403 inside them."""
    tokens = _tokens(live)
    with live.client(token=tokens["drone"]) as drone:
        flight = _drone_flight(drone, "walk-flight", {"a.txt": b"abc"})
    with live.client(token=None) as anon:
        spec = anon.get("/openapi.json").json()
    values = {"flight_id": flight["id"], "name": "a.txt", "job_id": "0" * 32, "token_id": "0" * 32}
    operations = [(m, p, op) for p, ops in spec["paths"].items() for m, op in ops.items()]
    assert len(operations) >= 17
    checked = 0
    for method, path, op in operations:
        roles = op.get(OPENAPI_ROLES_KEY)
        if (method, path) in OPEN_OPERATIONS:
            assert roles is None
            continue
        assert roles, f"{method.upper()} {path} states no role"
        assert "admin" in roles and f"Roles: {', '.join(roles)}." in op["description"]
        url = path.format_map(_Ids(values))
        for caller in CALLERS:
            with live.client(token=tokens.get(caller)) as c:
                status = _call(c, method, url, op).status_code
            where = f"{caller} {method.upper()} {path}: HTTP {status}"
            if caller in ("no token", "revoked"):
                assert status == 401, where
            elif caller in roles:
                assert status not in (401, 403), where
            else:
                assert status == 403, where
            checked += 1
    assert checked == len(CALLERS) * (len(operations) - len(OPEN_OPERATIONS))


def test_a_drone_touches_only_the_flights_it_created(live: LiveServer) -> None:
    """Drone B cannot read, upload to, add files to or re-open drone A's flight; A can; an engineer reads all."""
    tokens: dict[str, str] = {}
    with live.client() as admin:
        for name, role in (("drone-a", "drone"), ("drone-b", "drone"), ("eng", "engineer")):
            tokens[name] = admin.post("/tokens", json={"role": role, "name": name}).json()["token"]
    data = b"rover observations"
    with live.client(token=tokens["drone-a"]) as a, live.client(token=tokens["drone-b"]) as b, \
            live.client(token=tokens["eng"]) as eng:
        flight = _drone_flight(a, "flight-a", {"rover.ubx": data})
        fid = flight["id"]
        url = f"/flights/{fid}/files/rover.ubx"
        chunk = {"params": {"offset": 0}, "content": data, "headers": {"X-Chunk-SHA256": _sha(data)}}
        extra = {"files": [{"name": "gcp.csv", "size": 1, "sha256": _sha(b"x"), "role": "gcp"}]}
        assert b.get(f"/flights/{fid}").status_code == 403
        assert b.head(url).status_code == 403
        assert b.get(url).status_code == 403
        assert b.put(url, **chunk).status_code == 403
        assert b.post(f"/flights/{fid}/files", json=extra).status_code == 403
        again = {"name": "flight-a", "files": [{"name": "rover.ubx", "size": len(data), "sha256": _sha(data)}]}
        assert b.post("/flights", json=again).status_code == 409
        assert b.get("/flights").status_code == 403
        assert a.head(url).headers["Upload-Offset"] == "0"  # B's refused PUT wrote nothing
        assert a.post("/flights", json=again).status_code == 200  # A resumes its own flight
        r = a.put(url, **chunk)
        assert r.status_code == 200 and r.json()["status"] == "complete", r.text
        assert a.get(f"/flights/{fid}").json()["status"] == "complete"
        assert a.get(f"{url}/content").status_code == 403  # a drone never downloads
        assert eng.get(f"{url}/content").content == data
        assert [(f["id"], f["created_by"]) for f in eng.get("/flights").json()] == [(fid, "drone-a")]
        assert flight["created_by"] == eng.get(f"/flights/{fid}").json()["created_by"] == "drone-a"
    with live.client() as admin:  # the bootstrap token's flights have no creator token
        assert _drone_flight(admin, "flight-admin", {"x.txt": b"x"})["created_by"] is None


def test_office_files_are_added_to_a_flight_and_uploaded(live: LiveServer) -> None:
    """`POST /flights/{id}/files`: an engineer adds orientations and GCPs to a drone's complete flight (checked
    like the manifest: bad name 400, a held name with another hash 409, the same entries again change nothing),
    the flight is `uploading` until their bytes arrive by PUT (or `write_file_bytes`, the web form's path)."""
    with live.client() as admin:
        drone_token = admin.post("/tokens", json={"role": "drone", "name": "d"}).json()["token"]
        eng_token = admin.post("/tokens", json={"role": "engineer", "name": "e"}).json()["token"]
    poses, gcp, empty = b"image,X,Y,Z\n" * 50, b"name,role,x,y,z\n", b""
    entries = [{"name": "poses.csv", "size": len(poses), "sha256": _sha(poses), "role": "orientations"},
               {"name": "gcp.csv", "size": len(gcp), "sha256": _sha(gcp), "role": "gcp"},
               {"name": "empty.txt", "size": 0, "sha256": _sha(empty)}]
    with live.client(token=drone_token) as drone, live.client(token=eng_token) as eng:
        flight = _drone_flight(drone, "f-office", {"events.jsonl": b""})
        fid = flight["id"]
        assert flight["status"] == "complete"
        for bad, status in (([{"name": "../x", "size": 1, "sha256": _sha(b"x")}], 400),
                            ([{"name": "x", "size": 1, "sha256": "z" * 64}], 400),
                            ([{"name": "x", "size": 1, "sha256": _sha(b"x")}] * 2, 400),
                            ([{"name": "x", "size": 0, "sha256": _sha(b"x")}], 422),
                            ([{"name": "x", "size": 10**9, "sha256": _sha(b"x")}], 413),
                            ([], 400),
                            ([{"name": "events.jsonl", "size": 1, "sha256": _sha(b"x")}], 409)):
            r = eng.post(f"/flights/{fid}/files", json={"files": bad})
            assert r.status_code == status, (bad, r.text)
        assert eng.post("/flights/nope/files", json={"files": entries}).status_code == 404
        r = eng.post(f"/flights/{fid}/files", json={"files": entries})
        assert r.status_code == 200, r.text
        state = {f["name"]: f for f in r.json()["files"]}
        assert r.json()["status"] == "uploading"
        assert (state["poses.csv"]["status"], state["poses.csv"]["role"]) == ("pending", "orientations")
        assert state["empty.txt"]["status"] == "complete"  # nothing to send: verified at once
        again = eng.post(f"/flights/{fid}/files", json={"files": entries[:1]})
        assert again.status_code == 200 and again.json()["files"] == r.json()["files"]
        changed = dict(entries[0], sha256=_sha(b"other"))
        assert eng.post(f"/flights/{fid}/files", json={"files": [changed]}).status_code == 409
        r = eng.put(f"/flights/{fid}/files/poses.csv", params={"offset": 0}, content=poses,
                    headers={"X-Chunk-SHA256": _sha(poses)})
        assert r.status_code == 200 and r.json()["status"] == "complete", r.text
        state_ = live.server.config.app.state
        principal = authenticate(state_.store, live.settings, eng_token)
        assert principal is not None
        with pytest.raises(HTTPException) as refused:  # bytes that are not the listed ones: refused, not stored
            write_file_bytes(live.settings, state_.store, state_.jobs, state_.file_locks, fid, "gcp.csv",
                             io.BytesIO(b"NAME,role,x,y,z\n"), principal)
        assert refused.value.status_code == 422
        out = write_file_bytes(live.settings, state_.store, state_.jobs, state_.file_locks, fid, "gcp.csv",
                               io.BytesIO(gcp), principal)
        assert out.status == "complete"
        assert eng.get(f"/flights/{fid}/files/gcp.csv/content").content == gcp
        assert eng.get(f"/flights/{fid}").json()["status"] == "complete"
        assert drone.post(f"/flights/{fid}/files", json={"files": [
            {"name": "late.txt", "size": 1, "sha256": _sha(b"x")}]}).status_code == 200  # its own flight


def test_token_command_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`python -m ground token create|list|revoke` on the data dir: create prints the token alone on stdout,
    list shows no secret, revoke refuses it; usage errors exit 2 with the product's error line."""
    data = ["--data-dir", str(tmp_path)]
    assert main(["token", "create", "--role", "drone", "--name", "drone-07", *data]) == 0
    out, err = capsys.readouterr()
    token = out.strip()
    assert out == token + "\n" and len(token) >= 43 and "drone-07" in err and token not in err
    assert main(["token", "create", "--role", "engineer", *data]) == 0
    eng = capsys.readouterr().out.strip()
    store, settings = _store(tmp_path), _settings(tmp_path)
    try:
        assert authenticate(store, settings, token) is not None
        assert authenticate(store, settings, eng).role is Role.ENGINEER  # type: ignore[union-attr]
        assert main(["token", "list", "--json", *data]) == 0
        listed = capsys.readouterr().out
        assert token not in listed and eng not in listed
        rows = json.loads(listed)
        assert (rows[0]["name"], rows[0]["role"], rows[0]["revoked_at"]) == ("drone-07", "drone", None)
        assert rows[1]["name"].startswith("engineer-")
        assert main(["token", "list", *data]) == 0
        table = capsys.readouterr().out
        assert "drone-07" in table and token not in table
        assert main(["token", "revoke", "drone-07", *data]) == 0
        assert authenticate(store, settings, token) is None
        assert main(["token", "revoke", "drone-07", *data]) == 2
        assert "no active token" in capsys.readouterr().err
        assert main(["token", "create", "--role", "drone", "--name", "drone-07", *data]) == 2
        assert "exists already" in capsys.readouterr().err
        with pytest.raises(SystemExit) as usage:
            main(["token", "create", "--role", "pilot", *data])
        assert usage.value.code == 2
    finally:
        store.close()


_DroneOnly = Annotated[Principal, Depends(require_role(Role.DRONE))]


def test_document_roles_reads_the_role_checks_of_each_route() -> None:
    """`x-roles` comes from the `require_role` dependencies wherever they are (parameter, `dependencies=`,
    router-level; two checks → their intersection); an open route states none; twice is the same as once."""
    app = FastAPI()
    router = APIRouter(prefix="/w", dependencies=[Depends(require_role(Role.WORKER, Role.ENGINEER))])

    @router.get("/a")
    def a() -> None:
        """Worker or engineer."""

    @router.get("/b", dependencies=[Depends(require_role(Role.WORKER))])
    def b() -> None:
        """Both checks: worker only."""

    @app.get("/c")
    def c(p: _DroneOnly) -> None:
        """Drone."""

    @app.get("/open")
    def open_() -> None:
        """No check."""

    app.include_router(router)
    document_roles(app)
    document_roles(app)
    paths = app.openapi()["paths"]
    assert paths["/w/a"]["get"][OPENAPI_ROLES_KEY] == ["engineer", "admin", "worker"]
    assert paths["/w/b"]["get"][OPENAPI_ROLES_KEY] == ["admin", "worker"]
    assert paths["/c"]["get"][OPENAPI_ROLES_KEY] == ["drone", "admin"]
    assert paths["/c"]["get"]["description"] == "Drone.\n\nRoles: drone, admin."
    assert OPENAPI_ROLES_KEY not in paths["/open"]["get"]
