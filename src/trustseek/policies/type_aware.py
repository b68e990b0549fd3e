"""The type-aware policy: alpha vectors over (type, trust) for a person whose type is unknown.

:class:`TypeAwarePolicy` is an :class:`~trustseek.policies.alpha_vector.AlphaVectorPolicy`
whose model is the product of a :class:`~trustseek.model.mixture.TypeMixture`
(:func:`trustseek.pomdp.supervisor_types.product_model`): its belief is over the M·K pairs (type, trust),
so ``PolicyRunner``, the simulator and the server run it like any alpha-vector policy.  It
keeps the mixture, so the type belief and the trust belief can be read off its belief.

JSON (kind ``type-aware``): the alpha-vector fields without ``model``, and the mixture::

    {"format": "trustseek.policy/1", "kind": "type-aware", "complexities": [...],
     "belief_update": "bayes", "mixture": {<trustseek.mixture/1>},
     "q_vectors": {C: {a: [[... M·K numbers ...], ...]}}, "value_vectors": [...], "info": {...}}
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..model.jsonfile import ModelError
from ..model.mixture import TypeMixture
from ..pomdp.supervisor_types import product_model, trust_marginal, type_marginal, warm_start_belief
from .alpha_vector import AlphaVectorPolicy


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
        try:
            return cls.from_alpha(mixture, plain)
        except ModelError as exc:
            raise ModelError(exc.problems, source) from None
