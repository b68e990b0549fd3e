"""Simulated supervisors: populations, schedules, the vectorized engine, results and designs.

* :mod:`.populations` -- ``Supervisors``: who the participants are (pooled, Dirichlet, a list);
* :mod:`.trial_orders` -- which complexity each participant meets on each trial;
* :mod:`.engine`      -- the vectorized kernel: ``Block``, ``run`` and ``simulate``;
* :mod:`.kernels`     -- the engine's common cases and the urn schedule compiled (numba);
  :mod:`.warm` compiles them into numba's cache once;
* :mod:`.results`     -- ``Simulation`` and ``CrossoverSimulation``: summaries and trial logs;
* :mod:`.designs`     -- the paper's data collection and its counterbalanced crossover.

Each name is loaded on first use (the names are in ``__init__.pyi``).
"""

import lazy_loader as _lazy

__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
