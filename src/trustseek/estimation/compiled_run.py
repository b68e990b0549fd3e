"""A whole run compiled: EM with SQUAREM, the quasi-Newton finish and the stationarity check in one call.

For a small problem (a few thousand trials) the E-step itself takes microseconds and a run
spends most of its time in Python between E-steps: the M-step, the SQUAREM step, scipy's
L-BFGS-B driver.  :func:`run_starts` runs each start from its first E-step to its end in
compiled code (numba), with the decisions of :func:`~.em.run_em` and
:func:`~.convergence.converge`:

* EM with SQUAREM (two EM steps, the extrapolated point kept only when its objective is at
  least the second step's) to the hand-over tolerance;
* the finish: a projected limited-memory BFGS on the stick-breaking fractions of the free
  cells (:class:`~.quasi_newton.Sticks`, the same box and the same gradient by Fisher's
  identity), with a backtracking line search along the projection onto the box, to the
  finish tolerance (relative change of an iteration, as L-BFGS-B's ``ftol``);
* the check: one EM step from the end point gains at most ``tol`` (relative), else EM goes
  on from that step's point and the next round begins.  The end point's expected counts
  are those of its own E-step, so the check costs one E-step (the point one step on).

Every start runs on one thread from start to end (starts go side by side on several
threads), so the result does not depend on the number of threads.  The E-step is the
compiled pass of :mod:`.kernels` over the same items in the same order: its numbers are
those of :meth:`~.estep.Workspace.estep`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..compiled import PARALLEL_LOCK, set_threads
from . import compiled_steps as steps
from . import kernels
from .em import CAPPED, STATIONARY, RunResult
from .estep import Workspace
from .options import RunSettings
from .spec import FitError, Params
from .sticks import Sticks, stick_gradient, stick_values
from .structure import FLOOR, Structure, Table

njit = kernels.njit
CHUNK = kernels.CHUNK
STICK_EPS = Sticks.EPS
ARMIJO = 1e-4  # sufficient decrease of the finish's line search
FINISH_FTOL = 1e-4  # the finish stops at this fraction of the fit's relative tolerance (a full step gaining less)
BACKTRACKS = 30  # halvings of the step before the line search gives up
SUBSAMPLE_MIN = 500_000  # trials from which a start runs on a subsample of the sequences first
SUBSAMPLE_EVERY = 10  # the subsample: every SUBSAMPLE_EVERY-th sequence
ENDED_STATIONARY, ENDED_CAPPED, ENDED_ZERO = 0, 1, 2  # how a compiled run ended


@njit(cache=True, nogil=True, inline="always")
def _theta(flat, model, sticks, n):
    """:meth:`.sticks.Sticks.theta` of the flat cells."""
    K, Ue, M, _Ut, _prior, _emt, _trt = model
    table, m, mass, tbase, tstride, coff, cptr, cdst = sticks
    a, b = K, K + Ue * K * M
    f0, f1, f2 = flat[:a], flat[a:b], flat[b:]
    out = np.empty(n)
    for i in range(len(m)):
        rem = mass[i]
        for j in range(m[i] - 1):
            q = cdst[cptr[coff[i] + j]]
            val = f0[q] if table[i] == 0 else (f1[q] if table[i] == 1 else f2[q])
            out[tbase[i] + j * tstride[i]] = min(max(val / max(rem, FLOOR), STICK_EPS), 1 - STICK_EPS)
            rem = rem - val
    return out


@njit(cache=True, nogil=True, inline="always")
def _fg(theta, base, flat, counts, model, sticks, ev, grad):
    """The cells of ``theta`` (on ``base``) into ``flat``, their E-step counts into ``counts`` and
    the gradient of the objective into ``grad``; (log-likelihood, objective)."""
    K, Ue, M, _Ut, prior, _emt, _trt = model
    a, b = K, K + Ue * K * M
    steps.copy(flat, base)
    stick_values(theta, sticks, (flat[:a], flat[a:b], flat[b:]))
    ll, f = steps.evaluate(flat, model, ev, counts)
    if math.isfinite(f):
        stick_gradient(theta, prior, sticks, (counts[:a], counts[a:b], counts[b:]), grad)
    return ll, f


@njit(cache=True, nogil=True)
def _box_qp(g, B, lo, hi, d):
    """Minimise g.d + d'Bd / 2 over lo <= d <= hi (B positive definite) into ``d``: a primal
    active-set method from d = 0 (feasible: lo <= 0 <= hi)."""
    n = len(g)
    d[:] = 0.0
    bound = np.zeros(n, dtype=np.int64)  # -1 at lo, +1 at hi, 0 free
    for i in range(n):
        if lo[i] == 0.0 and g[i] > 0.0:
            bound[i] = -1
        elif hi[i] == 0.0 and g[i] < 0.0:
            bound[i] = 1
    for _ in range(4 * n + 10):
        free = np.flatnonzero(bound == 0)
        nf = len(free)
        target = d.copy()
        if nf > 0:
            # B_FF d_F = -(g_F + B_FA d_A)
            A = np.empty((nf, nf))
            r = np.empty(nf)
            for a in range(nf):
                i = free[a]
                acc = g[i]
                for j in range(n):
                    if bound[j] != 0:
                        acc += B[i, j] * d[j]
                r[a] = -acc
                for c in range(nf):
                    A[a, c] = B[i, free[c]]
            sol = np.linalg.solve(A, r)
            for a in range(nf):
                target[free[a]] = sol[a]
        # the step from d to target, cut at the first bound it crosses
        t = 1.0
        hit = -1
        for a in range(nf):
            i = free[a]
            if target[i] < lo[i] and target[i] < d[i]:
                ti = (lo[i] - d[i]) / (target[i] - d[i])
                if ti < t:
                    t, hit = ti, i
            elif target[i] > hi[i] and target[i] > d[i]:
                ti = (hi[i] - d[i]) / (target[i] - d[i])
                if ti < t:
                    t, hit = ti, i
        for a in range(nf):
            i = free[a]
            d[i] = min(max(d[i] + t * (target[i] - d[i]), lo[i]), hi[i])
        if hit >= 0:
            if target[hit] < lo[hit]:
                d[hit], bound[hit] = lo[hit], -1
            else:
                d[hit], bound[hit] = hi[hit], 1
            continue
        # optimal on this face: release the bound variable whose multiplier has the wrong sign
        worst = 0.0
        rel = -1
        for i in range(n):
            if bound[i] != 0:
                gi = g[i] + np.dot(B[i], d)
                v = -gi if bound[i] < 0 else gi  # positive: the objective decreases moving inward
                if v > worst:
                    worst, rel = v, i
        if rel < 0:
            return
        bound[rel] = 0


@njit(cache=True, nogil=True)
def _finish(state, budget, ftol, model, ev, qn, history, nh):
    """The quasi-Newton finish from the run's point ``state`` (flat cells, counts, log-likelihood,
    objective; updated in place to the best accepted point).  Maximises the objective over the
    stick-breaking fractions in the box [EPS, 1 - EPS]: a BFGS model of the objective (dense,
    its Hessian updated from each step's gradient change), the step that is best for the model
    inside the box (a small bound-constrained quadratic programme, no E-steps), a backtracking
    line search along it; stops when an iteration changes the objective by at most ``ftol``
    (relative, as L-BFGS-B's ``ftol``), when no step decreases it, or at ``budget`` E-steps.
    ``qn`` is (the sticks' layout, their number n, ``B``, ``warm``): the model's matrix is ``B``
    (n, n), left there at the end; with ``warm`` the finish starts from the matrix it holds, else
    from a multiple of the identity.  (E-steps, stopped by the budget, entries in ``history``)."""
    flat, counts, stat = state
    sticks, n, B, warm = qn
    lo, hi = STICK_EPS, 1 - STICK_EPS
    base = flat.copy()
    x = _theta(base, model, sticks, n)
    g = np.empty(n)
    fl = np.empty(len(flat))
    cn = np.empty(len(flat))
    _ll, f = _fg(x, base, fl, cn, model, sticks, ev, g)
    calls = 1
    if not math.isfinite(f):
        return calls, False, nh
    F = -f
    g *= -1.0
    scaled = warm
    d = np.empty(n)
    dl = np.empty(n)
    dh = np.empty(n)
    xn = np.empty(n)
    gn = np.empty(n)
    fln = np.empty(len(flat))
    cnn = np.empty(len(flat))
    while True:
        if not scaled:  # before the first pair: a steepest-descent step of length at most 1
            gg = math.sqrt(np.dot(g, g))
            if gg == 0.0:
                break
            for i in range(n):
                B[i, :] = 0.0
                B[i, i] = max(gg, 1e-300)
        for i in range(n):
            dl[i] = lo - x[i]
            dh[i] = hi - x[i]
        _box_qp(g, B, dl, dh, d)
        slope = np.dot(g, d)
        if not slope < 0.0:
            break
        step = 1.0
        accepted = False
        Fn = 0.0
        lln = 0.0
        for _ in range(BACKTRACKS):
            if calls >= budget:
                return calls, True, nh
            for i in range(n):
                xn[i] = min(max(x[i] + step * d[i], lo), hi)
            lln, fn = _fg(xn, base, fln, cnn, model, sticks, ev, gn)
            calls += 1
            Fn = -fn
            if math.isfinite(Fn) and Fn <= F + ARMIJO * step * slope:
                accepted = True
                break
            step *= 0.5
        if not accepted:
            break
        gn *= -1.0
        s_ = xn - x
        y_ = gn - g
        sy = np.dot(s_, y_)
        if sy > 1e-12 * math.sqrt(np.dot(s_, s_) * np.dot(y_, y_)):
            if not scaled:
                for i in range(n):
                    B[i, :] = 0.0
                    B[i, i] = np.dot(y_, y_) / sy
                scaled = True
            Bs = B @ s_
            sBs = np.dot(s_, Bs)
            if sBs > 0.0:
                for i in range(n):
                    for j in range(n):
                        B[i, j] += y_[i] * y_[j] / sy - Bs[i] * Bs[j] / sBs
        # a shortened step's small change says little about the distance to the maximum
        small = step == 1.0 and F - Fn <= ftol * max(abs(F), abs(Fn), 1.0)
        steps.copy(x, xn)
        steps.copy(g, gn)
        F = Fn
        if -Fn > stat[1]:
            steps.copy(flat, fln)
            steps.copy(counts, cnn)
            stat[0] = lln
            stat[1] = -Fn
            history[nh] = -Fn
            nh += 1
        if small:
            break
    return calls, False, nh


@njit(cache=True, nogil=True)
def _em(state, tol, max_iter, its, model, ev, accelerate, history, nh):
    """EM with SQUAREM from the point ``state`` (its counts known) until a step gains less than
    ``tol`` (relative), rounding makes a step lose, or ``max_iter`` E-steps; updated in place.
    (E-steps so far, converged, entries in ``history``), as :func:`.em.run_em` decides."""
    flat, counts, stat = state
    L = len(flat)
    p1 = np.empty(L)
    c1 = np.empty(L)
    p2 = np.empty(L)
    c2 = np.empty(L)
    pe = np.empty(L)
    ce = np.empty(L)
    p0 = flat.copy()
    while True:
        if its >= max_iter:
            return its, False, nh
        f0 = stat[1]
        steps.em_step(flat, counts, model, p1)
        ll1, f1 = steps.evaluate(p1, model, ev, c1)
        its += 1
        if not f1 >= f0:  # only rounding does this at a fixed point: keep the better point
            return its, True, nh
        history[nh] = f1
        nh += 1
        if f1 - f0 <= tol * abs(f0):
            steps.copy(flat, p1)
            steps.copy(counts, c1)
            stat[0], stat[1] = ll1, f1
            return its, True, nh
        if not accelerate:
            steps.copy(flat, p1)
            steps.copy(counts, c1)
            stat[0], stat[1] = ll1, f1
            continue
        if its >= max_iter:
            steps.copy(flat, p1)
            steps.copy(counts, c1)
            stat[0], stat[1] = ll1, f1
            return its, False, nh
        steps.copy(p0, flat)
        steps.em_step(p1, c1, model, p2)
        ll2, f2 = steps.evaluate(p2, model, ev, c2)
        its += 1
        if not f2 >= f1:
            steps.copy(flat, p1)
            steps.copy(counts, c1)
            stat[0], stat[1] = ll1, f1
            return its, True, nh
        history[nh] = f2
        nh += 1
        steps.copy(flat, p2)
        steps.copy(counts, c2)
        stat[0], stat[1] = ll2, f2
        if f2 - f1 <= tol * abs(f1):
            return its, True, nh
        if its < max_iter and steps.extrapolate(p0, p1, p2, model, pe):
            lle, fe = steps.evaluate(pe, model, ev, ce)
            its += 1
            if fe >= f2 and math.isfinite(fe):
                history[nh] = fe
                nh += 1
                steps.copy(flat, pe)
                steps.copy(counts, ce)
                stat[0], stat[1] = lle, fe


@njit(cache=True, nogil=True)
def run_one(start, model, data, C, PE, settings, qn):
    """One start from its first E-step to its end (see the module).  Returns the end point's
    flat cells, (log-likelihood, objective), E-steps, how it ended, finishes, and the history.
    ``model``: (K, Ue, M, Ut, prior, emission table, transition table); ``data``: the kernel's
    index arrays, in ``C`` items with ``PE`` emission rows; ``settings``: (tol, max_iter, em_tol,
    finish_tol, quasi-Newton, accelerate, the E-step's items on numba's threads); ``qn``: (the
    sticks' layout, their number n, ``B``, ``warm``): ``B`` (n, n) holds the finish's quasi-Newton
    matrix at the end; with ``warm`` the finishes start from the matrix ``B`` holds, else each
    from a multiple of the identity."""
    K, _Ue, _M, Ut, _prior, _emt, _trt = model
    tol, max_iter, em_tol, finish_tol, use_qn, accelerate, threaded = settings
    n = qn[1]
    L = len(start)
    bufs = steps.estep_buffers(K, PE, Ut + 1, C, threaded)
    flat = start.copy()
    counts = np.empty(L)
    stat = np.empty(2)
    history = np.empty(max_iter + 2)
    ev = (data, bufs)
    stat[0], stat[1] = steps.evaluate(flat, model, ev, counts)
    if not math.isfinite(stat[1]):
        return flat, stat, 1, ENDED_ZERO, 0, history[:0]
    history[0] = stat[1]
    nh = np.int64(1)
    state = (flat, counts, stat)
    # np.int64(1), not the literal 1 (nor nh = 1): numba would compile a second _em for Literal[int](1)
    its, converged, nh = _em(state, em_tol, max_iter, np.int64(1), model, ev, accelerate, history, nh)
    finishes = 0
    q = np.empty(L)
    cq = np.empty(L)
    while True:
        if not converged:
            return flat, stat, its, ENDED_CAPPED, finishes, history[:nh]
        if use_qn and n > 0 and max_iter - its >= 2 and math.isfinite(stat[1]):
            calls, capped, nh = _finish(state, max_iter - its, finish_tol, model, ev, qn, history, nh)
            its += calls
            finishes += 1
            if capped:
                return flat, stat, its, ENDED_CAPPED, finishes, history[:nh]
        if its + 1 > max_iter or not math.isfinite(stat[1]):
            return flat, stat, its, ENDED_CAPPED, finishes, history[:nh]
        # the check: one EM step from the end point (its counts are known)
        steps.em_step(flat, counts, model, q)
        llq, fq = steps.evaluate(q, model, ev, cq)
        its += 1
        f = stat[1]
        if not fq - f > tol * abs(f):
            return flat, stat, its, ENDED_STATIONARY, finishes, history[:nh]
        steps.copy(flat, q)
        steps.copy(counts, cq)
        stat[0], stat[1] = llq, fq
        history[nh] = fq
        nh += 1
        its, converged, nh = _em(state, em_tol, max_iter, its, model, ev, accelerate, history, nh)


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

    def rows(e: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Which emission rows with an observed output and which transition rows occur (padding
        and unobserved outputs read the last emission row, a trial without successor the last
        transition row: neither has parameters)."""
        seen_e = np.bincount(e.ravel(), minlength=PE)[: PE - 1] > 0
        seen_t = np.bincount(t.ravel(), minlength=U1)[: U1 - 1] > 0
        return np.concatenate([seen_e, seen_t])

    if np.any(rows(kern.eidx, kern.tidx[:, : T - 1]) & ~rows(kern.eidx[idx], kern.tidx[idx, : T - 1])):
        return None
    return idx


def applies(structure: Structure, work: Workspace) -> bool:
    """Whether :func:`run_starts` can run this fit: the plain structure (no rating) and the compiled E-step."""
    return kernels.AVAILABLE and work.compiled and type(structure) is Structure and work.seqs.n_trials > 0


def run_starts(structure: Structure, work: Workspace, starts: Sequence[Params], settings: RunSettings) -> list[RunResult]:
    """Each start carried to a stationary point or to ``settings.max_iter`` E-steps, compiled (see
    the module; the finish to :data:`FINISH_FTOL` of ``settings.tol``); ``settings.threads`` run
    starts side by side, or with fewer starts than threads on data of
    ``compiled_steps.PARALLEL_ITEMS`` items or more share each E-step (the numbers do not depend on it).

    From :data:`SUBSAMPLE_MIN` trials on (:func:`subsample`) each start runs first on every
    :data:`SUBSAMPLE_EVERY`-th sequence to its own stationary point (or ``max_iter`` E-steps),
    then on the whole data from there to a stationary point of the whole data (or ``max_iter``
    more E-steps), its finish starting from the subsample's quasi-Newton matrix scaled by the
    ratio of trials: the whole data's curvature is about that.  ``RunResult.iterations``
    counts the whole data's E-steps, ``subsample_iterations`` the subsample's; the history is
    the whole data's.  A start whose subsample end gives the whole data probability zero is
    run again from its start on the whole data."""
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
                bool(settings.accelerate), threaded)  # fmt: skip
    template = starts[0]
    idx = subsample(kern) if quasi_newton and sticks.size > 0 else None
    if idx is not None:
        sub = tuple(np.ascontiguousarray(a[idx]) for a in data)
        sub_C = max((len(idx) + CHUNK - 1) // CHUNK, 1)
        ratio = kern.trials / float(sub[3].sum())

    def one(p: Params) -> RunResult:
        t0 = time.perf_counter()
        x = np.ascontiguousarray(p.vector(), dtype=float)
        B = np.zeros((sticks.size, sticks.size))
        sub_its = 0
        if idx is not None:
            y, _stat, sub_its, sub_ended, _f, _h = run_one(x, model, sub, sub_C, work.PE, numbers, (layout, n, B, False))
            if sub_ended == ENDED_ZERO:
                raise FitError(["the initial values give the data probability zero"])
            B *= ratio
            flat, stat, its, ended, finishes, history = run_one(y, model, data, kern.C, work.PE, numbers, (layout, n, B, True))
            if ended != ENDED_ZERO:
                return result(flat, stat, its, ended, finishes, history, sub_its, t0)
            sub_its = 0  # the subsample's end is impossible for the whole data: from the start again
        flat, stat, its, ended, finishes, history = run_one(x, model, data, kern.C, work.PE, numbers, (layout, n, B, False))
        if ended == ENDED_ZERO:
            raise FitError(["the initial values give the data probability zero"])
        return result(flat, stat, its, ended, finishes, history, sub_its, t0)

    def result(
        flat: np.ndarray, stat: np.ndarray, its: int, ended: int, finishes: int, history: np.ndarray, sub_its: int, t0: float
    ) -> RunResult:
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

    if threaded:
        with PARALLEL_LOCK:
            set_threads(threads)
            return [one(p) for p in starts]
    if threads > 1 and len(starts) > 1:
        with ThreadPoolExecutor(min(threads, len(starts)), thread_name_prefix="trustseek-fit") as pool:
            return list(pool.map(one, starts))
    return [one(p) for p in starts]
