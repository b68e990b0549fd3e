"""A whole run compiled: EM with SQUAREM, the quasi-Newton finish and the stationarity check in one call.

On a few thousand trials an E-step takes microseconds and a run spends its time in Python between
E-steps.  :func:`run_starts` runs each start from its first E-step to its end in numba, with the
decisions of :func:`~.em.run_em` and :func:`~.em.converge`: EM with SQUAREM to the hand-over
tolerance; the finish, a projected BFGS on the stick-breaking fractions (:mod:`.sticks`: the same
box and gradient) with a backtracking line search, to the finish tolerance (as L-BFGS-B's
``ftol``); the check, one EM step from the end point (its counts known: one E-step).  A start runs
on one thread from start to end, so the result does not depend on the number of threads; the
E-step is :mod:`.kernels`' pass over the same items in the same order, so its numbers are those of
:meth:`~.estep.Workspace.estep`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..compiled import PARALLEL_LOCK, compiled_once, set_threads
from . import compiled_steps as steps
from . import kernels
from .em import CAPPED, STATIONARY, RunResult
from .estep import Workspace
from .options import RunSettings
from .spec import FitError, Params
from .sticks import EPS, Sticks, stick_gradient, stick_theta, stick_values
from .structure import Structure, Table

njit = kernels.njit
CHUNK = kernels.CHUNK
ARMIJO = 1e-4  # sufficient decrease of the finish's line search
FINISH_FTOL = 1e-4  # the finish stops at this fraction of the fit's relative tolerance (a full step gaining less)
BACKTRACKS = 30  # halvings of the step before the line search gives up
SUBSAMPLE_MIN = 500_000  # trials from which a start runs on a subsample of the sequences first
SUBSAMPLE_EVERY = 10  # the subsample: every SUBSAMPLE_EVERY-th sequence
ENDED_STATIONARY, ENDED_CAPPED, ENDED_ZERO = 0, 1, 2  # how a compiled run ended


@njit(cache=True, nogil=True, inline="always")
def _take(state, p, c, ll, f):
    """The point ``p`` with E-step counts ``c``, log-likelihood ``ll`` and objective ``f`` into ``state``."""
    flat, counts, stat = state
    steps.copy(flat, p)
    steps.copy(counts, c)
    stat[0] = ll
    stat[1] = f


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
    """The quasi-Newton finish from ``state`` (flat cells, counts, (log-likelihood, objective); updated
    in place to the best accepted point): a dense BFGS model of the objective over the fractions in
    [EPS, 1 - EPS], its best step inside the box (:func:`_box_qp`), a backtracking line search; stops
    when an iteration changes the objective by at most ``ftol`` (relative), no step decreases it, or
    at ``budget`` E-steps.  ``qn``: (the sticks' layout, their number n, ``B`` (n, n), ``warm``): the
    model's matrix is left in ``B``; with ``warm`` it starts from ``B``, else from a multiple of the
    identity.  Returns (E-steps, stopped by the budget, entries in ``history``)."""
    flat, _counts, stat = state
    sticks, n, B, warm = qn
    lo, hi = EPS, 1 - EPS
    base = flat.copy()
    K, Ue, M = model[0], model[1], model[2]
    x = np.empty(n)
    stick_theta((base[:K], base[K : K + Ue * K * M], base[K + Ue * K * M :]), sticks, x)
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
            _take(state, fln, cnn, lln, -Fn)
            history[nh] = -Fn
            nh += 1
        if small:
            break
    return calls, False, nh


@njit(cache=True, nogil=True)
def _em(state, tol, max_iter, its, model, ev, accelerate, history, nh):
    """EM with SQUAREM from ``state`` (its counts known; updated in place), as :func:`.em.run_em`
    decides; (E-steps so far, converged, entries in ``history``)."""
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
        small = f1 - f0 <= tol * abs(f0)
        if small or not accelerate or its >= max_iter:
            _take(state, p1, c1, ll1, f1)
            if small or its >= max_iter:
                return its, small, nh
            continue
        steps.copy(p0, flat)
        steps.em_step(p1, c1, model, p2)
        ll2, f2 = steps.evaluate(p2, model, ev, c2)
        its += 1
        if not f2 >= f1:
            _take(state, p1, c1, ll1, f1)
            return its, True, nh
        history[nh] = f2
        nh += 1
        _take(state, p2, c2, ll2, f2)
        if f2 - f1 <= tol * abs(f1):
            return its, True, nh
        if its < max_iter and steps.extrapolate(p0, p1, p2, model, pe):
            lle, fe = steps.evaluate(pe, model, ev, ce)
            its += 1
            if fe >= f2 and math.isfinite(fe):
                history[nh] = fe
                nh += 1
                _take(state, pe, ce, lle, fe)


@njit(cache=True, nogil=True)
def run_one(start, model, data, C, PE, settings, qn):
    """One start from its first E-step to its end: the end point's flat cells, (log-likelihood,
    objective), E-steps, how it ended, finishes, and the history.  ``model``: (K, Ue, M, Ut, prior,
    emission table, transition table); ``data``: the kernel's index arrays, in ``C`` items with
    ``PE`` emission rows; ``settings``: (tol, max_iter, em_tol, finish_tol, quasi-Newton, accelerate,
    the E-step on numba's threads); ``qn``: as for :func:`_finish`."""
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
        _take(state, q, cq, llq, fq)
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
    """Each start carried to a stationary point or ``settings.max_iter`` E-steps, compiled (the finish
    to :data:`FINISH_FTOL` of ``settings.tol``); ``settings.threads`` run starts side by side, or, with
    fewer starts than threads on ``compiled_steps.PARALLEL_ITEMS`` items or more, share each E-step.

    From :data:`SUBSAMPLE_MIN` trials (:func:`subsample`) a start runs first on every
    :data:`SUBSAMPLE_EVERY`-th sequence to its own end, then on the whole data from there (at most
    ``max_iter`` more E-steps), the finish starting from the subsample's matrix scaled by the ratio of
    trials; ``subsample_iterations`` counts the subsample's E-steps.  A subsample end that gives the
    whole data probability zero is run again from the start on the whole data.  A process's first
    start runs alone, in :func:`~trustseek.compiled.compiled_once`: of several processes that need
    the run at once, one compiles it and the others load it from numba's cache."""
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

    def each(todo: Sequence[Params]) -> list[RunResult]:
        if threaded:
            with PARALLEL_LOCK:
                set_threads(threads)
                return [one(p) for p in todo]
        if threads > 1 and len(todo) > 1:
            with ThreadPoolExecutor(min(threads, len(todo)), thread_name_prefix="trustseek-fit") as pool:
                return list(pool.map(one, todo))
        return [one(p) for p in todo]

    if getattr(run_one, "signatures", None) or not starts:  # compiled, or loaded, in this process
        return each(starts)
    with compiled_once("compiled_run.run_one"):  # the first start compiles or loads it: one process at a time
        first = each(starts[:1])
    return first + each(starts[1:])
