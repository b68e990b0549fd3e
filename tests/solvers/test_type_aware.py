"""The types solver: the type-revealed upper bound, the type-seeded lower bound, and bounds that
agree with the point and alpha solvers and with the exact value of the returned policy."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pomdp_oracles import TIGER
from trustseek.interop.files import read_pomdp
from trustseek.model import TypeMixture, paper_conservative_mixture, paper_model, paper_task
from trustseek.model.core import TrustModel, trust_model
from trustseek.pomdp import AssistancePOMDP
from trustseek.pomdp.supervisor_types import type_aware_problem
from trustseek.solvers import make_solver
from trustseek.solvers.point import PointSolver
from trustseek.solvers.type_aware import TypeAwareSolver, solve_type_aware, type_bound
from trustseek.solvers.upper_bounds import closed_blocks


def _overlap(a, b, slack=1e-9):
    return a[0] <= b[1] + slack and b[0] <= a[1] + slack


def _discounted(task, discount):
    return dataclasses.replace(task, discount=discount)


def _random_type(rng: np.random.Generator) -> TrustModel:
    """A two-level supervisor with random emissions when the robot acts and random trust moves;
    when asked, the supervisor always intervenes (as in the paper's model)."""
    p = paper_model()
    emission = p.emission.copy()
    emission[:, 0] = rng.dirichlet(np.ones(2), size=(2, 2))
    transition = rng.dirichlet(np.full(2, 0.7), size=p.transition.shape[:-1])
    return trust_model(p.trust_levels, p.complexities, rng.dirichlet(np.ones(2)), emission, transition)


def _point(problem, resolution=16):
    """The point solver's bounds at b0 and its lower-bound vectors (each the exact value of a
    controller: an independent certified lower bound everywhere)."""
    solver = PointSolver(tol=1e-9, resolution=resolution, max_resolution=resolution)
    return solver.solve_bounds(problem), solver.vectors


@settings(max_examples=5, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), discount=st.sampled_from([0.3, 0.9]))
def test_the_upper_bounds_are_above_an_independent_lower_bound_everywhere(seed, discount):
    rng = np.random.default_rng(seed)
    mixture = TypeMixture(("a", "b"), rng.dirichlet(np.ones(2)), (_random_type(rng), _random_type(rng)))
    problem = type_aware_problem(mixture, _discounted(paper_task(), discount))
    bm = problem.branch_model()
    bound = type_bound(problem, bm)
    assert len(bound.lo) > 0 and len(closed_blocks(bm)) == 2
    B = np.vstack([rng.dirichlet(np.full(4, 0.5), size=200), np.eye(4), bm.initial])
    point, G = _point(problem)
    lower = (B @ G.T).max(axis=1)
    assert np.all(bound(B) >= lower - 1e-9)
    solver = TypeAwareSolver(tol=1e-9, resolution=8, max_resolution=8)
    sol = solver.solve_bounds(problem)
    assert np.all(solver.upper_at(B) >= lower - 1e-9)
    # the bound looked ahead from a belief (what the solver reports at b0) too
    for k in (-1, 0, 1, 2):
        assert solver.lookahead_upper(B[k], max_nodes=300) >= lower[k] - 1e-9
    # and the solver's own lower bound is below the point solver's upper bound
    assert sol.lower <= point.upper + 1e-9 and point.lower <= sol.upper + 1e-9


def test_a_known_type_has_that_types_value():
    task = paper_task()
    alpha = make_solver("alpha", gap=1e-6).solve(AssistancePOMDP(paper_model(), task)).info["value_bounds_at_initial_belief"]
    problem = type_aware_problem(paper_conservative_mixture().with_weights([1.0, 0.0]), task)
    bm = problem.branch_model()
    bound = type_bound(problem, bm)
    assert bound(bm.initial)[0] == pytest.approx(alpha[1], abs=1e-5)
    policy = solve_type_aware(
        paper_conservative_mixture(), task, solver="types", gap=1e-3, type_belief=[1.0, 0.0], max_seconds=30
    )
    lo, up = policy.info["value_bounds_at_initial_belief"]
    assert up - lo <= 1e-3
    assert _overlap((lo, up), alpha)
    # the type's own controller, evaluated on the product, is the lower bound: tight from the start
    assert lo == pytest.approx(alpha[0], abs=1e-4)


def test_loose_bounds_on_the_paper_conservative_mixture_agree_with_the_point_solver():
    problem = type_aware_problem(paper_conservative_mixture(), paper_task())
    types = make_solver("types", gap=0.2, max_resolution=8).solve(problem)
    point = make_solver("point", gap=0.2, max_resolution=8).solve(problem)
    lo, up = types.info["value_bounds_at_initial_belief"]
    assert lo <= up <= lo + 0.2
    assert _overlap((lo, up), point.info["value_bounds_at_initial_belief"])
    assert types.info["solver"] == "types" and types.info["type_blocks"] == 2
    # the base bound alone (type revealed, before any grid) is above the point solver's upper bound
    # at most by the value of knowing the type, never below its lower bound
    bm = problem.branch_model()
    base = float(type_bound(problem, bm)(bm.initial)[0])
    assert point.info["value_bounds_at_initial_belief"][0] <= base


def _policy_value(policy, bm, horizon):
    """The exact value of ``horizon`` trials of ``policy`` from b0 (every context and branch)."""
    B = bm.initial[None].copy()
    w = np.ones(1)
    total = 0.0
    for t in range(horizon):
        out_b, out_w = [], []
        for c, pc in enumerate(bm.context_probs):
            acts = policy.actions(B, np.full(len(B), c))
            total += bm.discount**t * pc * float(np.sum(w * np.einsum("nt,nt->n", B, bm.rewards[c, acts])))
            nb = np.einsum("nt,nbtu->nbu", B, bm.kernels[c, acts])  # (n, branch, next)
            p = nb.sum(axis=2)
            ok = p > 1e-15
            out_b.append(nb[ok] / p[ok][:, None])
            out_w.append((w[:, None] * pc * p)[ok])
        B, w = np.vstack(out_b), np.concatenate(out_w)
    return total


def test_the_returned_policy_is_worth_at_least_the_lower_bound():
    """γ = 0.3: six trials give the value of the policy within γ^6 max|r| / (1 - γ) = 3e-3."""
    gamma, horizon = 0.3, 6
    problem = type_aware_problem(paper_conservative_mixture(), _discounted(paper_task(), gamma))
    policy = make_solver("types", gap=1e-3, max_resolution=16).solve(problem)
    lo, up = policy.info["value_bounds_at_initial_belief"]
    assert up - lo <= 1e-3
    bm = problem.branch_model()
    tail = gamma**horizon * float(np.abs(bm.rewards).max()) / (1 - gamma)
    value = _policy_value(policy, bm, horizon)
    assert lo <= value + tail + 1e-9
    assert value - tail <= up + 1e-9
    exact = bm.finite_horizon_value(bm.initial, 3)
    assert exact - gamma**3 * float(np.abs(bm.rewards).max()) / (1 - gamma) <= up + 1e-9


def test_a_problem_without_types_falls_back_to_the_fast_informed_bound(pomdp):
    bm = pomdp.branch_model()
    bound = type_bound(pomdp, bm)
    assert len(bound.lo) == 0
    policy = make_solver("types", gap=1e-3).solve(pomdp)
    lo, up = policy.info["value_bounds_at_initial_belief"]
    alpha = make_solver("alpha", gap=1e-6).solve(pomdp).info["value_bounds_at_initial_belief"]
    assert up - lo <= 1e-3 and _overlap((lo, up), alpha)
    assert policy.info["type_blocks"] == 0


def test_a_flat_pomdp_is_solved_with_a_bounded_look_ahead():
    """Tiger's beliefs, merged, grow by two a trial: the look-ahead stops at its depth limit."""
    policy = make_solver("types", gap=1e-4).solve(read_pomdp("tiger.pomdp", TIGER))
    lo, up = policy.info["value_bounds_at_initial_belief"]
    assert up - lo <= 1e-4 and lo - 1e-6 <= 19.371368 <= up + 1e-6
    assert policy.info["type_blocks"] == 0
