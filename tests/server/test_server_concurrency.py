"""The decision API under many robots at once: requests of many sessions interleaved on one
event loop (and a second application on the same database, as a second worker process is),
with retried requests; every acknowledged trial is stored exactly once, and every decision and
belief is the one the in-process policy (``PolicyRunner``) gives for the same history."""

from __future__ import annotations

import asyncio
import json
import random
import sqlite3

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from asgi_client import asgi_post
from trustseek.model.core import TrustModel
from trustseek.model.task import Task
from trustseek.policies import PolicyRunner, policy_from_dict
from trustseek.server.app import create_app

TOKEN = "concurrency-experimenter-token"
POLICIES = [
    {"kind": "trust-aware", "grid": 51},
    {"kind": "randomized", "p_ask": {"low": 0.3, "high": 0.6}},
    {"kind": "trust-agnostic"},
]


async def post(app, path: str, body: dict, token: str) -> tuple[int, dict]:
    raw = json.dumps(body).encode()
    headers = {"authorization": f"Bearer {token}", "content-type": "application/json", "content-length": str(len(raw))}
    status, _, out = await asgi_post(app, path, raw, headers, disconnect=False)
    return status, json.loads(out)


def forget_caches(*apps) -> None:
    """As a process that did not open the sessions (another worker, or after a restart)."""
    for app in apps:
        app.state.deploy_plans.clear()


def replay(plan: dict, policy_json: dict, seed: int, history: list[dict]) -> list[tuple[str, float | None, float | None]]:
    """(action, belief before, belief after) of each trial of ``history`` (the stored trials),
    from the in-process policy: a runner per trial seeded by (seed, trial), as the server
    always decided."""
    model = TrustModel.from_dict(plan["model"])
    pol = policy_from_dict(policy_json)
    pm = getattr(pol, "model", None) or model
    belief = np.asarray(pm.initial, dtype=float)
    out = []
    for t in history:
        runner = PolicyRunner(pol, model=pm, rng=np.random.default_rng([seed, t["trial"], 0]), belief=belief)
        action = runner.decide(t["complexity"])
        after = runner.observe(t["complexity"], action, t["human_action"], t["experience"])
        out.append((action, float(belief[-1]), None if after is None else float(after[-1])))
        belief = after
    return out


def robot_plan(rng: random.Random, trials: int) -> list[tuple[str, str, str | None]]:
    """Per trial: complexity, human action if the robot acts alone, outcome if the human relies."""
    steps = []
    for _ in range(trials):
        human = "intervene" if rng.random() < 0.2 else "rely"
        steps.append((rng.choice(["low", "high"]), human, rng.choice(["success", "failure"]) if human == "rely" else None))
    return steps


async def run_robot(app, sid: str, token: str, steps, rng: random.Random, acked: dict) -> None:
    base = f"/api/deploy/sessions/{sid}"
    for n, (cx, human, outcome) in enumerate(steps, start=1):
        status, d = await post(app, f"{base}/decide", {"trial": n, "complexity": cx}, token)
        assert status == 200, d
        if rng.random() < 0.3:  # a retried decision: the same answer
            await asyncio.sleep(0)
            assert await post(app, f"{base}/decide", {"trial": n, "complexity": cx}, token) == (200, d)
        await asyncio.sleep(0)
        body = {"trial": n} if d["robot_action"] == "ask" else {"trial": n, "human_action": human, "outcome": outcome}
        status, o = await post(app, f"{base}/observe", body, token)
        assert status == 200 and o["duplicate"] is False, o
        if rng.random() < 0.3:  # a retried observation: the stored trial, not a second one
            status, again = await post(app, f"{base}/observe", body, token)
            assert status == 200 and again["duplicate"] is True and again["trial"] == o["trial"]
        acked[sid].append((d, o["trial"]))
        await asyncio.sleep(0)


def stored(path, sid: str) -> list[dict]:
    with sqlite3.connect(path) as con:
        con.row_factory = sqlite3.Row
        return [dict(r) for r in con.execute("SELECT * FROM trials WHERE session_id = ? ORDER BY trial", (sid,))]


@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**16), trials=st.integers(3, 8))
def test_interleaved_robots_on_two_applications_match_the_in_process_policy(tmp_path_factory, seed, trials):
    path = tmp_path_factory.mktemp("conc") / "conc.sqlite"
    url = f"sqlite:///{path}"
    apps = [create_app(url, token=TOKEN), create_app(url, token=TOKEN)]  # as two worker processes
    rng = random.Random(seed)
    robots = []
    for i in range(12):
        policy = POLICIES[i % len(POLICIES)]
        status, info = asyncio.run(
            post(apps[0], "/api/deploy/sessions", {"label": f"r{i}", "policy": policy, "seed": seed + i % 4}, TOKEN)
        )
        assert status == 201, info
        robots.append((info, robot_plan(rng, trials)))
    if rng.random() < 0.5:
        forget_caches(*apps)  # the sessions' first requests read their plans back from the database
    acked: dict[str, list] = {info["session_id"]: [] for info, _ in robots}

    async def everyone():
        # each robot's requests go to either application, interleaved with the others'
        await asyncio.gather(
            *(
                run_robot(apps[k % 2], info["session_id"], info["token"], steps, random.Random(seed * 100 + k), acked)
                for k, (info, steps) in enumerate(robots)
            )
        )

    asyncio.run(everyone())
    for info, _ in robots:
        sid = info["session_id"]
        rows = stored(path, sid)
        assert [r["trial"] for r in rows] == list(range(1, trials + 1))  # every acknowledged trial, once
        for (decision, trial), row in zip(acked[sid], rows, strict=True):
            assert decision["robot_action"] == row["robot_action"] == trial["robot_action"]
            assert trial["belief_after"] == row["belief_after"] and trial["experience"] == row["experience"]
        with sqlite3.connect(path) as con:
            plan, sha = con.execute(
                "SELECT plan, json_extract(plan, '$.policy_sha256') FROM sessions WHERE id = ?", (sid,)
            ).fetchone()
            (policy_json,) = con.execute("SELECT policy FROM policies WHERE sha256 = ?", (sha,)).fetchone()
            seed_of = con.execute("SELECT seed FROM sessions WHERE id = ?", (sid,)).fetchone()[0]
        expected = replay(json.loads(plan), json.loads(policy_json), seed_of, rows)
        assert [(r["robot_action"], r["belief"], r["belief_after"]) for r in rows] == expected
        for r in rows:  # Section III: the experience of each trial
            if r["robot_action"] == "autonomous":
                assert r["experience"] == ("reliable" if r["outcome"] == "success" else "faulty")
    for app in apps:
        app.state.deploy_store.close()
        app.state.engine.dispose()


def test_a_deploy_plan_is_shared_by_sessions_with_the_same_task_model_and_policy(tmp_path):
    app = create_app(f"sqlite:///{tmp_path / 'plans.sqlite'}", token=TOKEN)
    plans_of = app.state.deploy_plans
    opened = [
        asyncio.run(post(app, "/api/deploy/sessions", {"policy": POLICIES[k], "seed": i}, TOKEN))[1]
        for k in (0, 0, 1)
        for i in range(2)
    ]
    plans = [plans_of.by_session.get(o["session_id"]) for o in opened]
    assert len({id(p) for p in plans[:4]}) == 1 and len({id(p) for p in plans}) == 2
    forget_caches(app)  # read back from the database: shared again, and the same task and model
    store = app.state.deploy_store
    with store.transaction() as tx:
        back = [plans_of.of(tx, o["session_id"]) for o in opened]
    assert len({id(p) for p in back[:4]}) == 1 and back[4] is back[5] and back[0] is not back[4]
    assert isinstance(back[0].task, Task) and back[0].task.to_dict() == plans[0].task.to_dict()
    assert back[0].model.to_dict() == plans[0].model.to_dict() and back[0].sha == plans[0].sha


@pytest.mark.parametrize("policy", POLICIES[:2])
def test_remembered_decisions_equal_fresh_ones(tmp_path, policy):
    """A decision a plan remembers is the one the policy would make again; a decision that
    drew from the session's generator is never remembered."""
    app = create_app(f"sqlite:///{tmp_path / 'memo.sqlite'}", token=TOKEN)
    _, info = asyncio.run(post(app, "/api/deploy/sessions", {"policy": policy, "seed": 5}, TOKEN))
    plan = app.state.deploy_plans.by_session.get(info["session_id"])
    pol = plan.policy()
    pm = getattr(pol, "model", None) or plan.model
    beliefs = [[1 - x, x] for x in np.linspace(0.0, 1.0, 21)]
    for b in beliefs:
        for n in (1, 2, 3):
            for cx in ("low", "high"):
                a = plan.decide(b, 5, n, cx)
                fresh = PolicyRunner(pol, model=pm, rng=np.random.default_rng([5, n, 0]), belief=np.asarray(b)).decide(cx)
                assert a == fresh
    if policy["kind"] == "randomized":
        assert len(plan._decided) == 0
    else:
        assert len(plan._decided) == 2 * len(beliefs)


@pytest.mark.parametrize("policy", POLICIES)
def test_a_plans_step_is_policy_runners_step(tmp_path, policy):
    """The decision API decides and updates with ``PolicyRunner``'s own step: for any belief,
    trial and events, the same action and the same belief as a runner with that belief and the
    session's generator of (seed, trial), remembered or not."""
    app = create_app(f"sqlite:///{tmp_path / 'step.sqlite'}", token=TOKEN)
    _, info = asyncio.run(post(app, "/api/deploy/sessions", {"policy": policy, "seed": 11}, TOKEN))
    plan = app.state.deploy_plans.by_session.get(info["session_id"])
    pol = plan.policy()
    pm = getattr(pol, "model", None) or plan.model
    rng = random.Random(3)
    cases = [
        (
            [1 - (x := rng.random()), x],
            1 + k % 5,
            rng.choice(["low", "high"]),
            rng.choice(["autonomous", "ask"]),
            rng.choice(["intervene", "rely"]),
            rng.choice(["faulty", "reliable"]),
        )
        for k in range(40)
    ]
    for _ in range(2):  # the second time from what the plan remembers
        for b, n, cx, a, h, e in cases:
            runner = PolicyRunner(pol, model=pm, rng=np.random.default_rng([11, n, 0]), belief=np.asarray(b))
            assert plan.decide(b, 11, n, cx) == runner.decide(cx)
            after = runner.observe(cx, a, h, e)
            assert plan.update(b, cx, a, h, e) == [float(v) for v in after]
    app.state.deploy_store.close()
