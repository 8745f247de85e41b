"""Issue 14, API side: the job runner ends every job (SystemExit, KeyboardInterrupt, time limit), job
parameters checked at submission (422, RTK `direction: sideways` included), capped JSON bodies (413), a
zero-size manifest entry with a wrong SHA (422), and hypothesis fuzzing of the job route."""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ground.api.app import create_app
from ground.api.jobs import run_job_process
from ground.api.schemas import AdjustParams
from ground.api.settings import ApiSettings
from tests.ground_api import jobfuncs

TOKEN = "test-token-0123456789abcdef"
EMPTY = hashlib.sha256(b"").hexdigest()


@pytest.mark.parametrize(("func", "message"), [
    (jobfuncs.exits, "SystemExit: 2"), (jobfuncs.interrupted, "KeyboardInterrupt"),
    (jobfuncs.hangs, "exceeded the time limit of 3 s"),
])
@pytest.mark.slow
def test_every_job_ends(tmp_path: Path, func, message: str) -> None:  # type: ignore[no-untyped-def]
    """Case 5: SystemExit escaped `except Exception` and left the job running forever; now each ends failed."""
    t0 = time.monotonic()
    status, text = run_job_process(func, (None, {}, {}, tmp_path, tmp_path), timeout_s=3.0)
    assert status == "failed" and message in text
    assert time.monotonic() - t0 < 30
    assert run_job_process(jobfuncs.works, (None, {}, {}, tmp_path, tmp_path), 30.0) == ("done", "ok")


@pytest.fixture
def client(tmp_path: Path):  # type: ignore[no-untyped-def]
    s = ApiSettings(data_dir=tmp_path / "data", token=TOKEN, max_json_bytes=64 * 1024)
    with TestClient(create_app(s), headers={"Authorization": f"Bearer {TOKEN}"}) as c:
        yield c


def _complete_flight(c: TestClient, roles: dict[str, str]) -> str:
    files = [{"name": n, "size": 0, "sha256": EMPTY, "role": r} for n, r in roles.items()]
    r = c.post("/flights", json={"name": f"f-{len(roles)}-{time.monotonic_ns()}", "files": files})
    assert r.status_code == 201, r.text
    assert r.json()["status"] == "complete"
    return str(r.json()["id"])


def test_job_parameters_are_checked_at_submission(client: TestClient) -> None:
    """Case 5/3: `direction: sideways`, a NaN lever arm, a non-ECEF base: 422 with the rule, no job created."""
    fid = _complete_flight(client, {"r.obs": "rover_obs", "b.obs": "base_obs", "e.csv": "events",
                                    "o.csv": "orientations", "t.pos": "trajectory"})
    cases = [
        ({"kind": "rtk", "params": {"direction": "sideways"}}, "direction"),
        ({"kind": "rtk", "params": {"base_pos": "nan,nan,nan"}}, "must be a finite number"),
        ({"kind": "rtk", "params": {"base_pos": [0, 0, 0]}}, "near the Earth's surface"),
        ({"kind": "rtk", "params": {"systems": "GX"}}, "letters of G, R, E, C, J"),
        ({"kind": "adjust", "params": {"lever_arm": [float("nan"), 0, 0]}}, "must be a finite number"),
        ({"kind": "adjust", "params": {"delay": float("inf")}}, "must be a finite number"),
        ({"kind": "adjust", "params": {"capture_times": {"a.jpg": "yesterday"}}}, "capture_times"),
        ({"kind": "adjust", "params": {"unknown": 1}}, "unknown"),
    ]
    for body, words in cases:  # NaN as JSON's NaN literal (Python's json and Starlette's request.json accept it)
        r = client.post(f"/flights/{fid}/jobs", content=json.dumps(body), headers={"content-type": "application/json"})
        assert r.status_code == 422 and words in r.text, (body, r.text)
    assert client.get(f"/flights/{fid}").json()["jobs"] == []


def test_capture_times_are_expressible_through_the_api() -> None:
    """Case 5: the adjustment of an events.jsonl flight needs capture times: a file role or an inline map."""
    p = AdjustParams.model_validate({"capture_times": {"IMG_0001.JPG": "2024:05:01 10:15:00.250"},
                                     "lever_arm": [0.05, -0.12, -0.08], "delay": 0.064})
    assert p.job_options().lever_arm_m == (0.05, -0.12, -0.08)
    assert AdjustParams.model_validate({"capture_times": "times.csv"}).capture_times == "times.csv"


def test_json_bodies_are_capped_and_empty_files_need_the_empty_hash(client: TestClient) -> None:
    """Case 10: JSON bodies had no cap (now 413); a zero-size file with a wrong SHA made a flight that could
    never complete (now 422)."""
    big = {"name": "big", "files": [{"name": f"f{i}.ubx", "size": 1, "sha256": "0" * 64} for i in range(2000)]}
    r = client.post("/flights", json=big)
    assert r.status_code == 413 and "limit" in r.text
    bad = {"name": "zero", "files": [{"name": "a.ubx", "size": 0, "sha256": "1" * 64}]}
    r = client.post("/flights", json=bad)
    assert r.status_code == 422 and "could never complete" in r.text


_JSONISH = st.recursive(st.one_of(st.none(), st.booleans(), st.floats(), st.integers(), st.text(max_size=8)),
                        lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                st.dictionaries(st.text(max_size=8), inner, max_size=3)),
                        max_leaves=8)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(kind=st.sampled_from(["adjust", "rtk", "other"]),
       params=st.dictionaries(st.sampled_from(["lever_arm", "delay", "delay_sigma", "crs", "estimate", "base_pos",
                                               "direction", "elmask_deg", "capture_times", "events", "x"]),
                              _JSONISH, max_size=4))
@pytest.mark.slow
def test_fuzz_job_route(client: TestClient, kind: str, params: dict) -> None:  # type: ignore[type-arg]
    """60 drawn job bodies on a flight without usable files: always a clean 422 (never 500, never a job)."""
    fid = _complete_flight(client, {"n.txt": "raw"})
    r = client.post(f"/flights/{fid}/jobs", content=json.dumps({"kind": kind, "params": params}),
                    headers={"content-type": "application/json"})
    assert r.status_code == 422, r.text
    assert "Traceback" not in r.text


@pytest.mark.slow
def test_the_api_adjusts_an_events_jsonl_flight_with_capture_times(live, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """Case 5: the API could not pass capture times, so it could not adjust the demo's kind of flight (onboard
    events.jsonl + camera capture times, lever-arm prior, delay estimated); now the job params carry them."""
    import datetime as dt

    import httpx

    from onboard.gnsstime import GpsTime
    from onboard.upload.client import Uploader, UploaderOptions
    from tests.ground_io.flightgen import write_synthetic_flight
    from tests.ground_io.test_adjust_cli import _events_jsonl_from_csv

    folder = tmp_path / "flight-jsonl"
    truth = write_synthetic_flight(folder, n_lines=2)
    names = _events_jsonl_from_csv(folder, drop=5)
    rows = [line.split(",") for line in (folder / "events.csv").read_text().splitlines()[1:]]
    (folder / "events.csv").unlink()
    caps = {}
    for name, (_, week, tow) in zip(names, rows):
        t = GpsTime.from_week_tow_s(int(week), float(tow)).to_gpst_datetime().replace(tzinfo=None)
        caps[name] = (t.replace(microsecond=0) + dt.timedelta(hours=1, seconds=12.3)).isoformat()
    roles = {"SOL.pos": "raw", "events.jsonl": "raw", "poses.csv": "raw", "gcp.csv": "raw"}
    rep = Uploader(live.url, TOKEN, UploaderOptions(chunk_bytes=60_000), sleep=lambda s: None).upload_flight(
        folder, roles)
    params = {"trajectory": "SOL.pos", "events": "events.jsonl", "orientations": "poses.csv", "gcp": "gcp.csv",
              "capture_times": caps, "lever_arm": list(truth.lever_arm_m), "lever_arm_sigma": 0.005,
              "estimate": ["delay"]}
    with httpx.Client(base_url=live.url, headers={"Authorization": f"Bearer {TOKEN}"}, timeout=30) as c:
        r = c.post(f"/flights/{rep.flight_id}/jobs", json={"kind": "adjust", "params": params})
        assert r.status_code == 202, r.text
        job_id = r.json()["id"]
        deadline = time.monotonic() + 120
        while (job := c.get(f"/flights/{rep.flight_id}/jobs/{job_id}").json())["status"] not in ("done", "failed"):
            assert time.monotonic() < deadline, "job did not finish"
            time.sleep(0.3)
        assert job["status"] == "done", job["message"]
        res = c.get(f"/flights/{rep.flight_id}/results").json()
    assert res["matching"]["method"] == "capture_time" and res["matching"]["missing_marks"] == [names[5]]
    assert res["delay_s"] == pytest.approx(truth.delay_s, abs=0.005)
