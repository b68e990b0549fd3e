"""The supervisor and the task: ``TrustModel`` (trust dynamics and human actions), ``Task``
(complexities, success probabilities, rewards of eq. (1), discount), their JSON formats, and
the built-in presets."""

from .core import ACTIONS, EXPERIENCES, HUMAN_ACTIONS, ModelError, Rewards, Task, TrustModel
from .presets import MODEL_PRESETS, TASK_PRESETS, load_model, load_task, paper_model, paper_task

__all__ = [
    "ACTIONS",
    "EXPERIENCES",
    "HUMAN_ACTIONS",
    "MODEL_PRESETS",
    "TASK_PRESETS",
    "ModelError",
    "Rewards",
    "Task",
    "TrustModel",
    "load_model",
    "load_task",
    "paper_model",
    "paper_task",
]
