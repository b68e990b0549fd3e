"""A flat POMDP: enumerated states, actions and observations (what standard files hold).

:class:`FlatPOMDP` is a plain discrete POMDP: ``transition[a, s, s2]``,
``observation[a, s2, o]`` (the observation depends on the action and the NEXT
state, as in the file formats), ``reward[a, s, s2, o]``, a discount and a start
distribution.  The point-based solver takes it through :meth:`FlatPOMDP.branch_model`
(one context whose branches are the observations); ``trustseek.interop`` reads and
writes it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import TrustseekError
from .belief import Branches, BranchModel


class FlatPOMDPError(TrustseekError, ValueError):
    """A flat POMDP whose arrays are not a POMDP (shapes, probability rows, discount)."""


@dataclass(eq=False)
class FlatPOMDP:
    """A discrete POMDP over enumerated states, actions and observations."""

    states: tuple[str, ...]
    actions: tuple[str, ...]
    observations: tuple[str, ...]
    transition: np.ndarray  # [a, s, s2]
    observation: np.ndarray  # [a, s2, o]
    reward: np.ndarray  # [a, s, s2, o]
    discount: float
    start: np.ndarray  # [s]
    notes: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.states, self.actions, self.observations = tuple(self.states), tuple(self.actions), tuple(self.observations)
        n_s, n_a, n_o = len(self.states), len(self.actions), len(self.observations)
        self.transition = np.asarray(self.transition, dtype=float)
        self.observation = np.asarray(self.observation, dtype=float)
        self.reward = np.asarray(self.reward, dtype=float)
        self.start = np.asarray(self.start, dtype=float)
        problems = []
        for name, arr, shape in (
            ("transition", self.transition, (n_a, n_s, n_s)),
            ("observation", self.observation, (n_a, n_s, n_o)),
            ("reward", self.reward, (n_a, n_s, n_s, n_o)),
            ("start", self.start, (n_s,)),
        ):
            if arr.shape != shape:
                problems.append(f"{name} has shape {arr.shape}, expected {shape}")
        if not problems:
            for name, arr, labels in (
                ("transition", self.transition, (self.actions, self.states)),
                ("observation", self.observation, (self.actions, self.states)),
            ):
                sums = arr.sum(axis=-1)
                bad = np.argwhere((np.abs(sums - 1.0) > 1e-6) | np.any(arr < 0, axis=-1))
                for a, s in bad[:5]:
                    problems.append(f"{name}[{labels[0][a]}, {labels[1][s]}] must be a probability row, sums to {sums[a, s]:.9g}")
            if abs(self.start.sum() - 1.0) > 1e-6 or np.any(self.start < 0):
                problems.append(f"start must be a probability distribution, sums to {self.start.sum():.9g}")
            if not 0.0 <= self.discount <= 1.0:
                problems.append(f"discount = {self.discount} must lie in [0, 1]")
        if problems:
            raise FlatPOMDPError(problems)

    @property
    def expected_reward(self) -> np.ndarray:
        """r[a, s] = Σ_{s2, o} T(s2 | s, a) O(o | s2, a) R(a, s, s2, o)."""
        return np.einsum("aij,ajo,aijo->ai", self.transition, self.observation, self.reward)

    @property
    def branch_kernels(self) -> np.ndarray:
        """M[a, o, s, s2] = T(s2 | s, a) O(o | s2, a): the unnormalized belief update."""
        return np.einsum("aij,ajo->aoij", self.transition, self.observation)

    def branch_model(self) -> BranchModel:
        """The problem in branch form: one context, one branch per observation."""
        branches = Branches.from_kernels(self.branch_kernels[None])
        return BranchModel(np.ones(1), self.expected_reward[None], branches, self.discount, self.start.copy())

    def finite_horizon_value(self, belief, horizon: int) -> float:
        """The exact optimal value of ``horizon`` steps from a belief (enumerating action and
        observation branches; for small problems and short horizons)."""
        return self.branch_model().finite_horizon_value(np.asarray(belief, dtype=float), horizon)
