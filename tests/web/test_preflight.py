"""The pre-flight check page: checks from snapshots, and the real page in a real browser."""

from __future__ import annotations

import json
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import uvicorn

from onboard.realtime.service import RtkStatus
from onboard.recorder.status import RTK_STATUS_NAME, SatelliteStatus, StatusSnapshot, write_status
from onboard.web.app import create_app
from onboard.web.checks import FAIL, OK, WARN, overall, preflight_checks

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def _healthy(now_ns: int) -> StatusSnapshot:
    return StatusSnapshot(
        pid=1, updated_wall_ns=now_ns, state="recording", flight="flight-1", port_device="/dev/ttyAMA0",
        port_open=True, receiver_model="m8t", receiver_sw_version="ROM CORE 3.01 (107888)", config_state="verified",
        epochs=120, last_epoch_gpst="1590:345600.992", time_marks=3, disk_free_bytes=20 * 10**9,
        disk_floor_bytes=200 * 10**6,
        satellites=[SatelliteStatus(0, prn, 44.0) for prn in (2, 5, 10, 12, 25, 29, 31)],
    )


def _levels(status: dict | None, now_ns: int) -> dict[str, str]:
    return {c.name: c.level for c in preflight_checks(status, now_ns)}


def test_healthy_recorder_is_ready() -> None:
    now = time.time_ns()
    checks = preflight_checks(_healthy(now).to_json(), now)
    assert overall(checks) == OK, checks


def test_each_problem_is_named() -> None:
    now = time.time_ns()
    assert _levels(None, now) == {"recorder": FAIL}
    stale = _healthy(now - 60 * 10**9).to_json()
    assert _levels(stale, now)["recorder"] == FAIL
    snap = _healthy(now)
    snap.config_state, snap.config_error = "failed", "CFG-TP5.flags: NAK from receiver"
    checks = preflight_checks(snap.to_json(), now)
    assert any(c.level == FAIL and "CFG-TP5.flags" in c.detail for c in checks)
    snap = _healthy(now)
    snap.satellites = snap.satellites[:4]
    assert _levels(snap.to_json(), now)["satellites"] == FAIL
    snap = _healthy(now)
    snap.disk_free_bytes = 300 * 10**6
    assert _levels(snap.to_json(), now)["disk"] == FAIL
    snap = _healthy(now)
    snap.time_marks = 0
    assert _levels(snap.to_json(), now)["camera time marks"] == WARN
    snap = _healthy(now)
    snap.port_open, snap.port_error, snap.state = False, "device disappeared", "port_lost"
    lv = _levels(snap.to_json(), now)
    assert lv["receiver link"] == FAIL and lv["recorder"] == FAIL


def _satellites(now_ns: int, sats: list[SatelliteStatus], rtk: dict | None = None) -> tuple[str, str]:
    snap = _healthy(now_ns)
    snap.satellites = sats
    (check,) = [c for c in preflight_checks(snap.to_json(), now_ns, rtk=rtk) if c.name == "satellites"]
    return check.level, check.detail


def test_satellites_of_every_constellation_the_engine_uses_count() -> None:
    """An M8T on GPS + GLONASS + Galileo: 5 + 4 + 3 strong satellites are 9 double differences (one reference per
    constellation), more than the 5 of 6 GPS satellites; counting GPS alone, the page said 5 of 6."""
    now = time.time_ns()
    sats = ([SatelliteStatus(0, prn, 44.0) for prn in (2, 5, 10, 12, 25)]
            + [SatelliteStatus(6, sv, 40.0) for sv in (1, 2, 8, 17)]
            + [SatelliteStatus(2, sv, 42.0) for sv in (3, 11, 24)]
            + [SatelliteStatus(0, 31, 30.0), SatelliteStatus(1, 123, 45.0)])  # weak GPS, SBAS: not counted
    rtk = {**_rtk_fixed().to_json(), "systems": "GRE"}
    assert _satellites(now, sats, rtk) == (
        OK, ("12 satellites ≥ 35 dB-Hz: GPS 5, GLONASS 4, Galileo 3 (need 6 of one constellation, one more for "
             "each further one)"))
    # the engine set to GPS alone counts GPS alone: one double difference short
    assert _satellites(now, sats, {**rtk, "systems": "G"}) == (WARN, "5 GPS satellites ≥ 35 dB-Hz (need 6)")
    # no real-time RTK (or its constellations not decided yet): what the receiver tracks, SBAS aside
    assert _satellites(now, sats, None)[0] == OK
    assert _satellites(now, sats, {**rtk, "systems": None})[1].startswith("12 satellites")
    assert _satellites(now, sats, {**rtk, "systems": 7})[1].startswith("12 satellites")  # a damaged rtk.json


def test_a_constellation_adds_its_satellites_less_its_reference() -> None:
    now = time.time_ns()

    def split(n_gps: int, n_glo: int) -> str:
        sats = [SatelliteStatus(0, prn, 44.0) for prn in range(1, n_gps + 1)]
        sats += [SatelliteStatus(6, sv, 44.0) for sv in range(1, n_glo + 1)]
        return _satellites(now, sats, {**_rtk_fixed().to_json(), "systems": "GR"})[0]

    assert [split(4, 3), split(3, 3), split(3, 2), split(6, 0), split(6, 1)] == [OK, WARN, FAIL, OK, OK]
    assert [split(5, 1), split(4, 1), split(1, 1)] == [WARN, FAIL, FAIL]
    assert _satellites(now, [], None) == (FAIL, "0 GPS satellites ≥ 35 dB-Hz (need 6)")


def _rtk_fixed() -> RtkStatus:
    """The real-time RTK snapshot of a rover fixed on the epoch the recorder saw last (`_healthy`)."""
    return RtkStatus(running=True, radio_open=True, radio_bytes=52000, base_frames=400, base_epochs=120,
                     epochs=120, fixed=80, float_=40, q=1, ratio=12.5, ns=9, age_s=0.8, baseline_m=420.0,
                     last_gpst="1590:345600.992000000", ttff_s=38.0)


def _rtk_level(rtk: RtkStatus | dict, now_ns: int) -> tuple[str, str]:
    snap = rtk.to_json() if isinstance(rtk, RtkStatus) else rtk
    (check,) = [c for c in preflight_checks(_healthy(now_ns).to_json(), now_ns, rtk=snap) if c.name == "RTK"]
    return check.level, check.detail


def test_rtk_line_only_when_the_daemon_runs_rtk() -> None:
    now = time.time_ns()
    assert "RTK" not in _levels(_healthy(now).to_json(), now)  # no rtk.json: the ground post-processes
    checks = preflight_checks(_healthy(now).to_json(), now, rtk=_rtk_fixed().to_json())
    assert overall(checks) == OK
    level, detail = _rtk_level(_rtk_fixed(), now)
    assert level == OK and "ratio 12.5" in detail and "9 satellites" in detail and "0.42 km" in detail


def test_rtk_problems_are_warnings_with_their_cause() -> None:
    """Float, a silent base, a dead radio, old corrections, a lagging or stopped engine: each says what it is
    (a warning, not a no-go: the journals still let the ground compute the trajectory)."""
    now = time.time_ns()
    cases = {
        "not fixed yet": {"q": 2, "ratio": 1.8},
        "float, base 9.8 km away: beyond 6 km": {"q": 2, "baseline_m": 9800.0, "max_first_fix_baseline_km": 6.0},
        "L1 RTK does not fix from a cold start": {"q": 2, "baseline_m": 9800.0, "max_first_fix_baseline_km": 6.0},
        "beyond 8.5 km": {"q": 2, "baseline_m": 9800.0, "max_first_fix_baseline_km": 8.5},  # as configured
        "no base corrections yet": {"base_epochs": 0, "q": 5},
        "base radio closed: device disappeared": {"radio_open": False, "radio_error": "device disappeared"},
        "base corrections 45 s old": {"age_s": 45.0, "q": 2},
        "6 s behind the receiver": {"last_gpst": "1590:345594.992000000"},
        "no solution yet": {"last_gpst": None},
        "not running (2 errors": {"running": False, "errors": 2},
    }
    for expect, change in cases.items():
        rtk = _rtk_fixed()
        for k, v in change.items():
            setattr(rtk, k, v)
        level, detail = _rtk_level(rtk, now)
        assert level == WARN and expect in detail, (change, detail)
    level, detail = _rtk_level({**_rtk_fixed().to_json(), "baseline_m": 9800.0, "max_first_fix_baseline_km": 6.0},
                               now)
    assert level == OK  # a fix held from a shorter baseline (or a surveyed take-off point) stays ok
    level, detail = _rtk_level({**_rtk_fixed().to_json(), "q": 2, "baseline_m": 9800.0,
                                "max_first_fix_baseline_km": 12.0}, now)
    assert level == WARN and "not fixed yet" in detail  # within the configured limit: the usual wait
    level, detail = _rtk_level({**_rtk_fixed().to_json(), "ratio": "abc"}, now)
    assert level == WARN and "malformed" in detail


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture
def live_page(tmp_path: Path) -> Iterator[tuple[str, Path]]:
    status_path = tmp_path / "status.json"
    port = _free_port()
    server = uvicorn.Server(uvicorn.Config(create_app(status_path), host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 10
    while not server.started and time.monotonic() < deadline:
        time.sleep(0.05)
    assert server.started, "uvicorn did not start"
    yield f"http://127.0.0.1:{port}", status_path
    server.should_exit = True
    thread.join(timeout=5)


@pytest.mark.slow
def test_page_in_a_real_browser_follows_the_snapshot(live_page: tuple[str, Path]) -> None:
    if not CHROMIUM.exists():
        pytest.skip("Debian's chromium is not installed (scripts/test.sh installs it when run as root)")
    sync_api = pytest.importorskip("playwright.sync_api")
    url, status_path = live_page
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        page = browser.new_page()
        page.goto(url)
        # no snapshot yet: the page says so
        page.wait_for_function("document.getElementById('verdict').textContent === 'DO NOT FLY'", timeout=10000)
        assert "no status snapshot" in page.inner_text("#checks")
        write_status(status_path, _healthy(time.time_ns()))
        page.wait_for_function("document.getElementById('verdict').textContent === 'READY TO FLY'", timeout=10000)
        assert page.locator("#sats .bar").count() == 7
        snap = _healthy(time.time_ns())
        snap.config_state, snap.config_error = "failed", "CFG-TP5.flags: NAK from receiver"
        write_status(status_path, snap)
        page.wait_for_function("document.getElementById('verdict').textContent === 'DO NOT FLY'", timeout=10000)
        assert "CFG-TP5.flags" in page.inner_text("#checks")
        # the daemon runs RTK: its snapshot beside the status adds the RTK line, float → warnings
        write_status(status_path, _healthy(time.time_ns()))
        rtk = _rtk_fixed()
        rtk.q, rtk.ratio = 2, 1.4
        write_status(status_path.with_name(RTK_STATUS_NAME), rtk.to_json())
        page.wait_for_function("document.getElementById('verdict').textContent === 'CHECK WARNINGS'", timeout=10000)
        assert "wait for the fix before take-off" in page.inner_text("#checks")
        write_status(status_path.with_name(RTK_STATUS_NAME), _rtk_fixed().to_json())
        page.wait_for_function("document.getElementById('verdict').textContent === 'READY TO FLY'", timeout=10000)
        assert "fixed: ratio 12.5" in page.inner_text("#checks")
        # a snapshot with a field of the wrong kind: a no-go that names it (the API answered 500 before)
        status_path.write_text(json.dumps({**_healthy(time.time_ns()).to_json(), "epochs": "many"}))
        page.wait_for_function("document.getElementById('verdict').textContent === 'DO NOT FLY'", timeout=10000)
        assert "status snapshot unreadable: epochs: must be a whole number, got 'many'" in page.inner_text("#checks")
        browser.close()


def test_api_survives_a_garbage_snapshot(live_page: tuple[str, Path]) -> None:
    import httpx

    url, status_path = live_page
    status_path.write_text("{ not json")
    body = httpx.get(url + "/api/preflight", timeout=5).json()
    assert body["overall"] == FAIL and body["error"]


def test_api_survives_a_garbage_rtk_snapshot(live_page: tuple[str, Path]) -> None:
    """A torn rtk.json costs the RTK line its content, not the page: the other checks still come through."""
    import httpx

    url, status_path = live_page
    write_status(status_path, _healthy(time.time_ns()))
    status_path.with_name(RTK_STATUS_NAME).write_text('{"running": tr')
    body = httpx.get(url + "/api/preflight", timeout=5).json()
    levels = {c["name"]: c["level"] for c in body["checks"]}
    assert levels["RTK"] == WARN and levels["recorder"] == OK
    assert any("RTK status unreadable" in c["detail"] for c in body["checks"])
    status_path.with_name(RTK_STATUS_NAME).write_text("[1, 2]")  # JSON, but not an RTK snapshot
    body = httpx.get(url + "/api/preflight", timeout=5).json()
    assert any("not a JSON object" in c["detail"] for c in body["checks"] if c["name"] == "RTK")
    write_status(status_path.with_name(RTK_STATUS_NAME), _rtk_fixed().to_json())
    body = httpx.get(url + "/api/preflight", timeout=5).json()
    assert body["overall"] == OK and body["rtk"]["q"] == 1
