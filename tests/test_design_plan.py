"""The replicate's dense planning matrices against the grid solver's sparse ones."""

import numpy as np
import pytest

from trustseek import paper_model, paper_task
from trustseek.design.replicate import _dense_transitions
from trustseek.pomdp.problem import AssistancePOMDP
from trustseek.solvers.grid import GridSolver


@pytest.mark.parametrize("update", ["paper", "bayes"])
@pytest.mark.parametrize("grid", [3, 17, 201])
def test_dense_transitions_are_the_grid_solvers(update, grid):
    pomdp = AssistancePOMDP(paper_model(), paper_task())
    solver = GridSolver(grid=grid, belief_update=update)
    points, _, P = solver.build(pomdp)
    dense = _dense_transitions(pomdp, update, np.stack([1.0 - points, points], axis=1))
    assert dense.shape == (2, 2, grid, grid)
    for c in range(2):
        for a in range(2):
            np.testing.assert_allclose(dense[c, a], P[c][a].toarray(), rtol=0, atol=1e-15)
    np.testing.assert_allclose(dense.sum(axis=3), 1.0, rtol=0, atol=1e-12)


@pytest.mark.parametrize("update", ["paper", "bayes"])
def test_the_coarse_start_ends_where_the_greedy_start_does(update):
    from trustseek.design.replicate import FitSettings, _policy_iteration, plan
    from trustseek.estimation.fit import fit_trust_model
    from trustseek.policies import randomized
    from trustseek.simulation import simulate

    task = paper_task()
    models = [paper_model()]
    for seed in range(3):  # fitted models, as a replicate plans with
        frame = simulate(paper_model(), task, randomized({"low": 0.2, "high": 0.5}), 6, counts=(20, 15), seed=seed).trials()
        models.append(fit_trust_model(frame, restarts=1, seed=seed, n_jobs=1).model)
    for model in models:
        policy = plan(model, task, FitSettings(belief_update=update, grid=101))
        _, q = _policy_iteration(AssistancePOMDP(model, task), update, 101, None)
        np.testing.assert_array_equal(policy.q, np.moveaxis(q, 2, 0))
