"""trustseek: trust-aware assistance-seeking for human-supervised autonomy.

The Python API, by package:

* :mod:`trustseek.model`    -- ``TrustModel`` (the supervisor) and ``Task``; JSON formats; presets
* :mod:`trustseek.pomdp`    -- the assistance POMDP (Section IV) and its belief filter (``bayes``, ``paper``)
* :mod:`trustseek.policies` -- the ``Policy`` interface, every policy kind, ``PolicyRunner``
* :mod:`trustseek.solvers`  -- ``solver.solve(problem) -> Policy``; the registry (``make_solver``)

Every name is loaded on first use (``lazy_loader`` reads them from ``__init__.pyi``): ``import
trustseek`` costs no more than the names a program uses.
"""

import lazy_loader as _lazy

__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
