"""numba's ``njit``, or the plain Python function where numba cannot be imported.

numba is a declared dependency; the fallback keeps the compiled modules importable (and their
numpy or Python paths usable) on a platform without a numba wheel.  ``AVAILABLE`` says which.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

try:  # numba is a declared dependency
    import numba

    AVAILABLE = True
except ImportError:  # pragma: no cover - exercised only without numba
    AVAILABLE = False

__all__ = ["AVAILABLE", "njit"]


def njit(**options: Any) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """numba's ``njit(**options)`` when numba is installed, else the plain Python function."""
    if not AVAILABLE:  # pragma: no cover - exercised only without numba
        return lambda f: f
    return numba.njit(**options)
