"""The belief-MDP solver: value iteration against brute force, convergence, thresholds."""

import functools

import numpy as np
import pytest

from trustseek import AssistancePOMDP, GridSolver, solve


def test_paper_thresholds_both_updates(model, task):
    for update in ("paper", "bayes"):
        pol = solve(model, task, belief_update=update)
        th = pol.thresholds()
        assert th["low"] is None, update  # never asks in low complexity
        assert 0.72 <= th["high"] <= 0.80, (update, th)
        assert pol.ask_intervals()["high"][0][0] == 0.0


def test_reference_values_bayes(model, task):
    pol = solve(model, task, belief_update="bayes", grid=4001)
    v1 = pol.q_values(1.0).max(axis=-1)
    # reference values computed independently (belief grid, SARSOP, pomdp-solve)
    assert v1 == pytest.approx([111.061, 110.249], abs=2e-3)
    assert float(v1 @ task.complexity_probs) == pytest.approx(110.655, abs=2e-3)
    assert pol.thresholds()["high"] == pytest.approx(0.7815, abs=5e-4)


def test_threshold_stable_in_grid(pomdp):
    ths = [GridSolver(grid=g).solve(pomdp).thresholds()["high"] for g in (501, 2001, 8001)]
    assert max(ths) - min(ths) < 0.005
    assert abs(ths[1] - ths[2]) < 1e-4


def test_policy_iteration_equals_value_iteration(pomdp):
    for update in ("bayes", "paper"):
        a = GridSolver(grid=201, belief_update=update, method="policy-iteration").solve_grid(pomdp)
        b = GridSolver(grid=201, belief_update=update, method="value-iteration", tol=1e-10).solve_grid(pomdp)
        np.testing.assert_allclose(a.q, b.q, atol=1e-8)
        assert b.error_bound < 1e-8


def test_value_iteration_converges_monotonically(pomdp):
    _, _, _, _, bellman = GridSolver(grid=101).operators(pomdp)
    gamma = pomdp.discount
    W = np.zeros(101)
    prev_delta = None
    for _ in range(300):
        W_new = bellman(W)
        # from W = 0 the Bellman operator is monotone and T(0) >= 0, so iterates never decrease
        assert np.all(W_new >= W - 1e-12)
        delta = np.max(np.abs(W_new - W))
        if prev_delta is not None:
            assert delta <= gamma * prev_delta + 1e-12  # contraction
        prev_delta, W = delta, W_new


def _backup_at(pomdp, update, bh, W):
    """One Bellman backup at P(trust = high) = bh by explicit loops over complexities, actions and
    branches: Σ_C P(C) max_a [r + γ Σ_branch w W(x')], with W a function of x' (skipped for
    branches that cannot happen)."""
    b = np.array([[1 - bh, bh]])
    total = 0.0
    for c in range(pomdp.n_complexity):
        best = -np.inf
        for a in range(2):
            q = float(b[0] @ pomdp.expected_reward[c, a])
            p, nxt = pomdp.branches(update).successors(b, c, a)
            for w, nb in zip(p[0], nxt[0], strict=True):
                if w > 0:
                    q += pomdp.discount * w * W(float(nb[1]))
            best = max(best, q)
        total += pomdp.complexity_probs[c] * best
    return total


def _brute_force_on_grid(pomdp, update, grid, horizon):
    """H-step value on the grid by explicit loops over grid points, complexities, actions and
    branches, interpolating with numpy.interp (independent of the solver's sparse matrices)."""
    W = np.zeros(len(grid))
    for _ in range(horizon):
        W = np.array([_backup_at(pomdp, update, x, lambda z, W=W: np.interp(z, grid, W)) for x in grid])
    return W


@pytest.mark.parametrize("update", ["bayes", "paper"])
def test_value_iteration_matches_brute_force_expansion(pomdp, update):
    grid = np.linspace(0, 1, 11)
    horizon = 6
    _, _, _, _, bellman = GridSolver(grid=11, belief_update=update).operators(pomdp)
    W = np.zeros(11)
    for _ in range(horizon):
        W = bellman(W)
    np.testing.assert_allclose(W, _brute_force_on_grid(pomdp, update, grid, horizon), atol=1e-10)


def _exact_finite_horizon(pomdp, update, b_high, horizon):
    """Exact H-step value by expanding the belief tree (no grid)."""

    @functools.cache
    def V(bh, h):
        if h == 0:
            return 0.0
        return _backup_at(pomdp, update, bh, lambda z: V(round(z, 14), h - 1))

    return V(round(float(b_high), 14), horizon)


@pytest.mark.parametrize("update", ["bayes", "paper"])
def test_fine_grid_approaches_exact_tree(pomdp, update):
    horizon = 5
    G = 4001
    _, _, _, _, bellman = GridSolver(grid=G, belief_update=update).operators(pomdp)
    W = np.zeros(G)
    for _ in range(horizon):
        W = bellman(W)
    grid = np.linspace(0, 1, G)
    for bh in (0.0, 0.3, 0.75, 0.9, 1.0):
        exact = _exact_finite_horizon(pomdp, update, bh, horizon)
        assert np.interp(bh, grid, W) == pytest.approx(exact, abs=2e-3)


def test_grid_solver_rejects_three_levels(task):
    from trustseek import trust_model

    K = 3
    m = trust_model(
        ("low", "mid", "high"),
        ("low", "high"),
        np.ones(K) / K,
        np.full((2, 2, K, 2), 0.5),
        np.tile(np.eye(K), (2, 2, 2, 1, 1)),
    )
    with pytest.raises(ValueError, match="two trust levels"):
        GridSolver().solve(AssistancePOMDP(m, task))
