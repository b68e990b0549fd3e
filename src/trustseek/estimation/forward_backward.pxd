from libc.stdint cimport int32_t, int64_t


cdef struct Tables:
    # R parameter sets: initial (R, K), emit (R, PE, K), trans (R, P, K, K), C order
    const double* initial
    const double* emit
    const double* trans
    Py_ssize_t K, PE, P


cdef struct Data:
    # eidx, tidx and code (N, T) int32, lengths (N,), C order
    const int32_t* eidx
    const int32_t* tidx
    const int32_t* code
    const int64_t* lengths
    Py_ssize_t N, T


cdef struct Sums:
    # each item's own sums (R, C, ...): ll (R, C) and the counts, flat per item (ni, ne, nt cells)
    double* ll
    double* pi
    double* pe
    double* pt
    Py_ssize_t C, ni, ne, nt


cdef void estep_range(
    Py_ssize_t first, Py_ssize_t last, Py_ssize_t chunk, const Tables* tables, const Data* data,
    const unsigned char* active, Sums* sums,
) noexcept nogil

cdef void reduce_sums(const unsigned char* active, Py_ssize_t R, const Sums* sums, double* loglik,
                      double* c_init, double* c_emit, double* c_trans) noexcept nogil

cdef double* array_data(object a) except NULL

cdef int tables_from(tuple tables, Tables* out, list keep) except -1

cdef int data_from(tuple data, Data* out, list keep) except -1

cdef int sums_from(tuple sums, Py_ssize_t C, Sums* out) except -1

cdef void* scratch(size_t size) noexcept nogil
