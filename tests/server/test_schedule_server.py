"""The deploy API with a schedule policy: the robot says which items remain, the service picks."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from trustseek import AssistancePOMDP, paper_model, paper_task
from trustseek.client import Client, ServerError
from trustseek.policies.scheduling import ScheduleRunner
from trustseek.pomdp.scheduling import SchedulingProblem
from trustseek.server import create_app
from trustseek.solvers.scheduling import ScheduleSolver

TOKEN = "experimenter-secret"


@pytest.fixture
def client(tmp_path):
    with TestClient(create_app(f"sqlite:///{tmp_path / 'db.sqlite'}", token=TOKEN)) as c:
        yield c


def _policy(counts, window=None):
    pomdp = AssistancePOMDP(paper_model(), paper_task())
    return ScheduleSolver(grid=101).solve(SchedulingProblem(pomdp, counts, window))


def test_deploy_schedule_policy_picks_the_items_like_the_runner(client):
    policy = _policy((3, 2))
    robot = Client("http://test", TOKEN, http=client).open_deploy(policy=policy.to_dict())
    local = ScheduleRunner(policy, model=policy.model)
    remaining = {"low": 3, "high": 2}
    outcomes = iter([("rely", "success"), ("intervene", None), ("rely", "failure"), ("rely", "success"), ("rely", "success")])
    for _ in range(5):
        cx, action = robot.choose(remaining)
        assert (cx, action) == local.choose()
        human, outcome = next(outcomes)
        if action == "ask":
            human, outcome = None, None
        belief = robot.observe(human, outcome)
        exp = "faulty" if human == "intervene" or outcome == "failure" else ("reliable" if action == "autonomous" else None)
        if action == "ask":
            exp = ("faulty", "reliable")[paper_task().ask_experience[paper_task().complexity_index(cx)]]
        local.observe(cx, action, human or "intervene", exp)
        assert belief == pytest.approx(local.belief[-1], abs=1e-12)
        remaining[cx] -= 1
    assert remaining == {"low": 0, "high": 0}
    trials = robot.state()["trials"]
    assert sorted(t["complexity"] for t in trials) == ["high", "high", "low", "low", "low"]


def test_deploy_schedule_refusals_and_imposed_items(client):
    c = Client("http://test", TOKEN, http=client)
    robot = c.open_deploy(policy=_policy((2, 2), window=1).to_dict())
    with pytest.raises(ServerError) as ei:
        robot.choose({"low": 2, "high": 2})  # a window of one item: the visible item is needed
    assert ei.value.status == 400 and "window" in str(ei.value)
    with pytest.raises(ServerError) as ei:
        robot.choose({"low": 2, "medium": 2})
    assert ei.value.status == 400 and "remaining" in str(ei.value)
    cx, action = robot.choose({"low": 2, "high": 2}, visible={"high": 1})
    assert cx == "high"
    assert robot.choose({"low": 2, "high": 2}, visible={"high": 1}) == (cx, action)  # idempotent
    robot.observe(None if action == "ask" else "intervene")
    with pytest.raises(ServerError) as ei:
        robot.decide("high")  # a schedule policy needs the remaining items
    assert ei.value.status == 400 and "remaining" in str(ei.value)
    _, action2 = robot.choose({"low": 2, "high": 1}, visible={"low": 1})
    assert robot.decide("low") == action2  # the imposed item of the pending decision
    plain = c.open_deploy(policy={"kind": "never-ask"})
    with pytest.raises(ServerError) as ei:
        plain.choose({"low": 1, "high": 1})
    assert ei.value.status == 400 and "schedule policy" in str(ei.value)
