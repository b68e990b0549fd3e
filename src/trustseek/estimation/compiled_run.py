"""A whole run compiled: EM with SQUAREM, the quasi-Newton finish and the stationarity check in one call.

On a few thousand trials an E-step takes microseconds and a run spends its time in Python between
E-steps.  :func:`run_starts` runs each start from its first E-step to its end in compiled code
(:func:`.compiled_em.run_one`), with the decisions of :func:`~.em.run_em` and
:func:`~.em.converge`: EM with SQUAREM to the hand-over tolerance; the finish, a projected BFGS on
the stick-breaking fractions (:mod:`.sticks`: the same box and gradient) with a backtracking line
search, to the finish tolerance (as L-BFGS-B's ``ftol``); the check, one EM step from the end
point (its counts known: one E-step).  A start runs on one thread from start to end, so the result
does not depend on the number of threads; the E-step is :mod:`.kernels`' pass over the same items
in the same order, so its numbers are those of :meth:`~.estep.Workspace.estep`.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from . import compiled_steps as steps
from . import kernels
from .em import CAPPED, STATIONARY, RunResult
from .estep import Workspace
from .options import RunSettings
from .spec import FitError, Params
from .sticks import Sticks
from .structure import Structure, Table

CHUNK = kernels.CHUNK
FINISH_FTOL = 1e-4  # the finish stops at this fraction of the fit's relative tolerance (a full step gaining less)
SUBSAMPLE_MIN = 500_000  # trials from which a start runs on a subsample of the sequences first
SUBSAMPLE_EVERY = 10  # the subsample: every SUBSAMPLE_EVERY-th sequence


def _table(t: Table) -> tuple[np.ndarray, ...]:
    return (
        np.ascontiguousarray(t.group, dtype=np.int64),
        np.ascontiguousarray(t.rep, dtype=np.int64),
        np.ascontiguousarray(t.gfixed, dtype=np.bool_),
        np.ascontiguousarray(t.gvalues, dtype=float),
        np.ascontiguousarray(t.mass, dtype=float),
    )


def subsample(kern: kernels.Kernel, every: int = SUBSAMPLE_EVERY) -> np.ndarray | None:
    """The sequences of the subsample phase: every ``every``-th one from the first, when the data
    have at least :data:`SUBSAMPLE_MIN` trials and the subsample has every emission row and every
    transition row the data have (a row it lacks would be estimated as zero); else None."""
    if kern.trials < SUBSAMPLE_MIN:
        return None
    idx = np.arange(0, kern.eidx.shape[0], every)
    if len(idx) == kern.eidx.shape[0]:  # one sequence (or every one): the subsample would be the data
        return None
    PE, U1, T = kern.PE, kern.P, kern.eidx.shape[1]
    # the emission rows with an observed output and the transition rows the subsample lacks (padding
    # and unobserved outputs read the last emission row, a trial without successor the last
    # transition row: neither has parameters), looked up in the whole data (a gather, not a count)
    lacks_e = np.bincount(kern.eidx[idx].ravel(), minlength=PE) == 0
    lacks_t = np.bincount(kern.tidx[idx, : T - 1].ravel(), minlength=U1) == 0
    lacks_e[PE - 1] = lacks_t[U1 - 1] = False
    if lacks_e[kern.eidx].any() or lacks_t[kern.tidx[:, : T - 1]].any():
        return None
    return idx


def applies(structure: Structure, work: Workspace) -> bool:
    """Whether :func:`run_starts` can run this fit: the plain structure (no rating) and the compiled E-step."""
    return work.compiled and type(structure) is Structure and work.seqs.n_trials > 0


def run_starts(structure: Structure, work: Workspace, starts: Sequence[Params], settings: RunSettings) -> list[RunResult]:
    """Each start carried to a stationary point or ``settings.max_iter`` E-steps, compiled (the finish
    to :data:`FINISH_FTOL` of ``settings.tol``); ``settings.threads`` run starts side by side, or, with
    fewer starts than threads on ``compiled_steps.PARALLEL_ITEMS`` items or more, share each E-step.

    From :data:`SUBSAMPLE_MIN` trials (:func:`subsample`) a start runs first on every
    :data:`SUBSAMPLE_EVERY`-th sequence to its own end, then on the whole data from there (at most
    ``max_iter`` more E-steps), the finish starting from the subsample's matrix scaled by the ratio of
    trials; ``subsample_iterations`` counts the subsample's E-steps.  A subsample end that gives the
    whole data probability zero is run again from the start on the whole data."""
    # (here: the compiled run loads scipy's BLAS and LAPACK, which a fit on the numpy path does not need)
    from .compiled_em import ENDED_STATIONARY, ENDED_ZERO, run_one

    K, M, Ue, Ut = structure.dims
    kern = work._kernel
    assert kern is not None
    sticks = Sticks(structure)
    layout = sticks._layout()
    data = (kern.eidx, kern.tidx, kern.code, kern.lengths)
    emt, trt = _table(structure.em), _table(structure.tr)
    prior = float(structure.spec.prior)
    n = sticks.size
    model = (K, Ue, M, Ut, prior, emt, trt)
    # fewer starts than threads on data of PARALLEL_ITEMS items or more: each E-step on the threads
    threads, tol, quasi_newton = settings.threads, settings.tol, settings.quasi_newton
    threaded = threads > 1 and len(starts) < threads and kern.C >= steps.PARALLEL_ITEMS
    numbers = (float(tol), int(settings.max_iter), float(settings.em_tol), float(tol * FINISH_FTOL), bool(quasi_newton),
                bool(settings.accelerate), threads if threaded else 1)  # fmt: skip
    template = starts[0]
    idx = subsample(kern) if quasi_newton and sticks.size > 0 else None
    if idx is not None:
        sub = tuple(np.ascontiguousarray(a[idx]) for a in data)
        sub_C = max((len(idx) + CHUNK - 1) // CHUNK, 1)
        ratio = kern.trials / float(sub[3].sum())

    def one(p: Params) -> RunResult:
        t0 = time.perf_counter()
        x = np.ascontiguousarray(p.vector(), dtype=float)
        B = np.zeros((n, n))
        sub_its, out = 0, None
        if idx is not None:
            y, _stat, sub_its, _ended, _f, _h = run_one(x, model, sub, sub_C, work.PE, numbers, (layout, n, B, False))
            B *= ratio
            out = run_one(y, model, data, kern.C, work.PE, numbers, (layout, n, B, True))
            if out[3] == ENDED_ZERO:  # the subsample's end is impossible for the whole data: from the start again
                sub_its, out = 0, None
        if out is None:
            out = run_one(x, model, data, kern.C, work.PE, numbers, (layout, n, B, False))
        flat, stat, its, ended, finishes, history = out
        if ended == ENDED_ZERO:
            raise FitError(["the initial values give the data probability zero"])
        return RunResult(
            template.from_vector(flat),
            float(stat[0]),
            float(stat[1]),
            [float(x) for x in history],
            int(its),
            ended == ENDED_STATIONARY,
            time.perf_counter() - t0,
            STATIONARY if ended == ENDED_STATIONARY else CAPPED,
            int(finishes),
            int(sub_its),
        )

    if threads > 1 and len(starts) > 1 and not threaded:
        with ThreadPoolExecutor(min(threads, len(starts)), thread_name_prefix="trustseek-fit") as pool:
            return list(pool.map(one, starts))
    return [one(p) for p in starts]
