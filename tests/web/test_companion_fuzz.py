"""autopilot.json and upload.json with any JSON value at any key (top level or nested): the API answers 200 and
a value it cannot read is a no-go naming the file and the key (property-based: hypothesis draws the values)."""

from __future__ import annotations

import json
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from onboard.recorder.status import write_status
from onboard.web.app import create_app
from onboard.web.checks import FAIL, OK
from tests.web.test_preflight import _healthy
from tests.web.test_preflight_companion import UPLOAD_OK, autopilot_ok
from tests.web.test_snapshot_fuzz import json_values

AP_KEYS = sorted(autopilot_ok()) + ["battery.voltage_v", "battery.remaining_pct", "gps.fix_type", "gps.h_acc_m",
                                    "camera_check.shots", "camera_check.last_delay_ms", "rtcm.messages"]
UPLOAD_KEYS = sorted(UPLOAD_OK)


@pytest.fixture(scope="module")
def page() -> Iterator[tuple[TestClient, Path]]:
    with tempfile.TemporaryDirectory() as d:
        status_path = Path(d) / "status.json"
        with TestClient(create_app(status_path, base_stream="mavlink")) as client:
            yield client, status_path


def _put(obj: dict[str, Any], key: str, value: Any) -> dict[str, Any]:
    out = json.loads(json.dumps(obj))
    head, _, tail = key.partition(".")
    if tail and isinstance(out.get(head), dict):
        out[head][tail] = value
    else:
        out[head] = value
    return out


def _answer(page: tuple[TestClient, Path], name: str, content: dict[str, Any]) -> dict[str, Any]:
    client, status_path = page
    write_status(status_path, _healthy(time.time_ns()))
    status_path.with_name(name).write_text(json.dumps(content))
    r = client.get("/api/preflight")
    assert r.status_code == 200, r.text
    body: dict[str, Any] = r.json()
    json.dumps(body, allow_nan=False)
    return body


@pytest.mark.slow
@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(key=st.sampled_from(AP_KEYS), value=json_values)
def test_any_autopilot_value_answers_200(page: tuple[TestClient, Path], key: str, value: Any) -> None:
    body = _answer(page, "autopilot.json", _put(autopilot_ok(), key, value))
    named = [c for c in body["checks"] if "autopilot.json:" in c["detail"]]
    assert all(c["level"] == FAIL and key.split(".")[0] in c["detail"] for c in named), named
    assert body["headline"]["level"] in (OK, "warn", FAIL)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(key=st.sampled_from(UPLOAD_KEYS), value=json_values)
def test_any_upload_value_answers_200(page: tuple[TestClient, Path], key: str, value: Any) -> None:
    body = _answer(page, "upload.json", _put(UPLOAD_OK, key, value))
    (line,) = [c for c in body["checks"] if c["name"] == "upload"]
    if "upload.json:" in line["detail"]:
        assert line["level"] == FAIL and key in line["detail"]
    assert body["headline"]["level"] in (OK, "warn", FAIL)
