"""The public names of :mod:`trustseek.design`: read by type checkers, and by ``__init__.py`` to load each on first use."""

# every submodule, as the package attribute of that name
from . import evaluation, replicate, sweep
from .evaluation import EVALUATION_GRID, Evaluation, evaluate_policy, high_threshold
from .replicate import Experiment1, FitSettings, Study, replicate_seed, run_replicate
from .sweep import TESTS, DesignConfig, DesignResult, ask_search, ask_search_problems, participants_needed, run_design

__all__ = [
    "EVALUATION_GRID",
    "TESTS",
    "DesignConfig",
    "DesignResult",
    "Evaluation",
    "Experiment1",
    "FitSettings",
    "Study",
    "ask_search",
    "ask_search_problems",
    "evaluate_policy",
    "high_threshold",
    "participants_needed",
    "replicate_seed",
    "run_design",
    "run_replicate",
]
