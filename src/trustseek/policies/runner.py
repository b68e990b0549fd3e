"""``PolicyRunner``: a policy with its live belief, one trial at a time.

This is how the experiment server and a robot run a policy: ``decide`` before a trial,
``observe`` its events after it.  The step itself is written once: ``action_at`` and
``belief_after`` at any one belief (the server's decision API keeps many sessions' beliefs and
applies them to each), ``actions_many`` and ``beliefs_after_many`` at many beliefs at once, in
codes (the simulation's numpy path: one row per simulated participant).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model.core import TrustModel
from ..pomdp.belief import make_updater
from ..vocab import ACTIONS, EXPERIENCES, HUMAN_ACTIONS, UNOBSERVED
from .base import Policy, PolicyError


@dataclass
class PolicyRunner:
    """A policy with its live belief: ``decide`` before a trial, ``observe`` after it.

    For complexity-only policies the belief is still tracked when a model is given
    (useful for logging), with the ``bayes`` update unless the policy names one.
    """

    policy: Policy
    model: TrustModel | None = None
    belief_update: str | None = None
    rng: np.random.Generator = field(default_factory=np.random.default_rng)
    belief: np.ndarray | None = None
    trial: int = 0

    def __post_init__(self) -> None:
        self.model = self.model or self.policy.model
        self.belief_update = self.belief_update or self.policy.belief_update or "bayes"
        self._updater = make_updater(self.belief_update, self.model) if self.model is not None else None
        if self.belief is None and self._updater is not None:
            self.belief = self._updater.initial()
        if self.policy.belief_update is not None and self._updater is None:
            raise PolicyError(["this policy needs a trust model for its belief update"])

    def decide(self, complexity: int | str) -> str:
        """The robot action (``autonomous`` or ``ask``) for the next trial."""
        return self.action_at(self.belief, complexity)

    def observe(self, complexity: int | str, action: str, human_action: str | None, experience: str) -> np.ndarray | None:
        """Update the belief from one trial's events; returns the new belief (or None without a model)."""
        after = self.belief_after(self.belief, complexity, action, human_action, experience)
        self.trial += 1
        if after is not None:
            self.belief = after
        return after

    def action_at(self, belief: np.ndarray | None, complexity: int | str, rng: np.random.Generator | None = None) -> str:
        """The robot action the policy takes at ``belief`` (drawing from ``rng``, else the runner's own)."""
        return ACTIONS[self.policy.action(belief, complexity, self.rng if rng is None else rng)]

    def belief_after(
        self, belief: np.ndarray | None, complexity: int | str, action: str, human_action: str | None, experience: str
    ) -> np.ndarray | None:
        """The belief after one trial's events from ``belief`` (None without a model)."""
        c = self.policy.complexity_index(complexity)
        if action not in ACTIONS:
            raise ValueError(f"robot action must be one of {list(ACTIONS)}, got {action!r}")
        if human_action is not None and human_action not in HUMAN_ACTIONS:
            raise ValueError(f"human action must be one of {list(HUMAN_ACTIONS)} or None, got {human_action!r}")
        if experience not in EXPERIENCES:
            raise ValueError(f"experience must be one of {list(EXPERIENCES)}, got {experience!r}")
        if self._updater is None:
            return None
        o = UNOBSERVED if human_action is None else HUMAN_ACTIONS.index(human_action)
        return self._updater.update(belief, c, ACTIONS.index(action), o, EXPERIENCES.index(experience))

    def initial_beliefs(self, n: int) -> np.ndarray | None:
        """``n`` rows of the initial belief (None without a model)."""
        if self._updater is None:
            return None
        b0 = self._updater.initial()
        return np.broadcast_to(b0, (n, len(b0))).copy()

    def actions_many(self, beliefs: np.ndarray, complexities: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The robot actions (codes) the policy takes at each row of ``beliefs``, each in its own
        complexity (index)."""
        return np.asarray(self.policy.actions(beliefs, complexities, rng), dtype=np.int64)

    def beliefs_after_many(
        self, beliefs: np.ndarray, complexities: np.ndarray, action: np.ndarray, human: np.ndarray, experience: np.ndarray
    ) -> np.ndarray:
        """Each row of ``beliefs`` after its trial's events (codes; the rows unchanged without a model)."""
        if self._updater is None:
            return beliefs
        return self._updater.update(beliefs, complexities, action, human, experience)
