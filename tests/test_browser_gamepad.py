"""An intervention made with a gamepad button is logged as ``via: "gamepad"`` (headless Chromium
with a scripted standard-mapping gamepad; the keyboard does the teleoperation)."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pandas as pd
import pytest

import test_browser
from trustseek.client import Client
from trustseek.server.app import STATIC
from trustseek.testing.browser import CHROMIUM, launch_chromium
from trustseek.testing.servers import ThreadServer

pytestmark = pytest.mark.browser

TOKEN = "gamepad-test-token"

# navigator.getGamepads() returns one connected standard gamepad whose X button (index 2) is
# held while window.__padX is true
FAKE_GAMEPAD = """
window.__padX = false;
Object.defineProperty(Navigator.prototype, "getGamepads", {
  configurable: true,
  value: () => [{
    id: "Scripted pad (STANDARD GAMEPAD)", index: 0, connected: true, mapping: "standard",
    timestamp: performance.now(), axes: [0, 0, 0, 0],
    buttons: Array.from({ length: 17 }, (_, i) => ({ pressed: i === 2 && window.__padX, touched: false, value: 0 })),
  }],
});
"""


def test_gamepad_intervention_is_logged_as_gamepad(tmp_path):
    if not Path(CHROMIUM).exists():
        pytest.fail(f"{CHROMIUM} is missing: run scripts/setup.sh")
    if not (STATIC / "participant.js").exists():
        pytest.fail("front end not built: run scripts/setup.sh (npm ci && npm run build in web/)")
    from playwright.sync_api import sync_playwright

    with ThreadServer(f"sqlite:///{tmp_path / 'pad.sqlite'}", TOKEN) as url:
        c = Client(url, TOKEN)
        study = c.create_study(
            {
                "name": "pad",
                "blocks": [{"policy": {"kind": "never-ask"}, "schedule": {"trials": ["high"]}}],
                "animation_speed": 3.0,
            }
        )
        link = c.create_sessions(study["id"], participants=["pad-1"])[0]["link"]
        with sync_playwright() as p:
            browser = launch_chromium(p)
            page = browser.new_page(viewport={"width": 1320, "height": 900})
            page.add_init_script(FAKE_GAMEPAD)
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(link + "?speed=1")
            page.wait_for_selector("#screen-consent:not([hidden])")
            page.check("#agree")
            page.click("#consent-btn")
            page.wait_for_selector("#screen-instructions:not([hidden])")
            page.click("#start-btn")
            page.wait_for_function("window.trustseek.state().phase === 'approach'")
            page.wait_for_timeout(200)  # frames polled with the button up
            page.evaluate("window.__padX = true")
            page.wait_for_function("window.trustseek.state().phase === 'teleop'", timeout=5000)
            page.evaluate("window.__padX = false")
            test_browser.teleoperate(page)
            page.wait_for_selector("#screen-done:not([hidden])", timeout=20000)
            browser.close()
        assert errors == []
        events = pd.read_csv(io.BytesIO(c.export(study["id"], table="events")))
        c.close()
    data = [json.loads(d) for d in events[events["type"] == "intervene"]["data"]]
    assert [d["via"] for d in data] == ["gamepad"]
