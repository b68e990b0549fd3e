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
