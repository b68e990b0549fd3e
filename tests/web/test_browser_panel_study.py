"""End-to-end: a full study run from an online panel's study link in headless Chromium: the
comprehension quiz (a wrong attempt sends the participant back to the instructions), practice
with one asked trial, two blocks, a per-block questionnaire with an attention check and the
12-item trust-in-automation questionnaire at the end, the completion code and the redirect to the
panel; the same panel id back at the link gets a page saying it completed.  ``&speed=`` on the
link changes nothing.  The score changes only when the outcome is shown, and no banner is left
over the next trial.  The export fits with ``trustseek fit``.  The page's clock is the test's
(``&manual=1``, scene_drive.step_until): it moves by the page's state, not by the wall clock."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pandas as pd
import pytest

from scene_drive import step_until
from test_browser import artifacts_dir, st, teleoperate
from trustseek.client import Client
from trustseek.server.app import STATIC
from trustseek.testing.browser import CHROMIUM, launch_chromium, screenshot
from trustseek.testing.servers import ThreadServer

pytestmark = pytest.mark.browser

TOKEN = "browser-panel-token"
PANEL = "https://panel.example/complete"


def answer_questionnaire(page, value_of) -> list[str]:
    """Tick one point per item; the submit button is enabled only when every item is answered."""
    step_until(page, "s.phase === 'questionnaire'")
    items = page.eval_on_selector_all(".q-item input[type=radio][value='1']", "xs => xs.map(x => x.dataset.item)")
    for k, item in enumerate(items):
        assert page.is_disabled("#questionnaire-btn")
        page.check(f"input[name='q-{item}'][value='{value_of(k)}']")
    page.click("#questionnaire-btn")
    # the overlay closes, or shows the next questionnaire with nothing ticked
    page.wait_for_function(
        "document.getElementById('screen-questionnaire').hidden"
        " || document.querySelectorAll('#questionnaire-items input:checked').length === 0",
        timeout=15000,
    )
    return items


def test_panel_study_in_chromium(tmp_path):
    if not Path(CHROMIUM).exists():
        pytest.fail(f"{CHROMIUM} is missing: run scripts/setup.sh")
    if not (STATIC / "participant.js").exists():
        pytest.fail("front end not built: run scripts/setup.sh (npm ci && npm run build in web/)")
    from playwright.sync_api import sync_playwright

    out = artifacts_dir(tmp_path)
    with ThreadServer(f"sqlite:///{tmp_path / 'panel.sqlite'}", TOKEN) as url:
        c = Client(url, TOKEN)
        study = c.create_study(
            {
                "name": "panel",
                "practice": {"trials": ["low", "low"]},
                "quiz": {
                    "questions": [
                        {
                            "id": "ask",
                            "text": "When the robot asks for help, you...",
                            "options": ["watch", "drive it"],
                            "answer": 1,
                        }
                    ]
                },
                "blocks": [
                    {"name": "watch", "policy": {"kind": "never-ask"}, "schedule": {"trials": ["low", "high"]}},
                    {"name": "take-over", "policy": {"kind": "never-ask"}, "schedule": {"trials": ["high"]}},
                ],
                "questionnaires": [
                    {
                        "name": "quick",
                        "when": "block",
                        "items": [
                            {"id": "trust", "text": "I trust the robot."},
                            {"id": "predict", "text": "I can predict it."},
                            {"id": "attention", "text": "To show that you read this, choose 2.", "check": 2},
                        ],
                        "scale": {"min": 1, "max": 5, "anchors": ["disagree", "agree"]},
                    },
                    {"template": "jian2000", "when": "end"},
                ],
                "panel": {"completion_code": "E2E-CODE", "redirect_url": PANEL + "?cc={completion_code}"},
                "animation_speed": 6.0,
            }
        )
        link = study["link"]  # one link for every participant of the panel
        with sync_playwright() as p:
            browser = launch_chromium(p)
            page = browser.new_page(viewport={"width": 1000, "height": 600})
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.route(PANEL + "**", lambda route: route.fulfill(status=200, content_type="text/html", body="<p>panel</p>"))
            # &speed= on a participant's link changes nothing: the study's speed is the page's
            page.goto(link + "?speed=50&manual=1&quality=0&PROLIFIC_PID=pp-42&STUDY_ID=st-7&SESSION_ID=se-9")

            page.wait_for_selector("#screen-consent:not([hidden])")
            # the trials counted, not a fixed duration, and the practice trials said apart
            assert "has 3 trials (after 2 practice trials, not scored). " in page.inner_text("#consent-text")
            screenshot(page, path=str(out / "browser_panel_consent.png"))
            page.check("#agree")
            page.click("#consent-btn")
            page.wait_for_selector("#screen-instructions:not([hidden])")
            page.click("#start-btn")

            # the comprehension quiz: a wrong answer, the instructions again, then the right one
            page.wait_for_selector("#screen-quiz:not([hidden])")
            assert page.is_disabled("#quiz-btn")
            page.check("input[name='quiz-ask'][value='0']")
            screenshot(page, path=str(out / "browser_panel_quiz.png"))
            page.click("#quiz-btn")
            page.wait_for_selector("#instructions-again:not([hidden])")
            screenshot(page, path=str(out / "browser_panel_quiz_again.png"))
            page.click("#start-btn")
            page.wait_for_selector("#screen-quiz:not([hidden])")
            assert "Attempt 2 of 2" in page.inner_text("#quiz-attempt")
            page.check("input[name='quiz-ask'][value='1']")
            page.click("#quiz-btn")

            # practice: the robot works alone, then asks; nothing is scored, and it is counted apart
            page.wait_for_function("window.trustseek.state().phase === 'approach'")
            s = st(page)
            assert s["practice"] is True and page.inner_text("#block-name") == "Practice trial (not scored)"
            assert s["speed"] == 6.0 and s["trial_label"] == "1 / 2"
            step_until(page, "s.trial === 2 && s.phase === 'teleop'")
            assert st(page)["robot_action"] == "ask" and "Practice" in page.inner_text("#hint")
            screenshot(page, path=str(out / "browser_panel_practice_ask.png"))
            teleoperate(page)
            step_until(page, "s.trial === 3 && s.phase === 'approach'")
            assert st(page)["practice"] is False and page.inner_text("#score") == "0"
            assert page.inner_text("#trial-no") == "1 / 3"
            # no banner of the practice trial over this one
            assert page.eval_on_selector("#banner", "b => getComputedStyle(b).opacity") == "0"

            # while the outcome is animated, the score on screen is still the one before the trial
            during = step_until(page, "s.phase === 'outcome'", frames=1)["s"]
            shown = page.inner_text("#score")
            assert during["score"] != 0 and during["shown_score"] == 0 and shown == "0", (during, shown)
            step_until(page, "s.phase === 'result'")
            assert page.inner_text("#score") == str(int(during["score"])) or float(page.inner_text("#score")) == during["score"]

            # trial 2 of the study in the same block, then the block's questionnaire
            step_until(page, "s.trial === 4")
            answer_questionnaire(page, lambda k: 4 - k)

            # block 2: the participant takes over
            step_until(page, "s.trial === 5 && s.phase === 'approach'")
            page.keyboard.press(" ")
            step_until(page, "s.phase === 'teleop'", frames=1, limit=3)
            teleoperate(page)
            answer_questionnaire(page, lambda k: 3)
            items = answer_questionnaire(page, lambda k: 1 + k % 7)
            assert len(items) == 12

            # the end: the completion code, then the panel
            step_until(page, "s.phase === 'done'")
            assert page.inner_text("#completion-code") == "E2E-CODE"
            assert page.inner_text("#final-trials") == "3"
            screenshot(page, path=str(out / "browser_panel_done.png"))
            page.wait_for_url(PANEL + "?cc=E2E-CODE", timeout=15000)
            # back at the study link with the same panel id: a page says so, and no new session
            page.goto(link + "?PROLIFIC_PID=pp-42&STUDY_ID=st-7&SESSION_ID=se-10")
            assert page.get_attribute("body", "data-page") == "completed"
            screenshot(page, path=str(out / "browser_panel_completed.png"))
            browser.close()
        assert not errors, errors

        trials = pd.read_csv(io.BytesIO(c.export(study["id"])))
        reports = pd.read_csv(io.BytesIO(c.export(study["id"], table="reports")))
        sessions = pd.read_csv(io.BytesIO(c.export(study["id"], table="sessions")))

    assert trials["trial"].tolist() == [1, 2, 3] and trials["session_trial"].tolist() == [3, 4, 5]
    assert len(sessions) == 1 and sessions["panel_id"].tolist() == ["pp-42"] and sessions["speed"].tolist() == [6.0]
    assert sessions[["quiz_attempts", "quiz_outcome"]].values.tolist() == [[2, "passed"]]
    assert trials["human_action"].tolist() == ["rely", "rely", "intervene"]
    assert json.loads(sessions["panel"].iloc[0]) == {"PROLIFIC_PID": "pp-42", "STUDY_ID": "st-7", "SESSION_ID": "se-9"}
    quick = reports[reports.questionnaire == "quick"].sort_values(["trial", "item"])
    assert quick["trial"].tolist() == [2, 2, 2, 3, 3, 3]
    assert dict(zip(quick["item"][:3], quick["value"][:3], strict=True)) == {"attention": 2.0, "predict": 3.0, "trust": 4.0}
    attention = quick[quick["item"] == "attention"]
    assert attention["check_passed"].tolist() == [True, False]  # 2 (4 - k at k = 2), then 3
    assert (reports.questionnaire == "trust-in-automation").sum() == 12

    path = out / "browser_panel_trials.csv"
    trials.to_csv(path, index=False)
    from typer.testing import CliRunner

    from trustseek.cli import app

    res = CliRunner().invoke(app, ["fit", str(path), "--restarts", "2", "--json"])
    assert res.exit_code == 0, res.output
    assert "3 trials" in json.loads(res.output)["model"]["notes"]
