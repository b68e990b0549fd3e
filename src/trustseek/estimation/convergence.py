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

:func:`converge_runs` carries several runs so, each on a thread of its own, their E-steps
pooled into one batched E-step (:class:`_Pool`): a run's finish is a sequence of single
E-steps with Python in between, and on small data one E-step of ten parameter sets costs
little more than one of a single set.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numpy as np

from ..solvers.base import one_blas_thread
from .em import CAPPED, STATIONARY, RunResult, run_em
from .estep import EStep, EStepper, Workspace
from .options import RunSettings
from .quasi_newton import finish, optimizer
from .spec import Params
from .sticks import Sticks
from .structure import Structure

FINISH_FTOL = 0.01  # the finish stops at this fraction of the fit's relative tolerance
CHECK_STEPS = 2  # E-steps of the check: counts at the end point, then the objective one EM step on
POOLED = 32  # runs at most whose E-steps are pooled (a thread each)


def em_step(structure: Structure, work: EStepper, p: Params) -> tuple[float, Params, float]:
    """The objective at ``p``, the point one EM step on, and the objective there."""
    st = work.estep(p)
    f = float(st.loglik + structure.log_prior(p))
    q = structure.mstep(st, p)
    return f, q, float(work.loglik(q) + structure.log_prior(q))


def stationary(f: float, fq: float, tol: float) -> bool:
    """Whether one EM step from a point with objective ``f`` gaining ``fq - f`` stays within ``tol`` (relative)."""
    return not fq - f > tol * abs(f)


def converge(
    structure: Structure, work: EStepper, run: RunResult, settings: RunSettings, sticks: Sticks | None = None
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


def converge_runs(
    structure: Structure, work: Workspace, runs: Sequence[RunResult], settings: RunSettings, sticks: Sticks | None = None
) -> Iterator[RunResult]:
    """:func:`converge` of each of ``runs``, in order.  Where the workspace runs parameter sets
    side by side (:meth:`~.estep.Workspace.lockstep`), the runs go on threads of their own, in
    groups of that many (at most :data:`POOLED`), and their E-steps are pooled: the numbers are
    those of each run alone (a parameter set of a batch gets the numbers it gets alone)."""
    group = min(work.lockstep(len(runs)), POOLED)
    if group < 2 or len(runs) < 2:
        for r in runs:
            yield converge(structure, work, r, settings, sticks)
        return
    if settings.quasi_newton:
        optimizer()  # loaded here, so that the limit below covers its BLAS on every thread
    for g in range(0, len(runs), group):
        part = runs[g : g + group]
        pool = _Pool(work, len(part))

        def one(r: RunResult, pool: _Pool = pool) -> RunResult:
            try:
                return converge(structure, pool, r, settings, sticks)
            finally:
                pool.leave()

        with one_blas_thread(), ThreadPoolExecutor(len(part), thread_name_prefix="trustseek-fit") as threads:
            try:
                yield from threads.map(one, part)
            except BaseException:
                pool.cancel()  # the other runs stop at their next E-step
                raise


class _Cancelled(Exception):
    """Another run of the pool failed, or the fit was interrupted."""


class _Pool:
    """The E-steps of ``live`` runs, each on a thread of its own, computed together: a call waits
    until every run still going has asked, and the last to ask computes one batched E-step
    for all (the workspace's :meth:`~.estep.Workspace.estep`; :meth:`loglik` asks the same)."""

    def __init__(self, work: Workspace, live: int):
        self.work, self.live = work, live
        self.ready = threading.Condition()
        self.asked: dict[int, tuple[Params, np.ndarray | None]] = {}
        self.answers: dict[int, EStep | BaseException] = {}
        self.tickets = 0
        self.cancelled = False

    def estep(self, p: Params, active: np.ndarray | None = None, posteriors: bool = False) -> EStep:
        if posteriors:
            raise ValueError("a pooled E-step gives no posteriors")
        q = self.work.as_own(p)
        batch = q if q.batched else q.as_batch()
        with self.ready:
            ticket, self.tickets = self.tickets, self.tickets + 1
            self.asked[ticket] = (batch, active)
            self._serve()
            while ticket not in self.answers:
                self.ready.wait()
            answer = self.answers.pop(ticket)
        if isinstance(answer, BaseException):
            raise answer
        return answer if q.batched else answer.take(0)

    def loglik(self, p: Params) -> np.ndarray:
        return self.estep(p).loglik

    def leave(self) -> None:
        """A run has ended: the others no longer wait for it."""
        with self.ready:
            self.live -= 1
            self._serve()

    def cancel(self) -> None:
        with self.ready:
            self.cancelled = True
            self._serve()

    def _serve(self) -> None:
        """With every live run asking (or the pool cancelled), answer them all (the lock held)."""
        if not self.asked or (len(self.asked) < self.live and not self.cancelled):
            return
        asked, self.asked = self.asked, {}
        try:
            if self.cancelled:
                raise _Cancelled()
            batches = [b for b, _ in asked.values()]
            joined = type(batches[0])(
                *(np.concatenate([getattr(b, a) for b in batches]) for a in ("initial", "emission", "transition"))
            )
            masks = [np.ones(len(b.initial), dtype=bool) if a is None else a for b, a in asked.values()]
            st = self.work.estep(joined, np.concatenate(masks))
            ends = np.cumsum([len(b.initial) for b in batches])
            for ticket, end, b in zip(asked, ends, batches, strict=True):
                self.answers[ticket] = st.take(slice(end - len(b.initial), end))
        except BaseException as e:  # every run asking gets it
            for ticket in asked:
                self.answers[ticket] = e
        self.ready.notify_all()
