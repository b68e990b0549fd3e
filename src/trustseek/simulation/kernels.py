"""Compiled loops of the simulation engine (numba): the common case of a block, and the urn schedule.

:func:`run_block` runs one block for a chunk of participants with two trust levels when the robot
asks below a threshold on its scalar belief (:data:`THRESHOLD`, the bounds of
:func:`~trustseek.policies.base.ask_bounds`; ``paper`` or ``bayes`` update) or with fixed
probabilities per complexity (:data:`FIXED`).  It does per participant exactly the arithmetic of
the engine's numpy loop on uniforms drawn beforehand in the same order, so both give the same
simulation to the last bit.  :func:`urn_schedule` is
:func:`~trustseek.simulation.trial_orders.schedule_counts`'s urn for two complexities.
"""

from __future__ import annotations

import numpy as np

from ..compiled import AVAILABLE as AVAILABLE  # callers read kernels.AVAILABLE
from ..compiled import loaded, njit


def worth_calling() -> bool:
    """Whether the compiled loops run: numba is installed and this process has loaded it already
    (a fit or :func:`~trustseek.compiled.load` did).  They give the numpy loop's simulation to the
    last bit and save only its per-call overhead (on a large run both draw about 30 M trials/s),
    so a process that has not loaded numba, a one-off ``trustseek simulate`` among them, does not
    pay its load (0.3-0.5 s) or, in a fresh environment, its compile."""
    return AVAILABLE and loaded()


THRESHOLD = 0  # ask when x < bounds[C]
FIXED = 1  # ask with probability p_ask[C]

NO_BELIEF = 0  # nothing tracks the belief (recorded as NaN)
PAPER = 1
BAYES = 2


@njit(cache=True, nogil=True)
def run_block(
    sched,  # (T, m) int64 complexity indices
    uniforms,  # (u, upol, draws), see below
    policy,  # (mode, act): THRESHOLD or FIXED; (N,) bounds (THRESHOLD) or ask probabilities (FIXED)
    beliefs,  # (belief, a0, slope, lik_high, lik_low): NO_BELIEF, PAPER or BAYES, the ScalarBelief tables
    x,  # (m,) the robot's belief, updated in place
    tables,  # (p_int, p_reliable, trust_low, poff): the engine's flat tables, (m,) parameter-row offsets
    trust,  # (m,) int64 hidden trust, updated in place
    codes,  # (T_total, m) int8 outcome codes, rows t0.. written
    t0,
    records,  # (record, rc, ra, rh, re, rt, rb): the (T_total, m) records, written when ``record``
):
    """One block of ``sched``'s trials.  ``uniforms``: u (T, 3, m), the supervisors' uniforms
    (human action, experience, next trust); upol (D, m), the policy's, one row per trial that
    draws (FIXED mode); draws (T,) bool, whether trial t draws a row of upol.  The tables of the
    belief are unused without one; ``poff`` is zeros for a pooled population."""
    u, upol, draws = uniforms
    mode, act = policy
    belief, a0, slope, lik_high, lik_low = beliefs
    p_int, p_reliable, trust_low, poff = tables
    record, rc, ra, rh, re, rt, rb = records
    T, m = sched.shape
    k = 0
    for t in range(T):
        tg = t0 + t
        draw = draws[t]
        for i in range(m):
            c = sched[t, i]
            xi = x[i]
            if mode == THRESHOLD:
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
                rc[tg, i] = c
                ra[tg, i] = a
                rh[tg, i] = o
                re[tg, i] = e
                rt[tg, i] = tr
                rb[tg, i] = xi if belief != NO_BELIEF else np.nan
            codes[tg, i] = (a * 2 + o) * 2 + e
            trust[i] = 1 if u[t, 2, i] >= trust_low[kt] else 0
            if belief != NO_BELIEF:
                if belief == BAYES:
                    ko = ca * 2 + o
                    num = xi * lik_high[ko]
                    z = num + (1.0 - xi) * lik_low[ko]
                    if z > 0:
                        xi = num / z
                kb = ca * 2 + e
                x[i] = a0[kb] + slope[kb] * xi
        if draw:
            k += 1


@njit(cache=True, nogil=True)
def urn_schedule(u, first, out):
    """Two complexities: trial t of participant i is complexity 1 when ``u[t, i]`` times the
    number of trials left is at least the number of complexity-0 trials left (``first`` at the
    start); ``out`` (T, n) int8."""
    T, n = u.shape
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
