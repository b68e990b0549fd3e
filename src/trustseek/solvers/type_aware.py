"""The type-aware solve: a policy for a person whose supervisor type is unknown.

``solve_type_aware(mixture, task)`` builds the POMDP over (type, trust)
(:func:`trustseek.pomdp.types.type_aware_problem`) and solves it with a registered solver
(:mod:`.registry`), like any other problem; an alpha-vector result comes back as a
:class:`~trustseek.policies.type_aware.TypeAwarePolicy`, which keeps the mixture.

A person's own policy is the same solve from their type belief: ``type_belief`` (e.g. the
posterior of :func:`trustseek.pomdp.types.type_belief_from_log` over their earlier sessions)
replaces the mixture's weights as the initial belief.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..model.core import TrustModel
from ..model.mixture import TypeMixture
from ..model.task import Task
from ..policies.alpha_vector import AlphaVectorPolicy
from ..policies.base import Policy
from ..policies.type_aware import TypeAwarePolicy
from ..pomdp.types import type_aware_problem
from .defaults import DEFAULT_TYPE_AWARE_SOLVER
from .registry import make_solver

__all__ = ["DEFAULT_TYPE_AWARE_SOLVER", "solve_type_aware"]


def solve_type_aware(
    mixture: TypeMixture | TrustModel,
    task: Task,
    solver: str = DEFAULT_TYPE_AWARE_SOLVER,
    gap: float = 1e-3,
    type_belief: Sequence[float] | np.ndarray | None = None,
    **options: Any,
) -> Policy:
    """The policy of the (type, trust) POMDP of ``mixture`` and ``task``, solved by the registered
    solver ``solver`` to a bound gap ``gap`` at the initial belief (``options`` go to the solver).

    ``type_belief`` starts the types from that distribution instead of the mixture's weights
    (a returning person's warm start).  The result is a :class:`TypeAwarePolicy` when the
    solver returns alpha vectors; any other policy is returned as the solver built it (its
    model is the product model)."""
    if isinstance(mixture, TrustModel):
        mixture = TypeMixture.single(mixture)
    if type_belief is not None:
        mixture = mixture.with_weights(list(np.asarray(type_belief, dtype=float).reshape(-1)))
    policy = make_solver(solver, gap=gap, **options).solve(type_aware_problem(mixture, task))
    if type(policy) is AlphaVectorPolicy:
        out = TypeAwarePolicy.from_alpha(mixture, policy)
        out.info["types"] = list(mixture.names)
        out.info["type_weights"] = mixture.weights.tolist()
        return out
    return policy
