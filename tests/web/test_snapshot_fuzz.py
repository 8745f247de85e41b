"""A status snapshot with a field of the wrong kind: the page and the API answer 200 with a no-go naming the field,
never 500 (property-based: hypothesis draws the values)."""

from __future__ import annotations

import dataclasses
import json
import math
import tempfile
import time
import typing
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from onboard.recorder.status import (
    RTK_STATUS_NAME,
    SatelliteStatus,
    SnapshotError,
    StatusSnapshot,
    check_snapshot,
)
from onboard.web.app import create_app
from onboard.web.checks import FAIL, OK, checks_json, preflight_checks
from tests.web.test_preflight import _healthy

HINTS = typing.get_type_hints(StatusSnapshot)
FIELDS = [f.name for f in dataclasses.fields(StatusSnapshot) if f.name != "schema"]
EXAMPLES = 20  # per field through the reader and the checks: 36 fields × 20 = 720 snapshots
HTTP_EXAMPLES = 60  # through the web app (a request costs ~50 ms here)

json_scalars = st.one_of(st.none(), st.booleans(), st.integers(min_value=-(10**30), max_value=10**30),
                         st.floats(allow_nan=False, allow_infinity=False), st.text(max_size=20))
json_values = st.recursive(json_scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8), inner, max_size=4)), max_leaves=10)


def _accepts(hint: Any, value: Any) -> bool:
    """The schema's answer (from StatusSnapshot's annotations), written independently of the reader's."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if args and origin is not list and origin is not dict:  # X | None
        return any(_accepts(a, value) for a in args)
    if hint is type(None):
        return value is None
    if hint is bool:
        return type(value) is bool
    if hint is int:
        return type(value) is int
    if hint is float:
        return type(value) in (int, float) and math.isfinite(value)
    if hint is str:
        return type(value) is str
    if origin is list:
        return type(value) is list and all(_accepts(args[0], v) for v in value)
    if origin is dict:
        return type(value) is dict
    if hint is SatelliteStatus:
        return (type(value) is dict and type(value.get("gnss_id")) is int and type(value.get("sv_id")) is int
                and "cn0_dbhz" in value and _accepts(float, value["cn0_dbhz"]))
    raise AssertionError(hint)


@pytest.fixture(scope="module")
def page() -> Iterator[tuple[TestClient, Path]]:
    with tempfile.TemporaryDirectory() as d:
        status_path = Path(d) / "status.json"
        with TestClient(create_app(status_path)) as client:
            yield client, status_path


def _answer(page: tuple[TestClient, Path], snapshot: dict[str, Any]) -> dict[str, Any]:
    client, status_path = page
    status_path.write_text(json.dumps(snapshot))
    r = client.get("/api/preflight")
    assert r.status_code == 200, r.text
    body: dict[str, Any] = r.json()
    assert client.get("/api/status").status_code == 200
    return body


def _unreadable(body: dict[str, Any]) -> list[str]:
    return [c["detail"] for c in body["checks"] if c["detail"].startswith("status snapshot unreadable")]


@pytest.mark.parametrize("name", FIELDS)
@settings(max_examples=EXAMPLES, deadline=None)
@given(value=json_values)
def test_any_value_in_any_field_is_read_or_named(name: str, value: Any) -> None:
    """Any JSON value: a value the schema refuses is a SnapshotError naming the field; one it accepts gives
    checks that can be answered as JSON (no exception, no NaN)."""
    snap = {**_healthy(time.time_ns()).to_json(), name: value}
    try:
        checked = check_snapshot(json.loads(json.dumps(snap)))
    except SnapshotError as exc:
        assert not _accepts(HINTS[name], value)
        assert exc.field == name and str(exc).startswith(f"{name}: "), exc
        return
    assert _accepts(HINTS[name], value)
    json.dumps(checks_json(preflight_checks(checked, time.time_ns())), allow_nan=False)


@pytest.mark.slow
@settings(max_examples=HTTP_EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=st.sampled_from(FIELDS), value=json_values)
def test_any_value_in_any_field_answers_200(page: tuple[TestClient, Path], name: str, value: Any) -> None:
    """Through the app: always 200; a refused value is a no-go naming the field, an accepted one is not."""
    body = _answer(page, {**_healthy(time.time_ns()).to_json(), name: value})
    if _accepts(HINTS[name], value):
        assert not _unreadable(body), body
    else:
        assert body["overall"] == FAIL and body["status"] is None
        (detail,) = _unreadable(body)
        assert detail.startswith(f"status snapshot unreadable: {name}: "), detail


def test_the_cases_of_the_issue(page: tuple[TestClient, Path]) -> None:
    now = time.time_ns()
    cases = {
        "epochs": ("many", "status snapshot unreadable: epochs: must be a whole number, got 'many'"),
        "satellites": (5, "status snapshot unreadable: satellites: must be a list, got 5"),
        "disk_free_bytes": ("lots", "status snapshot unreadable: disk_free_bytes: must be a whole number, got 'lots'"),
        "port_open": (1, "status snapshot unreadable: port_open: must be true or false, got 1"),
    }
    for name, (value, message) in cases.items():
        body = _answer(page, {**_healthy(now).to_json(), name: value})
        assert body["overall"] == FAIL and _unreadable(body) == [message], body
    sats = _healthy(now).to_json()
    sats["satellites"][2]["cn0_dbhz"] = "strong"
    body = _answer(page, sats)
    assert _unreadable(body) == [("status snapshot unreadable: satellites: item 2: cn0_dbhz: must be a number, "
                                 "got 'strong'")]
    # null is what the recorder writes before its first free-space check: a warning, not unreadable
    body = _answer(page, {**_healthy(now).to_json(), "disk_free_bytes": None})
    assert not _unreadable(body) and {c["name"]: c["level"] for c in body["checks"]}["disk"] == "warn"
    # NaN is no JSON number: the answer could not even be encoded
    client, status_path = page
    status_path.write_text(json.dumps(_healthy(now).to_json()).replace('"epochs": 120', '"epochs": NaN'))
    r = client.get("/api/preflight")
    assert r.status_code == 200 and _unreadable(r.json()) == [
        "status snapshot unreadable: not valid JSON: NaN is not a number JSON allows"]
    status_path.write_text("[" * 100_000 + "]" * 100_000)
    assert "nested too deeply" in _unreadable(client.get("/api/preflight").json())[0]
    status_path.write_text(json.dumps(_healthy(now).to_json()))
    assert client.get("/api/preflight").json()["overall"] == OK


@settings(max_examples=HTTP_EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rtk=st.dictionaries(st.sampled_from(["running", "radio_open", "base_epochs", "q", "ratio", "ns", "age_s",
                                            "baseline_m", "last_gpst", "ttff_s", "errors", "restarts",
                                            "max_first_fix_baseline_km", "dropped_epochs", "radio_error"]),
                           json_values, max_size=8))
@pytest.mark.slow
def test_any_rtk_snapshot_answers_200(page: tuple[TestClient, Path], rtk: dict[str, Any]) -> None:
    _client, status_path = page
    status_path.with_name(RTK_STATUS_NAME).write_text(json.dumps(rtk))
    try:
        body = _answer(page, _healthy(time.time_ns()).to_json())
        assert any(c["name"] == "RTK" for c in body["checks"])
    finally:
        status_path.with_name(RTK_STATUS_NAME).unlink()


def test_the_app_takes_no_request_bodies() -> None:
    """The page only reads: every route is GET/HEAD, so no request body is ever read (nothing to size-cap).
    A route that accepts one must come with a cap (and this test changed with it)."""
    app = create_app(Path("/nonexistent/status.json"))
    methods = {m for r in app.routes for m in getattr(r, "methods", set()) if not r.path.startswith(("/docs",
                                                                                                     "/openapi",
                                                                                                     "/redoc"))}
    assert methods <= {"GET", "HEAD"}, methods
    with TestClient(app) as client:
        assert client.post("/api/preflight", content=b"x" * 1_000_000).status_code == 405
