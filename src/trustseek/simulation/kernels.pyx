"""Compiled loops of the simulation engine (Cython, built with the package): the common case of a
block, and the urn schedule.

:func:`run_block` runs one block for a chunk of participants with two trust levels when the robot
asks below a threshold on its scalar belief (:data:`THRESHOLD`, the bounds of
:func:`~trustseek.policies.base.ask_bounds`; ``paper`` or ``bayes`` update) or with fixed
probabilities per complexity (:data:`FIXED`).  It does per participant exactly the arithmetic of
the engine's numpy loop on uniforms drawn beforehand in the same order, so both give the same
simulation to the last bit.  :func:`urn_schedule` is
:func:`~trustseek.simulation.trial_orders.schedule_counts`'s urn for two complexities.
"""

from libc.math cimport NAN
from libc.stdint cimport int8_t, int64_t

import numpy as np

cdef enum:
    _THRESHOLD = 0
    _FIXED = 1
    _NO_BELIEF = 0
    _PAPER = 1
    _BAYES = 2

THRESHOLD = _THRESHOLD  # ask when x < bounds[C]
FIXED = _FIXED  # ask with probability p_ask[C]

NO_BELIEF = _NO_BELIEF  # nothing tracks the belief (recorded as NaN)
PAPER = _PAPER
BAYES = _BAYES


def run_block(sched, uniforms, policy, beliefs, x, tables, trust, codes, Py_ssize_t t0, records):
    """One block of ``sched``'s trials (``sched``: (T, m) int64 complexity indices).

    ``uniforms``: (u, upol, draws): u (T, 3, m), the supervisors' uniforms (human action,
    experience, next trust); upol (D, m), the policy's, one row per trial that draws (FIXED mode);
    draws (T,) bool, whether trial t draws a row of upol.  ``policy``: (mode, act), THRESHOLD or
    FIXED with (N,) bounds or ask probabilities.  ``beliefs``: (belief, a0, slope, lik_high,
    lik_low), NO_BELIEF, PAPER or BAYES and the ScalarBelief tables (unused without a belief).
    ``x``: (m,) the robot's belief and ``trust`` (m,) int64 the hidden trust, both updated in
    place.  ``tables``: (p_int, p_reliable, trust_low, poff), the engine's flat tables and (m,)
    parameter-row offsets (zeros for a pooled population).  ``codes``: (T_total, m) int8 outcome
    codes, rows t0.. written.  ``records``: (record, rc, ra, rh, re, rt, rb), the (T_total, m)
    records, written when ``record``."""
    u, upol, draws = uniforms
    mode, act = policy
    belief, a0, slope, lik_high, lik_low = beliefs
    p_int, p_reliable, trust_low, poff = tables
    record, rc, ra, rh, re, rt, rb = records
    _block(
        sched, u, upol, np.asarray(draws, dtype=np.uint8), mode, act, belief, a0, slope, lik_high, lik_low,
        x, p_int, p_reliable, trust_low, poff, trust, codes, t0, record, rc, ra, rh, re, rt, rb,
    )


cdef void _block(
    const int64_t[:, :] sched, const double[:, :, :] u, const double[:, :] upol, const unsigned char[:] draws,
    int mode, const double[:] act, int belief, const double[:] a0, const double[:] slope,
    const double[:] lik_high, const double[:] lik_low, double[:] x, const double[:] p_int,
    const double[:] p_reliable, const double[:] trust_low, const int64_t[:] poff, int64_t[:] trust,
    int8_t[:, :] codes, Py_ssize_t t0, bint record, int8_t[:, :] rc, int8_t[:, :] ra, int8_t[:, :] rh,
    int8_t[:, :] re, int8_t[:, :] rt, double[:, :] rb,
) noexcept nogil:
    cdef Py_ssize_t T = sched.shape[0], m = sched.shape[1], k = 0, t, i, tg
    cdef int64_t c, a, ca, cap, tr, o, e, kt, ko, kb
    cdef bint draw
    cdef double xi, num, z
    for t in range(T):
        tg = t0 + t
        draw = draws[t]
        for i in range(m):
            c = sched[t, i]
            xi = x[i]
            if mode == _THRESHOLD:
                a = 1 if xi < act[c] else 0
            elif draw:
                a = 1 if upol[k, i] < act[c] else 0
            else:
                a = 1 if act[c] == 1.0 else 0
            ca = c * 2 + a
            cap = ca + poff[i]
            tr = trust[i]
            o = 1 if u[t, 0, i] >= p_int[cap * 2 + tr] else 0
            e = 1 if u[t, 1, i] < p_reliable[ca * 2 + o] else 0
            kt = (cap * 2 + e) * 2 + tr
            if record:
                rc[tg, i] = <int8_t>c
                ra[tg, i] = <int8_t>a
                rh[tg, i] = <int8_t>o
                re[tg, i] = <int8_t>e
                rt[tg, i] = <int8_t>tr
                rb[tg, i] = xi if belief != _NO_BELIEF else NAN
            codes[tg, i] = <int8_t>((a * 2 + o) * 2 + e)
            trust[i] = 1 if u[t, 2, i] >= trust_low[kt] else 0
            if belief != _NO_BELIEF:
                if belief == _BAYES:
                    ko = ca * 2 + o
                    num = xi * lik_high[ko]
                    z = num + (1.0 - xi) * lik_low[ko]
                    if z > 0:
                        xi = num / z
                kb = ca * 2 + e
                x[i] = a0[kb] + slope[kb] * xi
        if draw:
            k += 1


def urn_schedule(const double[:, :] u, double first, int8_t[:, :] out):
    """Two complexities: trial t of participant i is complexity 1 when ``u[t, i]`` times the
    number of trials left is at least the number of complexity-0 trials left (``first`` at the
    start); ``out`` (T, n) int8."""
    cdef Py_ssize_t T = u.shape[0], n = u.shape[1], i, t
    cdef double remaining
    cdef int64_t left
    with nogil:
        for i in range(n):
            remaining = first
            left = T
            for t in range(T):
                if u[t, i] * left >= remaining:
                    out[t, i] = 1
                else:
                    out[t, i] = 0
                    remaining -= 1.0
                left -= 1
