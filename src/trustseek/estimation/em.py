"""Expectation-maximisation from R starts at once, with SQUAREM acceleration.

One loop serves one start (R = 1) and many: the starts advance in lockstep, each taking
exactly the decisions it would take alone, and a start that has stopped is frozen
while the others go on (the compiled E-step then skips it).  The objective is the
log-likelihood plus the log-prior; it never decreases along a run.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .estep import EStep, EStepper
from .spec import FitError, Params
from .structure import Structure

SHRINK = 0.05  # SQUAREM: a cell may shrink at most this factor per extrapolation

# how a run ended (RunResult.ended)
SMALL_STEP = "EM step below tol"  # EM's own test: the last step gained less than tol (relative)
CAPPED = "E-step cap"  # stopped by max_iter, not converged
STATIONARY = "stationary"  # checked at the end: one more EM step gains at most tol (relative)


@dataclass
class RunResult:
    """Where one start ended: its parameters, log-likelihood and objective (plus log-prior).

    ``history`` holds the objective of every accepted point in order (it never
    decreases); ``iterations`` counts E-steps; ``converged`` is false when the run
    stopped at the cap on E-steps; ``ended`` says how it ended (:data:`SMALL_STEP`,
    :data:`CAPPED` or :data:`STATIONARY`) and ``finishes`` how many quasi-Newton
    finishes it took.  ``subsample_iterations`` counts the E-steps of a first phase on a
    subsample of the sequences (:func:`.compiled_run.run_starts` on large data; not in
    ``iterations`` nor ``history``).
    """

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
    """EM from each of ``starts`` until the relative change of its objective is below ``tol``.

    With ``accelerate`` a SQUAREM cycle makes two EM steps, extrapolates, and keeps the
    extrapolated point only if its objective is at least that of the second EM step.
    A run stops (converged) when a step gains less than ``tol`` relative, or when
    rounding makes a step lose (it keeps the better point), and unconverged at
    ``max_iter`` E-steps.  ``seconds`` is the loop's time divided evenly.
    """
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
    """The SQUAREM point (Varadhan & Roland 2008, step length -|r| / |v|) from two EM steps
    p0 -> p1 -> p2, and where it is worth trying (step length below -1; elsewhere it is p2).

    A cell may shrink at most 1 / :data:`SHRINK`-fold: clamping cells to the boundary
    would leave EM crawling there and stop it early at a worse point.
    """
    v0, v1, v2 = p0.vector(), p1.vector(), p2.vector()
    r, v = v1 - v0, v2 - 2 * v1 + v0
    nv = np.sqrt((v * v).sum(-1))
    step = np.where(nv > 0, -np.sqrt((r * r).sum(-1)) / np.where(nv > 0, nv, 1.0), -1.0)
    s = step[:, None]
    x = np.maximum(v0 - 2 * s * r + s * s * v, SHRINK * v2)
    faster = step < -1.0
    return structure.project(p2.from_vector(x)).where(faster, p2), faster
