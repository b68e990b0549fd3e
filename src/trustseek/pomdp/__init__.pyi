"""The public names of :mod:`trustseek.pomdp`: read by type checkers, and by ``__init__.py`` to load each on first use."""

# every submodule, as the package attribute of that name
from . import belief, branch_model, flat, problem, scheduling, supervisor_types
from .belief import BELIEF_UPDATES, BayesUpdate, Branches, PaperUpdate, ScalarBelief, make_updater
from .branch_model import BranchModel
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
