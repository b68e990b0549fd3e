"""What a converged run is: a stationary point, where one more EM step gains at most the tolerance.

EM stops when a step gains less than a relative tolerance, and the quasi-Newton finish
when an iteration does; neither test alone proves the end point stationary.  The
finish in particular can stop after an iteration that made little progress on a
badly scaled stretch of the likelihood (cells near 0 or 1 in the stick-breaking
fractions) while the gradient elsewhere is far from zero, and would report a point
that EM climbs on from.  :func:`converge` therefore checks every end point with one
EM step (the EM map moves exactly when the point is not stationary, including cells
on the boundary) and, where that step gains more than ``tol``, continues from it:
EM, then the finish again, until the check passes or the E-step cap is reached.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

from .em import CAPPED, STATIONARY, RunResult, run_em
from .estep import Workspace
from .options import RunSettings
from .quasi_newton import finish
from .spec import Params
from .sticks import Sticks
from .structure import Structure

FINISH_FTOL = 0.01  # the finish stops at this fraction of the fit's relative tolerance
CHECK_STEPS = 2  # E-steps of the check: counts at the end point, then the objective one EM step on


def em_step(structure: Structure, work: Workspace, p: Params) -> tuple[float, Params, float]:
    """The objective at ``p``, the point one EM step on, and the objective there."""
    st = work.estep(p)
    f = float(st.loglik + structure.log_prior(p))
    q = structure.mstep(st, p)
    return f, q, float(work.loglik(q) + structure.log_prior(q))


def stationary(f: float, fq: float, tol: float) -> bool:
    """Whether one EM step from a point with objective ``f`` gaining ``fq - f`` stays within ``tol`` (relative)."""
    return not fq - f > tol * abs(f)


def converge(
    structure: Structure, work: Workspace, run: RunResult, settings: RunSettings, sticks: Sticks | None = None
) -> RunResult:
    """Carry ``run`` (an EM run to ``settings.em_tol``) to a stationary point or to ``settings.max_iter`` E-steps.

    Each round is the quasi-Newton finish (to :data:`FINISH_FTOL` of ``tol``; skipped without
    ``quasi_newton``), then the check: when one EM step from the end point gains more
    than ``tol`` (relative), EM goes on from that step's point to ``em_tol`` and the
    next round begins.  ``ended`` is :data:`~.em.STATIONARY` (``converged``) or
    :data:`~.em.CAPPED`; the objective history never decreases.  ``sticks`` is passed to the finish.
    """
    tol, max_iter, em_tol = settings.tol, settings.max_iter, settings.em_tol
    finish_tol = tol * FINISH_FTOL
    t0 = time.perf_counter()
    seconds = run.seconds
    while True:
        if settings.quasi_newton:
            run = finish(structure, work, run, tol=finish_tol, max_iter=max_iter, sticks=sticks)
        if run.iterations + CHECK_STEPS > max_iter or not math.isfinite(run.objective):
            return _ended(run, CAPPED, seconds, t0)
        f, q, fq = em_step(structure, work, run.params)
        if stationary(f, fq, tol):
            return _ended(replace(run, iterations=run.iterations + CHECK_STEPS), STATIONARY, seconds, t0)
        (more,) = run_em(
            structure, work, [q], tol=em_tol, max_iter=max_iter - run.iterations - CHECK_STEPS, accelerate=settings.accelerate
        )
        run = replace(
            more,
            history=run.history + more.history,
            iterations=run.iterations + CHECK_STEPS + more.iterations,
            seconds=run.seconds,
            finishes=run.finishes,
        )
        if not more.converged:
            return _ended(run, CAPPED, seconds, t0)


def _ended(run: RunResult, ended: str, seconds: float, t0: float) -> RunResult:
    """``run`` marked as ended, with the time of the EM phase plus that spent here."""
    return replace(run, converged=ended == STATIONARY, seconds=seconds + time.perf_counter() - t0, ended=ended)
