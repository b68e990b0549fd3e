# The comparisons of the compiled loops, as Python and numpy make them (NaN and ties included),
# so that the loops give the numbers of the Python and numpy code they mirror.


cdef inline double py_max(double a, double b) noexcept nogil:
    """Python's ``max(a, b)``: ``b`` only when it is greater."""
    return b if b > a else a


cdef inline double py_min(double a, double b) noexcept nogil:
    """Python's ``min(a, b)``: ``b`` only when it is smaller."""
    return b if b < a else a


cdef inline double np_maximum(double a, double b) noexcept nogil:
    """numpy's ``maximum(a, b)`` for ``b`` not NaN: ``a`` when it is NaN or at least ``b``."""
    return a if (a != a or a >= b) else b
