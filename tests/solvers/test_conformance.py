"""Conformance of every registered solver (in the spirit of POMDPTools' test_solver and
scikit-learn's check_estimator).

For each solver in the registry, each belief update it takes, and each problem (the paper
preset and the shipped three-level example): where the solver handles the problem,
solve -> JSON round trip -> PolicyRunner -> simulate must give the same decisions; where it
does not, it must refuse up front with a TrustseekError that names an alternative.  A new
solver in the registry is covered without touching this file.
"""

import json
import re

import numpy as np
import pytest

from trustseek import AssistancePOMDP, PolicyRunner, paper_model, paper_task
from trustseek.data import example_path
from trustseek.errors import TrustseekError
from trustseek.model.core import TrustModel
from trustseek.model.jsonfile import json_safe
from trustseek.model.task import Task
from trustseek.policies import policy_from_dict
from trustseek.simulation import simulate
from trustseek.solvers import SOLVERS, UnsupportedProblem, make_solver, solver_names
from trustseek.vocab import ACTIONS, BELIEF_UPDATES, EXPERIENCES, HUMAN_ACTIONS

PROBLEMS = ("paper", "three-level")


def _problem(name):
    if name == "paper":
        return AssistancePOMDP(paper_model(), paper_task())
    model = TrustModel.load(example_path("three_level_model.json"))
    return AssistancePOMDP(model, Task.load(example_path("three_level_task.json")))


@pytest.fixture(scope="module")
def problems():
    return {name: _problem(name) for name in PROBLEMS}


def _cases():
    """(solver, belief update or None) for every registered solver and update it takes."""
    for name, entry in SOLVERS.items():
        for update in BELIEF_UPDATES if "belief_update" in entry.options else (None,):
            yield name, update


#: options that keep a solver's run short here (the decisions are checked, not the bounds)
QUICK = {"reachable": {"max_seconds": 3.0}}


def _build(name, update):
    return make_solver(name, belief_update=update, **QUICK.get(name, {}))


def _handles(name, update, pomdp):
    return not _build(name, update).unsupported(pomdp)


@pytest.mark.parametrize("problem", PROBLEMS)
@pytest.mark.parametrize("name,update", list(_cases()))
def test_solver_conformance(name, update, problem, problems):
    pomdp = problems[problem]
    solver = _build(name, update)
    assert solver.name == name
    reasons = solver.unsupported(pomdp)
    if reasons:
        _check_refusal(name, update, pomdp, solver, reasons)
        return
    policy = solver.solve(pomdp)
    assert policy.complexities == pomdp.complexities
    if update is not None and policy.belief_update is not None:
        assert policy.belief_update == update

    # JSON round trip: the file format loads back into a policy that decides the same way
    again = policy_from_dict(json.loads(json.dumps(json_safe(policy.to_dict()), allow_nan=False)), "round trip")
    assert (again.kind, again.complexities, again.belief_update) == (policy.kind, policy.complexities, policy.belief_update)
    rng = np.random.default_rng(7)
    B = rng.dirichlet(np.ones(pomdp.n_trust), size=400)
    cx = rng.integers(0, pomdp.n_complexity, size=400)
    np.testing.assert_array_equal(again.actions(B, cx), policy.actions(B, cx))

    # the simulator and PolicyRunner (what the server and a robot use) make the same decisions
    sim = simulate(pomdp.model, pomdp.task, again, n_participants=12, trials=30, seed=3, belief_model=pomdp.model)
    a = sim.arrays
    for i in range(sim.n):
        runner = PolicyRunner(again, model=pomdp.model)
        for t in range(a["action"].shape[1]):
            c = int(a["complexity"][i, t])
            if policy.belief_update is not None:
                assert runner.belief[-1] == pytest.approx(a["belief"][i, t], abs=1e-9)
            assert runner.decide(c) == ACTIONS[a["action"][i, t]], (i, t)
            runner.observe(c, ACTIONS[a["action"][i, t]], HUMAN_ACTIONS[a["human"][i, t]], EXPERIENCES[a["experience"][i, t]])


def _check_refusal(name, update, pomdp, solver, reasons):
    """Refused up front, with a TrustseekError whose every line names another solver; when some
    registered solver handles the case, the message names one that does."""
    with pytest.raises(UnsupportedProblem) as exc:
        solver.solve(pomdp)
    assert isinstance(exc.value, TrustseekError)
    assert exc.value.problems == reasons
    capable = {n for n, u in _cases() if n != name and u in (update, None) and _handles(n, u, pomdp) and _takes_belief(n, update)}
    named: set[str] = set()
    for line in reasons:
        in_line = {n for n in solver_names() if n != name and re.search(rf"(?<![\w-]){re.escape(n)}(?![\w-])", line)}
        assert in_line, f"{name}: {line!r} names no alternative"
        named |= in_line
    if capable:
        assert named & capable, f"{name}: {reasons} name {sorted(named)}, but only {sorted(capable)} handle it"


def _takes_belief(name, update):
    """A solver that ignores the belief is no alternative for a belief update."""
    return update is None or "belief_update" in SOLVERS[name].options


def test_every_solver_builds_with_its_defaults_and_rejects_unknown_options():
    for name, entry in SOLVERS.items():
        assert make_solver(name, **entry.options).name == name
    with pytest.raises(TrustseekError, match="unknown solver 'magic'"):
        make_solver("magic")
    with pytest.raises(TrustseekError, match="unknown solver option 'colour'"):
        make_solver("grid", colour="blue")


@pytest.mark.parametrize("name", [n for n, e in SOLVERS.items() if "gap" in e.options or "tol" in e.options])
@pytest.mark.parametrize("tol", [0.0, -1.0, float("inf"), float("nan")])
def test_every_target_gap_is_a_finite_number_above_zero(name, tol):
    key = "gap" if "gap" in SOLVERS[name].options else "tol"
    with pytest.raises(TrustseekError, match="the target gap must be a finite number > 0"):
        make_solver(name, **{key: tol})
