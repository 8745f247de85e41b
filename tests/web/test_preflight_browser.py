"""The pre-flight page in a real browser (Playwright + Debian's chromium) as the flight companion comes up and as
faults are injected: first with the snapshot files written step by step as the daemon writes them, then with the
real daemon against `python -m hil_sim receiver` and `python -m hil_sim autopilot` on ptys.

Screenshots go to `$PREFLIGHT_SCREENSHOTS` (default the test's tmp folder). The browser is required: a
missing chromium fails these tests (a skipped browser test could not fail)."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import uvicorn

from onboard.recorder.status import RTK_STATUS_NAME, StatusSnapshot, write_status
from onboard.web.app import create_app
from tests.web.test_preflight import CHROMIUM, CHROMIUM_ARGS, _free_port, _healthy, _rtk_fixed
from tests.web.test_preflight_companion import autopilot_ok

PROJECT = Path(__file__).resolve().parents[2]
pytestmark = [pytest.mark.slow, pytest.mark.timeout(240)]
VERDICT = "document.getElementById('verdict').textContent"


@contextlib.contextmanager
def page_server(status_path: Path, base_stream: str | None = None) -> Iterator[str]:
    port = _free_port()
    server = uvicorn.Server(uvicorn.Config(create_app(status_path, base_stream=base_stream), host="127.0.0.1",
                                           port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 10
    while not server.started and time.monotonic() < deadline:
        time.sleep(0.05)
    assert server.started, "uvicorn did not start"
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(timeout=5)


@contextlib.contextmanager
def browser_page(url: str) -> Iterator[Any]:
    from playwright.sync_api import sync_playwright

    assert CHROMIUM.exists(), "Debian's chromium (/usr/bin/chromium) is needed: apt-get install chromium"
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1100, "height": 1300})
        page.goto(url)
        page.evaluate("window.__loaded_once = true")  # survives only if the page never reloads
        try:
            yield page
        finally:
            browser.close()


def wait_verdict(page: Any, verdict: str, fault: str = "", timeout_s: float = 15) -> str:
    """Wait until the top line reads `verdict` and its fault text contains `fault`; returns the fault text."""
    page.wait_for_function(
        f"{VERDICT} === {verdict!r} && document.getElementById('fault').textContent.includes({fault!r})",
        timeout=timeout_s * 1000)
    assert page.evaluate("window.__loaded_once === true"), "the page reloaded"
    return str(page.inner_text("#fault"))


def shots_dir(tmp_path: Path) -> Path:
    d = Path(os.environ.get("PREFLIGHT_SCREENSHOTS", str(tmp_path)))
    d.mkdir(parents=True, exist_ok=True)
    return d


def test_page_follows_the_companion_coming_up_and_its_faults(tmp_path: Path) -> None:
    """Snapshot files written step by step as the daemon writes them (status.json, autopilot.json, rtk.json)."""
    status_path = tmp_path / "status.json"
    ap_path, rtk_path = status_path.with_name("autopilot.json"), status_path.with_name(RTK_STATUS_NAME)
    with page_server(status_path, base_stream="mavlink") as url, browser_page(url) as page:
        wait_verdict(page, "DO NOT FLY", "recorder: no status snapshot")
        now = time.time_ns()
        write_status(status_path, StatusSnapshot(pid=1, updated_wall_ns=now, started_wall_ns=now,
                                                 port_device="/dev/ttyAMA0"))
        wait_verdict(page, "DO NOT FLY", "recorder: state starting")
        write_status(status_path, _healthy(time.time_ns()))
        write_status(ap_path, {**autopilot_ok(), "link_open": False, "link_error": "not open yet",
                               "heartbeat_age_s": None, "link_up": False})
        wait_verdict(page, "DO NOT FLY", "autopilot link: serial:/dev/ttyAMA1@921600 closed")
        write_status(ap_path, {**autopilot_ok(), "rtcm": {"fragments": 40, "messages": 12, "dropped": 0,
                                                          "bytes": 5000}})
        # real-time RTK configured (rtk.base_stream = "mavlink"), its snapshot not written yet, then no base yet
        wait_verdict(page, "DO NOT FLY", "base corrections: real-time RTK configured (MAVLink GPS_RTCM_DATA")
        write_status(rtk_path, {**_rtk_fixed().to_json(), "base_epochs": 0, "age_s": None, "q": 5})
        wait_verdict(page, "DO NOT FLY", "base corrections: none yet from MAVLink GPS_RTCM_DATA")
        write_status(rtk_path, _rtk_fixed().to_json())
        wait_verdict(page, "READY TO FLY")
        assert page.inner_text("#fault") == ""
        autopilot = page.inner_text("#block-autopilot")
        assert "LOITER" in autopilot and "6 (RTK fixed)" in autopilot and "16.40 V" in autopilot
        assert "MAVLink GPS_RTCM_DATA" in page.inner_text("#block-base-corrections")
        assert "no automatic upload configured" in page.inner_text("#block-upload")
        page.screenshot(path=str(shots_dir(tmp_path) / "preflight-files-go.png"), full_page=True)

        # the base corrections stop: rtk.json's age grows past the pre-flight timeout (rtk.json's own, 12 s here)
        for age in (3.0, 8.0):
            write_status(status_path, _healthy(time.time_ns()))
            write_status(rtk_path, {**_rtk_fixed().to_json(), "age_s": age, "preflight_base_timeout_s": 12.0})
            wait_verdict(page, "READY TO FLY")
        write_status(rtk_path, {**_rtk_fixed().to_json(), "age_s": 14.0, "preflight_base_timeout_s": 12.0})
        fault = wait_verdict(page, "DO NOT FLY", "base corrections: base corrections stopped 14 s ago")
        assert "(source MAVLink GPS_RTCM_DATA (ground station inject); no-go after 12 s)" in fault
        page.screenshot(path=str(shots_dir(tmp_path) / "preflight-files-base-stopped.png"), full_page=True)

        # the autopilot link stops: its heartbeat ages past link_timeout_s
        write_status(rtk_path, _rtk_fixed().to_json())
        write_status(ap_path, {**autopilot_ok(), "link_up": False, "heartbeat_age_s": 4.2})
        wait_verdict(page, "DO NOT FLY", "autopilot link: autopilot link lost: last heartbeat 4 s ago")
        # a value of the wrong kind: a named no-go, the page keeps working
        write_status(ap_path, {**autopilot_ok(), "heartbeat_age_s": "late"})
        wait_verdict(page, "DO NOT FLY", "autopilot.json: heartbeat_age_s must be a number, got 'late'")
        write_status(ap_path, autopilot_ok())
        wait_verdict(page, "READY TO FLY")


def _start(cmd: list[str], env: dict[str, str], log: Path) -> tuple[subprocess.Popen[bytes], str]:
    """Start a simulator; its first stdout line is its pty. Its log goes to a file (a pipe nobody reads would
    fill and stall it)."""
    with log.open("wb") as err:
        proc = subprocess.Popen(cmd, cwd=PROJECT, env=env, stdout=subprocess.PIPE, stderr=err)
    assert proc.stdout is not None
    line = proc.stdout.readline().decode().strip()
    assert line, log.read_text(errors="replace")[-3000:] or f"{cmd} printed nothing"
    return proc, line


def test_page_with_the_real_daemon_and_simulators_on_ptys(tmp_path: Path) -> None:
    """The real daemon (`python -m onboard run`) with the hil_sim receiver (M8T) and the hil_sim autopilot on
    raw ptys: red while the system starts, go once the receiver is configured, tracks and flashes and the
    autopilot's heartbeat comes; the autopilot stand-in stopped: a no-go naming the autopilot link."""
    env = dict(os.environ, PYTHONPATH=str(PROJECT))
    env.pop("NOTIFY_SOCKET", None)
    status_path = tmp_path / "run" / "status.json"
    procs: list[subprocess.Popen[bytes]] = []
    with page_server(status_path) as url, browser_page(url) as page:
        try:
            wait_verdict(page, "DO NOT FLY", "no status snapshot")
            receiver, rx_pty = _start([sys.executable, "-m", "hil_sim", "receiver", "--model", "m8t", "--speed",
                                       "4", "--time-valid-after", "4"], env, tmp_path / "receiver.log")
            procs.append(receiver)
            autopilot, ap_pty = _start([sys.executable, "-m", "hil_sim", "autopilot", "--speed", "4",
                                        "--arm-at", "100000"], env, tmp_path / "autopilot.log")
            procs.append(autopilot)
            cfg = tmp_path / "recorder.toml"
            cfg.write_text('[receiver]\ncamera_period_s = 2.0\n[journal]\ndisk_floor_mb = 1.0\n'
                           f'[status]\ninterval_s = 0.5\n[autopilot]\nlink = "serial:{ap_pty}@921600"\n'
                           'link_timeout_s = 2.0\n')
            daemon_log = tmp_path / "daemon.log"
            with daemon_log.open("wb") as out:
                daemon = subprocess.Popen(
                    [sys.executable, "-m", "onboard", "run", "--config", str(cfg), "--port", rx_pty, "--baud",
                     "115200", "--data-dir", str(tmp_path / "data"), "--status", str(status_path)],
                    cwd=PROJECT, env=env, stdout=out, stderr=subprocess.STDOUT)
            procs.append(daemon)
            # the system comes up: the daemon's own no-gos first (starting, no epochs yet, configuring, no
            # heartbeat yet...), then go; every distinct top line is kept
            seen: list[str] = []
            red_shot = False
            deadline = time.monotonic() + 120
            while time.monotonic() < deadline:
                line = f"{page.inner_text('#verdict')} | {page.inner_text('#fault')}"
                if not seen or seen[-1] != line:
                    seen.append(line)
                    if line.startswith("DO NOT FLY") and "no status snapshot" not in line and not red_shot:
                        red_shot = True
                        page.screenshot(path=str(shots_dir(tmp_path) / "preflight-daemon-red.png"), full_page=True)
                if line.startswith("READY TO FLY"):
                    break
                time.sleep(0.1)
            assert seen[-1].startswith("READY TO FLY"), (
                f"never go: {seen}\ndaemon: {daemon_log.read_text(errors='replace')[-2000:]}")
            daemon_red = [x for x in seen if x.startswith("DO NOT FLY") and "no status snapshot" not in x]
            assert daemon_red, f"no no-go from the daemon's own snapshots before go: {seen}"
            (shots_dir(tmp_path) / "preflight-daemon-sequence.txt").write_text("\n".join(seen) + "\n")
            checks = page.inner_text("#checks")
            assert "heartbeat" in checks and "disarmed" in checks and "applied and verified" in checks
            assert "pre-arm checks pass" in checks
            block = page.inner_text("#block-autopilot")
            assert "6 (RTK fixed)" in block and "on_ground" in block
            page.screenshot(path=str(shots_dir(tmp_path) / "preflight-daemon-go.png"), full_page=True)

            autopilot.send_signal(signal.SIGTERM)  # the autopilot link stops (the stand-in is gone)
            autopilot.communicate(timeout=30)
            fault = wait_verdict(page, "DO NOT FLY", "autopilot link", timeout_s=30)
            assert "autopilot link" in fault and ("lost" in fault or "closed" in fault), fault
            page.screenshot(path=str(shots_dir(tmp_path) / "preflight-daemon-link-lost.png"), full_page=True)
            daemon.send_signal(signal.SIGTERM)
            daemon.wait(timeout=30)
            assert daemon.returncode == 0, daemon_log.read_text(errors="replace")[-3000:]
        finally:
            for proc in reversed(procs):  # daemon, then the stand-ins: only the processes this test started
                if proc.poll() is None:
                    proc.send_signal(signal.SIGTERM)
                    with contextlib.suppress(subprocess.TimeoutExpired):
                        proc.communicate(timeout=20)
                if proc.poll() is None:
                    proc.kill()
                    proc.communicate()
