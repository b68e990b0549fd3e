"""Simulated supervisors: populations, schedules, the vectorized engine, results and designs.

* :mod:`.populations` -- ``Supervisors``: who the participants are (pooled, Dirichlet, a list);
* :mod:`.schedules`   -- which complexity each participant meets on each trial;
* :mod:`.engine`      -- the vectorized kernel: ``Block``, ``run`` and ``simulate``;
* :mod:`.kernels`     -- the engine's common cases and the urn schedule compiled (numba);
  :mod:`.warm` compiles them into numba's cache once;
* :mod:`.results`     -- ``Simulation`` and ``CrossoverSimulation``: summaries and trial logs;
* :mod:`.designs`     -- the paper's data collection and its counterbalanced crossover.
"""

from .designs import add_ratings, crossover, simulate_design
from .engine import Block, run, simulate
from .populations import SimulationError, Supervisors
from .results import CrossoverSimulation, Simulation, participant_ids, summarize
from .schedules import schedule_counts, schedule_iid

__all__ = [
    "Block",
    "CrossoverSimulation",
    "Simulation",
    "SimulationError",
    "Supervisors",
    "add_ratings",
    "crossover",
    "participant_ids",
    "run",
    "schedule_counts",
    "schedule_iid",
    "simulate",
    "simulate_design",
    "summarize",
]
