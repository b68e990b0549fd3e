"""The steps of the compiled run (:mod:`.compiled_run`) on flat cells, in numba: the E-step of one
parameter set (the compiled pass of :mod:`.kernels` over the same items in the same order, so its
numbers are those of :meth:`~.estep.Workspace.estep`), the M-step, the projection and the log-prior
of :class:`~.structure.Structure`, and the SQUAREM point of :func:`.em._extrapolate`.

A parameter set is flat: the initial distribution (K,), the emission rows (Ue, K, M) and the
transition rows (Ut, K, K) one after the other (:meth:`~.spec.Params.vector`); ``model`` is the
tuple (K, Ue, M, Ut, prior, emission table, transition table) and ``ev`` the E-step's (data,
buffers).
"""

from __future__ import annotations

import math

import numpy as np

from . import kernels
from .em import SHRINK
from .structure import FLOOR, PROJECT_FLOOR

njit = kernels.njit
CHUNK = kernels.CHUNK


@njit(cache=True, nogil=True)
def _estep(pi, em, tr, data, bufs, ci, cem, ctr):
    """E-step of one parameter set: counts into ``ci`` (K,), ``cem`` (Ue, K, M), ``ctr`` (Ut, K, K);
    the log-likelihood (-inf: probability zero, counts zero).  Items of :data:`CHUNK` sequences
    summed in item order, as :meth:`.kernels.Kernel.run` does."""
    eidx = data[0]
    ini, emit, trans, ll, pin, pe, pt = bufs
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
        trans[0, u] = tr[u]
    N = eidx.shape[0]
    C = ll.shape[0]
    for c in range(C):
        lo = c * CHUNK
        pin[c] = 0.0
        pe[c] = 0.0
        pt[c] = 0.0
        # np.int64(0), not the literal 0: numba would compile a second _item (and _sequence) for Literal[int](0)
        ll[c] = kernels._item(np.int64(0), lo, min(N, lo + CHUNK), (ini, emit, trans), data, (pin[c], pe[c], pt[c]))
    ci[:] = 0.0
    cem[:] = 0.0
    ctr[:] = 0.0
    for c in range(C):
        if not ll[c] > -math.inf:
            return -math.inf
    total = 0.0
    tot_i = np.zeros(K)
    tot_e = np.zeros((Ue * M + 1, K))
    tot_t = np.zeros((Ut + 1, K, K))
    for c in range(C):
        total += ll[c]
        tot_i += pin[c]
        tot_e += pe[c]
        tot_t += pt[c]
    ci[:] = tot_i
    for u in range(Ue):
        for k in range(K):
            for m in range(M):
                cem[u, k, m] = tot_e[u * M + m, k]
    ctr[:] = tot_t[:Ut]
    return total


@njit(cache=True, nogil=True)
def _table_mstep(counts, prior, prev, tab, out):
    """:meth:`.structure.Table.mstep` of one table into ``out``."""
    group, rep, gfixed, gvalues, mass = tab
    U, K, M = counts.shape
    G = rep.shape[0]
    cg = np.zeros((G, K, M))
    for u in range(U):
        cg[group[u]] += counts[u]
    rows = np.empty((G, K, M))
    for g in range(G):
        for k in range(K):
            tot = 0.0
            for m in range(M):
                if not gfixed[g, k, m]:
                    tot += cg[g, k, m] + prior
            for m in range(M):
                if gfixed[g, k, m]:
                    rows[g, k, m] = gvalues[g, k, m]
                elif tot > 0:
                    rows[g, k, m] = (cg[g, k, m] + prior) / tot * mass[g, k]
                else:
                    rows[g, k, m] = prev[rep[g], k, m]
    for u in range(U):
        out[u] = rows[group[u]]


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
def _table_project(p, tab, out):
    """:meth:`.structure.Table.project` of one table into ``out``."""
    group, rep, gfixed, gvalues, mass = tab
    U, K, M = p.shape
    G = rep.shape[0]
    rows = np.empty((G, K, M))
    for g in range(G):
        for k in range(K):
            s = 0.0
            for m in range(M):
                if not gfixed[g, k, m]:
                    s += max(p[rep[g], k, m], PROJECT_FLOOR)
            d = s if s > 0 else 1.0
            for m in range(M):
                if gfixed[g, k, m]:
                    rows[g, k, m] = gvalues[g, k, m]
                else:
                    rows[g, k, m] = max(p[rep[g], k, m], PROJECT_FLOOR) / d * mass[g, k]
    for u in range(U):
        out[u] = rows[group[u]]


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
def _views(flat, K, Ue, M, Ut):
    a, b = K, K + Ue * K * M
    return flat[:a], flat[a:b].reshape((Ue, K, M)), flat[b:].reshape((Ut, K, K))


@njit(cache=True, nogil=True)
def evaluate(flat, model, ev, counts):
    """E-step at the flat cells ``flat`` into ``counts`` (flat, the layout of the cells); (log-likelihood,
    objective).  ``model``: (K, Ue, M, Ut, prior, emission table, transition table); ``ev``: (data, buffers)."""
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
