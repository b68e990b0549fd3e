"""The assistance-seeking POMDP of Section IV and its belief updaters."""

from .belief import BELIEF_UPDATES, BayesUpdate, PaperUpdate, make_updater
from .problem import AssistancePOMDP

__all__ = ["BELIEF_UPDATES", "AssistancePOMDP", "BayesUpdate", "PaperUpdate", "make_updater"]
