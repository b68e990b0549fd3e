"""The belief filter, once: how the belief over trust moves after a trial, and where it can move.

A belief is a probability vector over the model's trust levels (for the paper's two
levels, ``b[-1]`` is P(trust = high)).  Two updates are offered:

* ``paper`` -- eq. (3) exactly as printed: b' = sum_T P(T' | T, E', C, a) b(T).
  It uses the experience E' but ignores the human action o.
* ``bayes`` -- the exact Bayes filter.  It first conditions on the human action,
  b+(T) ∝ b(T) P(o | T, C, a) (an intervention is evidence of low trust), and
  then predicts through the transition: b'(T') = sum_T P(T' | T, E', C, a) b+(T).
  E' carries no further information about T once o is known, because the
  outcome depends on trust only through the human action.  A human action that
  was not recorded (``o = -1``) or that the model deems impossible is not
  conditioned on.

Three views of the same filter: :class:`BayesUpdate` / :class:`PaperUpdate` follow one observed
trial, any number of trust levels; :class:`ScalarBelief` on x = P(trust = high) (the simulator's
fast path); :class:`Branches` enumerates every successor of a belief (what the belief-MDP
solvers expand), and :class:`BranchModel` is a POMDP in that branch form.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import TrustseekError
from ..model.core import TrustModel
from ..vocab import BELIEF_UPDATES as BELIEF_UPDATES  # the package exports it from here
from ..vocab import check_belief_update

# --------------------------------------------------------------------------- observed trials


#: the most belief nodes an exact finite-horizon value expands (about 12 s at 12 µs a node)
MAX_TREE_NODES = 1_000_000


class BeliefError(TrustseekError, ValueError):
    """A belief that does not fit the model (e.g. one number for more than two trust levels)."""


class _Updater:
    """Follows the belief through observed trials: ``initial()``, ``update(b, c, a, o, e)``."""

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


class PaperUpdate(_Updater):
    """Eq. (3) of the paper: propagate through P(T' | T, E', C, a), ignoring the human action."""

    name = "paper"

    def update(self, b, c, a, o, e) -> np.ndarray:
        return self._predict(np.asarray(b, dtype=float), c, a, e)


class BayesUpdate(_Updater):
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

    def update(self, b, c, a, o, e) -> np.ndarray:
        return self._predict(self.condition(b, c, a, o), c, a, e)


def make_updater(name: str, model: TrustModel) -> BayesUpdate | PaperUpdate:
    """The updater called ``name`` (``bayes`` or ``paper``) for ``model``."""
    return BayesUpdate(model) if check_belief_update(name) == "bayes" else PaperUpdate(model)


def to_vector(belief, n_trust: int) -> np.ndarray:
    """Accept a scalar P(trust = highest level) for two levels, or a full vector."""
    arr = np.asarray(belief, dtype=float)
    if arr.ndim == 0:
        if n_trust != 2:
            raise BeliefError(["a scalar belief is only meaningful for two trust levels"])
        return np.array([1.0 - float(arr), float(arr)])
    return arr


class ScalarBelief:
    """The ``paper``/``bayes`` updates for two trust levels, on x = P(trust = high).

    ``step(x, ca, o, e)`` takes ``ca = c * 2 + a`` and index arrays of the same shape as
    ``x``.  The model's tables are flattened once so that a step is a few gathers and
    multiply-adds; the result equals :class:`BayesUpdate` / :class:`PaperUpdate` on
    (1 - x, x) (the tests check it)."""

    def __init__(self, model: TrustModel, update: str):
        if model.n_trust != 2:
            raise BeliefError([f"the scalar belief needs two trust levels; this model has {model.n_trust}"])
        self.update_name = check_belief_update(update)
        tr = model.transition  # [c, a, e, t, u]
        self.a0 = np.ascontiguousarray(tr[..., 0, 1]).reshape(-1)  # P(high | low)     [c, a, e]
        self.slope = np.ascontiguousarray(tr[..., 1, 1] - tr[..., 0, 1]).reshape(-1)
        em = model.emission  # [c, a, t, o]
        self.lik_high = np.ascontiguousarray(em[:, :, 1, :]).reshape(-1)  # [c, a, o]
        self.lik_low = np.ascontiguousarray(em[:, :, 0, :]).reshape(-1)
        self.x0 = float(model.initial[1])

    def step(self, x: np.ndarray, ca: np.ndarray, o: np.ndarray, e: np.ndarray) -> np.ndarray:
        if self.update_name == "bayes":
            ko = ca * 2 + o
            num = x * self.lik_high[ko]
            z = num + (1.0 - x) * self.lik_low[ko]
            ok = z > 0
            x = np.where(ok, num / np.where(ok, z, 1.0), x)
        k = ca * 2 + e
        return self.a0[k] + self.slope[k] * x


# --------------------------------------------------------------------------- every successor


@dataclass(frozen=True, eq=False)
class Branches:
    """Every successor of a belief after one trial of complexity C with robot action a.

    A *branch* is what the robot learns from the trial: the pair (o, E') for ``bayes``
    (branch index o * 2 + E'), the experience E' alone for ``paper`` (eq. 3 ignores o).
    With ``prob[c, a, br, t]`` = P(branch | T = t, C, a) and ``move[c, a, br, t, u]``, a
    belief b takes branch br with probability b @ prob[c, a, br] and moves to

    * ``bayes``: b' = b @ move / (b @ move).sum(), where move[t, u] = P(o, E', T' = u | T = t)
      (so the normalizer is the branch probability: this is Bayes' rule on (o, E'));
    * ``paper``: b' = b @ move, where move[t, u] = P(T' = u | T = t, E', C, a) (eq. 3).

    ``contexts`` and ``actions`` are the first two axes: the complexities and the robot
    actions for the assistance POMDP, a single context for a flat POMDP.
    """

    update: str
    prob: np.ndarray  # [c, a, br, t]
    move: np.ndarray  # [c, a, br, t, u]

    def __post_init__(self) -> None:
        check_belief_update(self.update)

    @classmethod
    def from_kernels(cls, kernels: np.ndarray) -> Branches:
        """The Bayes branches of unnormalized kernels M[c, a, br, t, u] = P(br, T' = u | T = t, c, a)."""
        kernels = np.asarray(kernels, dtype=float)
        return cls("bayes", kernels.sum(axis=-1), kernels)

    @property
    def n_hidden(self) -> int:
        return self.prob.shape[3]

    def successors(self, beliefs: np.ndarray, c: int | None = None, a: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(probabilities, next beliefs) of beliefs (n, K).

        For one (c, a): shapes (n, branches) and (n, branches, K); with ``c`` and ``a`` left
        out, every (c, a) at once: (n, C, A, branches) and (n, C, A, branches, K).  A branch
        of probability zero leads to the uniform belief (any belief would do: it is never
        reached), so every next belief is a distribution."""
        B = np.asarray(beliefs, dtype=float)
        move = self.move if c is None else self.move[c, a]  # (..., br, t, u)
        K = B.shape[1]
        # one matrix product for every (c, a, br) at once: b @ move
        nb = (B @ np.moveaxis(move, -2, 0).reshape(K, -1)).reshape(len(B), *move.shape[:-2], move.shape[-1])
        if self.update == "paper":
            prob = self.prob if c is None else self.prob[c, a]  # (..., br, t)
            return (B @ np.moveaxis(prob, -1, 0).reshape(K, -1)).reshape(len(B), *prob.shape[:-1]), nb
        p = nb @ np.ones(nb.shape[-1])  # (a matrix product: much faster than a sum over a short axis)
        impossible = p <= 0
        nxt = nb / np.where(impossible, 1.0, p)[..., None]
        if impossible.any():
            nxt[impossible] = 1.0 / nb.shape[-1]
        return p, nxt

    def two_level(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """For two trust levels, each branch as functions of x = P(trust = high):
        (p0, p1, m0, m1), arrays [c, a, br], with

            P(branch | x) = p0 (1 - x) + p1 x,
            x'(x) = (m0 (1 - x) + m1 x) / P(branch | x)   (bayes)   or   m0 (1 - x) + m1 x   (paper).
        """
        if self.n_hidden != 2:
            raise BeliefError([f"two_level() needs two trust levels; these branches have {self.n_hidden}"])
        return self.prob[..., 0], self.prob[..., 1], self.move[..., 0, 1], self.move[..., 1, 1]


# --------------------------------------------------------------------------- the branch form
# The complexity (a context, i.i.d., seen before acting) is observed, trust is not; a flat POMDP
# (a ``.pomdp`` file) is the case of one context whose branches are the observations.


@dataclass(frozen=True, eq=False)
class BranchModel:
    """context_probs[c], rewards[c, a, t], Bayes ``branches``, discount, initial belief[t]."""

    context_probs: np.ndarray
    rewards: np.ndarray
    branches: Branches
    discount: float
    initial: np.ndarray
    #: the sizes: contexts (complexities; one for a flat POMDP), actions, hidden states (trust levels)
    n_contexts: int = field(init=False)
    n_actions: int = field(init=False)
    n_hidden: int = field(init=False)

    def __post_init__(self) -> None:
        for name, size in zip(("n_contexts", "n_actions", "n_hidden"), self.rewards.shape, strict=True):
            object.__setattr__(self, name, int(size))

    @property
    def kernels(self) -> np.ndarray:
        """M[c, a, branch, t, t2] = P(branch, T' = t2 | T = t, c, a): the unnormalized belief update."""
        return self.branches.move

    def tree_size(self, belief: np.ndarray, horizon: int, context: int | None = None) -> int:
        """The belief nodes :meth:`finite_horizon_value` expands, counted before any of them on
        the beliefs' supports alone (a branch is expanded when it can happen from the support)."""
        reach = self.kernels > 0
        memo: dict[tuple[int, bytes, int], int] = {}

        def nodes(support: np.ndarray, c: int, h: int) -> int:
            key = (c, support.tobytes(), h)
            if key not in memo:
                n = 1
                if h > 1:
                    for a in range(self.n_actions):
                        for br in range(reach.shape[2]):
                            nxt = support @ reach[c, a, br]
                            if nxt.any():
                                n += sum(nodes(nxt, c2, h - 1) for c2, pc in enumerate(self.context_probs) if pc > 0)
                memo[key] = n
            return memo[key]

        start = np.asarray(belief, dtype=float) > 0
        contexts = [context] if context is not None else [c for c, pc in enumerate(self.context_probs) if pc > 0]
        return 0 if horizon == 0 else sum(nodes(start, c, horizon) for c in contexts)

    def finite_horizon_value(self, belief: np.ndarray, horizon: int, context: int | None = None) -> float:
        """The exact optimal value of ``horizon`` trials from a belief, by expanding the belief
        tree (every context, action and branch; for small problems and short horizons): for a
        known context of the first trial, or averaged over the context probabilities.  A tree of
        more than :data:`MAX_TREE_NODES` nodes (:meth:`tree_size`) is refused before any work."""
        b0 = np.asarray(belief, dtype=float)
        size = self.tree_size(b0, horizon, context)
        if size > MAX_TREE_NODES:
            raise BeliefError(
                [
                    f"horizon {horizon}: the exact value expands {size:,} belief nodes, more than {MAX_TREE_NODES:,} "
                    "(about 12 s): a shorter horizon"
                ]
            )
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
