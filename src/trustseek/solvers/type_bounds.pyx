"""The base bound of :class:`~.type_aware.TypeBound` at many beliefs (Cython, built with the package)."""

import numpy as np

from libc.math cimport INFINITY
from libc.stdint cimport int64_t
from ..minmax cimport py_max, py_min


cdef inline double _interp(const double[:] tab, double x) noexcept nogil:
    """Linear interpolation of ``tab`` (values on a uniform grid of [0, 1]) at x."""
    cdef Py_ssize_t r = tab.shape[0] - 1
    cdef double y = x * r
    cdef Py_ssize_t j = <Py_ssize_t>y  # int(y): toward zero
    if j < 0:
        j = 0
    if j > r - 1:
        j = r - 1
    return tab[j] + (y - j) * (tab[j + 1] - tab[j])


def base_many(const double[:, ::1] B, const double[:] pc, const double[:, :, :] beta, const int64_t[:] lo,
              const int64_t[:] hi, const double[:, :] vt, const double[:, :, :, :] qt):
    """The base bound (see :class:`~.type_aware.TypeBound`) at each row of B: the smallest of the fast
    informed bound Σ_c P(c) max_a β[c, a]·b, the type revealed now Σ_m w_m V̄_m(p_m) and the
    type revealed after one trial Σ_c P(c) max_a Σ_m w_m Q̄_m(c, a, p_m)."""
    cdef Py_ssize_t n = B.shape[0], S = B.shape[1], N = beta.shape[0], A = beta.shape[1], nb = lo.shape[0]
    out = np.empty(n)
    cdef double[::1] o = out
    cdef double[::1] ws = np.empty(max(nb, 1))
    cdef double[::1] ps = np.empty(max(nb, 1))
    cdef Py_ssize_t k, c, a, t, m, i, j
    cdef double fib, best, s, f, hf, w, p
    with nogil:
        for k in range(n):
            fib = 0.0
            for c in range(N):
                best = -INFINITY
                for a in range(A):
                    s = 0.0
                    for t in range(S):
                        s += beta[c, a, t] * B[k, t]
                    best = py_max(best, s)
                fib += pc[c] * best
            o[k] = fib
            if nb == 0:
                continue
            f = 0.0
            for m in range(nb):
                i, j = lo[m], hi[m]
                w = B[k, i] if i == j else B[k, i] + B[k, j]
                p = py_min(B[k, j] / w, 1.0) if (i != j and w > 0) else 0.0
                ws[m] = w
                ps[m] = p
                if w > 0:
                    f += w * _interp(vt[m], p)
            hf = 0.0
            for c in range(N):
                best = -INFINITY
                for a in range(A):
                    s = 0.0
                    for m in range(nb):
                        if ws[m] > 0:
                            s += ws[m] * _interp(qt[m, c, a], ps[m])
                    best = py_max(best, s)
                hf += pc[c] * best
            o[k] = py_min(py_min(fib, f), hf)
    return out
