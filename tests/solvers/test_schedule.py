"""The scheduling problem and solver against an exhaustive search with the exact Bayes belief."""

import json
from functools import cache

import numpy as np
import pytest

from trustseek import AssistancePOMDP, paper_model, paper_task
from trustseek.model.core import trust_model
from trustseek.model.jsonfile import json_safe
from trustseek.policies import policy_from_dict
from trustseek.policies.scheduling import SchedulePolicy, ScheduleRunner
from trustseek.pomdp.scheduling import SchedulingError, SchedulingProblem
from trustseek.solvers import UnsupportedProblem, make_solver
from trustseek.solvers.alpha import finite_horizon_value
from trustseek.solvers.scheduling import ScheduleSolver
from trustseek.vocab import ACTIONS, EXPERIENCES, HUMAN_ACTIONS


def oracle(model, task, counts, window):
    """The optimal expected discounted reward of a session, by plain recursion over every item
    choice and ask decision with the exact Bayes belief (no shared code with the solver)."""
    em, tr = model.emission, model.transition
    ex, rw, g = task.experience_table(), task.reward_table(), task.discount
    N = len(counts)

    def q(b, c, a, cont):
        total = 0.0
        for o in range(2):
            for e in range(2):
                joint = b * em[c, a, :, o] * ex[c, a, o, e]
                p = joint.sum()
                if p > 0:
                    total += p * (rw[a, o, e] + g * cont(tuple((joint / p) @ tr[c, a, e])))
        return total

    def arrive(b, rem, vis):
        """Expected value once the next queued item has entered the window."""
        w = sum(rem) if window is None else min(window, sum(rem))
        if sum(vis) == w:
            return value(b, rem, vis)
        hidden = [r - v for r, v in zip(rem, vis, strict=True)]
        tot = sum(hidden)
        return sum(h / tot * arrive(b, rem, tuple(v + (i == j) for i, v in enumerate(vis))) for j, h in enumerate(hidden) if h)

    @cache
    def value(b, rem, vis):
        if sum(rem) == 0:
            return 0.0
        best = -np.inf
        for k in range(N):
            if vis[k] == 0:
                continue
            rem2 = tuple(r - (i == k) for i, r in enumerate(rem))
            vis2 = tuple(v - (i == k) for i, v in enumerate(vis))
            for a in range(2):
                best = max(best, q(np.array(b), k, a, lambda b2, rem2=rem2, vis2=vis2: arrive(b2, rem2, vis2)))
        return best

    return arrive(tuple(model.initial), tuple(counts), (0,) * N)


def random_model(seed):
    rng = np.random.default_rng(seed)
    em = rng.dirichlet([2, 2], size=(2, 2, 2))
    tr = rng.dirichlet([2, 2], size=(2, 2, 2, 2))
    return trust_model(("low", "high"), ("low", "high"), rng.dirichlet([2, 2]), em, tr)


PAPER = AssistancePOMDP(paper_model(), paper_task())


@pytest.mark.parametrize("window", [None, 1, 2, 4])
def test_paper_model_three_plus_three_equals_exhaustive_search(window):
    problem = SchedulingProblem(PAPER, (3, 3), window)
    policy = ScheduleSolver(representation="alpha").solve(problem)
    assert policy.info["value"] == pytest.approx(oracle(PAPER.model, PAPER.task, (3, 3), window), abs=1e-9)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("window", [None, 1, 2])
def test_random_models_equal_exhaustive_search(seed, window):
    pomdp = AssistancePOMDP(random_model(seed), paper_task())
    counts = (2, 1) if seed % 2 else (1, 2)
    policy = ScheduleSolver(representation="alpha").solve(SchedulingProblem(pomdp, counts, window))
    assert policy.info["value"] == pytest.approx(oracle(pomdp.model, pomdp.task, counts, window), abs=1e-9)


def test_window_one_is_the_random_order_not_iid_complexities():
    """w = 1 is the paper's random order of known counts; with i.i.d. complexities (the
    existing finite-horizon machinery) the value differs."""
    rand = ScheduleSolver(representation="alpha").solve(SchedulingProblem(PAPER, (3, 3), 1)).info["value"]
    full = ScheduleSolver(representation="alpha").solve(SchedulingProblem(PAPER, (3, 3))).info["value"]
    iid = finite_horizon_value(PAPER, 6, PAPER.model.initial)
    assert rand == pytest.approx(oracle(PAPER.model, PAPER.task, (3, 3), 1), abs=1e-9)
    assert abs(rand - iid) > 1e-6
    assert full > rand + 1e-6  # choosing the order is worth something


def test_one_kind_of_item_equals_the_unscheduled_finite_horizon_value():
    """With only high-complexity items there is nothing to schedule: the value is the exact
    finite-horizon value of the existing alpha-vector machinery with P(high) = 1."""
    from dataclasses import replace

    task = replace(paper_task(), complexity_probs=np.array([0.0, 1.0]))
    pomdp = AssistancePOMDP(paper_model(), task)
    for window in (None, 1):
        v = ScheduleSolver(representation="alpha").solve(SchedulingProblem(pomdp, (0, 5), window)).info["value"]
        assert v == pytest.approx(finite_horizon_value(pomdp, 5, pomdp.model.initial), abs=1e-9)


@pytest.mark.parametrize("update", ["bayes", "paper"])
def test_grid_is_close_to_alpha_and_paper_update_runs(update):
    problem = SchedulingProblem(PAPER, (4, 4), 2)
    grid = ScheduleSolver(belief_update=update, grid=2001).solve(problem)
    if update == "bayes":
        exact = ScheduleSolver(representation="alpha").solve(problem)
        assert grid.info["value"] == pytest.approx(exact.info["value"], abs=1e-4)
    assert grid.belief_update == update


def test_json_round_trip_and_runner_follow_the_policy():
    problem = SchedulingProblem(PAPER, (4, 3))
    policy = make_solver("schedule", belief_update="bayes").solve(problem)
    again = policy_from_dict(json.loads(json.dumps(json_safe(policy.to_dict()), allow_nan=False)), "round trip")
    assert isinstance(again, SchedulePolicy)
    rng = np.random.default_rng(1)
    x = rng.random(300)
    rem = np.stack([rng.integers(0, 5, 300), rng.integers(0, 4, 300)], axis=1)
    rem[rem.sum(axis=1) == 0] = (1, 1)
    for a, b in zip(policy.choices(x, rem), again.choices(x, rem), strict=True):
        np.testing.assert_array_equal(a, b)
    # a runner through a session: the items it picks are the policy's, and they run out exactly
    runner = ScheduleRunner(again, model=PAPER.model)
    picked = []
    for _ in range(7):
        k, a = runner.choose()
        assert (PAPER.complexities.index(k), ACTIONS.index(a)) == again.choose(runner.belief, runner.remaining)
        assert runner.decide(k) == a
        runner.observe(k, a, HUMAN_ACTIONS[1] if a == "autonomous" else HUMAN_ACTIONS[0], EXPERIENCES[1])
        picked.append(k)
    assert sorted(picked) == ["high"] * 3 + ["low"] * 4
    assert runner.remaining == (0, 0)


def test_window_policy_needs_the_visible_items():
    policy = ScheduleSolver().solve(SchedulingProblem(PAPER, (3, 3), 2))
    runner = ScheduleRunner(policy, model=PAPER.model)
    with pytest.raises(Exception, match="window of 2"):
        runner.choose()
    k, _ = runner.choose({"low": 1, "high": 1})
    assert k in ("low", "high")
    k, _ = runner.choose({"high": 2})
    assert k == "high"


def test_rules_restrict_the_picks_and_force_the_first_hard_ask():
    problem = SchedulingProblem(PAPER, (3, 3))
    easy = ScheduleSolver(order="easy-first").solve(problem)
    hard = ScheduleSolver(order="hard-first").solve(problem)
    alt = ScheduleSolver(order="alternating").solve(problem)
    runner = ScheduleRunner(easy, model=PAPER.model)
    seq = []
    for _ in range(6):
        k, a = runner.choose()
        runner.observe(k, a, "rely" if a == "autonomous" else "intervene", "reliable")
        seq.append(k)
    assert seq == ["low"] * 3 + ["high"] * 3
    assert hard.choose(1.0, (3, 3))[0] == 1 and alt.choose(1.0, (3, 3))[0] == 0 and alt.choose(1.0, (2, 3))[0] == 1
    forced = ScheduleSolver(ask_first_hard=True).solve(SchedulingProblem(PAPER, (3, 3), 1))
    assert forced.choose(1.0, (3, 3), (0, 1)) == (1, 1)  # the first hard item: ask
    assert (
        forced.choose(1.0, (2, 2), (0, 1))[1]
        == ScheduleSolver().solve(SchedulingProblem(PAPER, (3, 3), 1)).choose(1.0, (2, 2), (0, 1))[1]
    )
    best = ScheduleSolver().solve(problem).info["value"]
    for pol in (easy, hard, alt):
        assert pol.info["value"] <= best + 1e-12


def test_bad_problems_are_refused_with_reasons():
    with pytest.raises(SchedulingError, match="counts"):
        SchedulingProblem(PAPER, (3, -1))
    with pytest.raises(SchedulingError, match="window"):
        SchedulingProblem(PAPER, (3, 3), 0)
    with pytest.raises(UnsupportedProblem, match="grid solver"):
        ScheduleSolver().solve(PAPER)
    with pytest.raises(UnsupportedProblem, match="bayes update only"):
        ScheduleSolver(belief_update="paper", representation="alpha").solve(SchedulingProblem(PAPER, (2, 2)))
    assert SchedulingProblem(PAPER, (2, 2), 9).full_control


def test_problems_too_large_to_solve_are_refused_and_growing_alpha_vectors_stop(monkeypatch):
    """A schedule of 10^9 items, and alpha vectors on the paper's 41 + 30 items (past two minutes
    and 7 GB), ran until killed: the size is refused before the solve, and the alpha vectors'
    growth stops the solve at a budget of pieces, each with the way out."""
    with pytest.raises(UnsupportedProblem, match="a window, or a coarser grid"):
        ScheduleSolver().solve(SchedulingProblem(PAPER, (10**9, 1)))
    with pytest.raises(UnsupportedProblem, match="use the grid representation"):
        ScheduleSolver(representation="alpha").solve(SchedulingProblem(PAPER, (2000, 2000)))
    import trustseek.solvers.scheduling as scheduling

    problem = SchedulingProblem(PAPER, (6, 6))
    ScheduleSolver(representation="alpha").solve(problem)  # within the budget
    monkeypatch.setattr(scheduling, "MAX_PIECES", 1000)
    with pytest.raises(scheduling.SolverError, match=r"grew past 1,000 pieces.*use the grid representation"):
        ScheduleSolver(representation="alpha").solve(problem)
