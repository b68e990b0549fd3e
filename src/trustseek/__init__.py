"""trustseek: trust-aware assistance-seeking for human-supervised autonomy.

The Python API, by module:

* :mod:`trustseek.model`   -- ``TrustModel`` (the supervisor) and ``Task``; JSON formats
* :mod:`trustseek.presets` -- the ``paper`` preset (Section V)
* :mod:`trustseek.pomdp`   -- the assistance-seeking POMDP (Section IV)
* :mod:`trustseek.belief`  -- belief updaters (``bayes``, ``paper``)
* :mod:`trustseek.solve`   -- belief-MDP solvers
* :mod:`trustseek.policy`  -- policies and ``PolicyRunner``
"""

from .pomdp.belief import BayesUpdate, PaperUpdate, make_updater
from .errors import TrustseekError
from .model.core import ACTIONS, EXPERIENCES, HUMAN_ACTIONS, ModelError, Rewards, Task, TrustModel
from .policies import (
    ComplexityPolicy,
    PolicyRunner,
    TrustAwarePolicy,
    always_ask,
    load_policy,
    never_ask,
    randomized,
)
from .solvers.agnostic import trust_agnostic
from .pomdp.problem import AssistancePOMDP
from .model.presets import load_model, load_task, paper_model, paper_task
from .solvers.grid import GridSolver, solve

__version__ = "0.1.0"

__all__ = [
    "ACTIONS",
    "EXPERIENCES",
    "HUMAN_ACTIONS",
    "AssistancePOMDP",
    "BayesUpdate",
    "ComplexityPolicy",
    "GridSolver",
    "ModelError",
    "PaperUpdate",
    "PolicyRunner",
    "Rewards",
    "Task",
    "TrustAwarePolicy",
    "TrustModel",
    "TrustseekError",
    "always_ask",
    "load_model",
    "load_policy",
    "load_task",
    "make_updater",
    "never_ask",
    "paper_model",
    "paper_task",
    "randomized",
    "solve",
    "trust_agnostic",
]
