"""The served HTML report in a real browser (Playwright driving Debian's chromium): parameter table and every
figure render, with no external request. Skips with a reason when chromium or playwright is absent."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from onboard.upload.client import Uploader, UploaderOptions
from tests.ground_api.conftest import TOKEN, LiveServer

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]

pytestmark = pytest.mark.timeout(180)


@pytest.mark.slow
def test_report_renders_in_chromium(live: LiveServer, tmp_path: Path) -> None:
    if not CHROMIUM.exists():
        pytest.skip("Debian's chromium (/usr/bin/chromium) is not installed: browser test skipped")
    sync_api = pytest.importorskip("playwright.sync_api")
    pytest.importorskip("ground.adjust.solve")
    from tests.ground_io.flightgen import write_synthetic_flight

    folder = tmp_path / "flight-report"
    write_synthetic_flight(folder, n_lines=2)
    roles = {"SOL.pos": "trajectory", "events.csv": "events", "poses.csv": "orientations", "gcp.csv": "gcp"}
    up = Uploader(live.url, TOKEN, UploaderOptions(chunk_bytes=60_000), sleep=lambda s: None)
    fid = up.upload_flight(folder, roles).flight_id
    up.close()
    with live.client() as c:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            jobs = c.get(f"/flights/{fid}").json()["jobs"]
            if jobs and jobs[-1]["status"] in ("done", "failed"):
                break
            time.sleep(0.2)
        assert jobs[-1]["status"] == "done", jobs[-1]["message"]
    external: list[str] = []
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        page = browser.new_page(extra_http_headers={"Authorization": f"Bearer {TOKEN}"})
        page.on("request", lambda r: external.append(r.url) if not r.url.startswith((live.url, "data:")) else None)
        page.goto(f"{live.url}/flights/{fid}/report")
        rows = page.locator("#parameters tbody tr")
        assert rows.count() >= 11
        assert "lever arm O_x" in rows.nth(0).inner_text()
        assert page.locator("#checkpoints tbody tr").count() == 2 + 3  # 2 points + mean/std/rms
        imgs = page.locator("img")
        assert imgs.count() >= 4
        widths = page.eval_on_selector_all("img", "els => els.map(e => e.complete ? e.naturalWidth : 0)")
        assert all(w > 100 for w in widths), widths  # every embedded PNG decoded
        shot = tmp_path / "report.png"
        page.screenshot(path=str(shot), full_page=False)
        assert shot.stat().st_size > 10_000
        browser.close()
    assert external == []
    # the unauthenticated browser gets 401 for the same report
    with live.client(token=None) as anon:
        assert anon.get(f"/flights/{fid}/report").status_code == 401
