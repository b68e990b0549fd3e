"""The compiled E-step of R parameter sets on the same sequences (numba), over the passes of
:mod:`.forward_backward`; the numpy E-step of :mod:`.estep` is the reference it is tested against.

Tables (leading axis R): ``initial`` (R, K); ``emit`` (R, PE, K), row ``emission-input combination
* M + output`` and a last row of ones (unobserved output); ``trans`` (R, Ut + 1, K, K), the last
unused padding.  Data: ``eidx`` (N, T) emission row per trial, ``tidx`` (N, T) transition row of
trial t (t -> t+1), ``lengths`` (N,), and ``code`` (N, T), the step codes (:func:`step_codes`) the
two-level pass reads.  Inactive parameter sets (``active[r]`` false) report 0 and zero counts; a
sequence of probability zero makes its set's log-likelihood -inf, with zero counts.

The work is cut into items of one parameter set and :data:`CHUNK` consecutive sequences, each
summing into its own counts, the sums added in a fixed order: on one thread or several (the
compiled code releases the GIL), the result is the same to the last bit.
"""

from __future__ import annotations

import itertools
import math
import os
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Any

import numpy as np

from ..compiled import AVAILABLE as AVAILABLE  # callers read kernels.AVAILABLE
from ..compiled import njit
from .forward_backward import (
    _backward,
    _backward2,
    _backward_codes,
    _backward_pair,
    _fold,
    _forward,
    _forward2,
    _forward_codes,
    _forward_pair,
    _sequence,
    _sequence2,
    _step_table,
    step_codes,
)

CHUNK = 128  # sequences per work item (a fixed grouping of the sums)
PARALLEL_MIN = 40_000  # trials x parameter sets from which an E-step is split over threads
COMPILE_MIN = 5_000  # trials from which a fit's E-steps run compiled (worth_compiling)


@njit(cache=True, nogil=True)
def _item(r, lo, hi, tables, data, counts):
    """Sequences ``lo:hi`` under parameter set ``r`` of ``tables`` (initial, emit, trans) into this
    item's ``counts`` (initial, emission, transition); their log-probability.  ``data``: (eidx,
    tidx, code, lengths)."""
    initial, emit, trans = tables
    eidx, tidx, code, lengths = data
    c_init, c_emit, c_trans = counts
    K = initial.shape[1]
    T = eidx.shape[1]
    total = 0.0
    if K == 2:
        # on the step codes (one 2 x 2 matrix per code, the counts per code, folded into the
        # tables at the end); sequences of equal length go two at a time, the second's counts
        # into their own sums
        PE = emit.shape[1]
        NC = trans.shape[1] * PE
        A = np.empty((NC, 4))
        _step_table(emit[r], trans[r], PE, A)
        buf = np.empty((max(T, 1), 2))
        buf2 = np.empty((max(T, 1), 2))
        marks = np.empty(max(T, 1), dtype=np.int64)
        marks2 = np.empty(max(T, 1), dtype=np.int64)
        ci = np.zeros(2 + 2 * PE)
        cs = np.zeros((NC, 4))
        di = np.zeros(2 + 2 * PE)
        ds = np.zeros((NC, 4))
        ini, em = initial[r], emit[r]
        n = lo
        while n < hi:
            L = lengths[n]
            if L > 0 and n + 1 < hi and lengths[n + 1] == L:
                la, lb, sa, sb = _forward_pair(n, n + 1, ini, em, A, code, L, (buf, marks), (buf2, marks2))
                total += la
                total += lb
                if not total > -math.inf:
                    return -math.inf
                _backward_pair(n, n + 1, A, code, L, (ci, cs, buf, marks, sa), (di, ds, buf2, marks2, sb))
                n += 2
                continue
            if L > 0:
                la, sa = _forward_codes(n, ini, em, A, code, L, buf, marks)
                total += la
                if not total > -math.inf:
                    return -math.inf
                _backward_codes(n, A, code, L, ci, cs, buf, marks, sa)
            n += 1
        ci += di
        cs += ds
        _fold(ci, cs, PE, c_init, c_emit, c_trans)
    else:
        alpha = np.empty((max(T, 1), K))
        beta = np.empty((max(T, 1), K))
        scale = np.empty(max(T, 1))
        work = (alpha, beta, scale, np.empty(K))
        for n in range(lo, hi):
            L = lengths[n]
            if L > 0:
                total += _sequence(r, n, initial, emit, trans, eidx, tidx, L, counts, work)
                if not total > -math.inf:
                    return -math.inf
    return total


@njit(cache=True, nogil=True)
def _reduce(active, ll, pi, pe, pt, loglik, c_init, c_emit, c_trans):
    """Add the items' sums per parameter set, in item order: ``ll`` (R, C) and the counts ``pi``,
    ``pe``, ``pt`` (R, C, X; trailing axes flattened: one function for every layout) into ``loglik``
    (R,) and ``c_init``, ``c_emit``, ``c_trans`` (R, X), cell by cell."""
    R, C = ll.shape
    for r in range(R):
        loglik[r] = 0.0
        c_init[r, :] = 0.0
        c_emit[r, :] = 0.0
        c_trans[r, :] = 0.0
        if not active[r]:
            continue
        dead = False
        for c in range(C):
            if not ll[r, c] > -math.inf:
                dead = True
        if dead:
            loglik[r] = -math.inf
            continue
        for c in range(C):
            loglik[r] += ll[r, c]
            for x in range(pi.shape[2]):
                c_init[r, x] += pi[r, c, x]
            for x in range(pe.shape[2]):
                c_emit[r, x] += pe[r, c, x]
            for x in range(pt.shape[2]):
                c_trans[r, x] += pt[r, c, x]


@njit(cache=True, nogil=True, inline="always")
def _slot(item, C, chunk, N, sums):
    """Item ``item`` (= r * C + c): its parameter set r, c, its sequences lo:hi and its own sums
    (initial, emission, transition), zeroed."""
    _ll, pi, pe, pt = sums
    r = item // C
    c = item % C
    lo = c * chunk
    pi[r, c] = 0.0
    pe[r, c] = 0.0
    pt[r, c] = 0.0
    return r, c, lo, min(N, lo + chunk), (pi[r, c], pe[r, c], pt[r, c])


@njit(cache=True, nogil=True)
def estep_items(first, last, C, chunk, tables, data, active, sums):
    """Items ``first:last`` (item = r * C + c: parameter set r, sequences c*chunk onwards) into their
    own ``sums`` (log-likelihood (R, C), initial, emission and transition counts per item)."""
    N = data[0].shape[0]
    for item in range(first, last):
        if active[item // C]:
            r, c, lo, hi, counts = _slot(item, C, chunk, N, sums)
            sums[0][r, c] = _item(r, lo, hi, tables, data, counts)


@njit(cache=True, nogil=True)
def _mixture_item(r, lo, hi, M, tables, data, counts, seq_ll):
    """Sequences ``lo:hi`` under the M types of parameter set ``r`` (sets ``r * M + m``; ``initial`` the
    joint P(type, S_1)): per sequence every type's forward pass, the responsibilities, then each
    type's backward pass weighted by its responsibility, counts into ``counts[.][m]`` and log
    P(sequence n, type m) into ``seq_ll[m, n]``; the mixture log-probability (-inf: zero)."""
    initial, emit, trans = tables
    eidx, tidx, lengths = data
    c_init, c_emit, c_trans = counts
    K = initial.shape[1]
    T = eidx.shape[1]
    alpha = np.empty((M, max(T, 1), K))
    beta = np.empty((max(T, 1), K))
    scale = np.empty((M, max(T, 1)))
    tmp = np.empty(K)
    v = np.empty(M)
    total = 0.0
    for n in range(lo, hi):
        L = lengths[n]
        if L <= 0:
            for m in range(M):
                seq_ll[m, n] = 0.0
            continue
        best = -math.inf
        for m in range(M):
            q = r * M + m
            if K == 2:
                lm = _forward2(n, initial[q], emit[q], trans[q], eidx, tidx, L, alpha[m])
            else:
                lm = _forward(q, n, initial, emit, trans, eidx, tidx, L, alpha[m], scale[m])
            seq_ll[m, n] = lm
            v[m] = lm
            if v[m] > best:
                best = v[m]
        if not best > -math.inf:
            return -math.inf
        s = 0.0
        for m in range(M):
            s += math.exp(v[m] - best)
        lse = best + math.log(s)
        total += lse
        for m in range(M):
            w = math.exp(v[m] - lse)
            if w > 0.0:
                q = r * M + m
                if K == 2:
                    _backward2(n, emit[q], trans[q], eidx, tidx, L, w, (c_init[m], c_emit[m], c_trans[m]), alpha[m])
                else:
                    cm = (c_init[m], c_emit[m], c_trans[m])
                    _backward(q, n, emit, trans, eidx, tidx, L, w, cm, (alpha[m], beta, scale[m], tmp))
    return total


@njit(cache=True, nogil=True)
def mixture_items(first, last, C, chunk, M, tables, data, active, sums, seq_ll):
    """Items ``first:last`` of a mixture E-step (item = r * C + c) into their own ``sums``: ``ll`` (R, C),
    ``pi`` (R, C, M, K), ``pe`` (R, C, M, PE, K), ``pt`` (R, C, M, P, K, K); ``seq_ll`` (R, M, N)."""
    N = data[0].shape[0]
    for item in range(first, last):
        if active[item // C]:
            r, c, lo, hi, counts = _slot(item, C, chunk, N, sums)
            sums[0][r, c] = _mixture_item(r, lo, hi, M, tables, data, counts, seq_ll[r])


@njit(cache=True, nogil=True)
def each_items(lo, hi, pidx, tables, data, active, out):
    """Sequences ``lo:hi``, sequence n under parameter set ``pidx[n]`` of ``tables`` (initial, emit,
    trans), each into its own counts ``ci[n]``, ``ce[n]``, ``ct[n]`` and log-probability ``ll[n]``
    (``out``: (ll, ci, ce, ct); skipped where ``active[n]`` is false).  ``data``: (eidx, tidx, lengths)."""
    initial, emit, trans = tables
    eidx, tidx, lengths = data
    ll, ci, ce, ct = out
    K = initial.shape[1]
    T = eidx.shape[1]
    alpha = np.empty((max(T, 1), K))
    beta = np.empty((max(T, 1), K))
    scale = np.empty(max(T, 1))
    work = (alpha, beta, scale, np.empty(K))
    for n in range(lo, hi):
        ci[n] = 0.0
        ce[n] = 0.0
        ct[n] = 0.0
        ll[n] = 0.0
        L = lengths[n]
        if not active[n] or L <= 0:
            continue
        q = pidx[n]
        if K == 2:
            ll[n] = _sequence2(n, initial[q], emit[q], trans[q], eidx, tidx, L, (ci[n], ce[n], ct[n]), alpha)
        else:
            ll[n] = _sequence(q, n, initial, emit, trans, eidx, tidx, L, (ci[n], ce[n], ct[n]), work)
        if not ll[n] > -math.inf:
            ci[n] = 0.0
            ce[n] = 0.0
            ct[n] = 0.0


#: set inside :func:`many_fits`: every fit compiled whatever its size
_MANY_FITS: ContextVar[bool] = ContextVar("many_fits", default=False)


@contextmanager
def many_fits() -> Iterator[None]:
    """Within: every fit's E-steps run compiled whatever its size (many fits of small data: a
    bootstrap, a design study, the reproduction's replicates)."""
    token = _MANY_FITS.set(True)
    try:
        yield
    finally:
        _MANY_FITS.reset(token)


def worth_compiling(trials: int) -> bool:
    """Whether E-steps on ``trials`` trials run compiled: from :data:`COMPILE_MIN` trials (below, a
    numpy fit takes less than loading numba, ~1 s), or inside :func:`many_fits`.  The choice depends
    on the call alone, so a fit gives the same numbers wherever it runs."""
    return AVAILABLE and (trials >= COMPILE_MIN or _MANY_FITS.get())


_POOL: ThreadPoolExecutor | None = None


def _pool(n: int) -> ThreadPoolExecutor:
    """The process's pool of E-step threads (grown when more are asked for)."""
    global _POOL
    if _POOL is None or _POOL._max_workers < n:
        if _POOL is not None:
            _POOL.shutdown(wait=False)
        _POOL = ThreadPoolExecutor(max_workers=n, thread_name_prefix="trustseek-estep")
    return _POOL


def _forget_pool() -> None:
    """In a forked child: the parent's pool has no threads here (work given to it would wait forever)."""
    global _POOL
    _POOL = None


os.register_at_fork(after_in_child=_forget_pool)


class Kernel:
    """The index arrays of one data set for :func:`estep_items`; the work is split over ``threads``
    from :data:`PARALLEL_MIN` trials x parameter sets (the result does not depend on it).  The
    items' sums live in buffers kept between calls: one kernel serves one caller at a time."""

    def __init__(self, eidx: np.ndarray, tidx: np.ndarray, lengths: np.ndarray, K: int, PE: int, P: int, threads: int = 1):
        """``eidx`` (T, N) and ``tidx`` (T-1, N) as time-major arrays (padding is never read)."""
        T, N = eidx.shape
        self.K, self.PE, self.P = K, PE, P
        self.threads = max(1, int(threads))
        self.eidx = np.ascontiguousarray(eidx.T, dtype=np.int32)
        t = np.zeros((N, max(T, 1)), dtype=np.int32)
        t[:, : T - 1] = tidx.T
        self.tidx = t
        self.code = step_codes(self.eidx, self.tidx, PE)  # the two-level pass reads these
        self.lengths = np.ascontiguousarray(lengths, dtype=np.int64)
        self.trials = int(self.lengths.sum())
        self.C = max((N + CHUNK - 1) // CHUNK, 1)  # items per parameter set
        self.every = np.ones(1, dtype=np.bool_)  # the default "all parameter sets active", grown as needed
        self._partials: dict[tuple[int, tuple[int, ...]], tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]] = {}

    def run(
        self, initial: np.ndarray, emit: np.ndarray, trans: np.ndarray, active: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(loglik (R,), initial counts (R, K), emission counts (R, PE, K), transition counts (R, P, K, K))."""
        R = initial.shape[0]
        data = (self.eidx, self.tidx, self.code, self.lengths)
        return self._items(estep_items, R, (), self._active(R, active), (_tables(initial, emit, trans), data), ())

    def _active(self, R: int, active: np.ndarray | None) -> np.ndarray:
        if active is None:
            if len(self.every) < R:
                self.every = np.ones(R, dtype=np.bool_)
            return self.every[:R]
        return np.ascontiguousarray(active, dtype=np.bool_)

    def _items(
        self, kernel: Callable[..., Any], R: int, lead: tuple[int, ...], act: np.ndarray, before: tuple, after: tuple
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``kernel``'s items of the active sets (its arguments: ``before``, the active sets, the sums,
        ``after``), each into its own sums (``lead``: the types' axes), the sums added per set in item
        order: (loglik (R,), initial (R, *lead, K), emission (R, *lead, PE, K), transition (R, *lead, P, K, K))."""
        C, K = self.C, self.K
        shapes = ((K,), (self.PE, K), (self.P, K, K))
        cached = self._partials.get((R, lead))
        if cached is None:  # each item's own sums, zeroed by the item itself, and their views for _reduce
            parts = (np.empty((R, C)), *(np.empty((R, C, *lead, *sh)) for sh in shapes))
            cached = self._partials[(R, lead)] = (parts, (parts[0], *(p.reshape(R, C, -1) for p in parts[1:])))
        parts, flat = cached
        args = (*before, act, parts, *after)
        n_active = int(act.sum())
        if self.threads > 1 and n_active * C > 1 and self.trials * n_active * math.prod(lead) >= PARALLEL_MIN:
            # contiguous runs of the active items, one per thread; each item writes only its own sums
            items = [r * C + c for r in np.flatnonzero(act) for c in range(C)]
            self._split(len(items), lambda a, b: _run_items(items[a:b], C, args, kernel))
        else:
            kernel(0, R * C, C, CHUNK, *args)
        ll = np.empty(R)
        totals = [np.empty((R, math.prod(lead) * math.prod(sh))) for sh in shapes]
        _reduce(act, *flat, ll, *totals)
        ci, ce, ct = (t.reshape((R, *lead, *sh)) for t, sh in zip(totals, shapes, strict=True))
        return ll, ci, ce, ct

    def run_mixture(
        self, initial: np.ndarray, emit: np.ndarray, trans: np.ndarray, M: int, active: np.ndarray | None = None
    ) -> tuple[np.ndarray, ...]:
        """The E-step of R mixtures of M types (tables of R * M sets, :func:`_mixture_item`): the
        log-likelihood (R,), the per-type counts (R, M, ...) and log P(sequence n, type m), (R, M, N)."""
        R = initial.shape[0] // M
        seq_ll = np.zeros((R, M, self.eidx.shape[0]))
        before = (M, _tables(initial, emit, trans), (self.eidx, self.tidx, self.lengths))
        return (*self._items(mixture_items, R, (M,), self._active(R, active), before, (seq_ll,)), seq_ll)

    def run_each(
        self, pidx: np.ndarray, initial: np.ndarray, emit: np.ndarray, trans: np.ndarray, active: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Sequence n under parameter set ``pidx[n]``, each with its own counts: log-likelihood (N,),
        initial (N, K), emission (N, PE, K) and transition (N, P, K, K) counts (zero where
        ``active[n]`` is false or the sequence has probability zero, with -inf)."""
        N = self.eidx.shape[0]
        K = initial.shape[1]
        act = self._active(N, active)
        ll = np.empty(N)
        ci = np.empty((N, K))
        ce = np.empty((N, self.PE, K))
        ct = np.empty((N, self.P, K, K))
        tables = _tables(initial, emit, trans)
        args = (np.ascontiguousarray(pidx, dtype=np.int64), tables, (self.eidx, self.tidx, self.lengths), act, (ll, ci, ce, ct))
        work = int(self.lengths[act].sum()) if active is not None else self.trials
        if self.threads > 1 and N > CHUNK and work >= PARALLEL_MIN:
            self._split(N, lambda a, b: each_items(a, b, *args))
        else:
            each_items(0, N, *args)
        return ll, ci, ce, ct

    def _split(self, n: int, part: Callable[[int, int], Any]) -> None:
        """``part(a, b)`` of ``n`` things cut into one contiguous run per thread, on the E-step threads."""
        bounds = np.linspace(0, n, min(self.threads, n) + 1).astype(int)
        pool = _pool(len(bounds) - 1)
        for f in [pool.submit(part, a, b) for a, b in itertools.pairwise(bounds)]:
            f.result()


def _tables(initial: np.ndarray, emit: np.ndarray, trans: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return tuple(np.ascontiguousarray(x, dtype=np.float64) for x in (initial, emit, trans))  # type: ignore[return-value]


def _run_items(items: list[int], C: int, args: tuple, kernel: Callable[..., Any]) -> None:
    """The items of one thread, as runs of consecutive items."""
    i = 0
    while i < len(items):
        j = i + 1
        while j < len(items) and items[j] == items[j - 1] + 1:
            j += 1
        kernel(items[i], items[j - 1] + 1, C, CHUNK, *args)
        i = j
