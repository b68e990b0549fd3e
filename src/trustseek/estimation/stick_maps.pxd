from libc.stdint cimport int64_t


cdef struct Layout:
    # the rows of Sticks._layout (table, m, mass, tbase, tstride, coff; rows entries) and their cells'
    # flat positions (cptr, cdst)
    const int64_t* table
    const int64_t* m
    const double* mass
    const int64_t* tbase
    const int64_t* tstride
    const int64_t* coff
    const int64_t* cptr
    const int64_t* cdst
    Py_ssize_t rows
    Py_ssize_t widest


cdef int layout_from(tuple layout, Layout* out, list keep) except -1

cdef void theta_of(const double* f0, const double* f1, const double* f2, const Layout* lay, double* out) noexcept nogil

cdef void values_of(const double* theta, const Layout* lay, double* out0, double* out1, double* out2) noexcept nogil

cdef void gradient_of(const double* theta, double prior, const Layout* lay, const double* w0, const double* w1,
                      const double* w2, double* out, double* w) noexcept nogil
