"""The maps of :class:`~.sticks.Sticks` between a fit's free cells and their stick-breaking
fractions (Cython, built with the package): :func:`stick_theta`, :func:`stick_values` and
:func:`stick_gradient`, called by :class:`~.sticks.Sticks` and, through the ``.pxd``, by the
compiled run's finish (:mod:`.compiled_em`).

The layout (table, m, mass, tbase, tstride, coff, cptr, cdst) is :meth:`.sticks.Sticks._layout`'s:
row i (``m[i]`` cells of total ``mass[i]`` in table ``table[i]``: 0 initial, 1 emission,
2 transition) has fraction j at ``theta[tbase[i] + j * tstride[i]]``; its cell j is at the flat
positions ``cdst[cptr[c]:cptr[c + 1]]`` of that table, c = ``coff[i] + j``.
"""

from libc.stdint cimport int64_t
from ..minmax cimport py_max, py_min

import numpy as np

from .structure import FLOOR as _FLOOR

EPS = 1e-12  # the fractions' box: [EPS, 1 - EPS]
cdef double C_EPS = EPS
cdef double C_FLOOR = _FLOOR


cdef inline double* _pick(Py_ssize_t table, double* out0, double* out1, double* out2) noexcept nogil:
    return out0 if table == 0 else (out1 if table == 1 else out2)


cdef int layout_from(tuple layout, Layout* out, list keep) except -1:
    """``out`` from :meth:`.sticks.Sticks._layout`'s arrays; the memoryviews holding them go to ``keep``."""
    cdef const int64_t[::1] table = layout[0]
    cdef const int64_t[::1] m = layout[1]
    cdef const double[::1] mass = layout[2]
    cdef const int64_t[::1] tbase = layout[3]
    cdef const int64_t[::1] tstride = layout[4]
    cdef const int64_t[::1] coff = layout[5]
    cdef const int64_t[::1] cptr = layout[6]
    cdef const int64_t[::1] cdst = layout[7]
    cdef Py_ssize_t i
    keep.extend((table, m, mass, tbase, tstride, coff, cptr, cdst))
    out.table, out.m, out.mass, out.tbase = &table[0], &m[0], &mass[0], &tbase[0]
    out.tstride, out.coff, out.cptr, out.cdst = &tstride[0], &coff[0], &cptr[0], &cdst[0]
    out.rows = m.shape[0]
    out.widest = 0
    for i in range(out.rows):
        out.widest = max(out.widest, m[i])
    return 0


cdef void theta_of(const double* f0, const double* f1, const double* f2, const Layout* lay, double* out) noexcept nogil:
    """The fractions of the flat cells ``f0``, ``f1``, ``f2`` (initial, emission, transition) into
    ``out``, each in [EPS, 1 - EPS]."""
    cdef Py_ssize_t i, j, q
    cdef double rem, val
    for i in range(lay.rows):
        rem = lay.mass[i]
        for j in range(lay.m[i] - 1):
            q = lay.cdst[lay.cptr[lay.coff[i] + j]]
            val = f0[q] if lay.table[i] == 0 else (f1[q] if lay.table[i] == 1 else f2[q])
            out[lay.tbase[i] + j * lay.tstride[i]] = py_min(py_max(val / py_max(rem, C_FLOOR), C_EPS), 1 - C_EPS)
            rem = rem - val


cdef void values_of(const double* theta, const Layout* lay, double* out0, double* out1, double* out2) noexcept nogil:
    """The cells of the stick-breaking rows from their fractions ``theta`` into the flat tables
    ``out0``, ``out1``, ``out2`` (initial, emission, transition)."""
    cdef Py_ssize_t i, j, c, q
    cdef double rem, v, val
    cdef double* out
    for i in range(lay.rows):
        rem = lay.mass[i]
        out = _pick(lay.table[i], out0, out1, out2)
        for j in range(lay.m[i]):
            if j < lay.m[i] - 1:
                v = theta[lay.tbase[i] + j * lay.tstride[i]]
                val = rem * v
                rem = rem * (1 - v)
            else:
                val = rem
            c = lay.coff[i] + j
            for q in range(lay.cptr[c], lay.cptr[c + 1]):
                out[lay.cdst[q]] = val


cdef void gradient_of(const double* theta, double prior, const Layout* lay, const double* w0, const double* w1,
                      const double* w2, double* out, double* w) noexcept nogil:
    """The gradient of the objective in the fractions ``theta`` into ``out``, from the expected counts
    ``w0``, ``w1``, ``w2`` of the three tables (flat): w_j / v_j - (sum_{i>j} w_i) / (1 - v_j) with w
    the row's counts plus ``prior`` (``w``: work space of ``lay.widest`` cells)."""
    cdef Py_ssize_t i, j, c, q, k
    cdef double acc, tail, v
    cdef const double* counts
    for i in range(lay.rows):
        counts = w0 if lay.table[i] == 0 else (w1 if lay.table[i] == 1 else w2)
        for j in range(lay.m[i]):
            c = lay.coff[i] + j
            acc = 0.0
            for q in range(lay.cptr[c], lay.cptr[c + 1]):
                acc += counts[lay.cdst[q]]
            w[j] = acc + prior
        tail = w[lay.m[i] - 1]
        for j in range(lay.m[i] - 2, -1, -1):
            k = lay.tbase[i] + j * lay.tstride[i]
            v = theta[k]
            out[k] = w[j] / v - tail / (1 - v)
            tail = tail + w[j]


def stick_theta(tuple cells, tuple layout, double[::1] out):
    """The fractions of the flat ``cells`` (initial, emission, transition) in the ``layout`` into
    ``out``, each in [EPS, 1 - EPS]."""
    cdef Layout lay
    cdef const double[::1] f0 = cells[0]
    cdef const double[::1] f1 = cells[1]
    cdef const double[::1] f2 = cells[2]
    keep = []
    layout_from(layout, &lay, keep)
    theta_of(&f0[0], &f1[0], &f2[0], &lay, &out[0])


def stick_values(const double[::1] theta, tuple layout, tuple out):
    """The cells of the stick-breaking rows from their fractions ``theta`` into ``out`` (initial,
    emission, transition; flat)."""
    cdef Layout lay
    cdef double[::1] o0 = out[0]
    cdef double[::1] o1 = out[1]
    cdef double[::1] o2 = out[2]
    keep = []
    layout_from(layout, &lay, keep)
    values_of(&theta[0], &lay, &o0[0], &o1[0], &o2[0])


def stick_gradient(const double[::1] theta, double prior, tuple layout, tuple counts, double[::1] out):
    """The gradient of the objective in the fractions of the ``layout`` into ``out``, from the
    expected ``counts`` of the three tables (initial, emission, transition; flat)."""
    cdef Layout lay
    cdef const double[::1] w0 = counts[0]
    cdef const double[::1] w1 = counts[1]
    cdef const double[::1] w2 = counts[2]
    keep = []
    layout_from(layout, &lay, keep)
    cdef double[::1] w = np.empty(max(lay.widest, 1))
    gradient_of(&theta[0], prior, &lay, &w0[0], &w1[0], &w2[0], &out[0], &w[0])
