"""The scaled forward-backward pass of one sequence, the posterior counts added straight into the
tables (no per-trial arrays; numba).  Tables and data as in :mod:`.kernels`, which runs these passes.

Vectors are multiplied by 2**:data:`RESCALE` (exact) when below 2**-RESCALE.  With K = 2 the
passes work in registers; the single-set pass on step codes: per code one 2 x 2 matrix ``trans[u, i,
j] * emit[e, j]``, each step's posterior added to its code's four sums, trial t's emission counts
taken from them at the end of the item (:func:`_fold`), the normaliser carried from the last trial.
The numbers equal the numpy reference's to rounding (about 1e-15 relative).
"""

from __future__ import annotations

import math

import numpy as np

from ..compiled import njit

RESCALE = 200  # forward and backward vectors are multiplied by 2**RESCALE when below 2**-RESCALE (exact)
TINY = 2.0**-RESCALE
HUGE = 2.0**RESCALE
LOG_HUGE = RESCALE * math.log(2.0)


@njit(cache=True, nogil=True, inline="always")
def _forward(r, n, initial, emit, trans, eidx, tidx, L, alpha, scale):
    """Scaled forward pass of sequence ``n`` under parameter set ``r`` into ``alpha`` and ``scale``;
    its log-probability (-inf: zero)."""
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
    return total


@njit(cache=True, nogil=True, inline="always")
def _backward(r, n, emit, trans, eidx, tidx, L, weight, counts, work):
    """Backward pass of sequence ``n`` after :func:`_forward`: its posterior counts times ``weight``
    added to ``counts`` (initial, emission, transition); ``work``: (alpha, beta, scale, tmp)."""
    c_init, c_emit, c_trans = counts
    alpha, beta, scale, tmp = work
    K = alpha.shape[1]
    # backward, scaled like alpha: gamma_t = alpha_t * beta_t sums to ``weight``
    for k in range(K):
        beta[L - 1, k] = weight
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


@njit(cache=True, nogil=True)
def _sequence(r, n, initial, emit, trans, eidx, tidx, L, counts, work):
    """Add the posterior counts of sequence ``n`` under parameter set ``r`` to ``counts`` (initial,
    emission, transition; ``work``: (alpha, beta, scale, tmp)); its log-probability (-inf: zero)."""
    total = _forward(r, n, initial, emit, trans, eidx, tidx, L, work[0], work[2])
    if not total > -math.inf:
        return total
    _backward(r, n, emit, trans, eidx, tidx, L, 1.0, counts, work)
    return total


@njit(cache=True, nogil=True, inline="always")
def _forward2(n, initial, emit, trans, eidx, tidx, L, alpha):
    """The forward pass of :func:`_sequence2` into ``alpha`` (unnormalised, rescaled by 2**RESCALE
    where needed); the log-probability of sequence ``n`` (-inf: zero)."""
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
    return math.log(a0 + a1) - shifts * LOG_HUGE


@njit(cache=True, nogil=True, inline="always")
def _backward2(n, emit, trans, eidx, tidx, L, weight, counts, alpha):
    """The backward pass of :func:`_sequence2` after :func:`_forward2`: the posterior counts of
    sequence ``n`` times ``weight`` added to ``counts`` (initial, emission, transition; the weight
    enters each trial's normaliser, so a weight of 1 adds exactly the unweighted counts)."""
    c_init, c_emit, c_trans = counts
    # backward: beta in (g0, g1), rescaled like alpha; gamma and xi normalised per trial
    g0 = 1.0
    g1 = 1.0
    z = weight / (alpha[L - 1, 0] + alpha[L - 1, 1])  # weight / sum(alpha_t * beta_t) at t = L - 1
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
        z = weight / z
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


@njit(cache=True, nogil=True)
def _sequence2(n, initial, emit, trans, eidx, tidx, L, counts, alpha):
    """:func:`_sequence` for K = 2 levels in registers: the vectors rescaled, not normalised, on the
    path from one trial to the next; the posteriors normalised trial by trial off that path."""
    total = _forward2(n, initial, emit, trans, eidx, tidx, L, alpha)
    if not total > -math.inf:
        return total
    _backward2(n, emit, trans, eidx, tidx, L, 1.0, counts, alpha)
    return total


@njit(cache=True, nogil=True)
def step_codes(eidx, tidx, PE):
    """The step code of every trial, (N, T): ``tidx[n, t - 1] * PE + eidx[n, t]`` (the transition
    into trial t and trial t's emission row) for t >= 1 and ``eidx[n, 0]`` for the first trial."""
    N, T = eidx.shape
    code = np.empty((N, T), dtype=np.int32)
    for n in range(N):
        if T > 0:
            code[n, 0] = eidx[n, 0]
        for t in range(1, T):
            code[n, t] = tidx[n, t - 1] * PE + eidx[n, t]
    return code


@njit(cache=True, nogil=True)
def _step_table(emit, trans, PE, A):
    """``A[u * PE + e] = (trans[u, 0, 0] emit[e, 0], trans[u, 0, 1] emit[e, 1], trans[u, 1, 0] emit[e, 0],
    trans[u, 1, 1] emit[e, 1])``: the 2 x 2 step matrix of every step code (K = 2)."""
    for u in range(trans.shape[0]):
        for e in range(PE):
            c = u * PE + e
            A[c, 0] = trans[u, 0, 0] * emit[e, 0]
            A[c, 1] = trans[u, 0, 1] * emit[e, 1]
            A[c, 2] = trans[u, 1, 0] * emit[e, 0]
            A[c, 3] = trans[u, 1, 1] * emit[e, 1]


@njit(cache=True, nogil=True, inline="always")
def _forward_codes(n, initial, emit, A, code, L, alpha, marks):
    """:func:`_forward2` on the step codes: ``alpha`` unnormalised, multiplied by 2**RESCALE
    where its sum falls below 2**-RESCALE (the trials where it was go to ``marks``); the
    log-probability of sequence ``n`` (-inf: zero) and the number of marks."""
    e = code[n, 0]
    a0 = initial[0] * emit[e, 0]
    a1 = initial[1] * emit[e, 1]
    s = 0
    if a0 + a1 < TINY:
        if not a0 + a1 > 0.0:
            return -math.inf, 0
        a0 *= HUGE
        a1 *= HUGE
        marks[s] = 0
        s += 1
    alpha[0, 0] = a0
    alpha[0, 1] = a1
    for t in range(1, L):
        c = code[n, t]
        x0 = a0 * A[c, 0] + a1 * A[c, 2]
        x1 = a0 * A[c, 1] + a1 * A[c, 3]
        a0 = x0
        a1 = x1
        if a0 + a1 < TINY:
            if not a0 + a1 > 0.0:
                return -math.inf, 0
            a0 *= HUGE
            a1 *= HUGE
            marks[s] = t
            s += 1
        alpha[t, 0] = a0
        alpha[t, 1] = a1
    return math.log(a0 + a1) - s * LOG_HUGE, s


@njit(cache=True, nogil=True, inline="always")
def _first(e, g0, g1, z, alpha, c_first):
    """The first trial's posterior (emission row ``e``; backward pair (g0, g1), inverse normaliser
    ``z``) added to ``c_first[2 + 2 e + k]`` and ``c_first[k]`` (the initial counts)."""
    q0 = alpha[0, 0] * g0 * z
    q1 = alpha[0, 1] * g1 * z
    c_first[2 + 2 * e] += q0
    c_first[3 + 2 * e] += q1
    c_first[0] += q0
    c_first[1] += q1


@njit(cache=True, nogil=True, inline="always")
def _rescaled(z, g0, g1, w00, w01, w10, w11):
    """Once ``z`` is above 2**RESCALE: ``z`` times 2**-RESCALE, the backward pair (g0, g1) and the
    step's four products times 2**RESCALE; else all as given."""
    if z > HUGE:
        return z * TINY, g0 * HUGE, g1 * HUGE, w00 * HUGE, w01 * HUGE, w10 * HUGE, w11 * HUGE
    return z, g0, g1, w00, w01, w10, w11


@njit(cache=True, nogil=True, inline="always")
def _backward_codes(n, A, code, L, c_first, c_step, alpha, marks, s):
    """The backward pass after :func:`_forward_codes`: each step's posterior (t - 1, t) added to
    ``c_step[code[n, t]]`` (row-major 2 x 2), the first trial's to ``c_first`` (:func:`_first`).
    sum_k alpha_t(k) beta_t(k) is the sequence's probability times the scale factors: its inverse
    ``z`` is known from the last trial and changes by 2**RESCALE where ``alpha`` was rescaled
    (``marks``) and by 2**-RESCALE where ``beta`` is (``z`` above 2**RESCALE)."""
    g0 = 1.0
    g1 = 1.0
    z = 1.0 / (alpha[L - 1, 0] + alpha[L - 1, 1])
    j = s - 1
    mark = marks[j] if j >= 0 else -1
    for t in range(L - 1, 0, -1):
        c = code[n, t]
        w00 = A[c, 0] * g0
        w01 = A[c, 1] * g1
        w10 = A[c, 2] * g0
        w11 = A[c, 3] * g1
        g0 = w00 + w01
        g1 = w10 + w11
        if t == mark:  # alpha[t] was multiplied by 2**RESCALE, alpha[t - 1] not
            z *= HUGE
            j -= 1
            mark = marks[j] if j >= 0 else -1
        z, g0, g1, w00, w01, w10, w11 = _rescaled(z, g0, g1, w00, w01, w10, w11)
        p0 = alpha[t - 1, 0] * z
        p1 = alpha[t - 1, 1] * z
        c_step[c, 0] += p0 * w00
        c_step[c, 1] += p0 * w01
        c_step[c, 2] += p1 * w10
        c_step[c, 3] += p1 * w11
    _first(code[n, 0], g0, g1, z, alpha, c_first)


@njit(cache=True, nogil=True)
def _forward_pair(n, m, initial, emit, A, code, L, first, second):
    """:func:`_forward_codes` of sequences ``n`` and ``m`` of one length side by side (two recursions
    in one loop keep the processor busy), the numbers of two calls; ``first``, ``second``: each one's
    (alpha, marks).  Their log-probabilities (both -inf when either is zero) and numbers of marks."""
    alpha, marks = first
    alpha2, marks2 = second
    e = code[n, 0]
    f = code[m, 0]
    a0 = initial[0] * emit[e, 0]
    a1 = initial[1] * emit[e, 1]
    b0 = initial[0] * emit[f, 0]
    b1 = initial[1] * emit[f, 1]
    sa = 0
    sb = 0
    if a0 + a1 < TINY:
        if not a0 + a1 > 0.0:
            return -math.inf, -math.inf, 0, 0
        a0 *= HUGE
        a1 *= HUGE
        marks[sa] = 0
        sa += 1
    if b0 + b1 < TINY:
        if not b0 + b1 > 0.0:
            return -math.inf, -math.inf, 0, 0
        b0 *= HUGE
        b1 *= HUGE
        marks2[sb] = 0
        sb += 1
    alpha[0, 0] = a0
    alpha[0, 1] = a1
    alpha2[0, 0] = b0
    alpha2[0, 1] = b1
    for t in range(1, L):
        c = code[n, t]
        d = code[m, t]
        x0 = a0 * A[c, 0] + a1 * A[c, 2]
        x1 = a0 * A[c, 1] + a1 * A[c, 3]
        y0 = b0 * A[d, 0] + b1 * A[d, 2]
        y1 = b0 * A[d, 1] + b1 * A[d, 3]
        a0 = x0
        a1 = x1
        b0 = y0
        b1 = y1
        if a0 + a1 < TINY:
            if not a0 + a1 > 0.0:
                return -math.inf, -math.inf, 0, 0
            a0 *= HUGE
            a1 *= HUGE
            marks[sa] = t
            sa += 1
        if b0 + b1 < TINY:
            if not b0 + b1 > 0.0:
                return -math.inf, -math.inf, 0, 0
            b0 *= HUGE
            b1 *= HUGE
            marks2[sb] = t
            sb += 1
        alpha[t, 0] = a0
        alpha[t, 1] = a1
        alpha2[t, 0] = b0
        alpha2[t, 1] = b1
    return math.log(a0 + a1) - sa * LOG_HUGE, math.log(b0 + b1) - sb * LOG_HUGE, sa, sb


@njit(cache=True, nogil=True)
def _backward_pair(n, m, A, code, L, first, second):
    """:func:`_backward_codes` of sequences ``n`` and ``m`` side by side after :func:`_forward_pair`, the
    numbers of two calls; ``first``, ``second``: each one's (c_first, c_step, alpha, marks, marks' number)."""
    ci, cs, alpha, marks, sa = first
    di, ds, alpha2, marks2, sb = second
    g0 = 1.0
    g1 = 1.0
    h0 = 1.0
    h1 = 1.0
    z = 1.0 / (alpha[L - 1, 0] + alpha[L - 1, 1])
    y = 1.0 / (alpha2[L - 1, 0] + alpha2[L - 1, 1])
    ja = sa - 1
    jb = sb - 1
    ma = marks[ja] if ja >= 0 else -1
    mb = marks2[jb] if jb >= 0 else -1
    for t in range(L - 1, 0, -1):
        c = code[n, t]
        d = code[m, t]
        w00 = A[c, 0] * g0
        w01 = A[c, 1] * g1
        w10 = A[c, 2] * g0
        w11 = A[c, 3] * g1
        q00 = A[d, 0] * h0
        q01 = A[d, 1] * h1
        q10 = A[d, 2] * h0
        q11 = A[d, 3] * h1
        g0 = w00 + w01
        g1 = w10 + w11
        h0 = q00 + q01
        h1 = q10 + q11
        if t == ma:
            z *= HUGE
            ja -= 1
            ma = marks[ja] if ja >= 0 else -1
        if t == mb:
            y *= HUGE
            jb -= 1
            mb = marks2[jb] if jb >= 0 else -1
        z, g0, g1, w00, w01, w10, w11 = _rescaled(z, g0, g1, w00, w01, w10, w11)
        y, h0, h1, q00, q01, q10, q11 = _rescaled(y, h0, h1, q00, q01, q10, q11)
        p0 = alpha[t - 1, 0] * z
        p1 = alpha[t - 1, 1] * z
        r0 = alpha2[t - 1, 0] * y
        r1 = alpha2[t - 1, 1] * y
        cs[c, 0] += p0 * w00
        cs[c, 1] += p0 * w01
        cs[c, 2] += p1 * w10
        cs[c, 3] += p1 * w11
        ds[d, 0] += r0 * q00
        ds[d, 1] += r0 * q01
        ds[d, 2] += r1 * q10
        ds[d, 3] += r1 * q11
    _first(code[n, 0], g0, g1, z, alpha, ci)
    _first(code[m, 0], h0, h1, y, alpha2, di)


@njit(cache=True, nogil=True)
def _fold(ci, cs, PE, c_init, c_emit, c_trans):
    """The per-code sums of :func:`_backward_codes` added to the tables: the step (u, e)'s
    posterior to transition u, its sum over the first level to emission row e."""
    c_init[0] += ci[0]
    c_init[1] += ci[1]
    for e in range(PE):
        c_emit[e, 0] += ci[2 + 2 * e]
        c_emit[e, 1] += ci[3 + 2 * e]
    for u in range(c_trans.shape[0]):
        for e in range(PE):
            c = u * PE + e
            c_emit[e, 0] += cs[c, 0] + cs[c, 2]
            c_emit[e, 1] += cs[c, 1] + cs[c, 3]
            c_trans[u, 0, 0] += cs[c, 0]
            c_trans[u, 0, 1] += cs[c, 1]
            c_trans[u, 1, 0] += cs[c, 2]
            c_trans[u, 1, 1] += cs[c, 3]
