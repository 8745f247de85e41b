"""The pre-flight check page: checks from snapshots, and the real page in a real browser."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import uvicorn

from onboard.status import SatelliteStatus, StatusSnapshot, write_status
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
        page.wait_for_function("document.getElementById('overall').textContent === 'DO NOT FLY'", timeout=10000)
        assert "no status snapshot" in page.inner_text("#checks")
        write_status(status_path, _healthy(time.time_ns()))
        page.wait_for_function("document.getElementById('overall').textContent === 'READY TO FLY'", timeout=10000)
        assert page.locator("#sats .bar").count() == 7
        snap = _healthy(time.time_ns())
        snap.config_state, snap.config_error = "failed", "CFG-TP5.flags: NAK from receiver"
        write_status(status_path, snap)
        page.wait_for_function("document.getElementById('overall').textContent === 'DO NOT FLY'", timeout=10000)
        assert "CFG-TP5.flags" in page.inner_text("#checks")
        browser.close()


def test_api_survives_a_garbage_snapshot(live_page: tuple[str, Path]) -> None:
    import httpx

    url, status_path = live_page
    status_path.write_text("{ not json")
    body = httpx.get(url + "/api/preflight", timeout=5).json()
    assert body["overall"] == FAIL and body["error"]
