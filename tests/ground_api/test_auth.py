"""Tokens with roles (ground.api.auth): hashed storage, authenticate/revoke, the role of every OpenAPI operation
checked per role against a live server, a drone confined to its own flights, the old database migrated."""

from __future__ import annotations

import hashlib
import sqlite3
from pathlib import Path
from typing import Any

import httpx
import pytest

from ground.api.auth import (
    OPENAPI_ROLES_KEY,
    Principal,
    Role,
    TokenNameTaken,
    authenticate,
    create_token,
    hash_token,
    list_tokens,
    require_role,
    revoke_token,
)
from ground.api.settings import ApiSettings
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
        assert revoke_token(store, "drone-7") is True
        assert authenticate(store, settings, clear) is None
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
        url = path.format(**values)
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
        assert [f["id"] for f in eng.get("/flights").json()] == [fid]
