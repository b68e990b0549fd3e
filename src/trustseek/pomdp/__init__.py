"""The assistance-seeking POMDP of Section IV, its belief filter, and the flat and branch forms
that solvers and standard files use."""

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
