"""Compile the simulation's numba kernels (:mod:`.kernels`) into numba's on-disk cache, once.

``python -m trustseek.simulation.warm`` runs every compiled path once on a few made-up
participants (the urn schedule, a threshold policy with each belief update, a complexity
policy with and without a belief, recorded or not), so that later processes, test workers
among them, load the kernels from the cache.  ``make test`` runs it (through
:mod:`trustseek.design.warm`) next to the static checks.
"""

from __future__ import annotations

import time

import numpy as np

from ..compiled import load
from ..model.presets import paper_model, paper_task
from ..policies import ComplexityPolicy, TrustAwarePolicy
from .designs import crossover
from .engine import simulate


def warm() -> float:
    """Run every compiled path once; the seconds it took."""
    t = time.perf_counter()
    load()  # the kernels run once numba is loaded
    model, task = paper_model(), paper_task()
    grid = np.linspace(0.0, 1.0, 11)
    q = np.zeros((len(grid), 2, 2))
    q[:, 1, 1] = 0.5 - grid  # asks below 0.5 in high complexity
    randomized = ComplexityPolicy("randomized", task.complexities, [0.1, 0.4])
    for update in ("paper", "bayes"):
        aware = TrustAwarePolicy(grid, q, model, task.complexities, update)
        for record in (True, False):
            crossover(model, task, [aware, randomized], 2, counts=(2, 2), record=record, belief_model=model)
            simulate(model, task, randomized, 2, counts=(2, 2), record=record)
    return time.perf_counter() - t


if __name__ == "__main__":
    import sys

    sys.stdout.write(f"compiled the simulation's kernels in {warm():.1f} s\n")
