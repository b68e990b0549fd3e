"""Belief updaters: how the belief over trust moves after one trial.

A belief is a probability vector over the model's trust levels (for the paper's
two levels, ``b[-1]`` is P(trust = high)).  Both updaters are vectorized: ``b``
may have shape (..., K) with integer arrays ``c, a, o, e`` of shape (...).

* ``paper`` -- eq. (3) exactly as printed: b' = sum_T P(T' | T, E', C, a) b(T).
  It uses the experience E' but ignores the human action o.
* ``bayes`` -- the exact Bayes filter.  It first conditions on the human action,
  b+(T) ∝ b(T) P(o | T, C, a) (an intervention is evidence of low trust), and
  then predicts through the transition: b'(T') = sum_T P(T' | T, E', C, a) b+(T).
  E' carries no further information about T once o is known, because the
  outcome depends on trust only through the human action.  A human action that
  was not recorded (``o = -1``) or that the model deems impossible is not
  conditioned on.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ..model.core import TrustModel
from ..vocab import BELIEF_UPDATES, UNOBSERVED, check_belief_update

__all__ = ["BELIEF_UPDATES", "UNOBSERVED", "BayesUpdate", "BeliefUpdater", "PaperUpdate", "make_updater", "to_vector"]



class BeliefUpdater(Protocol):
    name: str
    model: TrustModel

    def initial(self) -> np.ndarray: ...

    def update(self, b: np.ndarray, c, a, o, e) -> np.ndarray: ...


class _Base:
    name = ""

    def __init__(self, model: TrustModel):
        self.model = model

    def initial(self) -> np.ndarray:
        return np.array(self.model.initial, dtype=float)

    def _predict(self, b: np.ndarray, c, a, e) -> np.ndarray:
        tr = self.model.transition[c, a, e]  # (..., K, K)
        return np.einsum("...k,...kj->...j", b, tr)

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


class PaperUpdate(_Base):
    """Eq. (3) of the paper: propagate through P(T' | T, E', C, a), ignoring the human action."""

    name = "paper"

    def update(self, b, c, a, o, e):
        return self._predict(np.asarray(b, dtype=float), c, a, e)


class BayesUpdate(_Base):
    """The exact Bayes filter, conditioning on the human action before the transition."""

    name = "bayes"

    def condition(self, b, c, a, o) -> np.ndarray:
        """P(T | o, b, C, a): the belief after seeing the human action (before the transition)."""
        b = np.asarray(b, dtype=float)
        o = np.asarray(o)
        lik = self.model.emission[c, a, :, np.where(o < 0, 0, o)]  # (..., K)
        lik = np.where((o < 0)[..., None], 1.0, lik)
        post = b * lik
        z = post.sum(axis=-1, keepdims=True)
        # impossible under the model: keep the prior rather than divide by zero
        return np.where(z > 0, post / np.where(z > 0, z, 1.0), b)

    def update(self, b, c, a, o, e):
        return self._predict(self.condition(b, c, a, o), c, a, e)


def make_updater(name: str, model: TrustModel) -> BayesUpdate | PaperUpdate:
    return BayesUpdate(model) if check_belief_update(name) == "bayes" else PaperUpdate(model)


def to_vector(belief, n_trust: int) -> np.ndarray:
    """Accept a scalar P(trust = highest level) for two levels, or a full vector."""
    arr = np.asarray(belief, dtype=float)
    if arr.ndim == 0:
        if n_trust != 2:
            raise ValueError("a scalar belief is only meaningful for two trust levels")
        return np.array([1.0 - float(arr), float(arr)])
    return arr
