"""Compile the design study's numba kernels (those of the simulation) into numba's on-disk cache, once.

``python -m trustseek.design.warm`` runs :func:`trustseek.simulation.warm.warm` (every compiled
path of the simulation engine), so that later
processes, test workers among them, load them from the cache.  ``make test`` runs it next to the
static checks, after the fit's :mod:`trustseek.estimation.warm`.
"""

from __future__ import annotations

import time

from ..simulation.warm import warm as warm_simulation


def warm() -> float:
    """Run every compiled path once; the seconds it took."""
    t = time.perf_counter()
    warm_simulation()
    return time.perf_counter() - t


if __name__ == "__main__":
    import sys

    sys.stdout.write(f"compiled the simulation's kernels in {warm():.1f} s\n")
