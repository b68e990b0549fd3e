"""The scaled forward-backward pass of one sequence, the posterior counts added straight into the
tables (no per-trial arrays), and the E-step's items over it (Cython, built with the package).
Tables and data as in :mod:`.kernels`, which runs these items.

Vectors are multiplied by 2**:data:`RESCALE` (exact) when below 2**-RESCALE.  With K = 2 the
passes work in registers; the single-set pass on step codes: per code one 2 x 2 matrix ``trans[u, i,
j] * emit[e, j]``, each step's posterior added to its code's four sums, trial t's emission counts
taken from them at the end of the item (:func:`_fold`), the normaliser carried from the last trial.
The numbers equal the numpy reference's to rounding (about 1e-15 relative).

An item is one parameter set and ``chunk`` consecutive sequences, summed into its own counts
(:func:`estep_items`, :func:`mixture_items`); :func:`reduce_items` adds the items' sums per set
in item order, so that any split of the items over threads gives the same numbers.
"""

import math

import numpy as np

from libc.math cimport INFINITY, exp, ldexp, log
from libc.stdint cimport int32_t, int64_t
from libc.stdlib cimport abort, calloc, free
from libc.string cimport memset

RESCALE = 200  # forward and backward vectors are multiplied by 2**RESCALE when below 2**-RESCALE (exact)
cdef double TINY = ldexp(1.0, -RESCALE)
cdef double HUGE = ldexp(1.0, RESCALE)
cdef double LOG_HUGE = RESCALE * math.log(2.0)


# ---- the passes of any K, on one parameter set's tables (ini (K,), em (PE, K), tr (P, K, K)) ----

cdef double _forward(
    const double* ini, const double* em, const double* tr, Py_ssize_t K, const int32_t* eidx,
    const int32_t* tidx, Py_ssize_t L, double* alpha, double* scale,
) noexcept nogil:
    """Scaled forward pass of the sequence with emission rows ``eidx`` and transition rows ``tidx``
    into ``alpha`` (L, K) and ``scale``; its log-probability (-inf: zero)."""
    cdef Py_ssize_t k, t, i, j, e, u
    cdef double s, a, total, prod, inv, acc
    # forward, scaled: alpha[t] = P(S_t | y_1..t), 1 / scale[t] = P(y_t | y_<t) <= 1;
    # the scales are multiplied up and their log taken only before underflow
    e = eidx[0]
    s = 0.0
    for k in range(K):
        a = ini[k] * em[e * K + k]
        alpha[k] = a
        s += a
    if not s > 0.0:
        return -INFINITY
    total = 0.0
    prod = s
    inv = 1.0 / s
    scale[0] = inv
    for k in range(K):
        alpha[k] *= inv
    for t in range(1, L):
        e = eidx[t]
        u = tidx[t - 1]
        s = 0.0
        for j in range(K):
            acc = 0.0
            for i in range(K):
                acc += alpha[(t - 1) * K + i] * tr[(u * K + i) * K + j]
            a = acc * em[e * K + j]
            alpha[t * K + j] = a
            s += a
        if not s > 0.0:
            return -INFINITY
        inv = 1.0 / s
        scale[t] = inv
        prod *= s
        if prod < 1e-250:
            total += log(prod)
            prod = 1.0
        for j in range(K):
            alpha[t * K + j] *= inv
    total += log(prod)
    return total


cdef void _backward(
    const double* em, const double* tr, Py_ssize_t K, const int32_t* eidx, const int32_t* tidx,
    Py_ssize_t L, double weight, double* c_init, double* c_emit, double* c_trans, const double* alpha,
    double* beta, const double* scale, double* tmp,
) noexcept nogil:
    """Backward pass of a sequence after :func:`_forward`: its posterior counts times ``weight``
    added to ``c_init`` (K,), ``c_emit`` (PE, K) and ``c_trans`` (P, K, K); ``beta`` (L, K) and
    ``tmp`` (K,) are work space."""
    cdef Py_ssize_t k, t, i, j, e, u
    cdef double inv, acc, ai, w
    # backward, scaled like alpha: gamma_t = alpha_t * beta_t sums to ``weight``
    for k in range(K):
        beta[(L - 1) * K + k] = weight
    for t in range(L - 1, 0, -1):
        e = eidx[t]
        u = tidx[t - 1]
        inv = scale[t]
        for j in range(K):
            tmp[j] = em[e * K + j] * beta[t * K + j] * inv
        for i in range(K):
            acc = 0.0
            ai = alpha[(t - 1) * K + i]
            for j in range(K):
                w = tr[(u * K + i) * K + j] * tmp[j]
                acc += w
                c_trans[(u * K + i) * K + j] += ai * w
            beta[(t - 1) * K + i] = acc
    for t in range(L):
        e = eidx[t]
        for k in range(K):
            c_emit[e * K + k] += alpha[t * K + k] * beta[t * K + k]
    for k in range(K):
        c_init[k] += alpha[k] * beta[k]


# ---- K = 2 in registers, on one parameter set's tables ----

cdef double _forward2(
    const double* ini, const double* em, const double* tr, const int32_t* eidx, const int32_t* tidx,
    Py_ssize_t L, double* alpha,
) noexcept nogil:
    """The forward pass of a sequence for K = 2 into ``alpha`` (L, 2; unnormalised, rescaled by
    2**RESCALE where needed); its log-probability (-inf: zero)."""
    cdef Py_ssize_t t, e, u
    cdef int64_t shifts = 0
    cdef double a0, a1, b0, b1
    e = eidx[0]
    a0 = ini[0] * em[e * 2]
    a1 = ini[1] * em[e * 2 + 1]
    if a0 + a1 < TINY:
        if not a0 + a1 > 0.0:
            return -INFINITY
        a0 *= HUGE
        a1 *= HUGE
        shifts += 1
    alpha[0] = a0
    alpha[1] = a1
    for t in range(1, L):
        e = eidx[t]
        u = tidx[t - 1] * 4
        b0 = (a0 * tr[u] + a1 * tr[u + 2]) * em[e * 2]
        b1 = (a0 * tr[u + 1] + a1 * tr[u + 3]) * em[e * 2 + 1]
        a0 = b0
        a1 = b1
        if a0 + a1 < TINY:
            if not a0 + a1 > 0.0:
                return -INFINITY
            a0 *= HUGE
            a1 *= HUGE
            shifts += 1
        alpha[2 * t] = a0
        alpha[2 * t + 1] = a1
    return log(a0 + a1) - shifts * LOG_HUGE


cdef void _backward2(
    const double* em, const double* tr, const int32_t* eidx, const int32_t* tidx, Py_ssize_t L,
    double weight, double* c_init, double* c_emit, double* c_trans, const double* alpha,
) noexcept nogil:
    """The backward pass after :func:`_forward2`: the posterior counts of the sequence times
    ``weight`` added to the counts (the weight enters each trial's normaliser, so a weight of 1
    adds exactly the unweighted counts)."""
    cdef Py_ssize_t t, e, u
    cdef double g0, g1, z, m0, m1, w00, w01, w10, w11, p0, p1, q0, q1
    # backward: beta in (g0, g1), rescaled like alpha; gamma and xi normalised per trial
    g0 = 1.0
    g1 = 1.0
    z = weight / (alpha[2 * (L - 1)] + alpha[2 * (L - 1) + 1])  # weight / sum(alpha_t * beta_t) at t = L - 1
    for t in range(L - 1, 0, -1):
        e = eidx[t] * 2
        u = tidx[t - 1] * 4
        c_emit[e] += alpha[2 * t] * g0 * z
        c_emit[e + 1] += alpha[2 * t + 1] * g1 * z
        m0 = em[e] * g0
        m1 = em[e + 1] * g1
        w00 = tr[u] * m0
        w01 = tr[u + 1] * m1
        w10 = tr[u + 2] * m0
        w11 = tr[u + 3] * m1
        g0 = w00 + w01
        g1 = w10 + w11
        p0 = alpha[2 * (t - 1)]
        p1 = alpha[2 * (t - 1) + 1]
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
        c_trans[u] += p0 * w00
        c_trans[u + 1] += p0 * w01
        c_trans[u + 2] += p1 * w10
        c_trans[u + 3] += p1 * w11
    e = eidx[0] * 2
    q0 = alpha[0] * g0 * z
    q1 = alpha[1] * g1 * z
    c_emit[e] += q0
    c_emit[e + 1] += q1
    c_init[0] += q0
    c_init[1] += q1


# ---- K = 2 on step codes: A (codes, 4) the step matrices of one parameter set ----

def step_codes(const int32_t[:, ::1] eidx, const int32_t[:, ::1] tidx, int32_t PE):
    """The step code of every trial, (N, T): ``tidx[n, t - 1] * PE + eidx[n, t]`` (the transition
    into trial t and trial t's emission row) for t >= 1 and ``eidx[n, 0]`` for the first trial."""
    cdef Py_ssize_t N = eidx.shape[0], T = eidx.shape[1], n, t
    out = np.empty((N, T), dtype=np.int32)
    cdef int32_t[:, ::1] code = out
    with nogil:
        for n in range(N):
            if T > 0:
                code[n, 0] = eidx[n, 0]
            for t in range(1, T):
                code[n, t] = tidx[n, t - 1] * PE + eidx[n, t]
    return out


cdef void _step_table(const double* em, const double* tr, Py_ssize_t P, Py_ssize_t PE, double* A) noexcept nogil:
    """``A[u * PE + e] = (trans[u, 0, 0] emit[e, 0], trans[u, 0, 1] emit[e, 1], trans[u, 1, 0] emit[e, 0],
    trans[u, 1, 1] emit[e, 1])``: the 2 x 2 step matrix of every step code (K = 2)."""
    cdef Py_ssize_t u, e, c
    for u in range(P):
        for e in range(PE):
            c = 4 * (u * PE + e)
            A[c] = tr[4 * u] * em[2 * e]
            A[c + 1] = tr[4 * u + 1] * em[2 * e + 1]
            A[c + 2] = tr[4 * u + 2] * em[2 * e]
            A[c + 3] = tr[4 * u + 3] * em[2 * e + 1]


cdef double _forward_codes(
    const double* ini, const double* em, const double* A, const int32_t* code, Py_ssize_t L,
    double* alpha, int64_t* marks, Py_ssize_t* marked,
) noexcept nogil:
    """:func:`_forward2` on the step codes: ``alpha`` unnormalised, multiplied by 2**RESCALE
    where its sum falls below 2**-RESCALE (the trials where it was go to ``marks``, their number
    to ``marked``); the log-probability of the sequence (-inf: zero)."""
    cdef Py_ssize_t t, c, s = 0
    cdef double a0, a1, x0, x1
    marked[0] = 0
    c = code[0] * 2
    a0 = ini[0] * em[c]
    a1 = ini[1] * em[c + 1]
    if a0 + a1 < TINY:
        if not a0 + a1 > 0.0:
            return -INFINITY
        a0 *= HUGE
        a1 *= HUGE
        marks[s] = 0
        s += 1
    alpha[0] = a0
    alpha[1] = a1
    for t in range(1, L):
        c = code[t] * 4
        x0 = a0 * A[c] + a1 * A[c + 2]
        x1 = a0 * A[c + 1] + a1 * A[c + 3]
        a0 = x0
        a1 = x1
        if a0 + a1 < TINY:
            if not a0 + a1 > 0.0:
                return -INFINITY
            a0 *= HUGE
            a1 *= HUGE
            marks[s] = t
            s += 1
        alpha[2 * t] = a0
        alpha[2 * t + 1] = a1
    marked[0] = s
    return log(a0 + a1) - s * LOG_HUGE


cdef inline void _first(Py_ssize_t e, double g0, double g1, double z, const double* alpha, double* c_first) noexcept nogil:
    """The first trial's posterior (emission row ``e``; backward pair (g0, g1), inverse normaliser
    ``z``) added to ``c_first[2 + 2 e + k]`` and ``c_first[k]`` (the initial counts)."""
    cdef double q0 = alpha[0] * g0 * z
    cdef double q1 = alpha[1] * g1 * z
    c_first[2 + 2 * e] += q0
    c_first[3 + 2 * e] += q1
    c_first[0] += q0
    c_first[1] += q1


cdef inline void _rescaled(double* z, double* g, double* w) noexcept nogil:
    """Once ``z`` is above 2**RESCALE: ``z`` times 2**-RESCALE, the backward pair ``g`` (2,) and the
    step's four products ``w`` (4,) times 2**RESCALE; else all as given."""
    if z[0] > HUGE:
        z[0] = z[0] * TINY
        g[0] = g[0] * HUGE
        g[1] = g[1] * HUGE
        w[0] = w[0] * HUGE
        w[1] = w[1] * HUGE
        w[2] = w[2] * HUGE
        w[3] = w[3] * HUGE


cdef inline Py_ssize_t _mark(const int64_t* marks, Py_ssize_t j) noexcept nogil:
    return marks[j] if j >= 0 else -1


cdef void _backward_codes(
    const double* A, const int32_t* code, Py_ssize_t L, double* c_first, double* c_step,
    const double* alpha, const int64_t* marks, Py_ssize_t s,
) noexcept nogil:
    """The backward pass after :func:`_forward_codes`: each step's posterior (t - 1, t) added to
    ``c_step[code[t]]`` (row-major 2 x 2), the first trial's to ``c_first`` (:func:`_first`).
    sum_k alpha_t(k) beta_t(k) is the sequence's probability times the scale factors: its inverse
    ``z`` is known from the last trial and changes by 2**RESCALE where ``alpha`` was rescaled
    (``marks``) and by 2**-RESCALE where ``beta`` is (``z`` above 2**RESCALE)."""
    cdef Py_ssize_t t, c, j = s - 1, mark
    cdef double g[2]
    cdef double w[4]
    cdef double z, p0, p1
    g[0] = 1.0
    g[1] = 1.0
    z = 1.0 / (alpha[2 * (L - 1)] + alpha[2 * (L - 1) + 1])
    mark = _mark(marks, j)
    for t in range(L - 1, 0, -1):
        c = code[t] * 4
        w[0] = A[c] * g[0]
        w[1] = A[c + 1] * g[1]
        w[2] = A[c + 2] * g[0]
        w[3] = A[c + 3] * g[1]
        g[0] = w[0] + w[1]
        g[1] = w[2] + w[3]
        if t == mark:  # alpha[t] was multiplied by 2**RESCALE, alpha[t - 1] not
            z *= HUGE
            j -= 1
            mark = _mark(marks, j)
        _rescaled(&z, g, w)
        p0 = alpha[2 * (t - 1)] * z
        p1 = alpha[2 * (t - 1) + 1] * z
        c_step[c] += p0 * w[0]
        c_step[c + 1] += p0 * w[1]
        c_step[c + 2] += p1 * w[2]
        c_step[c + 3] += p1 * w[3]
    _first(code[0], g[0], g[1], z, alpha, c_first)


cdef bint _forward_pair(
    const double* ini, const double* em, const double* A, const int32_t* code, const int32_t* code2,
    Py_ssize_t L, double* alpha, int64_t* marks, double* alpha2, int64_t* marks2, double* ll,
    Py_ssize_t* marked,
) noexcept nogil:
    """:func:`_forward_codes` of two sequences of one length side by side (two recursions in one
    loop keep the processor busy), the numbers of two calls: their log-probabilities into ``ll``
    (2,) and numbers of marks into ``marked`` (2,); false (and both -inf) when either is zero."""
    cdef Py_ssize_t t, c, d, sa = 0, sb = 0
    cdef double a0, a1, b0, b1, x0, x1, y0, y1
    ll[0] = -INFINITY
    ll[1] = -INFINITY
    marked[0] = 0
    marked[1] = 0
    c = code[0] * 2
    d = code2[0] * 2
    a0 = ini[0] * em[c]
    a1 = ini[1] * em[c + 1]
    b0 = ini[0] * em[d]
    b1 = ini[1] * em[d + 1]
    if a0 + a1 < TINY:
        if not a0 + a1 > 0.0:
            return False
        a0 *= HUGE
        a1 *= HUGE
        marks[sa] = 0
        sa += 1
    if b0 + b1 < TINY:
        if not b0 + b1 > 0.0:
            return False
        b0 *= HUGE
        b1 *= HUGE
        marks2[sb] = 0
        sb += 1
    alpha[0] = a0
    alpha[1] = a1
    alpha2[0] = b0
    alpha2[1] = b1
    for t in range(1, L):
        c = code[t] * 4
        d = code2[t] * 4
        x0 = a0 * A[c] + a1 * A[c + 2]
        x1 = a0 * A[c + 1] + a1 * A[c + 3]
        y0 = b0 * A[d] + b1 * A[d + 2]
        y1 = b0 * A[d + 1] + b1 * A[d + 3]
        a0 = x0
        a1 = x1
        b0 = y0
        b1 = y1
        if a0 + a1 < TINY:
            if not a0 + a1 > 0.0:
                return False
            a0 *= HUGE
            a1 *= HUGE
            marks[sa] = t
            sa += 1
        if b0 + b1 < TINY:
            if not b0 + b1 > 0.0:
                return False
            b0 *= HUGE
            b1 *= HUGE
            marks2[sb] = t
            sb += 1
        alpha[2 * t] = a0
        alpha[2 * t + 1] = a1
        alpha2[2 * t] = b0
        alpha2[2 * t + 1] = b1
    ll[0] = log(a0 + a1) - sa * LOG_HUGE
    ll[1] = log(b0 + b1) - sb * LOG_HUGE
    marked[0] = sa
    marked[1] = sb
    return True


cdef void _backward_pair(
    const double* A, const int32_t* code, const int32_t* code2, Py_ssize_t L, double* ci, double* cs,
    const double* alpha, const int64_t* marks, Py_ssize_t sa, double* di, double* ds,
    const double* alpha2, const int64_t* marks2, Py_ssize_t sb,
) noexcept nogil:
    """:func:`_backward_codes` of two sequences side by side after :func:`_forward_pair`, the
    numbers of two calls: each one's (c_first, c_step, alpha, marks, marks' number)."""
    cdef Py_ssize_t t, c, d, ja = sa - 1, jb = sb - 1, ma, mb
    cdef double g[2]
    cdef double h[2]
    cdef double w[4]
    cdef double q[4]
    cdef double z, y, p0, p1, r0, r1
    g[0] = 1.0
    g[1] = 1.0
    h[0] = 1.0
    h[1] = 1.0
    z = 1.0 / (alpha[2 * (L - 1)] + alpha[2 * (L - 1) + 1])
    y = 1.0 / (alpha2[2 * (L - 1)] + alpha2[2 * (L - 1) + 1])
    ma = _mark(marks, ja)
    mb = _mark(marks2, jb)
    for t in range(L - 1, 0, -1):
        c = code[t] * 4
        d = code2[t] * 4
        w[0] = A[c] * g[0]
        w[1] = A[c + 1] * g[1]
        w[2] = A[c + 2] * g[0]
        w[3] = A[c + 3] * g[1]
        q[0] = A[d] * h[0]
        q[1] = A[d + 1] * h[1]
        q[2] = A[d + 2] * h[0]
        q[3] = A[d + 3] * h[1]
        g[0] = w[0] + w[1]
        g[1] = w[2] + w[3]
        h[0] = q[0] + q[1]
        h[1] = q[2] + q[3]
        if t == ma:
            z *= HUGE
            ja -= 1
            ma = _mark(marks, ja)
        if t == mb:
            y *= HUGE
            jb -= 1
            mb = _mark(marks2, jb)
        _rescaled(&z, g, w)
        _rescaled(&y, h, q)
        p0 = alpha[2 * (t - 1)] * z
        p1 = alpha[2 * (t - 1) + 1] * z
        r0 = alpha2[2 * (t - 1)] * y
        r1 = alpha2[2 * (t - 1) + 1] * y
        cs[c] += p0 * w[0]
        cs[c + 1] += p0 * w[1]
        cs[c + 2] += p1 * w[2]
        cs[c + 3] += p1 * w[3]
        ds[d] += r0 * q[0]
        ds[d + 1] += r0 * q[1]
        ds[d + 2] += r1 * q[2]
        ds[d + 3] += r1 * q[3]
    _first(code[0], g[0], g[1], z, alpha, ci)
    _first(code2[0], h[0], h[1], y, alpha2, di)


cdef void _fold(const double* ci, const double* cs, Py_ssize_t P, Py_ssize_t PE, double* c_init, double* c_emit,
                double* c_trans) noexcept nogil:
    """The per-code sums of :func:`_backward_codes` added to the tables: the step (u, e)'s
    posterior to transition u, its sum over the first level to emission row e."""
    cdef Py_ssize_t u, e, c
    c_init[0] += ci[0]
    c_init[1] += ci[1]
    for e in range(PE):
        c_emit[2 * e] += ci[2 + 2 * e]
        c_emit[2 * e + 1] += ci[3 + 2 * e]
    for u in range(P):
        for e in range(PE):
            c = 4 * (u * PE + e)
            c_emit[2 * e] += cs[c] + cs[c + 2]
            c_emit[2 * e + 1] += cs[c + 1] + cs[c + 3]
            c_trans[4 * u] += cs[c]
            c_trans[4 * u + 1] += cs[c + 1]
            c_trans[4 * u + 2] += cs[c + 2]
            c_trans[4 * u + 3] += cs[c + 3]


# ---- the E-step's items ----

cdef void* scratch(size_t size) noexcept nogil:
    """``size`` zeroed bytes of work space (a few kilobytes: their lack ends the process)."""
    cdef void* p = calloc(size if size > 0 else 1, 1)
    if p == NULL:
        abort()
    return p


cdef double _item2(Py_ssize_t r, Py_ssize_t lo, Py_ssize_t hi, const Tables* tb, const Data* d, double* c_init,
                   double* c_emit, double* c_trans) noexcept nogil:
    """:func:`_item` for K = 2, on the step codes (one 2 x 2 matrix per code, the counts per code,
    folded into the tables at the end); sequences of equal length go two at a time, the second's
    counts into their own sums."""
    cdef Py_ssize_t PE = tb.PE, P = tb.P, NC = P * PE, T1 = max(d.T, 1), NI = 2 + 2 * PE, n, L, i
    # A (NC, 4), buf and buf2 (T, 2), ci and di (NI,), cs and ds (NC, 4)
    cdef double* work = <double*>scratch(sizeof(double) * (12 * NC + 4 * T1 + 2 * NI))
    cdef int64_t* marks = <int64_t*>scratch(sizeof(int64_t) * 2 * T1)
    cdef double* A = work
    cdef double* buf = A + 4 * NC
    cdef double* buf2 = buf + 2 * T1
    cdef double* ci = buf2 + 2 * T1
    cdef double* di = ci + NI
    cdef double* cs = di + NI
    cdef double* ds = cs + 4 * NC
    cdef int64_t* marks2 = marks + T1
    cdef const double* ini = tb.initial + r * 2
    cdef const double* em = tb.emit + r * PE * 2
    cdef const int32_t* code = d.code
    cdef double total = 0.0, la
    cdef double ll[2]
    cdef Py_ssize_t marked[2]
    _step_table(em, tb.trans + r * P * 4, P, PE, A)
    n = lo
    while n < hi:
        L = d.lengths[n]
        if L > 0 and n + 1 < hi and d.lengths[n + 1] == L:
            _forward_pair(ini, em, A, code + n * d.T, code + (n + 1) * d.T, L, buf, marks, buf2, marks2, ll, marked)
            total += ll[0]
            total += ll[1]
            if not total > -INFINITY:
                break
            _backward_pair(A, code + n * d.T, code + (n + 1) * d.T, L, ci, cs, buf, marks, marked[0], di, ds, buf2,
                           marks2, marked[1])
            n += 2
            continue
        if L > 0:
            la = _forward_codes(ini, em, A, code + n * d.T, L, buf, marks, marked)
            total += la
            if not total > -INFINITY:
                break
            _backward_codes(A, code + n * d.T, L, ci, cs, buf, marks, marked[0])
        n += 1
    if total > -INFINITY:
        for i in range(NI):
            ci[i] += di[i]
        for i in range(4 * NC):
            cs[i] += ds[i]
        _fold(ci, cs, P, PE, c_init, c_emit, c_trans)
    else:
        total = -INFINITY
    free(work)
    free(marks)
    return total


cdef double _item(Py_ssize_t r, Py_ssize_t lo, Py_ssize_t hi, const Tables* tb, const Data* d, double* c_init,
                  double* c_emit, double* c_trans) noexcept nogil:
    """Sequences ``lo:hi`` under parameter set ``r`` into this item's counts (initial, emission,
    transition); their log-probability (-inf: zero)."""
    cdef Py_ssize_t K = tb.K, T1 = max(d.T, 1), n, L
    if K == 2:
        return _item2(r, lo, hi, tb, d, c_init, c_emit, c_trans)
    cdef double* alpha = <double*>scratch(sizeof(double) * (2 * T1 * K + T1 + K))
    cdef double* beta = alpha + T1 * K
    cdef double* scale = beta + T1 * K
    cdef double* tmp = scale + T1
    cdef const double* ini = tb.initial + r * K
    cdef const double* em = tb.emit + r * tb.PE * K
    cdef const double* tr = tb.trans + r * tb.P * K * K
    cdef double total = 0.0, ll
    for n in range(lo, hi):
        L = d.lengths[n]
        if L > 0:
            ll = _forward(ini, em, tr, K, d.eidx + n * d.T, d.tidx + n * d.T, L, alpha, scale)
            if ll > -INFINITY:
                _backward(em, tr, K, d.eidx + n * d.T, d.tidx + n * d.T, L, 1.0, c_init, c_emit, c_trans, alpha,
                          beta, scale, tmp)
            total += ll
            if not total > -INFINITY:
                total = -INFINITY
                break
    free(alpha)
    return total


cdef inline Py_ssize_t _slot(Py_ssize_t item, Py_ssize_t chunk, const Sums* sums) noexcept nogil:
    """Item ``item`` (= r * C + c: parameter set r, sequences c * chunk onwards): its own sums
    zeroed; the first of its sequences."""
    memset(sums.pi + item * sums.ni, 0, sizeof(double) * sums.ni)
    memset(sums.pe + item * sums.ne, 0, sizeof(double) * sums.ne)
    memset(sums.pt + item * sums.nt, 0, sizeof(double) * sums.nt)
    return (item % sums.C) * chunk


cdef void estep_range(
    Py_ssize_t first, Py_ssize_t last, Py_ssize_t chunk, const Tables* tables, const Data* data,
    const unsigned char* active, Sums* sums,
) noexcept nogil:
    """Items ``first:last`` (item = r * C + c: parameter set r, sequences c * chunk onwards) of the
    active sets into their own ``sums``."""
    cdef Py_ssize_t item, lo
    for item in range(first, last):
        if active[item // sums.C]:
            lo = _slot(item, chunk, sums)
            sums.ll[item] = _item(
                item // sums.C, lo, min(data.N, lo + chunk), tables, data,
                sums.pi + item * sums.ni, sums.pe + item * sums.ne, sums.pt + item * sums.nt,
            )


cdef double _mixture_item(
    Py_ssize_t r, Py_ssize_t lo, Py_ssize_t hi, Py_ssize_t M, const Tables* tb, const Data* d, double* c_init,
    double* c_emit, double* c_trans, double* seq_ll,
) noexcept nogil:
    """Sequences ``lo:hi`` under the M types of parameter set ``r`` (sets ``r * M + m``; ``initial`` the
    joint P(type, S_1)): per sequence every type's forward pass, the responsibilities, then each
    type's backward pass weighted by its responsibility, counts into type m's part of the counts
    ((M, K), (M, PE, K), (M, P, K, K)) and log P(sequence n, type m) into ``seq_ll[m, n]`` ((M, N));
    the mixture log-probability (-inf: zero)."""
    cdef Py_ssize_t K = tb.K, PE = tb.PE, P = tb.P, T1 = max(d.T, 1), n, m, q, L
    cdef Py_ssize_t si = K, se = PE * K, st = P * K * K
    cdef double* alpha = <double*>scratch(sizeof(double) * (M * T1 * K + T1 * K + M * T1 + K + M))
    cdef double* beta = alpha + M * T1 * K
    cdef double* scale = beta + T1 * K
    cdef double* tmp = scale + M * T1
    cdef double* v = tmp + K
    cdef const int32_t* eidx
    cdef const int32_t* tidx
    cdef double total = 0.0, best, s, lse, w, lm
    for n in range(lo, hi):
        L = d.lengths[n]
        if L <= 0:
            for m in range(M):
                seq_ll[m * d.N + n] = 0.0
            continue
        eidx = d.eidx + n * d.T
        tidx = d.tidx + n * d.T
        best = -INFINITY
        for m in range(M):
            q = r * M + m
            if K == 2:
                lm = _forward2(tb.initial + q * si, tb.emit + q * se, tb.trans + q * st, eidx, tidx, L,
                               alpha + m * T1 * K)
            else:
                lm = _forward(tb.initial + q * si, tb.emit + q * se, tb.trans + q * st, K, eidx, tidx, L,
                              alpha + m * T1 * K, scale + m * T1)
            seq_ll[m * d.N + n] = lm
            v[m] = lm
            if v[m] > best:
                best = v[m]
        if not best > -INFINITY:
            total = -INFINITY
            break
        s = 0.0
        for m in range(M):
            s += exp(v[m] - best)
        lse = best + log(s)
        total += lse
        for m in range(M):
            w = exp(v[m] - lse)
            if w > 0.0:
                q = r * M + m
                if K == 2:
                    _backward2(tb.emit + q * se, tb.trans + q * st, eidx, tidx, L, w, c_init + m * si,
                               c_emit + m * se, c_trans + m * st, alpha + m * T1 * K)
                else:
                    _backward(tb.emit + q * se, tb.trans + q * st, K, eidx, tidx, L, w, c_init + m * si,
                              c_emit + m * se, c_trans + m * st, alpha + m * T1 * K, beta, scale + m * T1, tmp)
    free(alpha)
    return total


# ---- from Python: the arrays' data ----

cdef double* array_data(object a) except NULL:
    """The data of ``a``, a C-contiguous float64 array (written in place)."""
    if not a.flags.c_contiguous:
        raise ValueError("a C-contiguous array is needed")
    cdef double[::1] v = a.reshape(-1)
    return &v[0]


cdef int tables_from(tuple tables, Tables* out, list keep) except -1:
    """``out`` from (initial (R, K), emit (R, PE, K), trans (R, P, K, K)); the memoryviews that
    hold the data go to ``keep``."""
    initial, emit, trans = tables
    cdef const double[:, ::1] i = initial
    cdef const double[:, :, ::1] e = emit
    cdef const double[:, :, :, ::1] t = trans
    keep.extend((i, e, t))
    out.K, out.PE, out.P = i.shape[1], e.shape[1], t.shape[1]
    out.initial, out.emit, out.trans = &i[0, 0], &e[0, 0, 0], &t[0, 0, 0, 0]
    return 0


cdef int data_from(tuple data, Data* out, list keep) except -1:
    """``out`` from (eidx, tidx, code, lengths) or (eidx, tidx, lengths) (no step codes)."""
    cdef const int32_t[:, ::1] e = data[0]
    cdef const int32_t[:, ::1] t = data[1]
    cdef const int32_t[:, ::1] c
    cdef const int64_t[::1] n = data[len(data) - 1]
    keep.extend((e, t, n))
    out.N, out.T = e.shape[0], e.shape[1]
    out.eidx, out.tidx, out.lengths = &e[0, 0], &t[0, 0], &n[0]
    out.code = NULL
    if len(data) == 4:
        c = data[2]
        keep.append(c)
        out.code = &c[0, 0]
    return 0


cdef int sums_from(tuple sums, Py_ssize_t C, Sums* out) except -1:
    """``out`` from the items' sums (ll (R, C), initial, emission, transition (R, C, ...))."""
    ll, pi, pe, pt = sums
    R = ll.shape[0]
    out.C = C
    out.ni, out.ne, out.nt = pi.size // max(R * C, 1), pe.size // max(R * C, 1), pt.size // max(R * C, 1)
    out.ll, out.pi, out.pe, out.pt = array_data(ll), array_data(pi), array_data(pe), array_data(pt)
    return 0


def estep_items(Py_ssize_t first, Py_ssize_t last, Py_ssize_t C, Py_ssize_t chunk, tuple tables, tuple data, active,
                tuple sums):
    """Items ``first:last`` (item = r * C + c: parameter set r, sequences c*chunk onwards) into their
    own ``sums`` (log-likelihood (R, C), initial, emission and transition counts per item).
    ``tables``: (initial, emit, trans); ``data``: (eidx, tidx, code, lengths)."""
    cdef Tables tb
    cdef Data d
    cdef Sums s
    keep = []
    cdef const unsigned char[::1] act = np.asarray(active).view(np.uint8)
    tables_from(tables, &tb, keep)
    data_from(data, &d, keep)
    if d.code == NULL:
        raise ValueError("the E-step's data need the step codes: (eidx, tidx, code, lengths)")
    sums_from(sums, C, &s)
    with nogil:
        estep_range(first, last, chunk, &tb, &d, &act[0], &s)


def mixture_items(Py_ssize_t first, Py_ssize_t last, Py_ssize_t C, Py_ssize_t chunk, Py_ssize_t M, tuple tables,
                  tuple data, active, tuple sums, seq_ll):
    """Items ``first:last`` of a mixture E-step (item = r * C + c) into their own ``sums``: ``ll`` (R, C),
    ``pi`` (R, C, M, K), ``pe`` (R, C, M, PE, K), ``pt`` (R, C, M, P, K, K); ``seq_ll`` (R, M, N).
    ``data``: (eidx, tidx, lengths)."""
    cdef Tables tb
    cdef Data d
    cdef Sums s
    cdef Py_ssize_t item, lo
    keep = []
    cdef const unsigned char[::1] act = np.asarray(active).view(np.uint8)
    tables_from(tables, &tb, keep)
    data_from(data, &d, keep)
    sums_from(sums, C, &s)
    cdef double* seq = array_data(seq_ll)
    with nogil:
        for item in range(first, last):
            if act[item // C]:
                lo = _slot(item, chunk, &s)
                s.ll[item] = _mixture_item(
                    item // C, lo, min(d.N, lo + chunk), M, &tb, &d, s.pi + item * s.ni, s.pe + item * s.ne,
                    s.pt + item * s.nt, seq + (item // C) * M * d.N,
                )


def each_items(Py_ssize_t lo, Py_ssize_t hi, const int64_t[::1] pidx, tuple tables, tuple data, active, tuple out):
    """Sequences ``lo:hi``, sequence n under parameter set ``pidx[n]`` of ``tables`` (initial, emit,
    trans), each into its own counts ``ci[n]``, ``ce[n]``, ``ct[n]`` and log-probability ``ll[n]``
    (``out``: (ll, ci, ce, ct); skipped where ``active[n]`` is false).  ``data``: (eidx, tidx, lengths)."""
    cdef Tables tb
    cdef Data d
    cdef Sums s
    cdef Py_ssize_t n, K, q, L, T1
    cdef double* alpha
    keep = []
    cdef const unsigned char[::1] act = np.asarray(active).view(np.uint8)
    tables_from(tables, &tb, keep)
    data_from(data, &d, keep)
    sums_from(out, 1, &s)
    K, T1 = tb.K, max(d.T, 1)
    with nogil:
        alpha = <double*>scratch(sizeof(double) * (2 * T1 * K + T1 + K))
        for n in range(lo, hi):
            memset(s.pi + n * s.ni, 0, sizeof(double) * s.ni)
            memset(s.pe + n * s.ne, 0, sizeof(double) * s.ne)
            memset(s.pt + n * s.nt, 0, sizeof(double) * s.nt)
            s.ll[n] = 0.0
            L = d.lengths[n]
            if not act[n] or L <= 0:
                continue
            s.ll[n] = _sequence(pidx[n], n, &tb, &d, L, s.pi + n * s.ni, s.pe + n * s.ne, s.pt + n * s.nt, alpha)
            if not s.ll[n] > -INFINITY:
                memset(s.pi + n * s.ni, 0, sizeof(double) * s.ni)
                memset(s.pe + n * s.ne, 0, sizeof(double) * s.ne)
                memset(s.pt + n * s.nt, 0, sizeof(double) * s.nt)
        free(alpha)


cdef double _sequence(Py_ssize_t q, Py_ssize_t n, const Tables* tb, const Data* d, Py_ssize_t L, double* c_init,
                      double* c_emit, double* c_trans, double* alpha) noexcept nogil:
    """Sequence ``n`` under parameter set ``q``: its posterior counts added to the counts, its
    log-probability (-inf: zero, nothing added).  ``alpha``: work space (2 T K + T + K)."""
    cdef Py_ssize_t K = tb.K, T1 = max(d.T, 1)
    cdef const double* ini = tb.initial + q * K
    cdef const double* em = tb.emit + q * tb.PE * K
    cdef const double* tr = tb.trans + q * tb.P * K * K
    cdef const int32_t* eidx = d.eidx + n * d.T
    cdef const int32_t* tidx = d.tidx + n * d.T
    cdef double ll
    if K == 2:
        ll = _forward2(ini, em, tr, eidx, tidx, L, alpha)
        if ll > -INFINITY:
            _backward2(em, tr, eidx, tidx, L, 1.0, c_init, c_emit, c_trans, alpha)
        return ll
    ll = _forward(ini, em, tr, K, eidx, tidx, L, alpha, alpha + 2 * T1 * K)
    if ll > -INFINITY:
        _backward(em, tr, K, eidx, tidx, L, 1.0, c_init, c_emit, c_trans, alpha, alpha + T1 * K, alpha + 2 * T1 * K,
                  alpha + 2 * T1 * K + T1)
    return ll


cdef void reduce_sums(const unsigned char* active, Py_ssize_t R, const Sums* sums, double* loglik, double* c_init,
                      double* c_emit, double* c_trans) noexcept nogil:
    """Add the items' sums per parameter set, in item order, into ``loglik`` (R,) and the counts
    (R, ni), (R, ne), (R, nt), cell by cell; 0 and zero counts for an inactive set, -inf and zero
    counts for a set with an item of probability zero."""
    cdef Py_ssize_t C = sums.C, r, c, x, item
    cdef bint dead
    for r in range(R):
        loglik[r] = 0.0
        memset(c_init + r * sums.ni, 0, sizeof(double) * sums.ni)
        memset(c_emit + r * sums.ne, 0, sizeof(double) * sums.ne)
        memset(c_trans + r * sums.nt, 0, sizeof(double) * sums.nt)
        if not active[r]:
            continue
        dead = False
        for c in range(C):
            if not sums.ll[r * C + c] > -INFINITY:
                dead = True
        if dead:
            loglik[r] = -INFINITY
            continue
        for c in range(C):
            item = r * C + c
            loglik[r] += sums.ll[item]
            for x in range(sums.ni):
                c_init[r * sums.ni + x] += sums.pi[item * sums.ni + x]
            for x in range(sums.ne):
                c_emit[r * sums.ne + x] += sums.pe[item * sums.ne + x]
            for x in range(sums.nt):
                c_trans[r * sums.nt + x] += sums.pt[item * sums.nt + x]


def reduce_items(active, tuple sums, loglik, c_init, c_emit, c_trans):
    """Add the items' ``sums`` (ll (R, C) and the counts (R, C, ...)) per parameter set, in item order,
    into ``loglik`` (R,) and the counts ``c_init``, ``c_emit``, ``c_trans`` (R, ...)."""
    cdef Sums s
    cdef const unsigned char[::1] act = np.asarray(active).view(np.uint8)
    sums_from(sums, sums[0].shape[1], &s)
    cdef double* ll = array_data(loglik)
    cdef double* ci = array_data(c_init)
    cdef double* ce = array_data(c_emit)
    cdef double* ct = array_data(c_trans)
    cdef Py_ssize_t R = sums[0].shape[0]
    with nogil:
        reduce_sums(&act[0], R, &s, ll, ci, ce, ct)
