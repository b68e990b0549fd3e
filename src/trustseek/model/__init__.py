"""The supervisor and the task: ``TrustModel`` (trust dynamics and human actions), ``Task``
(complexities, success probabilities, rewards of eq. (1), discount), their JSON formats, and
the built-in presets."""

from .core import ACTIONS, EXPERIENCES, HUMAN_ACTIONS, ModelError, RatingTable, Rewards, Task, TrustModel
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

__all__ = [
    "ACTIONS",
    "EXPERIENCES",
    "HUMAN_ACTIONS",
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
    "load_mixture",
    "load_model",
    "load_task",
    "paper_conservative_mixture",
    "paper_model",
    "paper_task",
]
