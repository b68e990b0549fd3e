"""The public names of :mod:`trustseek.model`: read by type checkers, and by ``__init__.py`` to load each on first use."""

# every submodule, as the package attribute of that name
from . import core, files, jsonfile, mixture, presets, rating, task
from .core import TrustModel, load_any_model, trust_model
from .files import IOHMM_FORMAT
from .jsonfile import ModelError
from .mixture import TypeMixture
from .presets import (
    MIXTURE_PRESETS,
    MODEL_PRESETS,
    TASK_PRESETS,
    conservative_model,
    load_mixture,
    load_model,
    load_task,
    paper_conservative_mixture,
    paper_model,
    paper_task,
)
from .rating import RatingTable
from .task import Rewards, Task

__all__ = [
    "IOHMM_FORMAT",
    "MIXTURE_PRESETS",
    "MODEL_PRESETS",
    "TASK_PRESETS",
    "ModelError",
    "RatingTable",
    "Rewards",
    "Task",
    "TrustModel",
    "TypeMixture",
    "conservative_model",
    "load_any_model",
    "load_mixture",
    "load_model",
    "load_task",
    "paper_conservative_mixture",
    "paper_model",
    "paper_task",
    "trust_model",
]
