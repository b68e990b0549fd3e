"""Compiled scaled forward-backward with fused expected-count accumulation (numba).

One call runs the E-step of R parameter sets of a discrete IOHMM on the same
sequences: per sequence a scaled forward pass, a backward pass, and the
posterior counts added straight into the emission, transition and initial
tables, with no per-trial arrays.  The numpy implementation in
:mod:`.estep` (``Workspace(method="loop")``) is the reference it is tested
against.

Tables (leading axis R = parameter sets):

* ``initial`` (R, K);
* ``emit`` (R, PE, K): likelihood of the trial's observation per level, row
  ``emission-input combination * M + output`` and a last row of ones for an
  unobserved output;
* ``trans`` (R, Ut + 1, K, K): transition matrices, the last one unused padding.

Data: ``eidx`` (N, T) emission row per trial, ``tidx`` (N, T) transition row of
trial t (t -> t+1), ``lengths`` (N,).  Inactive parameter sets (``active[r]`` false)
are skipped and report log-likelihood 0 and zero counts.

The work is cut into items of one parameter set and :data:`CHUNK` consecutive
sequences; each item sums into its own counts, and the items' sums are added in a
fixed order.  The items run on one thread or are split over several (Python threads:
the compiled code releases the GIL), with the same grouping, so the result is the same
to the last bit whatever the number of threads.

A sequence whose probability is zero makes the log-likelihood of its parameter
set -inf, with zero counts.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np

try:  # numba is a declared dependency; without it the numpy E-step is used
    import numba

    AVAILABLE = True
except ImportError:  # pragma: no cover - exercised only without numba
    AVAILABLE = False

CHUNK = 128  # sequences per work item (a fixed grouping of the sums)
RESCALE = 200  # forward and backward vectors are multiplied by 2**RESCALE when below 2**-RESCALE (exact)
TINY = 2.0**-RESCALE
HUGE = 2.0**RESCALE
LOG_HUGE = RESCALE * math.log(2.0)
PARALLEL_MIN = 40_000  # trials x parameter sets from which an E-step is split over threads


def njit(**options: Any) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """numba's ``njit(**options)`` when numba is installed, else the plain Python function."""
    if not AVAILABLE:  # pragma: no cover - exercised only without numba
        return lambda f: f
    return numba.njit(**options)


@njit(cache=True, nogil=True)
def _sequence(r, n, initial, emit, trans, eidx, tidx, L, c_init, c_emit, c_trans, alpha, beta, scale, tmp):
    """Add the posterior counts of sequence ``n`` under parameter set ``r``; its log-probability (-inf: zero)."""
    K = initial.shape[1]
    # forward, scaled: alpha[t] = P(S_t | y_1..t), 1 / scale[t] = P(y_t | y_<t) <= 1;
    # the scales are multiplied up and their log taken only before underflow
    e = eidx[n, 0]
    s = 0.0
    for k in range(K):
        a = initial[r, k] * emit[r, e, k]
        alpha[0, k] = a
        s += a
    if not s > 0.0:
        return -math.inf
    total = 0.0
    prod = s
    inv = 1.0 / s
    scale[0] = inv
    for k in range(K):
        alpha[0, k] *= inv
    for t in range(1, L):
        e = eidx[n, t]
        u = tidx[n, t - 1]
        s = 0.0
        for j in range(K):
            acc = 0.0
            for i in range(K):
                acc += alpha[t - 1, i] * trans[r, u, i, j]
            a = acc * emit[r, e, j]
            alpha[t, j] = a
            s += a
        if not s > 0.0:
            return -math.inf
        inv = 1.0 / s
        scale[t] = inv
        prod *= s
        if prod < 1e-250:
            total += math.log(prod)
            prod = 1.0
        for j in range(K):
            alpha[t, j] *= inv
    total += math.log(prod)
    # backward, scaled like alpha: gamma_t = alpha_t * beta_t sums to 1
    for k in range(K):
        beta[L - 1, k] = 1.0
    for t in range(L - 1, 0, -1):
        e = eidx[n, t]
        u = tidx[n, t - 1]
        inv = scale[t]
        for j in range(K):
            tmp[j] = emit[r, e, j] * beta[t, j] * inv
        for i in range(K):
            acc = 0.0
            ai = alpha[t - 1, i]
            for j in range(K):
                w = trans[r, u, i, j] * tmp[j]
                acc += w
                c_trans[u, i, j] += ai * w
            beta[t - 1, i] = acc
    for t in range(L):
        e = eidx[n, t]
        for k in range(K):
            c_emit[e, k] += alpha[t, k] * beta[t, k]
    for k in range(K):
        c_init[k] += alpha[0, k] * beta[0, k]
    return total


@njit(cache=True, nogil=True)
def _sequence2(n, initial, emit, trans, eidx, tidx, L, c_init, c_emit, c_trans, alpha):
    """:func:`_sequence` for K = 2 levels, with the 2-vectors and 2x2 matrices in registers.

    The forward and backward vectors are not normalised at every trial (a division on
    the path from one trial to the next) but multiplied by 2**RESCALE (exact) when the
    forward sum, or the sum of forward times backward, falls below 2**-RESCALE; the
    posteriors are normalised trial by trial off that path.
    """
    e = eidx[n, 0]
    a0 = initial[0] * emit[e, 0]
    a1 = initial[1] * emit[e, 1]
    shifts = 0
    if a0 + a1 < TINY:
        if not a0 + a1 > 0.0:
            return -math.inf
        a0 *= HUGE
        a1 *= HUGE
        shifts += 1
    alpha[0, 0] = a0
    alpha[0, 1] = a1
    for t in range(1, L):
        e = eidx[n, t]
        u = tidx[n, t - 1]
        b0 = (a0 * trans[u, 0, 0] + a1 * trans[u, 1, 0]) * emit[e, 0]
        b1 = (a0 * trans[u, 0, 1] + a1 * trans[u, 1, 1]) * emit[e, 1]
        a0 = b0
        a1 = b1
        if a0 + a1 < TINY:
            if not a0 + a1 > 0.0:
                return -math.inf
            a0 *= HUGE
            a1 *= HUGE
            shifts += 1
        alpha[t, 0] = a0
        alpha[t, 1] = a1
    total = math.log(a0 + a1) - shifts * LOG_HUGE
    # backward: beta in (g0, g1), rescaled like alpha; gamma and xi normalised per trial
    g0 = 1.0
    g1 = 1.0
    z = 1.0 / (a0 + a1)  # 1 / sum(alpha_t * beta_t) at t = L - 1
    for t in range(L - 1, 0, -1):
        e = eidx[n, t]
        u = tidx[n, t - 1]
        c_emit[e, 0] += alpha[t, 0] * g0 * z
        c_emit[e, 1] += alpha[t, 1] * g1 * z
        m0 = emit[e, 0] * g0
        m1 = emit[e, 1] * g1
        w00 = trans[u, 0, 0] * m0
        w01 = trans[u, 0, 1] * m1
        w10 = trans[u, 1, 0] * m0
        w11 = trans[u, 1, 1] * m1
        g0 = w00 + w01
        g1 = w10 + w11
        p0 = alpha[t - 1, 0]
        p1 = alpha[t - 1, 1]
        # sum(alpha_{t-1} * beta_{t-1}), also the sum of the four xi terms: P(data) up to the scale
        # factors, so it only changes where alpha was rescaled; beta is rescaled to keep it normal
        z = p0 * g0 + p1 * g1
        if z < TINY:
            g0 *= HUGE
            g1 *= HUGE
            w00 *= HUGE
            w01 *= HUGE
            w10 *= HUGE
            w11 *= HUGE
            z *= HUGE
        z = 1.0 / z
        p0 *= z
        p1 *= z
        c_trans[u, 0, 0] += p0 * w00
        c_trans[u, 0, 1] += p0 * w01
        c_trans[u, 1, 0] += p1 * w10
        c_trans[u, 1, 1] += p1 * w11
    e = eidx[n, 0]
    q0 = alpha[0, 0] * g0 * z
    q1 = alpha[0, 1] * g1 * z
    c_emit[e, 0] += q0
    c_emit[e, 1] += q1
    c_init[0] += q0
    c_init[1] += q1
    return total


@njit(cache=True, nogil=True)
def _item(r, lo, hi, initial, emit, trans, eidx, tidx, lengths, c_init, c_emit, c_trans):
    """Sequences ``lo:hi`` under parameter set ``r`` into this item's counts; their log-probability."""
    K = initial.shape[1]
    T = eidx.shape[1]
    total = 0.0
    if K == 2:
        buf = np.empty((max(T, 1), 2))
        for n in range(lo, hi):
            L = lengths[n]
            if L > 0:
                total += _sequence2(n, initial[r], emit[r], trans[r], eidx, tidx, L, c_init, c_emit, c_trans, buf)
                if not total > -math.inf:
                    return -math.inf
    else:
        alpha = np.empty((max(T, 1), K))
        beta = np.empty((max(T, 1), K))
        scale = np.empty(max(T, 1))
        tmp = np.empty(K)
        for n in range(lo, hi):
            L = lengths[n]
            if L > 0:
                total += _sequence(r, n, initial, emit, trans, eidx, tidx, L, c_init, c_emit, c_trans, alpha, beta, scale, tmp)
                if not total > -math.inf:
                    return -math.inf
    return total


@njit(cache=True, nogil=True)
def _reduce(active, ll, pi, pe, pt, loglik, c_init, c_emit, c_trans):
    """Add the items' sums per parameter set, in item order."""
    R, C = ll.shape
    for r in range(R):
        loglik[r] = 0.0
        c_init[r] = 0.0
        c_emit[r] = 0.0
        c_trans[r] = 0.0
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
            c_init[r] += pi[r, c]
            c_emit[r] += pe[r, c]
            c_trans[r] += pt[r, c]


@njit(cache=True, nogil=True)
def estep_items(first, last, C, chunk, initial, emit, trans, eidx, tidx, lengths, active, ll, pi, pe, pt):
    """Items ``first:last`` (item = r * C + c: parameter set r, sequences c*chunk onwards) into their own sums."""
    N = eidx.shape[0]
    for item in range(first, last):
        r = item // C
        c = item % C
        if active[r]:
            lo = c * chunk
            pi[r, c] = 0.0
            pe[r, c] = 0.0
            pt[r, c] = 0.0
            ll[r, c] = _item(r, lo, min(N, lo + chunk), initial, emit, trans, eidx, tidx, lengths, pi[r, c], pe[r, c], pt[r, c])


_POOL: ThreadPoolExecutor | None = None


def _pool(n: int) -> ThreadPoolExecutor:
    """The process's pool of E-step threads (grown when more are asked for)."""
    global _POOL
    if _POOL is None or _POOL._max_workers < n:
        if _POOL is not None:
            _POOL.shutdown(wait=False)
        _POOL = ThreadPoolExecutor(max_workers=n, thread_name_prefix="trustseek-estep")
    return _POOL


class Kernel:
    """The index arrays of one data set for :func:`estep_items` (any number of parameter sets).

    ``threads``: how many threads an E-step may use; the work is split over them when it is
    at least :data:`PARALLEL_MIN` trials x parameter sets.  The result does not depend on it.
    The items' sums live in buffers kept between calls: one kernel serves one caller at a time.
    """

    def __init__(self, eidx: np.ndarray, tidx: np.ndarray, lengths: np.ndarray, K: int, PE: int, P: int, threads: int = 1):
        """``eidx`` (T, N) and ``tidx`` (T-1, N) as time-major arrays (padding is never read)."""
        T, N = eidx.shape
        self.K, self.PE, self.P = K, PE, P
        self.threads = max(1, int(threads))
        self.eidx = np.ascontiguousarray(eidx.T, dtype=np.int32)
        t = np.zeros((N, max(T, 1)), dtype=np.int32)
        t[:, : T - 1] = tidx.T
        self.tidx = t
        self.lengths = np.ascontiguousarray(lengths, dtype=np.int64)
        self.trials = int(self.lengths.sum())
        self.C = max((N + CHUNK - 1) // CHUNK, 1)  # items per parameter set
        self.every = np.ones(1, dtype=np.bool_)  # the default "all parameter sets active", grown as needed
        self._partials: dict[int, tuple[np.ndarray, ...]] = {}

    def run(
        self, initial: np.ndarray, emit: np.ndarray, trans: np.ndarray, active: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(loglik (R,), initial counts (R, K), emission counts (R, PE, K), transition counts (R, P, K, K))."""
        R, K = initial.shape
        C = self.C
        if active is None:
            if len(self.every) < R:
                self.every = np.ones(R, dtype=np.bool_)
            act = self.every[:R]
        else:
            act = np.ascontiguousarray(active, dtype=np.bool_)
        parts = self._partials.get(R)
        if parts is None:  # each item's own sums, zeroed by the item itself: made once per number of parameter sets
            parts = self._partials[R] = (
                np.empty((R, C)),
                np.empty((R, C, K)),
                np.empty((R, C, self.PE, K)),
                np.empty((R, C, self.P, K, K)),
            )
        args = (
            np.ascontiguousarray(initial, dtype=np.float64),
            np.ascontiguousarray(emit, dtype=np.float64),
            np.ascontiguousarray(trans, dtype=np.float64),
            self.eidx,
            self.tidx,
            self.lengths,
            act,
            *parts,
        )
        n_active = int(act.sum())
        if self.threads > 1 and n_active * C > 1 and self.trials * n_active >= PARALLEL_MIN:
            # contiguous runs of the active items, one per thread; each item writes only its own sums
            items = [r * C + c for r in np.flatnonzero(act) for c in range(C)]
            bounds = np.linspace(0, len(items), min(self.threads, len(items)) + 1).astype(int)
            pool = _pool(len(bounds) - 1)
            futures = [pool.submit(_run_items, items[a:b], C, args) for a, b in itertools.pairwise(bounds)]
            for f in futures:
                f.result()
        else:
            estep_items(0, R * C, C, CHUNK, *args)
        ll = np.empty(R)
        ci = np.empty((R, K))
        ce = np.empty((R, self.PE, K))
        ct = np.empty((R, self.P, K, K))
        _reduce(act, *args[-4:], ll, ci, ce, ct)
        return ll, ci, ce, ct


def _run_items(items: list[int], C: int, args: tuple) -> None:
    """The items of one thread, as runs of consecutive items."""
    i = 0
    while i < len(items):
        j = i + 1
        while j < len(items) and items[j] == items[j - 1] + 1:
            j += 1
        estep_items(items[i], items[j - 1] + 1, C, CHUNK, *args)
        i = j
