"""The reproduction report renders offline in headless Chromium with every figure loaded."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from small_runs import small_reproduction
from trustseek.report import FIGURES, write_report
from trustseek.testing.browser import launch_chromium, screenshot

pytestmark = pytest.mark.browser


def test_report_renders_with_figures(tmp_path):
    from playwright.sync_api import sync_playwright

    paths = write_report(small_reproduction(), tmp_path / "report")
    html = paths["html"]
    # the HTML must stand alone: move it away from its PNGs before opening it
    alone = tmp_path / "alone" / "report.html"
    alone.parent.mkdir()
    alone.write_bytes(html.read_bytes())
    shots = Path(os.environ.get("TRUSTSEEK_ARTIFACTS", tmp_path))
    shots.mkdir(parents=True, exist_ok=True)
    with sync_playwright() as p:
        browser = launch_chromium(p)
        try:
            page = browser.new_page(viewport={"width": 1200, "height": 900})
            requests = []
            page.on("request", lambda r: requests.append(r.url))
            page.goto(alone.as_uri())
            page.wait_for_load_state("load")
            imgs = page.evaluate(
                "Array.from(document.images).map(i => ({file: i.dataset.file, complete: i.complete, w: i.naturalWidth, h: i.naturalHeight}))"
            )
            assert sorted(i["file"] for i in imgs) == sorted(f for f, *_ in FIGURES)
            for i in imgs:
                assert i["complete"] and i["w"] > 300 and i["h"] > 100, i
            # nothing is fetched besides the page itself (figures and styles are embedded)
            assert [u for u in requests if not u.startswith(("file:", "data:"))] == []
            assert "Paper vs reproduction" in page.inner_text("h2 >> nth=0")
            rows = page.locator("table >> nth=0").locator("tr").count()
            assert rows >= 30
            shot = shots / "reproduction_report.png"
            screenshot(page, path=str(shot), full_page=True)
            assert shot.stat().st_size > 50_000
        finally:
            browser.close()
