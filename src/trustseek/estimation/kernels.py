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

A sequence whose probability is zero makes the log-likelihood of its parameter
set -inf, with zero counts.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

try:  # numba is a declared dependency; without it the numpy E-step is used
    import numba

    AVAILABLE = True
except ImportError:  # pragma: no cover - exercised only without numba
    AVAILABLE = False


def njit(**options: Any) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """numba's ``njit(**options)`` when numba is installed, else the plain Python function."""
    if not AVAILABLE:  # pragma: no cover - exercised only without numba
        return lambda f: f
    return numba.njit(**options)


@njit(cache=True, nogil=True)
def _clear(r, loglik, c_init, c_emit, c_trans):
    """Zero the log-likelihood and the counts of parameter set ``r``."""
    loglik[r] = 0.0
    c_init[r, :] = 0.0
    c_emit[r, :, :] = 0.0
    c_trans[r, :, :, :] = 0.0


@njit(cache=True, nogil=True)
def estep_counts(initial, emit, trans, eidx, tidx, lengths, active, loglik, c_init, c_emit, c_trans, alpha, beta, scale, tmp):
    """Fill ``loglik`` (R,), ``c_init`` (R, K), ``c_emit`` (R, PE, K), ``c_trans`` (R, Ut+1, K, K).

    ``alpha``, ``beta`` (T, K), ``scale`` (T,) (inverse scales), ``tmp`` (K,) are work buffers.
    """
    R, K = initial.shape
    N = eidx.shape[0]
    for r in range(R):
        _clear(r, loglik, c_init, c_emit, c_trans)
        if not active[r]:
            continue
        total = 0.0
        for n in range(N):
            L = lengths[n]
            if L == 0:
                continue
            # forward, scaled: alpha[t] = P(S_t | y_1..t), 1 / scale[t] = P(y_t | y_<t) <= 1;
            # the scales are multiplied up and their log taken only before underflow
            e = eidx[n, 0]
            s = 0.0
            for k in range(K):
                a = initial[r, k] * emit[r, e, k]
                alpha[0, k] = a
                s += a
            if not s > 0.0:
                total = -math.inf
                break
            prod = s
            inv = 1.0 / s
            scale[0] = inv
            for k in range(K):
                alpha[0, k] *= inv
            dead = False
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
                    dead = True
                    break
                inv = 1.0 / s
                scale[t] = inv
                prod *= s
                if prod < 1e-250:
                    total += math.log(prod)
                    prod = 1.0
                for j in range(K):
                    alpha[t, j] *= inv
            if dead:
                total = -math.inf
                break
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
                        c_trans[r, u, i, j] += ai * w
                    beta[t - 1, i] = acc
            for t in range(L):
                e = eidx[n, t]
                for k in range(K):
                    c_emit[r, e, k] += alpha[t, k] * beta[t, k]
            for k in range(K):
                c_init[r, k] += alpha[0, k] * beta[0, k]
        if not total > -math.inf:
            _clear(r, loglik, c_init, c_emit, c_trans)
            loglik[r] = -math.inf
        else:
            loglik[r] = total


class Kernel:
    """Buffers and index arrays of one data set for :func:`estep_counts` (any number of parameter sets)."""

    def __init__(self, eidx: np.ndarray, tidx: np.ndarray, lengths: np.ndarray, K: int, PE: int, P: int):
        """``eidx`` (T, N) and ``tidx`` (T-1, N) as time-major arrays (padding is never read)."""
        T, N = eidx.shape
        self.K, self.PE, self.P = K, PE, P
        self.eidx = np.ascontiguousarray(eidx.T, dtype=np.int64)
        t = np.zeros((N, max(T, 1)), dtype=np.int64)
        t[:, : T - 1] = tidx.T
        self.tidx = t
        self.lengths = np.ascontiguousarray(lengths, dtype=np.int64)
        self.alpha = np.empty((max(T, 1), K))
        self.beta = np.empty((max(T, 1), K))
        self.scale = np.empty(max(T, 1))
        self.tmp = np.empty(K)
        self.every = np.ones(1, dtype=np.bool_)  # the default "all parameter sets active", grown as needed

    def run(
        self, initial: np.ndarray, emit: np.ndarray, trans: np.ndarray, active: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(loglik (R,), initial counts (R, K), emission counts (R, PE, K), transition counts (R, P, K, K))."""
        R, K = initial.shape
        ll = np.empty(R)
        ci = np.empty((R, K))
        ce = np.empty((R, self.PE, K))
        ct = np.empty((R, self.P, K, K))
        if active is None:
            if len(self.every) < R:
                self.every = np.ones(R, dtype=np.bool_)
            act = self.every[:R]
        else:
            act = np.ascontiguousarray(active, dtype=np.bool_)
        (estep_counts2 if K == 2 else estep_counts)(
            np.ascontiguousarray(initial, dtype=np.float64),
            np.ascontiguousarray(emit, dtype=np.float64),
            np.ascontiguousarray(trans, dtype=np.float64),
            self.eidx,
            self.tidx,
            self.lengths,
            act,
            ll,
            ci,
            ce,
            ct,
            self.alpha,
            self.beta,
            self.scale,
            self.tmp,
        )
        return ll, ci, ce, ct


@njit(cache=True, nogil=True)
def estep_counts2(initial, emit, trans, eidx, tidx, lengths, active, loglik, c_init, c_emit, c_trans, alpha, beta, scale, tmp):
    """:func:`estep_counts` for K = 2 levels, with the 2-vectors and 2x2 matrices in registers."""
    R = initial.shape[0]
    N = eidx.shape[0]
    for r in range(R):
        _clear(r, loglik, c_init, c_emit, c_trans)
        if not active[r]:
            continue
        total = 0.0
        dead = False
        for n in range(N):
            L = lengths[n]
            if L == 0:
                continue
            e = eidx[n, 0]
            a0 = initial[r, 0] * emit[r, e, 0]
            a1 = initial[r, 1] * emit[r, e, 1]
            s = a0 + a1
            if not s > 0.0:
                dead = True
                break
            prod = s
            inv = 1.0 / s
            scale[0] = inv
            a0 *= inv
            a1 *= inv
            alpha[0, 0] = a0
            alpha[0, 1] = a1
            for t in range(1, L):
                e = eidx[n, t]
                u = tidx[n, t - 1]
                b0 = (a0 * trans[r, u, 0, 0] + a1 * trans[r, u, 1, 0]) * emit[r, e, 0]
                b1 = (a0 * trans[r, u, 0, 1] + a1 * trans[r, u, 1, 1]) * emit[r, e, 1]
                s = b0 + b1
                if not s > 0.0:
                    dead = True
                    break
                inv = 1.0 / s
                scale[t] = inv
                prod *= s
                if prod < 1e-250:
                    total += math.log(prod)
                    prod = 1.0
                a0 = b0 * inv
                a1 = b1 * inv
                alpha[t, 0] = a0
                alpha[t, 1] = a1
            if dead:
                break
            total += math.log(prod)
            # backward; gamma and xi accumulated on the way
            g0 = 1.0
            g1 = 1.0
            for t in range(L - 1, 0, -1):
                e = eidx[n, t]
                u = tidx[n, t - 1]
                c_emit[r, e, 0] += alpha[t, 0] * g0
                c_emit[r, e, 1] += alpha[t, 1] * g1
                inv = scale[t]
                m0 = emit[r, e, 0] * g0 * inv
                m1 = emit[r, e, 1] * g1 * inv
                w00 = trans[r, u, 0, 0] * m0
                w01 = trans[r, u, 0, 1] * m1
                w10 = trans[r, u, 1, 0] * m0
                w11 = trans[r, u, 1, 1] * m1
                p0 = alpha[t - 1, 0]
                p1 = alpha[t - 1, 1]
                c_trans[r, u, 0, 0] += p0 * w00
                c_trans[r, u, 0, 1] += p0 * w01
                c_trans[r, u, 1, 0] += p1 * w10
                c_trans[r, u, 1, 1] += p1 * w11
                g0 = w00 + w01
                g1 = w10 + w11
            e = eidx[n, 0]
            c_emit[r, e, 0] += alpha[0, 0] * g0
            c_emit[r, e, 1] += alpha[0, 1] * g1
            c_init[r, 0] += alpha[0, 0] * g0
            c_init[r, 1] += alpha[0, 1] * g1
        if dead:
            _clear(r, loglik, c_init, c_emit, c_trans)
            loglik[r] = -math.inf
        else:
            loglik[r] = total
