"""The web interface in a real browser (Playwright driving Debian's chromium) against a live `python -m ground
serve` with a real SQLite file: a drone token refused at sign-in, an engineer signs in, sees the flight the
onboard uploader sent (with the drone's token), runs an adjustment through the form (the orientations as a
MicMac Ori folder zipped, and a GCP file), watches the job end through the page's live status, downloads
`geo.txt` (byte-identical to the API's), sees a failed job's message, and a form sent without its CSRF token is refused in words.

Screenshots go to `$GROUND_WEB_SCREENSHOTS` (default the test's tmp folder). The browser is required: a
missing chromium fails this test (a skipped browser test could not fail)."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest

from onboard.upload.client import Uploader, UploaderOptions
from tests.web.test_preflight import CHROMIUM, CHROMIUM_ARGS

ROOT = Path(__file__).resolve().parents[2]
BOOTSTRAP = "web-browser-bootstrap-0123456789"
pytestmark = [pytest.mark.slow, pytest.mark.timeout(420)]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("DIRECTGEO_TOKEN", "DATABASE_URL")}
    env["PYTHONPATH"] = str(ROOT)
    return env


@dataclass
class Served:
    url: str
    data: Path

    def token(self, role: str, name: str) -> str:
        """A token made by the real command line (`python -m ground token create`) in the server's database."""
        out = subprocess.run([sys.executable, "-m", "ground", "token", "create", "--role", role, "--name", name,
                              "--data-dir", str(self.data)], cwd=ROOT, env=_env(), capture_output=True, text=True,
                             timeout=60, check=True)
        return out.stdout.strip()


@pytest.fixture
def served(tmp_path: Path) -> Iterator[Served]:
    token_file = tmp_path / "bootstrap-token"
    token_file.write_text(BOOTSTRAP + "\n")
    data = tmp_path / "data"
    port = _free_port()
    log = (tmp_path / "serve.log").open("w")
    proc = subprocess.Popen([sys.executable, "-m", "ground", "serve", "--port", str(port), "--data-dir", str(data),
                             "--token-file", str(token_file)], cwd=ROOT, env=_env(), stdout=log,
                            stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                if httpx.get(f"{url}/health", timeout=1).status_code == 200:
                    break
            except httpx.TransportError:
                pass
            assert proc.poll() is None and time.monotonic() < deadline, (tmp_path / "serve.log").read_text()
            time.sleep(0.1)
        assert (data / "directgeo.sqlite3").is_file()
        yield Served(url, data)
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        log.close()


def _flight_folder(root: Path, name: str, rename_events: bool = False) -> tuple[Path, Path]:
    """A synthetic flight folder to upload (trajectory + events) and a folder with its office files (the
    bundle adjustment's poses.csv and gcp.csv). `rename_events`: the events name other images (a job that fails)."""
    from tests.ground_io.flightgen import write_synthetic_flight

    flight, office = root / name, root / f"{name}-office"
    write_synthetic_flight(flight, n_lines=2)
    office.mkdir()
    for n in ("poses.csv", "gcp.csv"):
        shutil.move(flight / n, office / n)
    if rename_events:
        (flight / "events.csv").write_text((flight / "events.csv").read_text().replace("IMG_", "DSC_"))
    return flight, office


def test_engineer_adjusts_a_flight_in_chromium(served: Served, tmp_path: Path) -> None:
    assert CHROMIUM.exists(), "Debian's chromium (/usr/bin/chromium) is needed: apt-get install chromium"
    from playwright.sync_api import sync_playwright

    shots = Path(os.environ.get("GROUND_WEB_SCREENSHOTS", tmp_path))
    shots.mkdir(parents=True, exist_ok=True)
    drone, engineer = served.token("drone", "drone-07"), served.token("engineer", "alice")
    flights = {}
    for name, broken in (("flight-20240215T101500Z", False), ("flight-20240215T140000Z", True)):
        folder, office = _flight_folder(tmp_path, name, rename_events=broken)
        up = Uploader(served.url, drone, UploaderOptions(chunk_bytes=32_000), sleep=lambda s: None)
        try:
            flights[name] = (up.upload_flight(folder, {"events.csv": "events"}).flight_id, office)
        finally:
            up.close()
    (good, office), (bad, bad_office) = flights["flight-20240215T101500Z"], flights["flight-20240215T140000Z"]
    # the good flight's bundle adjustment as MicMac gives it: its Ori folder, zipped
    from ground.io.orientations import read_opk_csv
    from tests.ground_io.test_micmac_zip import micmac_zip

    ori_zip = micmac_zip(read_opk_csv(office / "poses.csv").poses, tmp_path / "Ori-Bundle", tmp_path / "Ori-Bundle.zip")
    broken_poses = tmp_path / "cameras.json"
    broken_poses.write_text('{"not": "an OpenSfM reconstruction"}')

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        context = browser.new_context(accept_downloads=True, viewport={"width": 1200, "height": 1400})
        page = context.new_page()
        requests: list[tuple[str, dict[str, str]]] = []
        page.on("request", lambda r: requests.append((r.url, r.headers)))

        # sign-in: a drone token is refused in words, an engineer's opens a session
        page.goto(f"{served.url}/ui/flights")
        assert "/ui/login" in page.url
        page.fill("#token", drone)
        page.click("#sign-in")
        assert "a drone token cannot sign in" in page.text_content("#error")
        page.fill("#token", engineer)
        page.click("#sign-in")
        page.wait_for_url("**/ui/flights")
        assert "alice (engineer)" in page.text_content("#who")
        assert "directgeo_session" not in page.evaluate("document.cookie")  # HttpOnly: no script can read it

        # the uploaded flights, with what is derived of them
        row = page.locator(f'tr[data-flight="{good}"]').inner_text()
        assert "flight-20240215T101500Z" in row and "drone-07" in row and "uploaded" in row and "%" in row
        page.select_option("select[name=state]", "uploaded")
        page.fill("input[name=drone]", "drone-07")
        page.click("#filters button")
        assert page.locator("tr[data-flight]").count() == 2
        page.screenshot(path=str(shots / "flights.png"), full_page=True)

        # the flight page: files, the trajectory figure (the report's), and no job yet
        page.click(f'a[href="/ui/flights/{good}"]')
        assert page.text_content("#state") == "uploaded"
        assert page.locator("#file-table tr[data-file]").count() == 2
        widths = page.eval_on_selector_all(".plots img", "els => els.map(e => e.complete ? e.naturalWidth : 0)")
        assert len(widths) == 1 and widths[0] > 200, widths

        # a bad orientation file: refused in words, nothing queued
        page.click("#adjust-link")
        page.set_input_files("#orientations", str(broken_poses))
        page.click("#queue-adjust")
        assert "Nothing was queued" in page.text_content("#errors")
        assert "cameras.json" in page.text_content("#errors")
        page.screenshot(path=str(shots / "adjust-refused.png"), full_page=True)

        # the adjustment through the form: MicMac orientations + GCPs uploaded, lever-arm prior, a UTM export
        page.set_input_files("#orientations", str(ori_zip))
        page.set_input_files("#gcp", str(office / "gcp.csv"))
        page.check("input[name=lever_mode][value=prior]")
        for k, v in (("lever_x", "0.05"), ("lever_y", "-0.12"), ("lever_z", "-0.08"), ("lever_sigma", "0.05")):
            page.fill(f"input[name={k}]", v)
        page.fill("#crs", "EPSG:32630")
        page.click("#queue-adjust")
        page.wait_for_url(f"**/ui/flights/{good}#jobs")
        # the page's live status (its poll of the session-authenticated JSON) reloads it when the job ends
        page.wait_for_selector("a.export:text-is('geo.txt')", timeout=240_000)
        assert page.text_content("#state") == "done"
        assert "adjusted" in page.text_content("#job-table .job-message")
        with page.expect_download() as dl:
            page.click("a.export:text-is('geo.txt')")
        got = Path(dl.value.path()).read_bytes()
        api = httpx.get(f"{served.url}/flights/{good}/exports/geo.txt",
                        headers={"Authorization": f"Bearer {engineer}"}, timeout=30)
        assert api.status_code == 200 and got == api.content
        assert b"IMG_0000.JPG" in got
        assert page.locator("#file-table tr[data-file]").count() == 4  # Ori-Bundle.zip and gcp.csv added
        page.screenshot(path=str(shots / "flight-done.png"), full_page=True)

        # a form sent without its CSRF token is refused in words
        page.eval_on_selector("form[action$='/rtk'] input[name=csrf_token]", "e => e.remove()")
        with page.expect_response(lambda r: r.url.endswith("/rtk")) as resp:
            page.click("#rtk-button")
        assert resp.value.status == 403
        assert "security token (CSRF)" in page.text_content("#error")

        # a job that fails (the events name other images): its message on the page, from an OPK CSV
        page.goto(f"{served.url}/ui/flights/{bad}/adjust")
        page.set_input_files("#orientations", str(bad_office / "poses.csv"))
        page.click("#queue-adjust")
        page.wait_for_url(f"**/ui/flights/{bad}#jobs")
        page.wait_for_selector("#job-table .job-status span.failed", timeout=240_000)
        assert "no image has both a pose and an event" in page.text_content("#job-table .job-message")
        page.wait_for_function("document.getElementById('state').textContent === 'failed'", timeout=30_000)
        page.screenshot(path=str(shots / "flight-failed.png"), full_page=True)

        # the report of the good flight
        page.goto(f"{served.url}/ui/flights/{good}/report")
        assert page.locator("#parameters tbody tr").count() >= 11
        page.screenshot(path=str(shots / "report.png"))
        browser.close()

    # no request of the pages carried a bearer token: the session cookie only
    assert requests and not any("authorization" in h for _, h in requests)
    assert all(u.startswith((served.url, "data:")) for u, _ in requests)
