"""The flight store on a real PostgreSQL server (DATABASE_URL), not only SQLite.

A throw-away PostgreSQL cluster (`tests.postgres_cluster`, fixture `postgres_url`) is created with the machine's
`initdb`/`pg_ctl`; the API and the uploader then run exactly as with SQLite. Skips, with the reason, when the
PostgreSQL server binaries or the psycopg driver are absent.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from ground.api.auth import Principal, Role, authenticate, create_token, hash_token, revoke_token
from ground.api.settings import ApiSettings
from tests.ground_api.conftest import TOKEN, start_server
from tests.ground_api.test_api import _create, _flight_folder, _put, _sha, interrupt_upload, resume_upload

pytestmark = pytest.mark.timeout(180)


@pytest.mark.slow
def test_interrupted_upload_resumes_on_postgresql(postgres_url: str, tmp_path: Path) -> None:
    """Same protocol as on SQLite: link lost after 3 chunks, server restarted on the same database, the next run
    sends only the rest and the files are byte-identical; a corrupted chunk is refused; the rows are in
    PostgreSQL (read back with psycopg, not through our code); a drone token created, refused outside its role
    and its flights, revoked, and kept as its SHA-256 only."""
    import psycopg

    settings = ApiSettings(data_dir=tmp_path / "data", token=TOKEN, database_url=postgres_url,
                           max_chunk_bytes=64 * 1024, max_file_bytes=4 * 1024 * 1024,
                           max_flight_bytes=16 * 1024 * 1024)
    folder = _flight_folder(tmp_path / "onboard")
    interrupt_upload(settings, folder)
    srv = start_server(settings)
    try:
        rep = resume_upload(srv, settings, folder)
        with srv.client() as c:  # a corrupted chunk: 422, not stored, the offset stays
            data = os.urandom(30_000)
            fid = _create(c, {"b.ubx": data}, name="flight-corrupt")["id"]
            damaged = bytearray(data[:20_000])
            damaged[7] ^= 0x01
            assert _put(c, fid, "b.ubx", 0, bytes(damaged), sha=_sha(data[:20_000])).status_code == 422
            assert c.head(f"/flights/{fid}/files/b.ubx").headers["Upload-Offset"] == "0"
        with srv.client(token=None) as c:
            assert c.get("/flights").status_code == 401
        store = srv.server.config.app.state.store  # tokens with roles in PostgreSQL: create, use, revoke
        drone_id, drone = create_token(store, Role.DRONE, "pg-drone")
        assert authenticate(store, settings, drone) == Principal(drone_id, "pg-drone", Role.DRONE)
        with srv.client(token=drone) as c:
            assert c.get("/flights").status_code == 403
            assert c.get(f"/flights/{fid}").status_code == 403  # not its flight
            assert c.post("/flights", json={"name": "pg-drone-flight", "files": [
                {"name": "a.ubx", "size": 1, "sha256": _sha(b"a")}]}).status_code == 201
            assert revoke_token(store, drone_id) and authenticate(store, settings, drone) is None
            assert c.get("/health").status_code == 200 and c.get("/flights").status_code == 401
    finally:
        srv.stop()
    with psycopg.connect(postgres_url.replace("postgresql+psycopg", "postgresql")) as db:
        rows = db.execute("select received, size, status from flight_files where flight_id = %s",
                          (rep.flight_id,)).fetchall()
        assert len(rows) == 6 and all(r[0] == r[1] and r[2] == "complete" for r in rows)
        assert not (tmp_path / "data" / "directgeo.sqlite3").exists()  # nothing went to a SQLite fallback
        tokens = db.execute("select name, role, token_sha256, revoked_at is not null from api_tokens").fetchall()
        assert tokens == [("pg-drone", "drone", hash_token(drone), True)]
        created_by = db.execute("select created_by from flights where name = 'pg-drone-flight'").fetchone()
        assert created_by == (drone_id,)
