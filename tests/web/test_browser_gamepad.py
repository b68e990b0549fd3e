"""An intervention made with a gamepad button is logged as ``via: "gamepad"``, and a
teleoperation by the gamepad's sticks and buttons alone reaches the bin (headless Chromium with
a scripted standard-mapping gamepad). The page is driven by its state (``?manual=1``): a button
or a stick is held for as many frames as the goal needs, never for a fixed time."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pandas as pd
import pytest

from scene_drive import FAKE_GAMEPAD, Gamepad, start, step_until, teleoperate
from trustseek.client import Client
from trustseek.server.app import STATIC
from trustseek.testing.browser import CHROMIUM, launch_chromium
from trustseek.testing.servers import ThreadServer

pytestmark = pytest.mark.browser

TOKEN = "gamepad-test-token"


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
            page = browser.new_page(viewport={"width": 1000, "height": 600})
            page.add_init_script(FAKE_GAMEPAD)
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            # the page's clock stops (?manual=1): every frame below is a step of the test's
            start(page, link, "?speed=1&manual=1&quality=0")
            step_until(page, "s.phase === 'approach'", frames=1, limit=3)  # frames polled with the button up
            page.evaluate("window.__pad.buttons[2] = true")  # X
            step_until(page, "s.phase === 'teleop'", frames=1, limit=3)
            page.evaluate("window.__pad.buttons[2] = false")
            teleoperate(page, Gamepad())  # the sticks drive, A grasps, B deposits
            step_until(page, "s.phase === 'done'")
            browser.close()
        assert errors == []
        events = pd.read_csv(io.BytesIO(c.export(study["id"], table="events")))
        c.close()
    data = [json.loads(d) for d in events[events["type"] == "intervene"]["data"]]
    assert [d["via"] for d in data] == ["gamepad"]
    deposit = [json.loads(d) for d in events[events["type"] == "deposit"]["data"]]
    assert len(deposit) == 1 and deposit[0]["gamepad"].startswith("Scripted pad") and deposit[0]["inputs"] > 10
