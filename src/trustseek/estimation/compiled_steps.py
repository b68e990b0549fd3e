"""The steps of the compiled run (:mod:`.compiled_run`) on flat cells, in numba: the E-step of one
parameter set (:mod:`.kernels`' pass over the same items in the same order: the numbers of
:meth:`~.estep.Workspace.estep`), the M-step, projection and log-prior of
:class:`~.structure.Structure`, and the SQUAREM point of :func:`.em._extrapolate`.

A parameter set is flat (:meth:`~.spec.Params.vector`); ``model`` is (K, Ue, M, Ut, prior, emission
table, transition table) and ``ev`` the E-step's (data, buffers).  Compile time: numba compiles each
function another calls into a library of its own with all it calls, so small steps are inlined
(``inline="always"``) and arrays copied cell by cell (an array assignment's shape check compiles an
error message into every library above it); large functions stay functions.
"""

from __future__ import annotations

import math

import numpy as np

from ..compiled import prange
from . import kernels
from .em import SHRINK
from .structure import FLOOR, PROJECT_FLOOR

njit = kernels.njit
CHUNK = kernels.CHUNK
PARALLEL_ITEMS = 8  # items (of CHUNK sequences) from which the E-step runs on numba's threads


@njit(cache=True, nogil=True, inline="always")  # no kernel of its own in the cache
def estep_buffers(K, PE, U1, C, threaded):
    """The E-step's buffers for ``C`` items (:meth:`.kernels.Kernel.run`'s layout, R = 1): the tables,
    the active flag, the items' sums and totals, and whether the items go on numba's threads."""
    trans = np.zeros((1, U1, K, K))
    for k in range(K):
        trans[0, U1 - 1, k, k] = 1.0
    sums = (np.empty((1, C)), np.empty((1, C, K)), np.empty((1, C, PE, K)), np.empty((1, C, U1, K, K)))
    totals = (np.empty(1), np.empty((1, K)), np.empty((1, PE, K)), np.empty((1, U1, K, K)))
    return (np.empty((1, K)), np.empty((1, PE, K)), trans), np.ones(1, dtype=np.bool_), sums, totals, threaded


@njit(cache=True, nogil=True, parallel=True)
def _items_parallel(C, tables, data, active, sums):
    """The items on numba's threads, each into its own sums (the same numbers on any number of threads)."""
    for c in prange(C):
        i = np.int64(c)  # prange counts in uint64, and CHUNK would be a literal: Kernel.run's variant, not a second
        kernels.estep_items(i, i + 1, C, np.int64(CHUNK), tables, data, active, sums)


@njit(cache=True, nogil=True, inline="always")
def _estep(pi, em, tr, data, bufs, ci, cem, ctr):
    """E-step of one parameter set: counts into ``ci`` (K,), ``cem`` (Ue, K, M), ``ctr`` (Ut, K, K);
    the log-likelihood (-inf: probability zero).  ``bufs``: :func:`estep_buffers`."""
    tables, active, sums, totals, threaded = bufs
    ini, emit, trans = tables
    Ue, K, M = em.shape
    Ut = tr.shape[0]
    for u in range(Ue):
        for k in range(K):
            for m in range(M):
                emit[0, u * M + m, k] = em[u, k, m]
    for k in range(K):
        ini[0, k] = pi[k]
        emit[0, Ue * M, k] = 1.0
    for u in range(Ut):
        for i in range(K):
            for j in range(K):
                trans[0, u, i, j] = tr[u, i, j]
    C = sums[0].shape[1]
    if threaded and C >= PARALLEL_ITEMS:
        _items_parallel(C, tables, data, active, sums)
    else:
        kernels.estep_items(np.int64(0), C, C, np.int64(CHUNK), tables, data, active, sums)
    ll, tot_i, tot_e, tot_t = totals
    U1 = trans.shape[1]
    PE = emit.shape[1]
    kernels._reduce(
        active,
        sums[0],
        sums[1].reshape((1, C, K)),
        sums[2].reshape((1, C, PE * K)),
        sums[3].reshape((1, C, U1 * K * K)),
        ll,
        tot_i,
        tot_e.reshape((1, PE * K)),
        tot_t.reshape((1, U1 * K * K)),
    )
    for k in range(K):
        ci[k] = tot_i[0, k]
    for u in range(Ue):
        for k in range(K):
            for m in range(M):
                cem[u, k, m] = tot_e[0, u * M + m, k]
    for u in range(Ut):
        for i in range(K):
            for j in range(K):
                ctr[u, i, j] = tot_t[0, u, i, j]
    return ll[0]


@njit(cache=True, nogil=True, inline="always")  # no kernel of its own in the cache
def _rows(num, prev, tab, out):
    """Each group's rows ``num`` (G, K, M) with the fixed cells set and the free ones scaled to the free
    mass (summing to 0: ``prev``'s row), into ``out`` by group."""
    group, rep, gfixed, gvalues, mass = tab
    G, K, M = num.shape
    for g in range(G):
        for k in range(K):
            tot = 0.0
            for m in range(M):
                if not gfixed[g, k, m]:
                    tot += num[g, k, m]
            for m in range(M):
                if gfixed[g, k, m]:
                    num[g, k, m] = gvalues[g, k, m]
                elif tot > 0:
                    num[g, k, m] = num[g, k, m] / tot * mass[g, k]
                else:
                    num[g, k, m] = prev[rep[g], k, m]
    for u in range(out.shape[0]):
        for k in range(K):
            for m in range(M):
                out[u, k, m] = num[group[u], k, m]


@njit(cache=True, nogil=True, inline="always")
def _table_mstep(counts, prior, prev, tab, out):
    """:meth:`.structure.Table.mstep` of one table into ``out``."""
    group = tab[0]
    U, K, M = counts.shape
    cg = np.zeros((tab[1].shape[0], K, M))
    for u in range(U):
        for k in range(K):
            for m in range(M):
                cg[group[u], k, m] += counts[u, k, m]
    _rows(cg + prior, prev, tab, out)


@njit(cache=True, nogil=True, inline="always")
def _mstep(counts, prior, params, emt, trt, out):
    """The M-step (:meth:`.structure.Structure.mstep`) from the ``counts`` (initial, emission,
    transition) at ``params`` (the same three tables) into the three tables ``out``."""
    ci, cem, ctr = counts
    pi, em, tr = params
    qpi, qem, qtr = out
    tot = 0.0
    for k in range(len(ci)):
        tot += ci[k] + prior
    for k in range(len(ci)):
        qpi[k] = (ci[k] + prior) / tot if tot > 0 else pi[k]
    _table_mstep(cem, prior, em, emt, qem)
    _table_mstep(ctr, prior, tr, trt, qtr)


@njit(cache=True, nogil=True, inline="always")
def _table_project(p, tab, out):
    """:meth:`.structure.Table.project` of one table into ``out`` (a free cell counts at least PROJECT_FLOOR)."""
    rep = tab[1]
    num = np.empty((rep.shape[0], p.shape[1], p.shape[2]))
    for g in range(rep.shape[0]):
        for k in range(p.shape[1]):
            for m in range(p.shape[2]):
                num[g, k, m] = np.maximum(p[rep[g], k, m], PROJECT_FLOOR)
    _rows(num, p, tab, out)


@njit(cache=True, nogil=True, inline="always")
def _table_log_prior(p, prior, tab):
    _group, rep, gfixed, _gvalues, _mass = tab
    G, K, M = gfixed.shape
    s = 0.0
    for g in range(G):
        for k in range(K):
            for m in range(M):
                if not gfixed[g, k, m]:
                    s += math.log(max(p[rep[g], k, m], FLOOR))
    return prior * s


@njit(cache=True, nogil=True, inline="always")
def _log_prior(pi, em, tr, prior, emt, trt):
    """:meth:`.structure.Structure.log_prior`."""
    if prior == 0:
        return 0.0
    s = 0.0
    for k in range(len(pi)):
        s += math.log(max(pi[k], FLOOR))
    return prior * s + _table_log_prior(em, prior, emt) + _table_log_prior(tr, prior, trt)


@njit(cache=True, nogil=True)
def extrapolate(p0, p1, p2, model, out):
    """The SQUAREM point of :func:`.em._extrapolate` from the flat cells ``p0 -> p1 -> p2`` into the
    flat ``out`` (projected); whether it is worth trying (step length below -1)."""
    K, Ue, M, Ut, _prior, emt, trt = model
    rr = 0.0
    vv = 0.0
    for i in range(len(p0)):
        r = p1[i] - p0[i]
        v = p2[i] - 2 * p1[i] + p0[i]
        rr += r * r
        vv += v * v
    nv = math.sqrt(vv)
    step = -math.sqrt(rr) / nv if nv > 0 else -1.0
    if not step < -1.0:
        return False
    x = np.empty(len(p0))
    for i in range(len(p0)):
        r = p1[i] - p0[i]
        v = p2[i] - 2 * p1[i] + p0[i]
        x[i] = max(p0[i] - 2 * step * r + step * step * v, SHRINK * p2[i])
    s = 0.0
    for k in range(K):
        s += max(x[k], PROJECT_FLOOR)
    for k in range(K):
        out[k] = max(x[k], PROJECT_FLOOR) / s
    a, b = K, K + Ue * K * M
    _table_project(x[a:b].reshape((Ue, K, M)), emt, out[a:b].reshape((Ue, K, M)))
    _table_project(x[b:].reshape((Ut, K, K)), trt, out[b:].reshape((Ut, K, K)))
    return True


@njit(cache=True, nogil=True, inline="always")  # no kernel of its own in the cache
def copy(dst, src):
    """``dst[:] = src`` for 1-D arrays, cell by cell (see the module)."""
    for i in range(len(src)):
        dst[i] = src[i]


@njit(cache=True, nogil=True, inline="always")
def _views(flat, K, Ue, M, Ut):
    a, b = K, K + Ue * K * M
    return flat[:a], flat[a:b].reshape((Ue, K, M)), flat[b:].reshape((Ut, K, K))


@njit(cache=True, nogil=True)
def evaluate(flat, model, ev, counts):
    """E-step at the flat cells ``flat``, its counts into ``counts`` (flat); (log-likelihood, objective)."""
    K, Ue, M, Ut, prior, emt, trt = model
    data, bufs = ev
    pi, em, tr = _views(flat, K, Ue, M, Ut)
    ci, cem, ctr = _views(counts, K, Ue, M, Ut)
    ll = _estep(pi, em, tr, data, bufs, ci, cem, ctr)
    return ll, ll + _log_prior(pi, em, tr, prior, emt, trt)


@njit(cache=True, nogil=True)
def em_step(flat, counts, model, out):
    """The point one EM step on from ``flat`` with E-step counts ``counts``, into ``out``."""
    K, Ue, M, Ut, prior, emt, trt = model
    _mstep(_views(counts, K, Ue, M, Ut), prior, _views(flat, K, Ue, M, Ut), emt, trt, _views(out, K, Ue, M, Ut))
