"""The participant page with the keyboard only, checked by axe-core on every screen, at the
smallest supported window (1280 x 720); phones are refused politely; the dashboard shows a
refused study as a list of problems; a consent or a self-report that fails to save is retried."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pandas as pd
import pytest

from scene_drive import step_until
from test_browser import artifacts_dir, teleoperate
from trustseek.client import Client
from trustseek.server.app import STATIC
from trustseek.testing.browser import CHROMIUM, launch_chromium, screenshot
from trustseek.testing.servers import ThreadServer

pytestmark = pytest.mark.browser

TOKEN = "access-test-token"
AXE = Path(__file__).resolve().parents[2] / "web" / "node_modules" / "axe-core" / "axe.min.js"
STUDY = {
    "name": "keyboard",
    "blocks": [{"name": "watch", "policy": {"kind": "never-ask"}, "schedule": {"trials": ["high", "low"]}}],
    "self_report": "block",
    "questionnaires": [
        {
            "name": "short",
            "when": "end",
            "title": "Two questions",
            "items": [{"id": "a", "text": "The robot is dependable."}, {"id": "b", "text": "I am confident in the robot."}],
            "scale": {"min": 1, "max": 5, "anchors": ["not at all", "extremely"]},
        }
    ],
    "animation_speed": 3.0,
}


def check_prerequisites() -> None:
    if not Path(CHROMIUM).exists():
        pytest.fail(f"{CHROMIUM} is missing: run scripts/setup.sh")
    if not (STATIC / "participant.js").exists():
        pytest.fail("front end not built: run scripts/setup.sh (npm ci && npm run build in web/)")
    if not AXE.exists():
        pytest.fail(f"{AXE} is missing: run scripts/setup.sh (npm ci in web/)")


def axe(page, screen: str) -> None:
    """axe-core on what the page shows now: no serious or critical violation."""
    if not page.evaluate("typeof window.axe !== 'undefined'"):
        page.add_script_tag(content=AXE.read_text(encoding="utf-8"))
    result = page.evaluate("axe.run(document, {resultTypes: ['violations']})")
    bad = [
        f"{v['id']} ({v['impact']}): {v['help']} at {[n['target'] for n in v['nodes']][:3]}"
        for v in result["violations"]
        if v["impact"] in ("serious", "critical")
    ]
    assert not bad, f"{screen}: {bad}"


def focused(page) -> str:
    return page.evaluate("document.activeElement ? document.activeElement.id : ''")


def tab_to(page, element_id: str, limit: int = 12) -> None:
    for _ in range(limit):
        page.keyboard.press("Tab")
        if focused(page) == element_id:
            return
    raise AssertionError(f"Tab never reached #{element_id} (focus on {focused(page)!r})")


def in_view(page, selector: str) -> bool:
    box = page.locator(selector).bounding_box()
    vp = page.viewport_size
    return (
        box is not None
        and box["y"] >= 0
        and box["x"] >= 0
        and box["y"] + box["height"] <= vp["height"]
        and box["x"] + box["width"] <= vp["width"]
    )


def test_keyboard_only_run_with_axe_on_every_screen_at_1280x720(tmp_path):
    check_prerequisites()
    from playwright.sync_api import sync_playwright

    out = artifacts_dir(tmp_path)
    with ThreadServer(f"sqlite:///{tmp_path / 'kb.sqlite'}", TOKEN) as url:
        c = Client(url, TOKEN)
        study = c.create_study(STUDY)
        link = c.create_sessions(study["id"], participants=["keys-1"])[0]["link"]
        with sync_playwright() as p:
            browser = launch_chromium(p)
            page = browser.new_page(viewport={"width": 1280, "height": 720})
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(link + "?manual=1")  # the page's clock is the test's (scene_drive.step_until)

            # consent: Tab to the box, Space ticks it; Tab to the button, Space presses it
            page.wait_for_selector("#screen-consent:not([hidden])")
            axe(page, "consent")
            tab_to(page, "agree")
            page.keyboard.press(" ")
            assert page.is_checked("#agree"), "Space did not tick the consent box"
            tab_to(page, "consent-btn")
            page.keyboard.press(" ")
            page.wait_for_selector("#screen-instructions:not([hidden])")
            axe(page, "instructions")
            if focused(page) != "start-btn":
                tab_to(page, "start-btn")
            page.keyboard.press("Enter")

            # the task at 1280 x 720: everything, the Intervene button too, without scrolling
            page.wait_for_function("window.trustseek.state().phase === 'approach'")
            step_until(page, "true")  # drawn
            screenshot(page, path=str(out / "access_task_1280x720.png"))
            assert in_view(page, "#intervene-btn"), page.locator("#intervene-btn").bounding_box()
            assert in_view(page, "#world") and in_view(page, "#status")
            assert page.evaluate("document.documentElement.scrollHeight <= innerHeight + 1")
            axe(page, "task")
            page.keyboard.press(" ")  # intervene
            step_until(page, "s.phase === 'teleop'", frames=1, limit=3)
            teleoperate(page)  # arrows, I/K, J/L, R/F, G, B

            # trial 2: rely; then the self-report slider with the arrow keys
            step_until(page, "s.phase === 'report'")
            axe(page, "self-report")
            tab_to(page, "report-slider")
            for _ in range(3):
                page.keyboard.press("ArrowRight")
            assert page.input_value("#report-slider") == "53", "the slider ignores the arrow keys"
            tab_to(page, "report-btn")
            page.keyboard.press(" ")

            # the questionnaire: Tab into each radio group, arrows choose
            page.wait_for_selector("#screen-questionnaire:not([hidden])")
            axe(page, "questionnaire")
            page.keyboard.press("Tab")
            page.keyboard.press("ArrowRight")  # the first radio group: its second point
            page.keyboard.press("Tab")
            page.keyboard.press("ArrowRight")
            page.keyboard.press("ArrowRight")
            tab_to(page, "questionnaire-btn")
            page.keyboard.press("Enter")
            page.wait_for_selector("#screen-done:not([hidden])", timeout=30000)
            axe(page, "done")

            # an invalid link: a screen that says so, not a blank page
            bad = browser.new_page(viewport={"width": 1280, "height": 720})
            bad.goto(f"{url}/s/not-a-valid-token-at-all")
            bad.wait_for_selector("#screen-error:not([hidden])")
            assert "not valid" in bad.inner_text("#screen-error")
            axe(bad, "invalid link")
            browser.close()
        assert not errors, errors
        trials = pd.read_csv(io.BytesIO(c.export(study["id"])))
        reports = pd.read_csv(io.BytesIO(c.export(study["id"], table="reports")))
    assert trials["human_action"].tolist() == ["intervene", "rely"]
    assert trials["self_report"].tolist()[-1] == 53.0
    answers = reports[reports.questionnaire == "short"].set_index("item")["value"].to_dict()
    assert answers == {"a": 2, "b": 3}


def test_phones_are_refused_politely(tmp_path):
    check_prerequisites()
    from playwright.sync_api import sync_playwright

    with ThreadServer(f"sqlite:///{tmp_path / 'phone.sqlite'}", TOKEN) as url:
        c = Client(url, TOKEN)
        study = c.create_study(STUDY)
        link = c.create_sessions(study["id"], participants=["phone-1"])[0]["link"]
        with sync_playwright() as p:
            browser = launch_chromium(p)
            ctx = browser.new_context(viewport={"width": 390, "height": 844}, is_mobile=True, has_touch=True)
            page = ctx.new_page()
            page.goto(link)
            page.wait_for_selector("#screen-error:not([hidden])")
            assert "computer" in page.inner_text("#screen-error")
            assert page.is_hidden("#screen-consent")
            axe(page, "phone")
            browser.close()
        assert c.dashboard(study["id"])["participants"][0]["status"] == "new"


def test_saving_failures_are_shown_and_retried(tmp_path):
    check_prerequisites()
    from playwright.sync_api import sync_playwright

    with ThreadServer(f"sqlite:///{tmp_path / 'fail.sqlite'}", TOKEN) as url:
        c = Client(url, TOKEN)
        study = c.create_study(
            {
                "name": "f",
                "blocks": [{"name": "w", "policy": {"kind": "never-ask"}, "schedule": {"trials": ["low"]}}],
                "self_report": "block",
                "animation_speed": 6.0,
                "scene": "2d",  # what is saved and retried is tested here, not the scene
            }
        )
        link = c.create_sessions(study["id"], participants=["fail-1"])[0]["link"]
        with sync_playwright() as p:
            browser = launch_chromium(p)
            page = browser.new_page(viewport={"width": 800, "height": 600})
            failures = {"consent": 3, "reports": 3}

            def flaky(route):
                kind = route.request.url.rsplit("/", 1)[-1]
                if failures.get(kind, 0) > 0:
                    failures[kind] -= 1
                    return route.abort("connectionrefused")
                return route.continue_()

            page.route("**/api/sessions/*/*", flaky)
            page.goto(link + "?retry_cap=300")
            page.wait_for_selector("#screen-consent:not([hidden])")
            page.check("#agree")
            page.click("#consent-btn")
            page.wait_for_selector("#connection:not([hidden])", timeout=5000)  # shown while it retries
            page.wait_for_selector("#screen-instructions:not([hidden])", timeout=10000)
            assert page.is_hidden("#connection") and failures["consent"] == 0
            page.click("#start-btn")
            page.wait_for_selector("#screen-report:not([hidden])", timeout=45000)
            page.fill("#report-slider", "40")
            page.click("#report-btn")
            page.wait_for_selector("#connection:not([hidden])", timeout=5000)
            page.wait_for_selector("#screen-done:not([hidden])", timeout=10000)
            browser.close()
        trials = pd.read_csv(io.BytesIO(c.export(study["id"])))
    assert trials["self_report"].tolist() == [40.0]


def test_dashboard_shows_study_problems_as_sentences(tmp_path):
    check_prerequisites()
    from playwright.sync_api import sync_playwright

    with ThreadServer(f"sqlite:///{tmp_path / 'dash.sqlite'}", TOKEN) as url, sync_playwright() as p:
        browser = launch_chromium(p)
        dash = browser.new_page(viewport={"width": 1280, "height": 720})
        dash.goto(f"{url}/dashboard")
        axe(dash, "dashboard")
        dash.fill("#token", TOKEN)
        dash.dispatch_event("#token", "change")
        dash.click("#new-study-toggle")
        bad = {"name": "x", "blocks": [{"name": "b", "policy": {"kind": "no-such-kind"}, "schedule": {"trials": ["low"]}}]}
        dash.fill("#study-json", json.dumps(bad))
        dash.click("#create-study")
        dash.wait_for_selector("#create-msg li")
        text = dash.inner_text("#create-msg")
        assert "not created" in text
        assert "{" not in text and '"' not in text.replace("'", ""), text  # sentences, not raw JSON
        dash.fill("#study-json", json.dumps({"name": "y", "blocks": "many"}))
        dash.click("#create-study")
        dash.wait_for_function(
            "document.querySelectorAll('#create-msg li').length >= 1 && !document.getElementById('create-msg').textContent.includes('no-such-kind')"
        )
        assert "{" not in dash.inner_text("#create-msg")
        axe(dash, "dashboard with a refused study")
        browser.close()
