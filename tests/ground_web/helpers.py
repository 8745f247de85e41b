"""Shared by the web interface's tests: a flight made through the API (manifest, then chunks) and the sign-in
form driven like a browser does (its CSRF cookie and field)."""

from __future__ import annotations

import hashlib
import re
from pathlib import Path
from typing import Any

import httpx

CSRF_RE = re.compile(r'name="csrf_token" value="([^"]+)"')
ERROR_RE = re.compile(r'id="error">([^<]*)<')


def csrf_of(html: str) -> str:
    """The CSRF token a page's forms carry."""
    m = CSRF_RE.search(html)
    assert m is not None, "no CSRF field on the page"
    return m.group(1)


def error_of(html: str) -> str:
    """The error message a page shows in words."""
    m = ERROR_RE.search(html)
    assert m is not None, f"no error on the page: {html[:400]}"
    return m.group(1)


def sign_in(client: Any, token: str) -> Any:
    """GET the sign-in form, POST the token with its CSRF field; returns the POST's response (not followed)."""
    page = client.get("/ui/login")
    assert page.status_code == 200
    return client.post("/ui/login", data={"csrf_token": csrf_of(page.text), "token": token, "next": "/ui/flights"},
                       follow_redirects=False)


def upload_flight(client: Any, token: str, name: str, files: dict[str, tuple[bytes, str | None]]) -> str:
    """Create a flight by the API (`POST /flights`) and PUT each file whole; returns the flight id."""
    headers = {"Authorization": f"Bearer {token}"}
    manifest = [{"name": n, "size": len(b), "sha256": hashlib.sha256(b).hexdigest(), "role": r}
                for n, (b, r) in files.items()]
    r = client.post("/flights", json={"name": name, "files": manifest}, headers=headers)
    assert r.status_code == 201, r.text
    fid = str(r.json()["id"])
    for n, (b, _) in files.items():
        if b:
            r = client.put(f"/flights/{fid}/files/{n}", params={"offset": 0}, content=b,
                           headers={**headers, "X-Chunk-SHA256": hashlib.sha256(b).hexdigest()})
            assert r.status_code == 200, r.text
    return fid


def synthetic_files(folder: Path, with_orientations: bool = False) -> dict[str, tuple[bytes, str | None]]:
    """The synthetic flight of tests/ground_io/flightgen: trajectory and events (orientations and GCPs are
    what the adjustment form uploads)."""
    from tests.ground_io.flightgen import write_synthetic_flight

    write_synthetic_flight(folder, n_lines=2)
    files: dict[str, tuple[bytes, str | None]] = {
        "SOL.pos": ((folder / "SOL.pos").read_bytes(), "trajectory"),
        "events.csv": ((folder / "events.csv").read_bytes(), "events"),
    }
    if with_orientations:
        files["poses.csv"] = ((folder / "poses.csv").read_bytes(), "orientations")
    return files


def client_cookies(client: httpx.Client) -> dict[str, str]:
    """The client's cookies by name."""
    return {c.name: c.value for c in client.cookies.jar}
