"""The assistance-seeking POMDP of Section IV, built from a TrustModel and a Task.

States are S = (T, E, C): hidden trust T, the last experience E and the trial's
complexity C (both observed).  Actions are {autonomous, ask}; observations are
the human actions {intervene, rely}.  Timing follows the paper: the human
action o_t depends on the state at the START of trial t, P(o_t | T_t, C_t, a_t),
and the next state is drawn as

    P(S_{t+1} | S_t, a_t) = P(T_{t+1} | E_{t+1}, T_t, C_t, a_t) P(C_{t+1}) P(E_{t+1} | T_t, C_t, a_t),
    P(E_{t+1} | T_t, C_t, a_t) = sum_o P(E_{t+1} | o, C_t, a_t) P(o | T_t, C_t, a_t).

The reward R(S, a) is eq. (2), the expectation of eq. (1) over o and E'.  The arrays have
named axes (:data:`AXES`): factored ones (what the belief-MDP solvers use) and flat ones over
the enumerated states (``transition_matrix``, ``observation_matrix``, ``reward_matrix``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..model.core import TrustModel
from ..model.task import Task
from ..vocab import ACTIONS, EXPERIENCES, HUMAN_ACTIONS, check_belief_update
from .belief import Branches, BranchModel

AXES = {
    "emission": ("complexity", "robot_action", "trust", "human_action"),
    "experience": ("complexity", "robot_action", "human_action", "next_experience"),
    "trust_transition": ("complexity", "robot_action", "next_experience", "trust", "next_trust"),
    "complexity_probs": ("complexity",),
    "trial_reward": ("robot_action", "human_action", "next_experience"),
    "expected_reward": ("complexity", "robot_action", "trust"),
    "outcome_probs": ("complexity", "robot_action", "trust", "human_action", "next_experience"),
    "kernel": ("complexity", "robot_action", "trust", "human_action", "next_experience", "next_trust"),
    "transition_matrix": ("robot_action", "state", "next_state"),
    "observation_matrix": ("robot_action", "state", "human_action"),
    "reward_matrix": ("state", "robot_action"),
}


@dataclass(frozen=True, eq=False)
class AssistancePOMDP:
    model: TrustModel
    task: Task

    axes = AXES  # the named axes of every array below

    def __post_init__(self) -> None:
        self.task.check_compatible(self.model)

    # -- sizes and names ---------------------------------------------------
    @property
    def n_trust(self) -> int:
        return self.model.n_trust

    @property
    def n_complexity(self) -> int:
        return self.task.n_complexity

    @property
    def discount(self) -> float:
        return self.task.discount

    @property
    def complexities(self) -> tuple[str, ...]:
        return self.task.complexities

    @property
    def trust_levels(self) -> tuple[str, ...]:
        return self.model.trust_levels

    actions = ACTIONS
    observations = HUMAN_ACTIONS
    experiences = EXPERIENCES

    # -- factored arrays ---------------------------------------------------
    @property
    def emission(self) -> np.ndarray:
        """P(o | T, C, a), axes [c, a, t, o]."""
        return self.model.emission

    @property
    def trust_transition(self) -> np.ndarray:
        """P(T' | T, E', C, a), axes [c, a, e, t, t2]."""
        return self.model.transition

    @property
    def complexity_probs(self) -> np.ndarray:
        return self.task.complexity_probs

    @cached_property
    def experience(self) -> np.ndarray:
        """P(E' | o, C, a), axes [c, a, o, e]."""
        return self.task.experience_table()

    @cached_property
    def trial_reward(self) -> np.ndarray:
        """Eq. (1), axes [a, o, e]."""
        return self.task.reward_table()

    @cached_property
    def kernel(self) -> np.ndarray:
        """Joint one-step kernel P(o, E', T' | T, C, a), axes [c, a, t, o, e, t2]."""
        return np.einsum("cato,caoe,caetu->catoeu", self.emission, self.experience, self.trust_transition, optimize=True)

    @cached_property
    def outcome_probs(self) -> np.ndarray:
        """P(o, E' | T, C, a), axes [c, a, t, o, e]."""
        return np.einsum("cato,caoe->catoe", self.emission, self.experience)

    @cached_property
    def expected_reward(self) -> np.ndarray:
        """R(S, a) of eq. (2) (it does not depend on E), axes [c, a, t]."""
        return np.einsum("catoe,aoe->cat", self.outcome_probs, self.trial_reward)

    # -- the belief MDP ----------------------------------------------------
    def branches(self, update: str) -> Branches:
        """The successors of a belief after one trial, for the ``bayes`` or ``paper`` update."""
        if check_belief_update(update) == "bayes":
            return self._bayes_branches
        return self._paper_branches

    @cached_property
    def _bayes_branches(self) -> Branches:
        K, N = self.n_trust, self.n_complexity
        # the joint kernel with the branch (o, E') in front of the trust axes: [c, a, (o, e), t, u]
        return Branches.from_kernels(np.transpose(self.kernel, (0, 1, 3, 4, 2, 5)).reshape(N, 2, 4, K, K))

    @cached_property
    def _paper_branches(self) -> Branches:
        pe = np.einsum("catoe->caet", self.outcome_probs)  # P(E' | T, C, a)
        return Branches("paper", pe, np.asarray(self.trust_transition))

    def branch_model(self) -> BranchModel:
        """The problem in branch form (contexts = complexities, Bayes branches (o, E'))."""
        return BranchModel(
            self.complexity_probs.copy(),
            self.expected_reward.copy(),
            self.branches("bayes"),
            self.discount,
            self.model.initial.copy(),
        )

    # -- flat arrays -------------------------------------------------------
    @cached_property
    def states(self) -> tuple[tuple[str, str, str], ...]:
        """Enumerated states (trust, experience, complexity); index = (t * 2 + e) * N + c."""
        return tuple((tn, en, cn) for tn in self.trust_levels for en in EXPERIENCES for cn in self.complexities)

    @cached_property
    def transition_matrix(self) -> np.ndarray:
        """P(S' | S, a), axes [a, s, s2]."""
        K, N = self.n_trust, self.n_complexity
        pet = self.kernel.sum(axis=3).transpose(1, 2, 0, 4, 3)  # P(e', t' | t, c, a) as [a, t, c, u, e2]
        out = pet[..., None] * self.complexity_probs  # [a, t, c, u, e2, c2]
        return np.broadcast_to(out[:, :, None], (2, K, 2, N, K, 2, N)).reshape(2, K * 2 * N, -1)  # independent of e

    @cached_property
    def observation_matrix(self) -> np.ndarray:
        """P(o | S, a) for the state S at the start of the trial, axes [a, s, o]."""
        K, N = self.n_trust, self.n_complexity
        return np.broadcast_to(self.emission.transpose(1, 2, 0, 3)[:, :, None], (2, K, 2, N, 2)).reshape(2, -1, 2)

    @cached_property
    def reward_matrix(self) -> np.ndarray:
        """R(S, a) of eq. (2), axes [s, a]."""
        K, N = self.n_trust, self.n_complexity
        return np.broadcast_to(self.expected_reward.transpose(2, 0, 1)[:, None], (K, 2, N, 2)).reshape(-1, 2)
