"""The steps of the compiled run (:mod:`.compiled_em`) on flat cells (Cython, built with the package):
the E-step of one parameter set (:mod:`.forward_backward`'s items in the same order: the numbers of
:meth:`~.estep.Workspace.estep`), the M-step, projection and log-prior of
:class:`~.structure.Structure`, and the SQUAREM point of :func:`.em._extrapolate`.

A parameter set is flat (:meth:`~.spec.Params.vector`: initial (K,), emission (Ue, K, M),
transition (Ut, K, K)); ``model`` is (K, Ue, M, Ut, prior, emission table, transition table) and
``ev`` the E-step's (data, :func:`estep_buffers`).  The functions of the ``.pxd`` take them as C
structs (:func:`model_from`, :func:`estep_from`); those of Python the tuples, for the tests.
"""

import numpy as np

from cpython.ref cimport PyObject
from libc.math cimport log, sqrt
from libc.stdint cimport int64_t
from libc.stdlib cimport free
from ..minmax cimport np_maximum, py_max

from .forward_backward cimport (
    Data,
    Sums,
    Tables,
    array_data,
    data_from,
    estep_range,
    reduce_sums,
    scratch,
    sums_from,
    tables_from,
)

from . import kernels
from .em import SHRINK as _SHRINK
from .forward_backward import estep_items
from .structure import FLOOR as _FLOOR
from .structure import PROJECT_FLOOR as _PROJECT_FLOOR

CHUNK = kernels.CHUNK
cdef Py_ssize_t C_CHUNK = CHUNK
PARALLEL_ITEMS = 8  # items (of CHUNK sequences) from which the E-step runs on several threads
cdef double FLOOR = _FLOOR
cdef double PROJECT_FLOOR = _PROJECT_FLOOR
cdef double SHRINK = _SHRINK


# ---- the E-step ----

cdef class EStepBuffers:
    """The E-step's buffers for ``C`` items (:meth:`.kernels.Kernel.run`'s layout, R = 1): the tables,
    the active flag, the items' sums and their totals, and the threads the items run on."""

    cdef readonly tuple tables, sums
    cdef readonly object active, totals
    cdef readonly Py_ssize_t C, threads
    cdef tuple data

    def __init__(self, Py_ssize_t K, Py_ssize_t PE, Py_ssize_t U1, Py_ssize_t C, Py_ssize_t threads):
        trans = np.zeros((1, U1, K, K))
        for k in range(K):
            trans[0, U1 - 1, k, k] = 1.0
        self.tables = (np.empty((1, K)), np.empty((1, PE, K)), trans)
        self.active = np.ones(1, dtype=np.uint8)
        self.sums = (np.empty((1, C)), np.empty((1, C, K)), np.empty((1, C, PE, K)), np.empty((1, C, U1, K, K)))
        self.totals = np.empty(1 + K + PE * K + U1 * K * K)  # log-likelihood, initial, emission, transition
        self.C, self.threads = C, max(threads, 1)

    def run_items(self):
        """The items on the E-step threads of :mod:`.kernels`, one contiguous run per thread, each item
        into its own sums (the same numbers on any number of threads)."""
        args = (self.C, CHUNK, self.tables, self.data, self.active, self.sums)
        kernels.split(self.C, self.threads, lambda a, b: estep_items(a, b, *args))


def estep_buffers(Py_ssize_t K, Py_ssize_t PE, Py_ssize_t U1, Py_ssize_t C, Py_ssize_t threads):
    """The E-step's buffers (:class:`EStepBuffers`) for ``C`` items, run on ``threads`` threads from
    :data:`PARALLEL_ITEMS` items."""
    return EStepBuffers(K, PE, U1, C, threads)


cdef int estep_from(tuple ev, EStep* out, list keep) except -1:
    """``out`` from (data, :class:`EStepBuffers`); what holds the arrays goes to ``keep``."""
    data, buffers = ev
    cdef EStepBuffers bufs = buffers
    cdef unsigned char[::1] active = bufs.active
    bufs.data = data
    data_from(data, &out.data, keep)
    if out.data.code == NULL:
        raise ValueError("the E-step's data need the step codes: (eidx, tidx, code, lengths)")
    tables_from(bufs.tables, &out.tables, keep)
    out.ini, out.emit, out.trans = array_data(bufs.tables[0]), array_data(bufs.tables[1]), array_data(bufs.tables[2])
    sums_from(bufs.sums, bufs.C, &out.sums)
    out.totals = array_data(bufs.totals)
    out.active = &active[0]
    keep.extend((active, bufs))
    out.parallel = <PyObject*>bufs if bufs.threads > 1 and bufs.C >= PARALLEL_ITEMS else NULL
    return 0


cdef int _estep(const double* flat, const Model* md, EStep* ev, double* counts, double* ll) except -1 nogil:
    """E-step at the flat cells ``flat``: counts into ``counts`` (flat), the log-likelihood into ``ll``
    (-inf: probability zero)."""
    cdef Py_ssize_t K = md.K, Ue = md.Ue, M = md.M, Ut = md.Ut, PE = ev.tables.PE, u, k, m, i, j
    cdef const double* em = flat + K
    cdef const double* tr = em + Ue * K * M
    for u in range(Ue):
        for k in range(K):
            for m in range(M):
                ev.emit[(u * M + m) * K + k] = em[(u * K + k) * M + m]
    for k in range(K):
        ev.ini[k] = flat[k]
        ev.emit[Ue * M * K + k] = 1.0
    for u in range(Ut):
        for i in range(K):
            for j in range(K):
                ev.trans[(u * K + i) * K + j] = tr[(u * K + i) * K + j]
    if ev.parallel != NULL:
        with gil:
            (<EStepBuffers><object>ev.parallel).run_items()
    else:
        estep_range(0, ev.sums.C, C_CHUNK, &ev.tables, &ev.data, ev.active, &ev.sums)
    cdef double* tot_i = ev.totals + 1
    cdef double* tot_e = tot_i + K
    cdef double* tot_t = tot_e + PE * K
    reduce_sums(ev.active, 1, &ev.sums, ev.totals, tot_i, tot_e, tot_t)
    cdef double* cem = counts + K
    cdef double* ctr = cem + Ue * K * M
    for k in range(K):
        counts[k] = tot_i[k]
    for u in range(Ue):
        for k in range(K):
            for m in range(M):
                cem[(u * K + k) * M + m] = tot_e[(u * M + m) * K + k]
    for u in range(Ut):
        for i in range(K):
            for j in range(K):
                ctr[(u * K + i) * K + j] = tot_t[(u * K + i) * K + j]
    ll[0] = ev.totals[0]
    return 0


# ---- the M-step, projection and log-prior of a table with ties ----

cdef int tie_from(tuple table, Tie* out, list keep) except -1:
    """``out`` from (group, rep, gfixed, gvalues, mass) (``compiled_run._table``)."""
    cdef const int64_t[::1] group = table[0]
    cdef const int64_t[::1] rep = table[1]
    cdef const unsigned char[::1] gfixed = np.asarray(table[2]).reshape(-1).view(np.uint8)
    cdef const double[::1] gvalues = np.asarray(table[3]).reshape(-1)
    cdef const double[::1] mass = np.asarray(table[4]).reshape(-1)
    keep.extend((group, rep, gfixed, gvalues, mass))
    out.group, out.rep, out.gfixed, out.gvalues, out.mass = &group[0], &rep[0], &gfixed[0], &gvalues[0], &mass[0]
    out.U, out.G = group.shape[0], rep.shape[0]
    return 0


cdef int model_from(tuple model, Model* out, list keep) except -1:
    """``out`` from (K, Ue, M, Ut, prior, emission table, transition table)."""
    out.K, out.Ue, out.M, out.Ut, out.prior = model[0], model[1], model[2], model[3], model[4]
    tie_from(model[5], &out.em, keep)
    tie_from(model[6], &out.tr, keep)
    return 0


cdef Py_ssize_t size(const Model* md) noexcept nogil:
    """The number of flat cells of a parameter set."""
    return md.K + md.Ue * md.K * md.M + md.Ut * md.K * md.K


cdef void copy(double* dst, const double* src, Py_ssize_t n) noexcept nogil:
    """``dst[:n] = src[:n]``."""
    cdef Py_ssize_t i
    for i in range(n):
        dst[i] = src[i]


cdef void _rows(double* num, const double* prev, const Tie* tab, Py_ssize_t K, Py_ssize_t M, double* out) noexcept nogil:
    """Each group's rows ``num`` (G, K, M) with the fixed cells set and the free ones scaled to the free
    mass (summing to 0: ``prev``'s row), into ``out`` (U, K, M) by group."""
    cdef Py_ssize_t g, k, m, u, x, r
    cdef double tot
    for g in range(tab.G):
        for k in range(K):
            r = (g * K + k) * M
            tot = 0.0
            for m in range(M):
                if not tab.gfixed[r + m]:
                    tot += num[r + m]
            for m in range(M):
                if tab.gfixed[r + m]:
                    num[r + m] = tab.gvalues[r + m]
                elif tot > 0:
                    num[r + m] = num[r + m] / tot * tab.mass[g * K + k]
                else:
                    num[r + m] = prev[(tab.rep[g] * K + k) * M + m]
    for u in range(tab.U):
        for x in range(K * M):
            out[u * K * M + x] = num[tab.group[u] * K * M + x]


cdef void _table_mstep(const double* counts, double prior, const double* prev, const Tie* tab, Py_ssize_t K,
                       Py_ssize_t M, double* out) noexcept nogil:
    """:meth:`.structure.Table.mstep` of one table (U, K, M) into ``out``."""
    cdef Py_ssize_t u, x, n = tab.G * K * M
    cdef double* cg = <double*>scratch(sizeof(double) * n)
    for u in range(tab.U):
        for x in range(K * M):
            cg[tab.group[u] * K * M + x] += counts[u * K * M + x]
    for x in range(n):
        cg[x] = cg[x] + prior
    _rows(cg, prev, tab, K, M, out)
    free(cg)


cdef void em_step_at(const double* flat, const double* counts, const Model* md, double* out) noexcept nogil:
    """The M-step (:meth:`.structure.Structure.mstep`) from the E-step ``counts`` at ``flat`` into
    ``out`` (all flat)."""
    cdef Py_ssize_t K = md.K, a = K, b = K + md.Ue * K * md.M, k
    cdef double tot = 0.0, prior = md.prior
    for k in range(K):
        tot += counts[k] + prior
    for k in range(K):
        out[k] = (counts[k] + prior) / tot if tot > 0 else flat[k]
    _table_mstep(counts + a, prior, flat + a, &md.em, K, md.M, out + a)
    _table_mstep(counts + b, prior, flat + b, &md.tr, K, K, out + b)


cdef void _table_project(const double* p, const Tie* tab, Py_ssize_t K, Py_ssize_t M, double* out) noexcept nogil:
    """:meth:`.structure.Table.project` of one table into ``out`` (a free cell counts at least PROJECT_FLOOR)."""
    cdef Py_ssize_t g, x
    cdef double* num = <double*>scratch(sizeof(double) * tab.G * K * M)
    for g in range(tab.G):
        for x in range(K * M):
            num[g * K * M + x] = np_maximum(p[tab.rep[g] * K * M + x], PROJECT_FLOOR)
    _rows(num, p, tab, K, M, out)
    free(num)


cdef double _table_log_prior(const double* p, double prior, const Tie* tab, Py_ssize_t K, Py_ssize_t M) noexcept nogil:
    cdef Py_ssize_t g, x
    cdef double s = 0.0
    for g in range(tab.G):
        for x in range(K * M):
            if not tab.gfixed[g * K * M + x]:
                s += log(py_max(p[tab.rep[g] * K * M + x], FLOOR))
    return prior * s


cdef double _log_prior(const double* flat, const Model* md) noexcept nogil:
    """:meth:`.structure.Structure.log_prior`."""
    cdef Py_ssize_t K = md.K, k
    cdef double s = 0.0
    if md.prior == 0:
        return 0.0
    for k in range(K):
        s += log(py_max(flat[k], FLOOR))
    return (md.prior * s + _table_log_prior(flat + K, md.prior, &md.em, K, md.M)
            + _table_log_prior(flat + K + md.Ue * K * md.M, md.prior, &md.tr, K, K))


cdef bint extrapolate_at(const double* p0, const double* p1, const double* p2, const Model* md,
                         double* out) noexcept nogil:
    """The SQUAREM point of :func:`.em._extrapolate` from the flat cells ``p0 -> p1 -> p2`` into the
    flat ``out`` (projected); whether it is worth trying (step length below -1)."""
    cdef Py_ssize_t L = size(md), K = md.K, a = K, b = K + md.Ue * K * md.M, i, k
    cdef double rr = 0.0, vv = 0.0, r, v, nv, step, s
    for i in range(L):
        r = p1[i] - p0[i]
        v = p2[i] - 2 * p1[i] + p0[i]
        rr += r * r
        vv += v * v
    nv = sqrt(vv)
    step = -sqrt(rr) / nv if nv > 0 else -1.0
    if not step < -1.0:
        return False
    cdef double* x = <double*>scratch(sizeof(double) * L)
    for i in range(L):
        r = p1[i] - p0[i]
        v = p2[i] - 2 * p1[i] + p0[i]
        x[i] = py_max(p0[i] - 2 * step * r + step * step * v, SHRINK * p2[i])
    s = 0.0
    for k in range(K):
        s += py_max(x[k], PROJECT_FLOOR)
    for k in range(K):
        out[k] = py_max(x[k], PROJECT_FLOOR) / s
    _table_project(x + a, &md.em, K, md.M, out + a)
    _table_project(x + b, &md.tr, K, K, out + b)
    free(x)
    return True


cdef int evaluate_at(const double* flat, const Model* md, EStep* ev, double* counts, double* ll,
                     double* f) except -1 nogil:
    """E-step at the flat cells ``flat``, its counts into ``counts`` (flat); the log-likelihood and
    the objective into ``ll`` and ``f``."""
    _estep(flat, md, ev, counts, ll)
    f[0] = ll[0] + _log_prior(flat, md)
    return 0


# ---- from Python (the tests) ----

def evaluate(double[::1] flat, tuple model, tuple ev, double[::1] counts):
    """E-step at the flat cells ``flat``, its counts into ``counts`` (flat); (log-likelihood, objective)."""
    cdef Model md
    cdef EStep e
    cdef double ll, f
    keep = []
    model_from(model, &md, keep)
    estep_from(ev, &e, keep)
    with nogil:
        evaluate_at(&flat[0], &md, &e, &counts[0], &ll, &f)
    return ll, f


def em_step(const double[::1] flat, const double[::1] counts, tuple model, double[::1] out):
    """The point one EM step on from ``flat`` with E-step counts ``counts``, into ``out``."""
    cdef Model md
    keep = []
    model_from(model, &md, keep)
    em_step_at(&flat[0], &counts[0], &md, &out[0])


def extrapolate(const double[::1] p0, const double[::1] p1, const double[::1] p2, tuple model, double[::1] out):
    """The SQUAREM point from ``p0 -> p1 -> p2`` into ``out`` (projected); whether it is worth trying."""
    cdef Model md
    keep = []
    model_from(model, &md, keep)
    return extrapolate_at(&p0[0], &p1[0], &p2[0], &md, &out[0])
