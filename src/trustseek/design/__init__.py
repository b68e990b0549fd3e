"""Study design and power analysis: how many participants and trials a trust-POMDP study needs.

* :mod:`.evaluation` -- the exact value of a policy under a true model (its regret);
* :mod:`.replicate` -- one replicate: experiment 1 → fit → solve → evaluate → experiment 2 → tests;
* :mod:`.sweep` -- the sweep over designs (in process, local processes or a Dask cluster), its
  summary, the smallest design meeting the targets, the data-collection design search.
"""

from .evaluation import EVALUATION_GRID, Evaluation, evaluate_policy, high_threshold
from .replicate import Experiment1, FitSettings, Study, replicate_seed, run_replicate
from .sweep import TESTS, DesignConfig, DesignResult, ask_search, run_design

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
    "evaluate_policy",
    "high_threshold",
    "replicate_seed",
    "run_design",
    "run_replicate",
]
