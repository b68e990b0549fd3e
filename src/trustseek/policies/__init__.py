"""Policies: what the robot does on the next trial (the ``Policy`` base class and its kinds, their
JSON, ``PolicyRunner``).  Policies never solve anything: the solvers build them.

Each name is loaded on first use (the names are in ``__init__.pyi``).
"""

import lazy_loader as _lazy

__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
