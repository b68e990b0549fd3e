"""Acceptance of the panel study link: 20 participants in headless Chromium arrive through one
study link at once (three of them a second tab of a panel id already running, some reloading
during a trial, one returning after completing).  No duplicate sessions, one session per panel
id, block orders balanced to within one, every trial and event stored once, completion codes
shown only at the end.  Pages are driven by their state, never by wall-clock sleeps (on
SQLite; concurrent arrivals on PostgreSQL are tested through the API).  The dashboard, the
consent, quiz, paused, closed and completed pages and a revoked link are photographed; a
preview run to its end page leaves the study's database and export unchanged."""

from __future__ import annotations

import asyncio
import io
from collections import Counter
from pathlib import Path
from urllib.parse import urlsplit

import httpx
import pandas as pd
import pytest

from server_checks import database_rows
from test_browser import artifacts_dir
from trustseek.client import Client
from trustseek.server.app import STATIC
from trustseek.testing.browser import CHROMIUM, CHROMIUM_ARGS, screenshot
from trustseek.testing.servers import TemporaryPostgres, ThreadServer, postgres_binaries

pytestmark = pytest.mark.browser

TOKEN = "browser-crowd-token"
STUDY = {
    "name": "crowd",
    "blocks": [
        # one trial a block: the arrivals at once are the point, not the number of trials
        {"name": "first", "policy": {"kind": "never-ask"}, "schedule": {"trials": ["low"]}},
        {"name": "second", "policy": {"kind": "never-ask"}, "schedule": {"trials": ["high"]}},
    ],
    "counterbalance": "rotate",
    "quiz": {"questions": [{"id": "q", "text": "Space...", "options": ["intervenes", "pauses"], "answer": 0}]},
    "questionnaires": [
        {"name": "end", "items": [{"id": "attn", "text": "Choose 3.", "check": 3}], "scale": {"min": 1, "max": 5}}
    ],
    "panel": {"completion_code": "CROWD-OK"},
    "animation_speed": 20.0,  # the study sets the pace: fast animations for the test
    "scene": "2d",  # twenty pages at once: the data path is tested here, the 3-D scene in test_browser_scene.py
}
PIDS = [f"crowd-{i:02d}" for i in range(17)] + ["crowd-00", "crowd-01", "crowd-02"]  # 20 arrivals, 17 panel ids
RELOADERS = {3, 7, 11}
#: the page's clock is the test's (``?manual=1``): a trial is stepped on, undrawn, from its approach
#: until the page moves past its result (twenty pages drawing at once cost more than the data path
#: tested here); while a save waits for the server, the page waits with it
RUN_TRIAL = """async (trial) => {
  const past = (s) => s.trial !== trial || ["questionnaire", "done", "error", "report"].includes(s.phase);
  for (let i = 0; i < 5000; i++) {
    const s = window.trustseek.state();
    if (past(s)) return true;
    if (s.saving || s.phase === "loading") await new Promise((r) => setTimeout(r, 20));
    else {
      window.__scene.step(0.05, 1, false);
      await new Promise((r) => setTimeout(r, 2));
    }
  }
  return false;
}"""
#: true once no event batch of the page waits for the server's answer (api.ts keeps them in localStorage)
UNSENT = "!Object.keys(localStorage).some((k) => k.startsWith('trustseek-outbox-'))"


async def next_phase(page) -> str:
    await page.wait_for_function(
        "['consent','instructions','quiz','questionnaire','approach','done','error'].includes(document.body.dataset.phase)",
        timeout=60000,
    )
    return await page.evaluate("document.body.dataset.phase")


#: what a participant answers on each form: the choice to tick (if any) and the button that sends it
FORMS = {
    "consent": ("#agree", "#consent-btn"),
    "instructions": (None, "#start-btn"),
    "quiz": ("input[name='quiz-q'][value='0']", "#quiz-btn"),
    "questionnaire": ("input[name='q-attn'][value='3']", "#questionnaire-btn"),
}


async def step(page, phase: str) -> None:
    """Answer what the page asks in ``phase`` and wait until it has moved on."""
    if phase in FORMS:
        choice, button = FORMS[phase]
        if choice is not None:
            await page.check(choice)
        await page.click(button)
        await page.wait_for_function(f"document.body.dataset.phase !== '{phase}'", timeout=30000)
    elif phase == "approach":
        trial = await page.evaluate("window.trustseek.state().trial")  # null in a page just reloaded
        assert await page.evaluate(RUN_TRIAL, trial), (
            f"trial {trial} never ended: {await page.evaluate('window.trustseek.state()')}"
        )


async def run_participant(browser, link: str, k: int, pid: str) -> dict:
    """One participant's page from the study link to the end page, by what the page shows."""
    ctx = await browser.new_context(viewport={"width": 640, "height": 480})  # small canvases: twenty pages draw
    page = await ctx.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    await page.goto(f"{link}?PROLIFIC_PID={pid}&STUDY_ID=crowd&SESSION_ID=s{k}&manual=1")
    codes_early, reload = 0, k in RELOADERS
    while True:
        phase = await next_phase(page)
        if phase != "done" and await page.is_visible("#completion"):
            codes_early += 1
        if phase == "approach" and reload and await page.evaluate("window.trustseek.state().trial") == 2:
            # a reload part of the way through trial 2's approach (the page's clock stands still meanwhile)
            await page.evaluate("window.__scene.step(0.05, 2, false)")
            await page.reload()
            reload = False
            continue
        await step(page, phase)
        if phase == "done":
            code = await page.inner_text("#completion-code")
            # the page's event batches are answered before it is closed (a closed page sends
            # what it kept when it opens again, like a reloaded one)
            await page.wait_for_function(UNSENT, timeout=60000)
            break
        elif phase == "error":
            raise AssertionError(f"participant {k} ({pid}) on {page.url}: {await page.evaluate('document.body.innerText')}")
    await ctx.close()
    return {"k": k, "pid": pid, "code": code, "codes_early": codes_early, "errors": errors}


async def preview_run(link: str) -> dict:
    from playwright.async_api import async_playwright

    async with async_playwright() as p:
        browser = await p.chromium.launch(executable_path=CHROMIUM, args=list(CHROMIUM_ARGS), headless=True)
        result = await run_participant(browser, link, 0, "previewer")
        await browser.close()
    return result


async def crowd(url: str, link: str, out: Path) -> tuple[list[dict], str]:
    from playwright.async_api import async_playwright

    async with async_playwright() as p:
        browser = await p.chromium.launch(executable_path=CHROMIUM, args=list(CHROMIUM_ARGS), headless=True)
        results = await asyncio.gather(*(run_participant(browser, link, k, pid) for k, pid in enumerate(PIDS)))
        # one returns after completing: a page says so
        page = await browser.new_page(viewport={"width": 800, "height": 600})
        await page.goto(f"{link}?PROLIFIC_PID=crowd-05&STUDY_ID=crowd&SESSION_ID=again")
        returning = await page.get_attribute("body", "data-page")
        await page.screenshot(path=str(out / "crowd_completed_page.png"))
        await browser.close()
    return results, returning


# twenty Chromium pages and the server on two cores: once, on SQLite (concurrent arrivals on
# PostgreSQL are tested through the API in tests/server/test_server_panel_link.py)
@pytest.mark.parametrize("backend", ["sqlite"])
def test_twenty_participants_through_one_study_link(tmp_path, backend):
    if not Path(CHROMIUM).exists():
        pytest.fail(f"{CHROMIUM} is missing: run scripts/setup.sh")
    if not (STATIC / "participant.js").exists():
        pytest.fail("front end not built: run scripts/setup.sh (npm ci && npm run build in web/)")
    cluster = None
    if backend == "postgresql":
        if postgres_binaries() is None:
            pytest.skip("PostgreSQL server binaries not found; scripts/setup.sh installs Debian's postgresql package as root")
        cluster = TemporaryPostgres()
        db = cluster.start()
    else:
        db = f"sqlite:///{tmp_path / 'crowd.sqlite'}"
    out = artifacts_dir(tmp_path)
    try:
        with ThreadServer(db, TOKEN) as url:
            c = Client(url, TOKEN)
            study = c.create_study(STUDY)
            results, returning = asyncio.run(crowd(url, study["link"], out))
            dash = c.dashboard(study["id"])
            tables = {t: pd.read_csv(io.BytesIO(c.export(study["id"], table=t))) for t in ("trials", "sessions", "events")}
    finally:
        if cluster is not None:
            cluster.stop()

    assert all(not r["errors"] for r in results), [r["errors"] for r in results if r["errors"]]
    assert all(r["code"] == "CROWD-OK" for r in results) and not any(r["codes_early"] for r in results)
    assert returning == "completed"
    sessions, trials, events = tables["sessions"], tables["trials"], tables["events"]
    assert len(sessions) == 17 and sorted(sessions["panel_id"]) == sorted(set(PIDS))  # one session per panel id
    assert (sessions["status"] == "done").all() and dash["study"]["progress"]["done"] == 17
    firsts = Counter(sessions["block_order"].str.slice(2, 7))
    assert max(firsts.values()) - min(firsts.values()) <= 1, firsts
    assert len(trials) == 17 * 2 and not trials.duplicated(["participant", "trial"]).any()
    # every event names the page load that made it; an event stored twice would be the same
    # page's same event (two tabs of one session, or a page and its reload, are two page loads)
    assert events["page"].notna().all()
    twice = events[events.duplicated(["session", "page", "trial", "type", "client_time", "data"], keep=False)]
    assert twice.empty, twice.to_string()
    # the sessions table counts them: 2 or more for a session with a second tab or a reload
    per_session = events.groupby("session")["page"].nunique()
    assert (sessions["pages"] == sessions["session"].map(per_session)).all()
    pages = dict(zip(sessions["panel_id"], sessions["pages"], strict=True))
    assert all(pages[PIDS[k]] >= 2 for k in (0, 1, 2, *RELOADERS)), pages
    shown = events[events["type"] == "outcome_shown"].groupby("session")["trial"].apply(sorted)
    # every outcome shown is stored once: also of a session whose two tabs took its trials in
    # turns (the tab that committed a trial shows its outcome), or whose page was reloaded
    pid_of = dict(zip(sessions["session"], sessions["panel_id"], strict=True))
    resumed = set(events[events["type"] == "resumed"]["session"])
    assert {s for s, p in pid_of.items() if p in {PIDS[k] for k in RELOADERS}} <= resumed  # reloaded in a trial
    wrong = [s for s in sessions["session"] if shown.get(s) != [1, 2]]
    assert not wrong, {
        pid_of[s]: events[events["session"] == s][["trial", "type", "client_time", "data"]].to_string() for s in wrong
    }


def test_dashboard_the_pages_of_a_paused_closed_or_revoked_link_and_a_preview(tmp_path):
    from playwright.sync_api import sync_playwright

    from trustseek.testing.browser import launch_chromium

    out = artifacts_dir(tmp_path)
    path = tmp_path / "pages.sqlite"
    with ThreadServer(f"sqlite:///{path}", TOKEN) as url:
        c = Client(url, TOKEN)
        study = c.create_study({**STUDY, "quota": 40, "practice": {"trials": ["low"]}})  # the practice trial asks
        (link,) = c.create_sessions(study["id"], participants=["to-revoke"])
        (pilot,) = c.create_sessions(study["id"], count=1, pilot=True)
        ph = {"Authorization": f"Bearer {pilot['token']}"}
        base = f"{url}/api/sessions/{pilot['session_id']}"
        httpx.post(f"{base}/consent", json={"agree": True}, headers=ph).raise_for_status()
        httpx.post(f"{base}/quiz", json={"attempt": 1, "answers": {"q": 0}}, headers=ph).raise_for_status()
        assert httpx.get(f"{base}/state", headers=ph).json()["current"]["robot_action"] == "ask"
        body = {"trial": 1, "submission_id": "asked", "human_action": "intervene", "effort_ms": 5000}
        httpx.post(f"{base}/trials", json=body, headers=ph).raise_for_status()
        with sync_playwright() as p:
            browser = launch_chromium(p)
            page = browser.new_page(viewport={"width": 1320, "height": 700})
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            for pid in ("dash-1", "dash-2"):
                page.goto(f"{study['link']}?PROLIFIC_PID={pid}")
                page.wait_for_selector("#screen-consent:not([hidden])")
            screenshot(page, path=str(out / "page_join.png"))  # the consent page a study link opens
            page.check("#agree")
            page.click("#consent-btn")
            page.wait_for_selector("#screen-instructions:not([hidden])")
            page.click("#start-btn")
            page.wait_for_selector("#screen-quiz:not([hidden])")
            screenshot(page, path=str(out / "page_quiz.png"))
            c.revoke(study["id"], link["session_id"])
            page.goto(link["link"])
            assert page.get_attribute("body", "data-page") == "revoked"
            screenshot(page, path=str(out / "page_revoked.png"))
            c.set_status(study["id"], "paused")
            page.goto(f"{study['link']}?PROLIFIC_PID=late")
            assert page.get_attribute("body", "data-page") == "paused"
            screenshot(page, path=str(out / "page_paused.png"))

            dash = browser.new_page(viewport={"width": 1320, "height": 700})
            dash.on("pageerror", lambda e: errors.append(str(e)))
            dash.goto(f"{url}/dashboard")
            dash.fill("#token", TOKEN)
            dash.dispatch_event("#token", "change")
            dash.wait_for_selector("#rows td:has-text('dash-2')")
            assert dash.inner_text("#study-status") == "paused" and dash.is_disabled("#pause-study")
            assert urlsplit(dash.get_attribute("#study-link", "href")).path == urlsplit(study["link"]).path
            assert "revoked" in dash.inner_text("#rows") and "pilot" in dash.inner_text("#rows")
            assert (
                "1 revoked" in dash.inner_text("#progress")
                and "of a quota of 40" in dash.inner_text("#progress")
                and "preview" not in dash.inner_text("#progress")
            )
            assert "Enter the experimenter token" not in dash.inner_text("body")  # a valid token says no more
            pilot_row = dash.inner_text(f"#rows tr:has-text('{pilot['participant']}')")
            assert "teleoperated (asked)" in pilot_row and "intervene" not in pilot_row, pilot_row
            assert "0 / 2" in pilot_row and "(practice)" in pilot_row  # the practice trial counted apart
            screenshot(dash, path=str(out / "dashboard_study.png"))
            # a preview: the participant's view, where ?speed= works (and only there)
            page.goto(c.preview(study["id"]) + "?speed=3")
            page.wait_for_selector("#preview-tag:not([hidden])")
            assert page.evaluate("window.trustseek.state().speed") == 3 * STUDY["animation_speed"]
            screenshot(page, path=str(out / "page_preview.png"))
            dash.on("dialog", lambda d: d.accept())
            dash.click("#close-study")
            dash.wait_for_function("document.getElementById('study-status').textContent === 'closed'")
            page.goto(f"{study['link']}?PROLIFIC_PID=later")
            assert page.get_attribute("body", "data-page") == "closed"
            screenshot(page, path=str(out / "page_closed.png"))
            browser.close()
        # a preview run to its end page (of a study without the practice's teleoperation) leaves
        # the database and the export unchanged
        other = c.create_study(STUDY)
        c.create_sessions(other["id"], count=1, pilot=True)
        tables = ("trials", "sessions", "events")
        export = {t: c.export(other["id"], table=t) for t in tables}
        rows = database_rows(path)
        result = asyncio.run(preview_run(c.preview(other["id"])))
        assert result["code"] == "CROWD-OK" and not result["errors"], result  # the whole study was shown
        assert database_rows(path) == rows
        assert {t: c.export(other["id"], table=t) for t in tables} == export
    assert not errors, errors
