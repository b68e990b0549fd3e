"""Alpha-vector policies: greedy in Q(b, C, a) = max over a set of vectors α of α·b.

Each vector is the value of "take this action now, then follow a finite-state controller",
so max α·b is a lower bound on Q; the certified solvers (``alpha``, ``point``) return these
policies.  :class:`AlphaVectorPolicy` serves the assistance POMDP (any number of trust
levels); :class:`FlatAlphaPolicy` a flat POMDP read from a standard file.

:class:`TypeAwarePolicy` is an alpha-vector policy for a person whose supervisor type is
unknown: its model is the product of a :class:`~trustseek.model.mixture.TypeMixture`
(:func:`trustseek.pomdp.supervisor_types.product_model`), its belief is over the M·K pairs
(type, trust), so ``PolicyRunner``, the simulator and the server run it like any alpha-vector
policy; it keeps the mixture, so the type belief and the trust belief can be read off its
belief.  Its JSON (kind ``type-aware``, docs/types-planning.md) holds the alpha-vector fields
without ``model``, and the mixture.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..model.core import TrustModel
from ..model.jsonfile import ModelError, build
from ..model.mixture import TypeMixture
from ..pomdp.supervisor_types import product_model, trust_marginal, type_marginal, warm_start_belief
from ..vocab import ACTIONS, ASK, AUTONOMOUS
from .base import Policy, PolicyError, planned_for
from .envelope import envelope
from .regions import Interval, ask_intervals

Q_SETS = "every set of q_vectors"


def _vectors(value: Any, K: int, what: str, problems: list[str]) -> np.ndarray:
    """``value`` as a non-empty (n, K) array of finite numbers (a problem naming ``what`` noted, not raised)."""
    try:
        v = np.atleast_2d(np.asarray(value, dtype=float))
    except (TypeError, ValueError):
        v = np.empty((0, K))
    if v.ndim != 2 or v.shape[1] != K or len(v) == 0 or not np.all(np.isfinite(v)):
        problems.append(f"{what} must be a non-empty (n, {K}) array of finite numbers")
    return v


class AlphaVectorPolicy(Policy):
    """Greedy in Q(b, C, a) = max over the Q-vectors of (C, a) of α·b; any number of trust levels.

    ``q_vectors[c][a]`` is an array (n, K) of vectors, each the value of "take a now, then
    follow a controller", so max α·b is a lower bound on Q(b, C, a).  ``value_vectors`` (n, K)
    represent the lower bound on W(b) = Σ_C P(C) max_a Q(b, C, a).  Ties go to ``autonomous``.
    """

    kind = "alpha-vector"

    def __init__(
        self,
        q_vectors: Sequence[Sequence[np.ndarray]],
        value_vectors: np.ndarray,
        model: TrustModel,
        complexities: Sequence[str],
        belief_update: str = "bayes",
        info: Mapping[str, Any] | None = None,
    ):
        self.model = model
        self.complexities = tuple(complexities)
        self.belief_update = belief_update
        self.info = dict(info or {})
        K = model.n_trust
        problems: list[str] = []
        if len(q_vectors) != len(self.complexities) or any(len(p) != 2 for p in q_vectors):
            problems.append(f"q_vectors needs one entry per complexity {list(self.complexities)} and action {list(ACTIONS)}")
        self.q_vectors = [[_vectors(v, K, Q_SETS, problems) for v in per_a] for per_a in q_vectors]
        self.value_vectors = _vectors(value_vectors, K, "value_vectors", problems)
        if problems:
            raise ModelError(list(dict.fromkeys(problems)))

    # -- decisions -----------------------------------------------------------
    def q_of(self, beliefs: np.ndarray, complexities: np.ndarray) -> np.ndarray:
        """Q lower bounds for each (belief, complexity) pair; shape (n, 2)."""
        beliefs = np.atleast_2d(np.asarray(beliefs, dtype=float))
        complexities = np.asarray(complexities, dtype=np.int64).reshape(-1)
        out = np.empty((len(beliefs), 2))
        for c in np.unique(complexities):
            sel = complexities == c
            for a in range(2):
                out[sel, a] = (beliefs[sel] @ self.q_vectors[c][a].T).max(axis=1)
        return out

    def actions(self, beliefs: np.ndarray | None, complexities: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        q = self.q_of(np.asarray(beliefs, dtype=float), complexities)
        return np.where(q[:, ASK] > q[:, AUTONOMOUS], ASK, AUTONOMOUS).astype(np.int64)

    def describe(self) -> str:
        return f"{self.kind} ({sum(len(v) for p in self.q_vectors for v in p)} Q-vectors)"

    # -- values and ask regions ----------------------------------------------
    def q_values(self, b_high: Any) -> np.ndarray:
        """Q lower bounds at P(trust = high) = b_high (two trust levels); shape (..., N, 2)."""
        self._need_two_levels()
        x = np.asarray(b_high, dtype=float)
        b = np.stack([1 - x, x], axis=-1)
        return np.stack([np.stack([(b @ v.T).max(axis=-1) for v in per_a], axis=-1) for per_a in self.q_vectors], axis=-2)

    def ask_intervals(self) -> dict[str, list[Interval]]:
        """Per complexity, the belief intervals where the policy asks (exact: the advantage is
        piecewise linear, so its sign changes are found at breakpoints and by linear roots)."""
        self._need_two_levels()
        out = {}
        for c, cn in enumerate(self.complexities):
            pts = [np.array([0.0, 1.0])] + [envelope(self.q_vectors[c][a])[1] for a in range(2)]
            x = np.unique(np.concatenate(pts))
            q = self.q_values(x)[:, c]
            out[cn] = ask_intervals(x, q[:, ASK] - q[:, AUTONOMOUS])
        return out

    # -- JSON ----------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        assert self.model is not None
        d = self._file(
            belief_update=self.belief_update,
            info=self.info,
            model=self.model.to_dict(),
            q_vectors={
                cn: {an: self.q_vectors[c][a].tolist() for a, an in enumerate(ACTIONS)} for c, cn in enumerate(self.complexities)
            },
            value_vectors=self.value_vectors.tolist(),
        )
        if self.model.n_trust == 2:
            d["thresholds"] = self.thresholds()
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], source: str | None = None) -> AlphaVectorPolicy:
        cx, model, bu = planned_for(d, source)
        qv: Any = d.get("q_vectors")
        try:
            q = [[np.array(qv[c][a], dtype=float) for a in ACTIONS] for c in cx]
        except (KeyError, TypeError, ValueError):
            raise ModelError(
                [f"q_vectors must map each complexity {cx} and action {list(ACTIONS)} to a list of vectors"], source
            ) from None
        return build([], source, lambda: cls(q, d.get("value_vectors", []), model, cx, bu, d.get("info")))


class FlatAlphaPolicy(Policy):
    """Greedy in alpha vectors over the states of a flat POMDP (the point solver's policy for a
    standard ``.pomdp`` file): action a(b) = argmax_a max over the Q-vectors of a of α·b.

    A flat POMDP has no observed complexity: the policy has one context, :data:`CONTEXT`.
    Its actions are the file's, so it has no ask region and no trust belief of its own.
    """

    kind = "flat-alpha-vector"
    CONTEXT = "all"

    def __init__(
        self,
        q_vectors: Sequence[np.ndarray],
        value_vectors: np.ndarray,
        states: Sequence[str],
        action_names: Sequence[str],
        info: Mapping[str, Any] | None = None,
    ):
        self.complexities = (self.CONTEXT,)
        self.belief_update = "bayes"
        self.states = tuple(states)
        self.action_names = tuple(action_names)
        self.info = dict(info or {})
        problems: list[str] = []
        if len(q_vectors) != len(self.action_names):
            problems.append(f"q_vectors needs one set per action {list(self.action_names)}")
        self.q_vectors = [_vectors(v, len(self.states), Q_SETS, problems) for v in q_vectors]
        self.value_vectors = _vectors(value_vectors, len(self.states), "value_vectors", problems)
        if problems:
            raise ModelError(list(dict.fromkeys(problems)))

    def actions(self, beliefs: np.ndarray | None, complexities: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        B = np.atleast_2d(np.asarray(beliefs, dtype=float))
        q = np.stack([(B @ v.T).max(axis=1) for v in self.q_vectors], axis=1)
        return q.argmax(axis=1).astype(np.int64)

    def action(self, belief: Any, complexity: int | str = 0, rng: np.random.Generator | None = None) -> int:
        self.complexity_index(complexity)
        return int(self.actions(np.asarray(belief, dtype=float)[None, :], np.zeros(1, dtype=np.int64))[0])

    def ask_intervals(self) -> dict[str, list[Interval]] | None:
        actions = list(self.action_names)
        raise PolicyError([f"a {self.kind} policy chooses among the file's actions {actions}: it has no ask region"])

    def describe(self) -> str:
        return f"{self.kind} ({sum(len(v) for v in self.q_vectors)} Q-vectors over {len(self.states)} states)"

    def to_dict(self) -> dict[str, Any]:
        return self._file(
            states=list(self.states),
            actions=list(self.action_names),
            info=self.info,
            q_vectors={an: v.tolist() for an, v in zip(self.action_names, self.q_vectors, strict=True)},
            value_vectors=self.value_vectors.tolist(),
        )

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], source: str | None = None) -> FlatAlphaPolicy:
        states, names, qv = d.get("states"), d.get("actions"), d.get("q_vectors")
        if not isinstance(states, list) or not isinstance(names, list) or not isinstance(qv, Mapping):
            raise ModelError(["a flat-alpha-vector policy needs 'states', 'actions' and 'q_vectors'"], source)
        try:
            q = [np.array(qv[a], dtype=float) for a in names]
        except (KeyError, TypeError, ValueError):
            raise ModelError([f"q_vectors must map each action {names} to a list of vectors"], source) from None
        return build([], source, lambda: cls(q, d.get("value_vectors", []), states, names, d.get("info")))


class TypeAwarePolicy(AlphaVectorPolicy):
    """Greedy in Q-vectors over (type, trust) beliefs; ``mixture`` names the types."""

    kind = "type-aware"

    def __init__(
        self,
        mixture: TypeMixture,
        q_vectors: Sequence[Sequence[np.ndarray]],
        value_vectors: np.ndarray,
        complexities: Sequence[str],
        belief_update: str = "bayes",
        info: Mapping[str, Any] | None = None,
    ):
        self.mixture = mixture
        super().__init__(q_vectors, value_vectors, product_model(mixture), complexities, belief_update, info)

    @classmethod
    def from_alpha(cls, mixture: TypeMixture, policy: AlphaVectorPolicy) -> TypeAwarePolicy:
        """The alpha-vector policy of the product problem of ``mixture`` as a type-aware policy."""
        update = policy.belief_update or "bayes"
        return cls(mixture, policy.q_vectors, policy.value_vectors, policy.complexities, update, policy.info)

    @property
    def type_names(self) -> tuple[str, ...]:
        return self.mixture.names

    def type_belief(self, belief: Any) -> np.ndarray:
        """P(type) of a product belief."""
        return type_marginal(belief, self.mixture.n_types)

    def trust_belief(self, belief: Any) -> np.ndarray:
        """P(trust) of a product belief, whatever the type."""
        return trust_marginal(belief, self.mixture.n_types)

    def initial_belief(self, type_belief: Any = None) -> np.ndarray:
        """The product belief a session starts from: the mixture's weights, or ``type_belief``
        (e.g. the posterior of a returning person, ``type_belief_from_log``)."""
        return warm_start_belief(self.mixture, type_belief)

    def describe(self) -> str:
        n = sum(len(v) for p in self.q_vectors for v in p)
        return f"{self.kind} over {self.mixture.n_types} supervisor types {list(self.mixture.names)} ({n} Q-vectors)"

    def to_dict(self) -> dict[str, Any]:
        d = super().to_dict()
        d.pop("model")
        d["mixture"] = self.mixture.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], source: str | None = None) -> TypeAwarePolicy:
        mixture = TypeMixture.from_dict(d.get("mixture"), source)
        plain = AlphaVectorPolicy.from_dict({**d, "model": product_model(mixture).to_dict()}, source)
        return build([], source, lambda: cls.from_alpha(mixture, plain))
