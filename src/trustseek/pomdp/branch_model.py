"""A POMDP in branch form: what the point-based solver and controller evaluation work on.

The assistance POMDP has a *mixed* observability: the complexity (a context, drawn
i.i.d. from P(C) and seen before acting) is observed, trust (the hidden part) is not,
and after each trial a branch (o, E') moves the belief.  A flat POMDP (e.g. a ``.pomdp``
file) is the special case of one context whose branches are the observations.  Both are
written here as

    context_probs[c], rewards[c, a, t], branches (Bayes: kernels[c, a, branch, t, t2]),
    discount, initial[t].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .belief import Branches


@dataclass(frozen=True, eq=False)
class BranchModel:
    """context_probs[c], rewards[c, a, t], Bayes ``branches``, discount, initial belief[t]."""

    context_probs: np.ndarray
    rewards: np.ndarray
    branches: Branches
    discount: float
    initial: np.ndarray

    @property
    def kernels(self) -> np.ndarray:
        """M[c, a, branch, t, t2] = P(branch, T' = t2 | T = t, c, a): the unnormalized belief update."""
        return self.branches.move

    @property
    def n_hidden(self) -> int:
        return self.rewards.shape[2]

    @property
    def n_actions(self) -> int:
        return self.rewards.shape[1]

    @property
    def n_contexts(self) -> int:
        return len(self.context_probs)

    def finite_horizon_value(self, belief: np.ndarray, horizon: int, context: int | None = None) -> float:
        """The exact optimal value of ``horizon`` trials from a belief, by expanding the belief
        tree (every context, action and branch; for small problems and short horizons): for a
        known context of the first trial, or averaged over the context probabilities."""
        b0 = np.asarray(belief, dtype=float)
        M = self.kernels

        def v(b: np.ndarray, c: int, h: int) -> float:
            best = -np.inf
            for a in range(self.n_actions):
                q = float(self.rewards[c, a] @ b)
                if h > 1:
                    for br in range(M.shape[2]):
                        nb = b @ M[c, a, br]
                        p = nb.sum()
                        if p > 1e-300:
                            q += self.discount * p * w(nb / p, h - 1)
                best = max(best, q)
            return best

        def w(b: np.ndarray, h: int) -> float:
            return float(sum(pc * v(b, c, h) for c, pc in enumerate(self.context_probs) if pc > 0))

        if horizon == 0:
            return 0.0
        return w(b0, horizon) if context is None else v(b0, context, horizon)
