"""The public names of :mod:`trustseek`: read by type checkers, and by ``__init__.py`` to load each on first use."""

# the Python API's packages, as the package attributes of those names
from . import errors, model, policies, pomdp, solvers, version, vocab
from .errors import TrustseekError
from .model.core import TrustModel, trust_model
from .model.jsonfile import ModelError
from .model.presets import load_model, load_task, paper_model, paper_task
from .model.task import Rewards, Task
from .policies import (
    ComplexityPolicy,
    Policy,
    PolicyRunner,
    TrustAwarePolicy,
    always_ask,
    load_policy,
    never_ask,
    randomized,
)
from .pomdp.belief import BayesUpdate, PaperUpdate, make_updater
from .pomdp.problem import AssistancePOMDP
from .solvers import GridSolver, Solver, make_solver, solve, solver_names, trust_agnostic
from .version import __version__ as __version__
from .vocab import ACTIONS, EXPERIENCES, HUMAN_ACTIONS

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
    "Policy",
    "PolicyRunner",
    "Rewards",
    "Solver",
    "Task",
    "TrustAwarePolicy",
    "TrustModel",
    "TrustseekError",
    "__version__",
    "always_ask",
    "load_model",
    "load_policy",
    "load_task",
    "make_solver",
    "make_updater",
    "never_ask",
    "paper_model",
    "paper_task",
    "randomized",
    "solve",
    "solver_names",
    "trust_agnostic",
    "trust_model",
]
