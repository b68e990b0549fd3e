"""Simulated supervisors: populations, trial orders, the vectorized engine and its compiled kernels,
results and the paper's designs.  Names load on first use (``__init__.pyi``)."""

import lazy_loader as _lazy

__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
