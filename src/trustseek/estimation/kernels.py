"""The compiled E-step of R parameter sets on the same sequences, over the items of
:mod:`.forward_backward` (built with the package); the numpy E-step of :mod:`.estep` is the
reference it is tested against.

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
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np

from .forward_backward import each_items, estep_items, mixture_items, reduce_items, step_codes

CHUNK = 128  # sequences per work item (a fixed grouping of the sums)
PARALLEL_MIN = 40_000  # trials x parameter sets from which an E-step is split over threads
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
        self._partials: dict[tuple[int, tuple[int, ...]], tuple[np.ndarray, ...]] = {}

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
        parts = self._partials.get((R, lead))
        if parts is None:  # each item's own sums, zeroed by the item itself
            parts = self._partials[(R, lead)] = (np.empty((R, C)), *(np.empty((R, C, *lead, *sh)) for sh in shapes))
        args = (*before, act, parts, *after)
        n_active = int(act.sum())
        if self.threads > 1 and n_active * C > 1 and self.trials * n_active * math.prod(lead) >= PARALLEL_MIN:
            # contiguous runs of the active items, one per thread; each item writes only its own sums
            items = [r * C + c for r in np.flatnonzero(act) for c in range(C)]
            split(len(items), self.threads, lambda a, b: _run_items(items[a:b], C, args, kernel))
        else:
            kernel(0, R * C, C, CHUNK, *args)
        ll = np.empty(R)
        totals = [np.empty((R, math.prod(lead) * math.prod(sh))) for sh in shapes]
        reduce_items(act, parts, ll, *totals)
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
            split(N, self.threads, lambda a, b: each_items(a, b, *args))
        else:
            each_items(0, N, *args)
        return ll, ci, ce, ct


def _tables(initial: np.ndarray, emit: np.ndarray, trans: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return tuple(np.ascontiguousarray(x, dtype=np.float64) for x in (initial, emit, trans))  # type: ignore[return-value]


def split(n: int, threads: int, part: Callable[[int, int], Any]) -> None:
    """``part(a, b)`` of ``n`` things cut into one contiguous run per thread, on ``threads`` of the
    E-step threads."""
    bounds = np.linspace(0, n, min(threads, n) + 1).astype(int)
    pool = _pool(len(bounds) - 1)
    for f in [pool.submit(part, a, b) for a, b in itertools.pairwise(bounds)]:
        f.result()


def _run_items(items: list[int], C: int, args: tuple, kernel: Callable[..., Any]) -> None:
    """The items of one thread, as runs of consecutive items."""
    i = 0
    while i < len(items):
        j = i + 1
        while j < len(items) and items[j] == items[j - 1] + 1:
            j += 1
        kernel(items[i], items[j - 1] + 1, C, CHUNK, *args)
        i = j
