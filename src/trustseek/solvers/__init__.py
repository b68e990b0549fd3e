"""Solvers: turn a problem into a policy, ``solver.solve(problem) -> Policy``.

Built by name through :mod:`.registry` (``make_solver``, ``policy_from_spec``); the modules and
what each solver guarantees are listed in docs/architecture.md and docs/solvers.md.  Each name is
loaded on first use (the names are in ``__init__.pyi``).
"""

import lazy_loader as _lazy

__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
