"""The public names of :mod:`trustseek.pomdp`: read by type checkers, and by ``__init__.py`` to load each on first use."""

# every submodule, as the package attribute of that name
from . import belief, flat, problem, scheduling, supervisor_types
from .belief import BELIEF_UPDATES, BayesUpdate, Branches, BranchModel, PaperUpdate, ScalarBelief, make_updater
from .flat import FlatPOMDP
from .problem import AssistancePOMDP

__all__ = [
    "BELIEF_UPDATES",
    "AssistancePOMDP",
    "BayesUpdate",
    "BranchModel",
    "Branches",
    "FlatPOMDP",
    "PaperUpdate",
    "ScalarBelief",
    "make_updater",
]
