"""The EM driver: R starts at once with SQUAREM, the quasi-Newton finish, and the stationarity check.

:func:`run_em` runs the starts in lockstep, each taking exactly the decisions it would take
alone; a start that has stopped is frozen while the others go on.  :func:`finish` continues a
run with L-BFGS-B on the free cells' stick-breaking fractions (:mod:`.sticks`; gradient by
Fisher's identity): EM crawls along flat ridges of the likelihood, a quasi-Newton method walks
them.  Neither stopping test proves the end point stationary, so :func:`converge` checks it with
one EM step (which moves exactly when the point is not stationary) and, where that step gains
more than ``tol``, goes on: EM, then the finish again.  :func:`converge_runs` runs several runs
so, each on a thread of its own, their E-steps pooled into one batched E-step (:class:`_Pool`).
The objective is the log-likelihood plus the log-prior; it never decreases along a run.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..solvers.base import one_blas_thread
from .estep import EStep, EStepper, Workspace
from .options import RunSettings
from .spec import FitError, Params
from .sticks import EPS, Sticks
from .structure import Structure

SHRINK = 0.05  # SQUAREM: a cell may shrink at most this factor per extrapolation
MEMORY = 20  # L-BFGS-B correction pairs
RECENT = 32  # evaluations remembered to recover the parameters of an accepted iterate
FINISH_FTOL = 0.01  # the finish stops at this fraction of the fit's relative tolerance
CHECK_STEPS = 2  # E-steps of the check: counts at the end point, then the objective one EM step on
POOLED = 32  # runs at most whose E-steps are pooled (a thread each)

# how a run ended (RunResult.ended)
SMALL_STEP = "EM step below tol"  # EM's own test: the last step gained less than tol (relative)
CAPPED = "E-step cap"  # stopped by max_iter, not converged
STATIONARY = "stationary"  # checked at the end: one more EM step gains at most tol (relative)


@dataclass
class RunResult:
    """Where one start ended: parameters, log-likelihood, objective (plus log-prior), the objective
    of every accepted point (``history``, never decreasing), E-steps, how it ended (:data:`SMALL_STEP`,
    :data:`CAPPED`, :data:`STATIONARY`) and its quasi-Newton finishes; ``subsample_iterations``: the
    E-steps of a first phase on a subsample (:func:`.compiled_run.run_starts`; not in ``iterations``)."""

    params: Params
    loglik: float
    objective: float
    history: list[float]
    iterations: int
    converged: bool
    seconds: float
    ended: str = SMALL_STEP
    finishes: int = 0
    subsample_iterations: int = 0


class _Lockstep:
    """R runs advancing together; a run that stops is frozen at its final point."""

    def __init__(self, p: Params, st: EStep, f: np.ndarray):
        R = len(f)
        self.params, self.loglik, self.objective = p, np.array(st.loglik, dtype=float), np.array(f, dtype=float)
        self.history = [[float(x)] for x in f]
        self.iterations = np.ones(R, dtype=np.int64)
        self.active = np.ones(R, dtype=bool)
        self.converged = np.zeros(R, dtype=bool)

    def stop(self, mask: np.ndarray, p: Params, st: EStep, f: np.ndarray, converged: bool) -> None:
        """Freeze the active runs in ``mask`` at ``p``."""
        mask = mask & self.active
        if mask.any():
            self.params = p.where(mask, self.params)
            self.loglik = np.where(mask, st.loglik, self.loglik)
            self.objective = np.where(mask, f, self.objective)
            self.converged[mask] = converged
            self.active[mask] = False

    def record(self, mask: np.ndarray, f: np.ndarray) -> None:
        """Append the accepted objective ``f`` to the history of the active runs in ``mask``."""
        for r in np.flatnonzero(mask & self.active):
            self.history[r].append(float(f[r]))

    def results(self, seconds: float) -> list[RunResult]:
        return [
            RunResult(
                self.params.take(r),
                float(self.loglik[r]),
                float(self.objective[r]),
                self.history[r],
                int(self.iterations[r]),
                bool(self.converged[r]),
                seconds,
                SMALL_STEP if self.converged[r] else CAPPED,
            )
            for r in range(len(self.history))
        ]


def run_em(
    structure: Structure,
    work: EStepper,
    starts: Sequence[Params],
    tol: float = 1e-8,
    max_iter: int = 1000,
    accelerate: bool = True,
) -> list[RunResult]:
    """EM from each of ``starts`` until a step gains less than ``tol`` (relative) or rounding makes
    it lose (the better point kept), unconverged at ``max_iter`` E-steps.  With ``accelerate`` a
    SQUAREM cycle makes two EM steps and keeps the extrapolated point only if its objective is at
    least the second step's.  ``seconds`` is the loop's time divided evenly."""
    t0 = time.perf_counter()
    if not starts:
        raise FitError(["at least one start is needed"])

    def evaluate(p: Params, mask: np.ndarray | None = None) -> tuple[EStep, np.ndarray]:
        st = work.estep(p, mask)
        return st, st.loglik + structure.log_prior(p)

    def small(fa: np.ndarray, fb: np.ndarray) -> np.ndarray:
        return (fb - fa) <= tol * np.abs(fa)

    p0 = type(starts[0]).stack(starts)  # a subclass (e.g. a mixture's tables) stacks its own way
    st0, f0 = evaluate(p0)
    if not np.all(np.isfinite(f0)):
        raise FitError(["the initial values give the data probability zero"])
    runs = _Lockstep(p0, st0, f0)

    def em_step(p: Params, st: EStep, f: np.ndarray) -> tuple[Params, EStep, np.ndarray]:
        """One EM step of the active runs from ``p``; the runs it leaves converged stop."""
        q = structure.mstep(st, p)
        sq, fq = evaluate(q, runs.active)
        runs.iterations[runs.active] += 1
        runs.stop(~(fq >= f), p, st, f, True)  # only rounding can do this at a fixed point: keep the better point
        runs.record(runs.active, fq)
        runs.stop(small(f, fq), q, sq, fq, True)
        return q, sq, fq

    while True:
        runs.stop(runs.iterations >= max_iter, p0, st0, f0, False)
        if not runs.active.any():
            break
        p1, st1, f1 = em_step(p0, st0, f0)
        if not accelerate:
            p0, st0, f0 = p1, st1, f1
            continue
        runs.stop(runs.iterations >= max_iter, p1, st1, f1, False)
        if not runs.active.any():
            break
        p2, st2, f2 = em_step(p1, st1, f1)
        pe, faster = _extrapolate(structure, p0, p1, p2)
        ext = runs.active & faster & (runs.iterations < max_iter)
        p0, st0, f0 = p2, st2, f2
        if ext.any():
            pe = pe.where(ext, p2)
            ste, fe = evaluate(pe, ext)
            runs.iterations[ext] += 1
            ok = ext & (fe >= f2) & np.isfinite(fe)
            runs.record(ok, fe)
            p0, st0, f0 = pe.where(ok, p2), ste.where(ok, st2), np.where(ok, fe, f2)
    return runs.results((time.perf_counter() - t0) / len(starts))


def _extrapolate(structure: Structure, p0: Params, p1: Params, p2: Params) -> tuple[Params, np.ndarray]:
    """The SQUAREM point (Varadhan & Roland 2008, step length -|r| / |v|) from p0 -> p1 -> p2, and
    where it is worth trying (step length below -1; elsewhere p2).  A cell shrinks at most
    1 / :data:`SHRINK`-fold: clamped to the boundary, EM would crawl there and stop early."""
    v0, v1, v2 = p0.vector(), p1.vector(), p2.vector()
    r, v = v1 - v0, v2 - 2 * v1 + v0
    nv = np.sqrt((v * v).sum(-1))
    step = np.where(nv > 0, -np.sqrt((r * r).sum(-1)) / np.where(nv > 0, nv, 1.0), -1.0)
    s = step[:, None]
    x = np.maximum(v0 - 2 * s * r + s * s * v, SHRINK * v2)
    faster = step < -1.0
    return structure.project(p2.from_vector(x)).where(faster, p2), faster


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
    """scipy's ``minimize``, imported on first use (0.5 s of CPU), on the thread that limits BLAS
    (:func:`~trustseek.solvers.base.one_blas_thread`): a limit set on another misses scipy's BLAS."""
    from scipy.optimize import minimize

    return minimize


def finish(
    structure: Structure, work: EStepper, run: RunResult, tol: float = 1e-8, max_iter: int = 1000, sticks: Sticks | None = None
) -> RunResult:
    """Continue a run with L-BFGS-B on the stick-breaking fractions of the free cells, until an
    iteration changes the objective by less than ``tol`` (relative) or ``max_iter`` E-steps in all;
    a point is kept only if its objective is at least the run's.  ``sticks``: the free cells'
    layout, when not the structure's own (a mixture's tables)."""
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
                bounds=[(EPS, 1 - EPS)] * sticks.size,
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


def em_step(structure: Structure, work: EStepper, p: Params) -> tuple[float, Params, float]:
    """The objective at ``p``, the point one EM step on, and the objective there."""
    st = work.estep(p)
    f = float(st.loglik + structure.log_prior(p))
    q = structure.mstep(st, p)
    return f, q, float(work.loglik(q) + structure.log_prior(q))


def converge(
    structure: Structure, work: EStepper, run: RunResult, settings: RunSettings, sticks: Sticks | None = None
) -> RunResult:
    """Carry ``run`` (an EM run to ``settings.em_tol``) to a stationary point or ``settings.max_iter`` E-steps.

    Each round is the finish (to :data:`FINISH_FTOL` of ``tol``; with ``quasi_newton``), then the
    check: when one EM step gains more than ``tol`` (relative), EM goes on from there to ``em_tol``
    and the next round begins.  ``ended``: :data:`STATIONARY` (``converged``) or :data:`CAPPED`."""
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
        if not fq - f > tol * abs(f):  # stationary: one EM step gains at most tol (relative)
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
    """:func:`converge` of each of ``runs``, in order; where the workspace runs parameter sets side by
    side (:meth:`~.estep.Workspace.lockstep`), on threads of their own in groups of that many (at most
    :data:`POOLED`), their E-steps pooled (the numbers are each run's alone)."""
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
    """The E-steps of ``live`` runs, each on a thread of its own: a call waits until every run still
    going has asked, and the last to ask computes one batched E-step for all."""

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
