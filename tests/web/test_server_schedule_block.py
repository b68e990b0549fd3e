"""Study blocks whose schedule policy picks the items ("schedule": "policy"): the server serves
the policy's pick among the remaining (visible) items with its ask, the trial log records the
order, and the export is fitted with ``trustseek fit``; one short run in Chromium."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from fastapi.testclient import TestClient
from hypothesis import given, settings
from hypothesis import strategies as hst
from typer.testing import CliRunner

from scene_drive import step_until
from test_browser import artifacts_dir, teleoperate
from trustseek import paper_model, paper_task
from trustseek.cli import app
from trustseek.client import Client
from trustseek.data.trials import read_trials
from trustseek.policies.scheduling import ScheduleRunner
from trustseek.server import create_app
from trustseek.server.app import STATIC
from trustseek.server.studies import block_items
from trustseek.solvers.registry import policy_from_spec
from trustseek.testing.browser import CHROMIUM, launch_chromium, screenshot
from trustseek.testing.servers import ThreadServer

TOKEN = "schedule-block-token"
H = {"Authorization": f"Bearer {TOKEN}"}
SPEC = {"kind": "schedule", "counts": {"low": 4, "high": 3}, "window": None, "grid": 101}


@pytest.fixture
def client(tmp_path):
    with TestClient(create_app(f"sqlite:///{tmp_path / 'db.sqlite'}", token=TOKEN)) as c:
        yield c


def _study(c, blocks, **extra):
    r = c.post("/api/studies", json={"name": "scheduled", "blocks": blocks, **extra}, headers=H)
    return r


def _experience(task, cx: str, action: str, human: str, outcome: str) -> str:
    if action == "ask":
        return ("faulty", "reliable")[task.ask_experience[task.complexity_index(cx)]]
    return "reliable" if human == "rely" and outcome == "success" else "faulty"


def _run(c, session, decide_human, check=None, after=None) -> list[dict]:
    """Do every trial of a participant session; ``check(current)`` before each submission,
    ``after(trial)`` with each committed trial."""
    ph = {"Authorization": f"Bearer {session['token']}"}
    base = f"/api/sessions/{session['session_id']}"
    assert c.post(f"{base}/consent", json={"agree": True}, headers=ph).status_code == 200
    out = []
    while True:
        state = c.get(f"{base}/state", headers=ph).json()
        cur = state["current"]
        if cur is None:
            return out
        if check is not None:
            check(cur)
        human = "intervene" if cur["robot_action"] == "ask" else decide_human(cur)
        body = {"trial": cur["trial"], "submission_id": f"{session['session_id']}-{cur['trial']}", "human_action": human}
        r = c.post(f"{base}/trials", json=body, headers=ph)
        assert r.status_code in (200, 201), r.text
        out.append(r.json()["trial"])
        if after is not None:
            after(out[-1])


def test_policy_picks_each_item_like_the_schedule_runner(client):
    task = paper_task()
    r = _study(client, [{"name": "chosen", "policy": SPEC, "schedule": "policy"}])
    assert r.status_code == 201, r.text
    study = r.json()
    session = client.post(f"/api/studies/{study['id']}/sessions", json={"count": 1}, headers=H).json()[0]
    local = ScheduleRunner(policy_from_spec(SPEC, paper_model(), task))
    rng = np.random.default_rng(5)
    seen = []

    def check(cur):
        assert cur["items"]["visible"] is None
        assert cur["items"]["remaining"] == dict(zip(task.complexities, local.remaining, strict=True))
        assert (cur["complexity"], cur["robot_action"]) == local.choose()
        seen.append(cur["items"]["remaining"])

    def human(cur):
        return "intervene" if rng.random() < 0.3 else "rely"

    def after(t):
        local.observe(t["complexity"], t["robot_action"], t["human_action"], _experience(task, **_exp_args(t)))

    trials = _run(client, session, human, check, after)
    assert [sum(r.values()) for r in seen] == list(range(7, 0, -1))
    assert sorted(t["complexity"] for t in trials) == ["high"] * 3 + ["low"] * 4
    # the trial log holds the order the policy chose and its kind
    log = client.get(f"/api/studies/{study['id']}/export?format=csv", headers=H)
    assert log.status_code == 200
    rows = [line.split(",") for line in log.text.strip().splitlines()]
    head = rows[0]
    col = {k: head.index(k) for k in ("trial", "complexity", "policy")}
    assert [r[col["complexity"]] for r in rows[1:]] == [t["complexity"] for t in trials]
    assert {r[col["policy"]] for r in rows[1:]} == {"schedule"}


def _exp_args(t: dict) -> dict:
    return {"cx": t["complexity"], "action": t["robot_action"], "human": t["human_action"], "outcome": t["outcome"]}


def test_window_picks_among_the_visible_items(client):
    spec = {**SPEC, "counts": {"low": 3, "high": 3}, "window": 2}
    study = _study(
        client, [{"policy": spec, "schedule": "policy"}, {"policy": {"kind": "never-ask"}, "schedule": {"counts": {"low": 1}}}]
    )
    assert study.status_code == 201, study.text
    sid = study.json()["id"]
    for session in client.post(f"/api/studies/{sid}/sessions", json={"count": 3}, headers=H).json():

        def check(cur):
            if cur["block"] != 0:
                assert "items" not in cur
                return
            rem, vis = cur["items"]["remaining"], cur["items"]["visible"]
            assert sum(vis.values()) == min(2, sum(rem.values()))
            assert all(0 <= vis[c] <= rem[c] for c in rem)
            assert vis[cur["complexity"]] >= 1  # the robot goes for an item it sees

        trials = _run(client, session, lambda cur: "rely", check)
        assert [t["block"] for t in trials] == [0] * 6 + [1]


@settings(max_examples=60, deadline=None)
@given(hst.data())
def test_block_items_follow_the_queue(data):
    low, high = data.draw(hst.integers(0, 5)), data.draw(hst.integers(0, 5))
    window = data.draw(hst.one_of(hst.none(), hst.integers(1, 4)))
    queue = ["low"] * low + ["high"] * high
    queue = data.draw(hst.permutations(queue))
    cfg = {"blocks": [{"schedule": {"by": "policy", "counts": {"low": low, "high": high}, "window": window}}]}
    plan = {"queues": {"0": queue}}
    picks: list[str] = []
    model_queue = list(queue)
    for _ in range(low + high):
        rem, vis = block_items(cfg, plan, 0, picks)
        assert rem == {"low": low - picks.count("low"), "high": high - picks.count("high")}
        if window is None:
            assert vis is None
            choices = [c for c in rem if rem[c] > 0]
        else:
            front = model_queue[:window]
            assert vis == {c: front.count(c) for c in ("low", "high")}
            choices = sorted(set(front))
        c = data.draw(hst.sampled_from(choices))
        picks.append(c)
        if window is not None:
            model_queue.remove(c)  # the first of its kind: the items of one kind are alike
    assert block_items(cfg, plan, 0, picks)[0] == {"low": 0, "high": 0}


def test_configurations_refused_with_reasons(client):
    never = {"kind": "never-ask"}
    cases = [
        ([{"policy": never, "schedule": "policy"}], "needs a schedule policy"),
        ([{"policy": SPEC, "schedule": {"counts": {"low": 4, "high": 3}}}], '"schedule": "policy"'),
        ([{"policy": {**SPEC, "counts": {"low": 100, "high": 100}, "grid": 2001}, "schedule": "policy"}], "more than the"),
        ([{"policy": {**SPEC, "window": 0}, "schedule": "policy"}], "window"),
        ([{"policy": SPEC, "schedule": "optimal"}], "should be 'policy'"),
    ]
    for blocks, words in cases:
        r = _study(client, blocks)
        assert r.status_code in (400, 422), (blocks, r.text)
        assert words in str(r.json()), (words, r.text)
    r = _study(client, [{"policy": never, "schedule": {"counts": {"low": 1}}}], practice={"trials": ["low"], "policy": SPEC})
    assert r.status_code == 400 and "practice.policy" in r.text


def test_deploy_takes_the_short_schedule_spec(client):
    robot = Client("http://test", TOKEN, http=client).open_deploy(policy=SPEC)
    local = ScheduleRunner(policy_from_spec(SPEC, paper_model(), paper_task()))
    assert robot.choose({"low": 4, "high": 3}) == local.choose()


def _supervisor(model, task, rng):
    """A simulated supervisor of the model (some start with low trust): (decide, after trial)."""
    trust = [int(rng.random() < 0.5)]

    def human(cur):
        cx = task.complexity_index(cur["complexity"])
        return "intervene" if rng.random() < model.emission[cx, 0, trust[0], 0] else "rely"

    def after(t):
        a, cx = int(t["robot_action"] == "ask"), task.complexity_index(t["complexity"])
        e = int(t["outcome"] == "success" or (a == 1 and cx == 1))
        trust[0] = int(rng.random() < model.transition[cx, a, e, trust[0], 1])

    return human, after


def test_exported_scheduled_study_is_fitted(client, tmp_path):
    model, task = paper_model(), paper_task()
    spec = {**SPEC, "counts": {"low": 6, "high": 6}}
    study = _study(client, [{"policy": spec, "schedule": "policy"}]).json()
    rng = np.random.default_rng(11)
    for session in client.post(f"/api/studies/{study['id']}/sessions", json={"count": 4}, headers=H).json():
        human, after = _supervisor(model, task, rng)
        _run(client, session, human, after=after)
    r = client.get(f"/api/studies/{study['id']}/export?format=parquet", headers=H)
    assert r.status_code == 200, r.text
    out = tmp_path / "scheduled.parquet"
    out.write_bytes(r.content)
    frame = read_trials(out)
    assert len(frame) == 48 and set(frame["policy"]) == {"schedule"}
    res = CliRunner().invoke(app, ["fit", str(out), "--restarts", "2", "--json"])
    assert res.exit_code == 0, res.output
    assert "48 trials" in json.loads(res.output)["model"]["notes"]


@pytest.mark.browser
def test_scheduled_block_in_chromium(tmp_path):
    """A participant does a block whose policy picks the items: the page shows the items left
    with the next one marked, the served complexity is the policy's pick, the log keeps the order."""
    if not Path(CHROMIUM).exists():
        pytest.fail(f"{CHROMIUM} is missing: run scripts/setup.sh")
    if not (STATIC / "participant.js").exists():
        pytest.fail("front end not built: run scripts/setup.sh (npm ci && npm run build in web/)")
    from playwright.sync_api import sync_playwright

    spec = {**SPEC, "counts": {"low": 2, "high": 1}}
    local = ScheduleRunner(policy_from_spec(spec, paper_model(), paper_task()))
    out = artifacts_dir(tmp_path)
    shown = []
    with ThreadServer(f"sqlite:///{tmp_path / 'chosen.sqlite'}", TOKEN) as url:
        c = Client(url, TOKEN)
        study = c.create_study({"name": "chosen", "blocks": [{"policy": spec, "schedule": "policy"}], "animation_speed": 3.0})
        link = c.create_sessions(study["id"], participants=["chromium-s"])[0]["link"]
        with sync_playwright() as p:
            browser = launch_chromium(p)
            page = browser.new_page(viewport={"width": 1000, "height": 600})
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(link + "?manual=1&quality=0")  # the page's clock is the test's (scene_drive.step_until)
            page.wait_for_selector("#screen-consent:not([hidden])")
            page.check("#agree")
            page.click("#consent-btn")
            page.wait_for_selector("#screen-instructions:not([hidden])")
            page.click("#start-btn")
            for n in (1, 2, 3):
                s = step_until(page, f"s.trial === {n} && ['approach', 'teleop'].includes(s.phase)", frames=1)["s"]
                picks = s["picks"]
                assert len(picks) == 4 - n and all(t["visible"] for t in picks)
                assert [t["complexity"] for t in picks if t["next"]] == [s["complexity"]]
                shown.append((s["complexity"], s["robot_action"]))
                if n == 1:
                    screenshot(page, path=str(out / "browser_schedule_block.png"))
                if s["phase"] == "teleop":
                    teleoperate(page)
                else:  # the participant relies on the robot
                    step_until(page, "s.item.inBin || s.phase !== 'approach'")
            step_until(page, "s.phase === 'done'")
            browser.close()
        assert not errors, errors
        log = pd.read_csv(io.BytesIO(c.export(study["id"])))
    assert log["complexity"].tolist() == [cx for cx, _ in shown]
    assert sorted(log["complexity"]) == ["high", "low", "low"]
    # each served pick is the schedule runner's, given the trials before it
    for row in log.itertuples():
        assert local.choose() == (row.complexity, row.robot_action)
        local.observe(row.complexity, row.robot_action, row.human_action, row.experience)


def test_resolved_schedule_policies_cached_within_a_bound():
    from trustseek.server import studies
    from trustseek.server.cache import MAX_CACHED_SCHEDULES, StudyCaches

    model, task = paper_model(), paper_task()
    caches = StudyCaches()
    first = studies.resolve_policy({**SPEC, "grid": 5}, model, task, caches=caches)
    assert studies.resolve_policy({**SPEC, "grid": 5}, model, task, caches=caches) is first  # the same spec is solved once
    for k in range(2 * MAX_CACHED_SCHEDULES):
        studies.resolve_policy({**SPEC, "counts": {"low": 1, "high": k}, "grid": 5}, model, task, caches=caches)
        assert 1 <= len(caches.schedules) <= MAX_CACHED_SCHEDULES


def test_restarted_server_serves_the_same_picks(tmp_path):
    """The picks come from the committed trials and the stored plan: a fresh process (empty
    caches) on the same database serves the same trials."""
    db = f"sqlite:///{tmp_path / 'restart.sqlite'}"
    spec = {**SPEC, "counts": {"low": 3, "high": 3}, "window": 2}

    def fresh():  # a new application remembers nothing
        return TestClient(create_app(db, token=TOKEN))

    with fresh() as c:
        sid = _study(c, [{"policy": spec, "schedule": "policy"}]).json()["id"]
        s = c.post(f"/api/studies/{sid}/sessions", json={"count": 1}, headers=H).json()[0]
        ph, base = {"Authorization": f"Bearer {s['token']}"}, f"/api/sessions/{s['session_id']}"
        c.post(f"{base}/consent", json={"agree": True}, headers=ph)
    served = []
    for n in range(1, 7):
        with fresh() as c:  # one process serves the trial ...
            cur = c.get(f"{base}/state", headers=ph).json()["current"]
        with fresh() as c:  # ... another serves it again, then commits it
            assert c.get(f"{base}/state", headers=ph).json()["current"] == cur
            human = "intervene" if cur["robot_action"] == "ask" else "rely"
            body = {"trial": n, "submission_id": f"r-{n}", "human_action": human}
            assert c.post(f"{base}/trials", json=body, headers=ph).status_code in (200, 201)
        served.append(cur["items"])
    assert [sum(i["remaining"].values()) for i in served] == [6, 5, 4, 3, 2, 1]
