"""The BLAS and LAPACK routines of the compiled run (:mod:`.compiled_em`): ``ddot``, ``dgemv``
and ``dgesv`` of the OpenBLAS that scipy ships, the library ``scipy.linalg.cython_blas`` and
``cython_lapack`` call, so the numbers are theirs.  Its functions are found in the library
itself, without importing ``scipy.linalg`` (0.13-0.16 s of every compiled fit's start); where
scipy ships no such library (a build against the system's BLAS), through ``scipy.linalg``'s own
exported functions."""

from __future__ import annotations

import ctypes
import importlib.util
from pathlib import Path

NAMES = ("ddot", "dgemv", "dgesv")


def routines(direct: bool = True) -> tuple[int, int, int]:
    """The addresses of ``ddot``, ``dgemv`` and ``dgesv``: from scipy's OpenBLAS library when
    ``direct`` and it is found, else from ``scipy.linalg.cython_blas`` and ``cython_lapack``."""
    found = _in_library() if direct else None
    return found if found is not None else _in_scipy_linalg()


def library() -> Path | None:
    """scipy's OpenBLAS library (a wheel's ``scipy.libs/libscipy_openblas-*.so``), when there is one."""
    spec = importlib.util.find_spec("scipy")
    if spec is None or spec.origin is None:
        return None
    libs = sorted((Path(spec.origin).parent.parent / "scipy.libs").glob("libscipy_openblas*.so*"))
    return libs[0] if len(libs) == 1 else None


def _in_library() -> tuple[int, int, int] | None:
    path = library()
    if path is None:
        return None
    try:
        lib = ctypes.CDLL(str(path))
        a, b, c = (ctypes.cast(getattr(lib, f"scipy_{n}_"), ctypes.c_void_p).value for n in NAMES)
    except (OSError, AttributeError):  # not the library scipy's wheels ship
        return None
    return (a, b, c) if a and b and c else None


def _in_scipy_linalg() -> tuple[int, int, int]:
    from scipy.linalg import cython_blas, cython_lapack

    pointer = ctypes.PYFUNCTYPE(ctypes.c_void_p, ctypes.py_object, ctypes.c_char_p)(("PyCapsule_GetPointer", ctypes.pythonapi))
    name = ctypes.PYFUNCTYPE(ctypes.c_char_p, ctypes.py_object)(("PyCapsule_GetName", ctypes.pythonapi))
    capsules = (cython_blas.__pyx_capi__["ddot"], cython_blas.__pyx_capi__["dgemv"], cython_lapack.__pyx_capi__["dgesv"])
    a, b, c = (pointer(capsule, name(capsule)) for capsule in capsules)
    return a, b, c
