"""Compile the design study's and the simulation's numba kernels into numba's on-disk cache, once.

``python -m trustseek.design.warm`` runs :func:`trustseek.simulation.warm.warm` (every compiled
path of the simulation engine) and the signed-rank kernel of :mod:`.kernels`, so that later
processes, test workers among them, load them from the cache.  ``make test`` runs it next to the
static checks, after the fit's :mod:`trustseek.estimation.warm`.
"""

from __future__ import annotations

import time

import numpy as np

from ..simulation.warm import warm as warm_simulation
from .replicate import signed_rank_p


def warm() -> float:
    """Run every compiled path once; the seconds it took."""
    t = time.perf_counter()
    warm_simulation()
    signed_rank_p(np.array([1.0, -2.0, 2.0, 3.5]))
    return time.perf_counter() - t


if __name__ == "__main__":
    import sys

    sys.stdout.write(f"compiled the simulation's and the design study's kernels in {warm():.1f} s\n")
