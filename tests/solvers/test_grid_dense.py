"""The grid solver's dense policy iteration (small grids) against its sparse path."""

import numpy as np
import pytest

from trustseek import paper_model, paper_task
from trustseek.estimation.options import FitOptions
from trustseek.model.presets import conservative_model
from trustseek.pomdp.problem import AssistancePOMDP
from trustseek.solvers.grid import GridSolver, _dense_howard, dense_policy_iteration, dense_transitions


@pytest.mark.parametrize("update", ["paper", "bayes"])
@pytest.mark.parametrize("grid", [3, 17, 201])
def test_dense_transitions_are_the_grid_solvers(update, grid):
    pomdp = AssistancePOMDP(paper_model(), paper_task())
    solver = GridSolver(grid=grid, belief_update=update)
    points, _, P, _, _ = solver.operators(pomdp)
    dense = dense_transitions(pomdp, update, np.stack([1.0 - points, points], axis=1))
    assert dense.shape == (2, 2, grid, grid)
    for c in range(2):
        for a in range(2):
            np.testing.assert_allclose(dense[c, a], P[c][a].toarray(), rtol=0, atol=1e-15)
    np.testing.assert_allclose(dense.sum(axis=3), 1.0, rtol=0, atol=1e-12)


@pytest.mark.parametrize("update", ["paper", "bayes"])
def test_small_grids_are_solved_dense_with_the_sparse_paths_policy(update):
    task = paper_task()
    for model in (paper_model(), conservative_model()):  # the paper's supervisor and Remark 1's
        pomdp = AssistancePOMDP(model, task)
        dense = GridSolver(grid=201, belief_update=update).solve(pomdp)
        sparse = GridSolver(grid=201, belief_update=update, dense_max=0).solve(pomdp)
        assert dense.info["method"] == "policy-iteration (dense)"
        assert sparse.info["method"] == "policy-iteration"
        assert dense.thresholds() == pytest.approx(sparse.thresholds(), abs=1e-9)
        np.testing.assert_allclose(dense.q, sparse.q, atol=1e-7)
        assert dense.info["bellman_residual"] < 1e-9


@pytest.mark.parametrize("update", ["paper", "bayes"])
def test_the_coarse_start_ends_where_the_greedy_start_does(update):
    from trustseek.estimation.fit import fit_trust_model
    from trustseek.policies import randomized
    from trustseek.simulation import simulate

    task = paper_task()
    models = [paper_model()]
    for seed in range(3):  # fitted models, as a design replicate plans with
        frame = simulate(paper_model(), task, randomized({"low": 0.2, "high": 0.5}), 6, counts=(20, 15), seed=seed).trials()
        models.append(fit_trust_model(frame, options=FitOptions(restarts=1, seed=seed, n_jobs=1)).model)
    for model in models:
        pomdp = AssistancePOMDP(model, task)
        _, q_coarse, _, _ = dense_policy_iteration(pomdp, update, 101)
        _, q_greedy, _, _ = _dense_howard(pomdp, update, 101, None)
        np.testing.assert_array_equal(q_coarse, q_greedy)
