"""Study design and power analysis: how many participants and trials a trust-POMDP study needs.

* :mod:`.evaluation` -- the exact value of a policy under a true model (its regret);
* :mod:`.replicate` -- one replicate: experiment 1 → fit → solve → evaluate → experiment 2 → tests;
* :mod:`.sweep` -- the sweep over designs (in process, local processes or a Dask cluster), its
  summary, the smallest design meeting the targets, the data-collection design search.

Each name is loaded on first use (the names are in ``__init__.pyi``).
"""

import lazy_loader as _lazy

__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
