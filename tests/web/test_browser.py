"""End-to-end: a participant does a short study in headless Chromium (consent, instructions,
an intervention, an autonomous trial, an assisted teleoperation, self-reports); the export
holds exactly those trials in the canonical trial-log format.  The page's clock is the test's
(``?manual=1``, scene_drive.step_until): it moves by the page's state, not by the wall clock."""

from __future__ import annotations

import io
import json
import os
import time
from pathlib import Path

import pandas as pd
import pytest

import scene_drive
from scene_drive import step_until
from trustseek.client import Client
from trustseek.server.app import STATIC
from trustseek.testing.browser import CHROMIUM, launch_chromium, screenshot
from trustseek.testing.servers import ThreadServer

pytestmark = pytest.mark.browser

TOKEN = "browser-test-token"


def artifacts_dir(tmp_path: Path) -> Path:
    d = Path(os.environ.get("TRUSTSEEK_ARTIFACTS", tmp_path))
    d.mkdir(parents=True, exist_ok=True)
    return d


def st(page) -> dict:
    return page.evaluate("window.trustseek.state()")


def hold(page, key: str, until, timeout: float = 15.0) -> dict:
    """Hold ``key`` until ``until(state)`` is true."""
    page.keyboard.down(key)
    try:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            s = st(page)
            if until(s):
                return s
            page.wait_for_timeout(15)
        raise AssertionError(f"holding {key} never reached the goal; state {st(page)}")
    finally:
        page.keyboard.up(key)


def teleoperate(page) -> None:
    """Drive to the item's shelf side, line up, extend the arm, grasp, retract, deposit: by the
    page's state, with its clock stopped (scene_drive.teleoperate), never by timed key holds."""
    scene_drive.teleoperate(page)


def test_participant_study_in_chromium(tmp_path):
    if not Path(CHROMIUM).exists():
        pytest.fail(f"{CHROMIUM} is missing: run scripts/setup.sh")
    if not (STATIC / "participant.js").exists():
        pytest.fail("front end not built: run scripts/setup.sh (npm ci && npm run build in web/)")
    from playwright.sync_api import sync_playwright

    out = artifacts_dir(tmp_path)
    with ThreadServer(f"sqlite:///{tmp_path / 'e2e.sqlite'}", TOKEN) as url:
        c = Client(url, TOKEN)
        study = c.create_study(
            {
                "name": "e2e",
                "blocks": [
                    {"name": "watch", "policy": {"kind": "never-ask"}, "schedule": {"trials": ["high", "low"]}},
                    {"name": "help", "policy": {"kind": "always-ask"}, "schedule": {"trials": ["high"]}},
                ],
                "self_report": "block",
                "animation_speed": 3.0,
            }
        )
        link = c.create_sessions(study["id"], participants=["chromium-1"])[0]["link"]
        with sync_playwright() as p:
            browser = launch_chromium(p)
            page = browser.new_page(viewport={"width": 1000, "height": 600})
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            requests: list[str] = []
            page.on("request", lambda r: requests.append(r.url))
            page.goto(link + "?speed=1&manual=1&quality=0")

            # consent and instructions
            page.wait_for_selector("#screen-consent:not([hidden])")
            assert page.is_disabled("#consent-btn")
            page.check("#agree")
            page.click("#consent-btn")
            page.wait_for_selector("#screen-instructions:not([hidden])")
            page.click("#start-btn")

            # trial 1: autonomous in high complexity; the participant intervenes with the key
            page.wait_for_function("window.trustseek.state().phase === 'approach'")
            assert st(page)["trial"] == 1 and st(page)["complexity"] == "high"
            assert page.inner_text("#mode") == "Collecting autonomously"
            step_until(page, "true")  # the robot sets off
            screenshot(page, path=str(out / "browser_autonomous.png"))
            page.keyboard.press(" ")
            step_until(page, "s.phase === 'teleop'", frames=1, limit=3)
            assert "intervention" in page.inner_text("#mode")
            teleoperate(page)

            # trial 2: autonomous in low complexity; the participant relies and sees the outcome
            step_until(page, "s.trial === 2 && s.phase === 'approach'")
            step_until(page, "['outcome', 'result', 'report'].includes(s.phase)")

            # end of block 1: self-report
            step_until(page, "s.phase === 'report'")
            assert page.is_visible("#screen-report")
            page.fill("#report-slider", "73")
            page.click("#report-btn")

            # trial 3: the robot asks; the participant teleoperates
            step_until(page, "s.trial === 3 && s.phase === 'teleop'")
            assert page.inner_text("#mode") == "Asking for your help"
            teleoperate(page)
            step_until(page, "s.phase === 'report'")
            page.fill("#report-slider", "81")
            screenshot(page, path=str(out / "browser_report.png"))
            page.click("#report-btn")
            step_until(page, "s.phase === 'done'")
            final_score = float(page.inner_text("#final-score"))
            screenshot(page, path=str(out / "browser_done.png"))

            # the experimenter's dashboard shows the finished participant and creates a study
            dash = browser.new_page(viewport={"width": 1000, "height": 600})
            dash.on("pageerror", lambda e: errors.append(str(e)))
            dash.goto(f"{url}/dashboard")
            dash.fill("#token", TOKEN)
            dash.dispatch_event("#token", "change")
            dash.wait_for_selector("#rows td:has-text('chromium-1')")
            row = dash.inner_text("#rows tr")
            assert "done" in row and "3 / 3" in row and str(int(final_score)) in row
            dash.click("#new-study-toggle")
            dash.click("#create-study")
            dash.wait_for_function("document.getElementById('create-msg').textContent.startsWith('Created pilot')", timeout=20000)
            dash.click("#new-session")
            dash.wait_for_selector("#rows td:has-text('P001')")
            screenshot(dash, path=str(out / "browser_dashboard.png"))
            browser.close()
        assert not errors, errors
        assert all(u.startswith((url, "data:", "blob:")) for u in requests), [u for u in requests if not u.startswith(url)]
        assert [s["name"] for s in c.studies()] == ["e2e", "pilot"]

        trials = pd.read_csv(io.BytesIO(c.export(study["id"])))
        events = pd.read_csv(io.BytesIO(c.export(study["id"], table="events")))

    assert trials.columns[:6].tolist() == ["participant", "trial", "complexity", "robot_action", "human_action", "experience"]
    assert trials["participant"].tolist() == ["chromium-1"] * 3
    assert trials["trial"].tolist() == [1, 2, 3]
    assert trials["complexity"].tolist() == ["high", "low", "high"]
    assert trials["robot_action"].tolist() == ["autonomous", "autonomous", "ask"]
    assert trials["human_action"].tolist() == ["intervene", "rely", "intervene"]
    second = trials.iloc[1]
    assert trials["experience"].tolist() == ["faulty", "reliable" if second.outcome == "success" else "faulty", "reliable"]
    assert trials["reward"].tolist() == [0.0, 2.0 if second.outcome == "success" else -3.0, 1.0]
    assert final_score == trials["reward"].sum()
    assert trials["effort_ms"].iloc[0] > 0 and trials["effort_ms"].iloc[2] > 0 and pd.isna(trials["effort_ms"].iloc[1])
    assert trials["self_report"].tolist()[1:] == [73.0, 81.0]
    kinds = events["type"].tolist()
    for k in ("consent", "instructions_done", "trial_start", "intervene", "teleop_start", "grasp", "deposit", "outcome_shown"):
        assert k in kinds, (k, kinds)
    assert events[events.type == "intervene"]["trial"].tolist() == [1]
    deposits = [json.loads(d) for d in events[events.type == "deposit"]["data"]]
    assert events[events.type == "deposit"]["trial"].tolist() == [1, 3]
    assert all(d["driven_m"] > 0 and d["arm_m"] > 0 and d["grasp_attempts"] >= 1 for d in deposits)

    # the export is a valid trial log for the data module and the fit
    from trustseek.data.trials import read_trials

    frame = read_trials(trials)
    assert len(frame) == 3 and frame["human_action"].tolist() == ["intervene", "rely", "intervene"]
    path = out / "browser_trials.csv"
    trials.to_csv(path, index=False)
    from typer.testing import CliRunner

    from trustseek.cli import app

    res = CliRunner().invoke(app, ["fit", str(path), "--restarts", "2", "--json"])
    assert res.exit_code == 0, res.output
    assert "3 trials" in json.loads(res.output)["model"]["notes"]
