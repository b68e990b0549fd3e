from libc.stdint cimport int64_t
from cpython.ref cimport PyObject

from .forward_backward cimport Data, Sums, Tables


cdef struct Tie:
    # a table's tie structure (structure.Table): group (U,), rep (G,), gfixed (G, K, M) as bytes,
    # gvalues (G, K, M), mass (G, K)
    const int64_t* group
    const int64_t* rep
    const unsigned char* gfixed
    const double* gvalues
    const double* mass
    Py_ssize_t U, G


cdef struct Model:
    # (K, Ue, M, Ut, prior, emission ties, transition ties)
    Py_ssize_t K, Ue, M, Ut
    double prior
    Tie em, tr


cdef struct EStep:
    # the E-step of one parameter set: the data, its tables (ini, emit, trans: one set), the items'
    # sums and their totals; ``parallel``: the buffers' owner that runs the items on threads, or NULL
    Data data
    Tables tables
    double* ini
    double* emit
    double* trans
    unsigned char* active
    Sums sums
    double* totals
    PyObject* parallel


cdef int model_from(tuple model, Model* out, list keep) except -1

cdef int estep_from(tuple ev, EStep* out, list keep) except -1

cdef Py_ssize_t size(const Model* model) noexcept nogil

cdef void copy(double* dst, const double* src, Py_ssize_t n) noexcept nogil

cdef int evaluate_at(const double* flat, const Model* model, EStep* ev, double* counts, double* ll,
                     double* f) except -1 nogil

cdef void em_step_at(const double* flat, const double* counts, const Model* model, double* out) noexcept nogil

cdef bint extrapolate_at(const double* p0, const double* p1, const double* p2, const Model* model,
                         double* out) noexcept nogil
