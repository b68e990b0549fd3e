"""The public names of :mod:`trustseek.simulation`: read by type checkers, and by ``__init__.py`` to load each on first use."""

# every submodule, as the package attribute of that name
from . import designs, engine, kernels, populations, results, scheduling, trial_orders
from .designs import add_ratings, crossover, simulate_design
from .engine import Block, run, simulate
from .populations import SimulationError, Supervisors
from .results import CrossoverSimulation, Simulation, participant_ids
from .trial_orders import schedule_counts, schedule_iid

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
]
