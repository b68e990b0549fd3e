"""The reachable-belief solver: certified bounds at the initial belief that agree with the other
solvers, with pomdp-py's exact recursion and with exhaustive finite-horizon search."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from trustseek.model import paper_conservative_mixture, paper_task
from trustseek.pomdp import AssistancePOMDP
from trustseek.pomdp.flat import FlatPOMDP
from trustseek.pomdp.supervisor_types import type_aware_problem
from trustseek.solvers import make_solver
from trustseek.solvers.numerics import reachable_beliefs
from trustseek.solvers.reachable import ReachableSolver
from trustseek.solvers.type_aware import solve_type_aware
from trustseek.solvers.upper_bounds import fast_informed_bound


def _overlap(a, b, slack=1e-9):
    return a[0] <= b[1] + slack and b[0] <= a[1] + slack


def test_paper_preset_bounds_agree_with_the_alpha_and_point_solvers(pomdp):
    policy = make_solver("reachable", gap=1e-3, max_seconds=30).solve(pomdp)
    lo, up = policy.info["value_bounds_at_initial_belief"]
    assert up - lo <= 1e-3 and policy.info["certified_gap"] == pytest.approx(up - lo)
    alpha = make_solver("alpha", gap=1e-6).solve(pomdp).info["value_bounds_at_initial_belief"]
    point = make_solver("point", gap=1e-3).solve(pomdp).info["value_bounds_at_initial_belief"]
    assert _overlap((lo, up), alpha) and _overlap((lo, up), point)
    # the lower bound is what the policy's value vectors give at b0
    assert (policy.value_vectors @ pomdp.model.initial).max() == pytest.approx(lo)


def test_the_fast_informed_bound_is_above_the_optimal_value(pomdp):
    beta = fast_informed_bound(pomdp.branch_model())
    b0 = pomdp.model.initial
    fib = float(pomdp.complexity_probs @ (beta @ b0).max(axis=1))
    alpha = make_solver("alpha", gap=1e-6).solve(pomdp).info["value_bounds_at_initial_belief"]
    assert fib >= alpha[1] - 1e-9


def _short(task, discount):
    return dataclasses.replace(task, discount=discount)


@pytest.mark.parametrize("weights", [(0.7, 0.3), (0.5, 0.5)])
def test_type_aware_bounds_bracket_the_exhaustive_finite_horizon_value(weights):
    """With γ = 0.3 the value of 4 trials is within γ^4 max|r| / (1 - γ) of the infinite-horizon one."""
    gamma, horizon = 0.3, 4
    problem = type_aware_problem(paper_conservative_mixture().with_weights(list(weights)), _short(paper_task(), gamma))
    bm = problem.branch_model()
    exact = bm.finite_horizon_value(bm.initial, horizon)
    tail = gamma**horizon * float(np.abs(bm.rewards).max()) / (1 - gamma)
    sol = ReachableSolver(tol=1e-4, max_seconds=20).solve_bounds(problem)
    assert sol.gap <= 1e-4
    assert exact - tail <= sol.upper + 1e-9
    assert sol.lower <= exact + tail + 1e-9


def test_known_type_value_equals_the_single_type_value():
    """Weights (1, 0): the type-aware problem is the paper's supervisor; (0, 1): the conservative one."""
    mixture = paper_conservative_mixture()
    task = paper_task()
    for m, model in enumerate(mixture.models):
        onehot = np.eye(2)[m]
        aware = solve_type_aware(mixture, task, "reachable", gap=1e-3, type_belief=onehot, max_seconds=30)
        single = make_solver("alpha", gap=1e-6).solve(AssistancePOMDP(model, task))
        lo, up = aware.info["value_bounds_at_initial_belief"]
        assert up - lo <= 1e-3
        assert _overlap((lo, up), single.info["value_bounds_at_initial_belief"]), m


pomdp_py = pytest.importorskip("pomdp_py")


def _random_flat(rng, n_s=2, n_a=2, n_o=2, discount=0.3):
    trans = rng.dirichlet(np.ones(n_s), size=(n_a, n_s))
    obs = rng.dirichlet(np.ones(n_o), size=(n_a, n_s))
    rew = rng.uniform(-1, 1, size=(n_a, n_s, n_s, n_o))
    states, actions, observations = (tuple(f"{p}{i}" for i in range(n)) for p, n in (("s", n_s), ("a", n_a), ("o", n_o)))
    return FlatPOMDP(states, actions, observations, trans, obs, rew, discount, rng.dirichlet(np.ones(n_s)))


@pytest.mark.parametrize("seed", [1, 2])
def test_flat_bounds_bracket_pomdp_py_exact_recursion(seed):
    """pomdp-py's own belief-tree recursion (independent code) at horizon 6, within the tail."""
    from pomdp_oracles import pomdp_py_value

    flat = _random_flat(np.random.default_rng(seed))
    horizon = 6
    theirs = pomdp_py_value(flat, flat.start, horizon)
    tail = flat.discount**horizon * float(np.abs(flat.expected_reward).max()) / (1 - flat.discount)
    sol = ReachableSolver(tol=1e-5, max_seconds=20).solve_bounds(flat)
    assert sol.gap <= 1e-5
    assert theirs - tail <= sol.upper + 1e-9 and sol.lower <= theirs + tail + 1e-9
    policy = ReachableSolver(tol=1e-5, max_seconds=20).solve(flat)
    assert policy.kind == "flat-alpha-vector"


def test_refuses_the_eq3_update_and_names_alternatives(pomdp):
    reasons = ReachableSolver(belief_update="paper").unsupported(pomdp)
    assert reasons and "alpha" in reasons[0] and "grid" in reasons[0]


def test_a_consolidation_cut_by_the_clock_keeps_both_bounds(pomdp):
    """Past its deadline a consolidation stops after one round (lower) or one evaluation (upper);
    its vectors are still controllers' values and its points, raised by the Bellman residual,
    still lie above the value: checked against the alpha solver's value at every belief."""
    exact = make_solver("alpha", gap=1e-6).solve(pomdp)
    solver = ReachableSolver(tol=1e-3)
    solver._setup(pomdp.branch_model())
    B = reachable_beliefs(np.asarray(pomdp.model.initial, dtype=float), 3, solver._successors_many, solver.decimals)
    value = np.array([(exact.value_vectors @ b).max() for b in B])
    up_before, lo_before = solver.upper_at(B), solver.lower_at(B)
    solver._improve_upper(B, t_end=0.0)
    solver._improve_lower(B, t_end=0.0)
    up, lo = solver.upper_at(B), solver.lower_at(B)
    assert np.all(up >= value - 2e-6) and np.all(lo <= value + 2e-6)
    assert np.all(up <= up_before + 1e-12) and np.all(lo >= lo_before - 1e-12)
    # two supervisor types, where the first consolidation moves both bounds: they stay within
    # the point solver's certified bounds at every belief
    problem = type_aware_problem(paper_conservative_mixture(), paper_task())
    point = make_solver("point", gap=1e-3, max_seconds=60)
    point.solve_bounds(problem)
    solver = ReachableSolver(tol=1e-3)
    solver._setup(problem.branch_model())
    B = reachable_beliefs(np.asarray(problem.model.initial, dtype=float), 2, solver._successors_many, solver.decimals)
    up_before, lo_before = solver.upper_at(B), solver.lower_at(B)
    solver._improve_upper(B, t_end=0.0)
    solver._improve_lower(B, t_end=0.0)
    up, lo = solver.upper_at(B), solver.lower_at(B)
    assert np.all(up >= point.lower_at(B) - 1e-9) and np.all(lo <= point.upper_at(B) + 1e-9)
    assert np.any(up < up_before - 1e-6) and np.any(lo > lo_before + 1e-6)  # one step did something
