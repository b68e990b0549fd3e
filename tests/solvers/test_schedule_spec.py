"""The short ``schedule`` policy spec: solved from the model and task like the solver itself."""

from __future__ import annotations

import numpy as np
import pytest

from trustseek import AssistancePOMDP, paper_model, paper_task
from trustseek.policies.scheduling import SchedulePolicy
from trustseek.pomdp.scheduling import SchedulingProblem, schedule_size
from trustseek.solvers.registry import PolicySpecError, policy_from_spec
from trustseek.solvers.scheduling import ScheduleSolver


def test_schedule_spec_is_the_solvers_policy():
    model, task = paper_model(), paper_task()
    spec = {"kind": "schedule", "counts": {"low": 4, "high": 3}, "window": 2, "grid": 51, "order": "easy-first"}
    pol = policy_from_spec(spec, model, task)
    assert isinstance(pol, SchedulePolicy)
    ref = ScheduleSolver(grid=51, order="easy-first").solve(SchedulingProblem(AssistancePOMDP(model, task), (4, 3), 2))
    assert (pol.counts, pol.window, pol.belief_update) == ((4, 3), 2, "bayes")
    assert pol.info["value"] == pytest.approx(ref.info["value"], abs=1e-12)
    assert set(pol.q) == set(ref.q)
    for s in ref.q:
        for k in ref.q[s]:
            np.testing.assert_allclose(pol.q[s][k].values, ref.q[s][k].values, atol=1e-12)
    # counts as a list, one number per complexity; a missing complexity counts 0 items
    assert policy_from_spec({"kind": "schedule", "counts": [0, 2], "grid": 11}, model, task).counts == (0, 2)
    assert policy_from_spec({"kind": "schedule", "counts": {"high": 2}, "grid": 11}, model, task).counts == (0, 2)


def test_schedule_spec_options_reach_the_solver():
    model, task = paper_model(), paper_task()
    base = {"kind": "schedule", "counts": {"low": 3, "high": 3}, "grid": 41}
    opt = policy_from_spec(base, model, task)
    hard = policy_from_spec({**base, "order": "hard-first"}, model, task)
    paper = policy_from_spec({**base, "belief_update": "paper"}, model, task)
    first = policy_from_spec({**base, "ask_first_hard": True}, model, task)
    assert hard.info["value"] < opt.info["value"]
    assert paper.belief_update == "paper" and first.info["ask_first_hard"] is True
    assert len(opt.q[((3, 3), (3, 3))][0].xs) == 41


def test_schedule_spec_reports_every_problem():
    model, task = paper_model(), paper_task()
    bad = {"kind": "schedule", "counts": {"low": -1, "huge": 2}, "window": 0, "grid": 2, "order": "random", "x": 1}
    with pytest.raises(PolicySpecError) as ei:
        policy_from_spec(bad, model, task, where="blocks[0].policy")
    lines = ei.value.problems
    assert len(lines) == 5 and all(line.startswith("blocks[0].policy") for line in lines)
    for word in ("unknown entries ['x']", ".counts", ".window", ".grid", ".order"):
        assert any(word in line for line in lines), word
    with pytest.raises(PolicySpecError, match="at least one item"):
        policy_from_spec({"kind": "schedule", "counts": {"low": 0, "high": 0}}, model, task)
    with pytest.raises(PolicySpecError, match="ask_first_hard"):
        policy_from_spec({"kind": "schedule", "counts": [1, 1], "ask_first_hard": "yes"}, model, task)


def test_schedule_spec_bounded_before_solving():
    model, task = paper_model(), paper_task()
    assert schedule_size((17, 17), None, 201) == 18 * 18 * 2 * 2 * 201
    assert schedule_size((17, 17), 3, 201) == 18 * 18 * 4 * 2 * 2 * 201
    assert schedule_size((2, 2), 9, 5) == 9 * 2 * 2 * 5  # a window wider than the items is full control
    with pytest.raises(PolicySpecError, match="more than the 1000 allowed"):
        policy_from_spec({"kind": "schedule", "counts": [17, 17]}, model, task, max_values=1000)
    n_states = len(SchedulingProblem(AssistancePOMDP(model, task), (5, 4), 2).states())
    assert n_states * 2 * 2 * 7 <= schedule_size((5, 4), 2, 7)
