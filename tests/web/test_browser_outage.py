"""The participant page across a reload and a server outage longer than any retry budget: the
trial in progress survives the reload, the page keeps retrying (well past the ~76 s, nine
attempts, after which it used to give up), says that it is reconnecting, and resumes by
itself when the server is back; the trial is stored once, with every event once."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pandas as pd
import pytest

import scene_drive
from test_browser import st, teleoperate
from trustseek.client import Client
from trustseek.server.app import STATIC
from trustseek.testing.browser import CHROMIUM, launch_chromium
from trustseek.testing.servers import ThreadServer, free_port

pytestmark = pytest.mark.browser

TOKEN = "outage-test-token"
OLD_ATTEMPTS = 9  # a trial submission used to be tried 1 + 8 times (300 ms doubling: ~76 s), then abandoned


def test_reload_and_outage_lose_nothing(tmp_path):
    if not Path(CHROMIUM).exists():
        pytest.fail(f"{CHROMIUM} is missing: run scripts/setup.sh")
    if not (STATIC / "participant.js").exists():
        pytest.fail("front end not built: run scripts/setup.sh (npm ci && npm run build in web/)")
    from playwright.sync_api import sync_playwright

    db = f"sqlite:///{tmp_path / 'outage.sqlite'}"
    port = free_port()
    # the server in this process (a second process would take seconds to start, twice); it
    # goes away and comes back on the same port
    server = ThreadServer(db, TOKEN, port)
    url = server.__enter__()
    try:
        c = Client(url, TOKEN)
        study = c.create_study(
            {
                "name": "outage",
                "blocks": [{"name": "help", "policy": {"kind": "always-ask"}, "schedule": {"trials": ["low", "low"]}}],
                "animation_speed": 3.0,
            }
        )
        link = c.create_sessions(study["id"], participants=["outage-1"])[0]["link"]
        with sync_playwright() as p:
            browser = launch_chromium(p)
            page = browser.new_page(viewport={"width": 1000, "height": 600})
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(link + "?retry_cap=100&quality=0")
            page.wait_for_selector("#screen-consent:not([hidden])")
            page.check("#agree")
            page.click("#consent-btn")
            page.click("#start-btn")
            page.wait_for_function("window.trustseek.state().phase === 'teleop'")

            # drive part of the way, then reload: the robot is where it was, the trial goes on
            s0 = st(page)
            page.evaluate("window.__scene.manual(true)")  # driven by the page's state, its clock stopped
            r0 = s0["robot"]
            moved = scene_drive.hold(page, "ArrowUp", f"Math.hypot(s.robot.x - {r0['x']}, s.robot.y - {r0['y']}) > 0.5")["s"]
            before = st(page)
            assert abs(before["robot"]["y"] - moved["robot"]["y"]) < 1e-9
            page.reload()
            page.wait_for_function("window.trustseek.state().phase === 'teleop'")
            after = st(page)
            assert after["trial"] == 1
            assert abs(after["robot"]["y"] - before["robot"]["y"]) < 1e-6, (before["robot"], after["robot"])
            assert abs(after["robot"]["x"] - before["robot"]["x"]) < 1e-6

            # the server goes away; the participant finishes the trial; the page keeps it
            server.__exit__(None, None, None)
            teleoperate(page)
            page.wait_for_selector("#connection:not([hidden])", timeout=5000)
            page.wait_for_function(f"window.trustseek.state().retries > {2 * OLD_ATTEMPTS}", timeout=60000)
            s = st(page)
            assert s["phase"] == "result" and s["trial"] == 1 and s["connection"] == "retrying"
            assert page.is_hidden("#screen-error")

            # the server comes back: the page resumes by itself
            server = ThreadServer(db, TOKEN, port)
            server.__enter__()
            page.wait_for_function(
                "window.trustseek.state().trial === 2 && window.trustseek.state().phase === 'teleop'", timeout=30000
            )
            assert page.is_hidden("#connection")
            assert not errors, errors
            browser.close()

        trials = pd.read_csv(io.BytesIO(c.export(study["id"])))
        events = pd.read_csv(io.BytesIO(c.export(study["id"], table="events")))
    finally:
        server.__exit__(None, None, None)

    assert trials["trial"].tolist() == [1]
    assert trials["human_action"].tolist() == ["intervene"] and trials["effort_ms"].iloc[0] > 0
    first = events[events.trial == 1]
    kinds = first["type"].tolist()
    # the events from before the reload are there, and each once
    for k in ("trial_start", "teleop_start", "resumed", "grasp", "deposit"):
        assert kinds.count(k) == 1, (k, kinds)
    assert kinds.index("trial_start") < kinds.index("resumed") < kinds.index("deposit")
    resumed = json.loads(first[first.type == "resumed"]["data"].iloc[0])
    assert resumed == {"phase": "teleop"}
