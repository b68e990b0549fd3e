"""The quasi-Newton finish of an EM run: L-BFGS-B on the free cells, gradient by Fisher's identity.

EM crawls along flat ridges of the likelihood (weakly identified directions) with
tiny steps, and a relative-change test then stops it short of the maximum; a
quasi-Newton method walks such ridges.  The free cells are written as
stick-breaking fractions in [0, 1] (a box, so cells can sit on the boundary
exactly), and the gradient comes free with the E-step's expected counts.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..solvers.base import one_blas_thread
from .em import CAPPED, RunResult
from .estep import EStepper
from .spec import Params
from .sticks import Sticks
from .structure import Structure

MEMORY = 20  # L-BFGS-B correction pairs
RECENT = 32  # evaluations remembered to recover the parameters of an accepted iterate


class _Budget(Exception):
    """The finish ran out of E-steps."""


@dataclass
class _Best:
    """The best point L-BFGS-B has accepted so far, and the recent evaluations to find it among."""

    objective: float
    params: Params
    loglik: float
    history: list[float]
    seen: dict[bytes, tuple[float, Params, float]] = field(default_factory=dict)

    def remember(self, theta: np.ndarray, f: float, p: Params, ll: float) -> None:
        if len(self.seen) > RECENT:
            self.seen.pop(next(iter(self.seen)))
        self.seen[np.asarray(theta, dtype=float).tobytes()] = (f, p, ll)

    def accept(self, theta: np.ndarray) -> None:
        hit = self.seen.get(np.asarray(theta, dtype=float).tobytes())
        if hit is not None and hit[0] >= self.objective:
            if hit[0] > self.objective:
                self.history.append(float(hit[0]))
            self.objective, self.params, self.loglik = hit


def optimizer() -> Any:
    """scipy's ``minimize``, imported on first use (0.5 s of CPU; the compiled run never needs it).
    Import it on the thread that limits BLAS to one thread (:func:`~trustseek.solvers.base.one_blas_thread`)
    before others run the finish: a limit set on another thread misses the BLAS scipy loads."""
    from scipy.optimize import minimize

    return minimize


def finish(
    structure: Structure, work: EStepper, run: RunResult, tol: float = 1e-8, max_iter: int = 1000, sticks: Sticks | None = None
) -> RunResult:
    """Continue a run with L-BFGS-B on the stick-breaking fractions of the free cells.

    Every iterate of L-BFGS-B decreases the negated objective, and the result is kept
    only if its objective is at least the run's, so the objective history never
    decreases.  It stops when the relative change per iteration falls below ``tol``,
    which on a badly scaled stretch of the likelihood can happen short of a stationary
    point (:mod:`.convergence` checks and goes on); iterations count E-steps, within
    ``max_iter`` in total.  ``sticks``: the free cells' layout, when not the structure's own
    (a mixture's tables).
    """
    t0 = time.perf_counter()
    budget = max_iter - run.iterations
    sticks = Sticks(structure) if sticks is None else sticks
    if budget < 2 or sticks.size == 0 or not math.isfinite(run.objective):
        return run
    base = run.params
    best = _Best(run.objective, run.params, run.loglik, list(run.history))
    calls = 0

    def fun(theta: np.ndarray) -> tuple[float, np.ndarray]:
        nonlocal calls
        if calls >= budget:
            raise _Budget
        calls += 1
        p = sticks.params(theta, base)
        st = work.estep(p)
        f = float(st.loglik + structure.log_prior(p))
        best.remember(theta, f, p, float(st.loglik))
        if not math.isfinite(f):
            return math.inf, np.zeros_like(theta)
        return -f, -sticks.gradient(theta, st)

    minimize = optimizer()
    try:
        with one_blas_thread():
            res = minimize(
                fun,
                sticks.theta(base),
                jac=True,
                method="L-BFGS-B",
                bounds=[(sticks.EPS, 1 - sticks.EPS)] * sticks.size,
                callback=best.accept,
                options={"ftol": tol, "gtol": 0.0, "maxfun": budget, "maxiter": budget, "maxcor": MEMORY},
            )
        best.accept(res.x)
        success = calls < budget  # stopped by its tolerance (or at the limits of precision), not by the cap
    except _Budget:  # the E-step cap: keep the best accepted point
        success = False
    converged = run.converged and success
    return RunResult(
        best.params,
        best.loglik,
        best.objective,
        best.history,
        run.iterations + calls,
        converged,
        run.seconds + time.perf_counter() - t0,
        run.ended if converged else CAPPED,
        run.finishes + 1,
    )
