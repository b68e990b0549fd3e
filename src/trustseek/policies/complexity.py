"""Policies that look only at the complexity: ask with probability p_ask[C], ignoring the belief.

Kinds (the ``kind`` field of the policy JSON):

* ``trust-agnostic``: Section VI-A, one fixed action per complexity (p_ask in {0, 1});
* ``randomized``: the data-collection policy, ask with probability p_ask[C]
  (paper: 0.10 in low, 0.40 in high complexity);
* ``always-ask`` and ``never-ask``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..model.jsonfile import ModelError, build
from ..vocab import COMPLEXITY_POLICY_KINDS, PAPER_ASK_PROBABILITIES
from .base import Policy, PolicyError
from .regions import Interval


class ComplexityPolicy(Policy):
    """A policy that looks only at the complexity: ask with probability p_ask[C].

    Covers ``trust-agnostic`` (p_ask in {0, 1}), ``randomized``, ``always-ask`` and
    ``never-ask``.  It ignores the belief (``belief_update`` is None), so it has no Q-function;
    its ask region in a complexity is all beliefs or none, unless it asks at random.
    """

    def __init__(
        self, kind: str, complexities: Sequence[str], p_ask: Sequence[float] | np.ndarray, info: Mapping[str, Any] | None = None
    ):
        self.kind = kind
        self.complexities = tuple(complexities)
        self.p_ask = np.asarray(p_ask, dtype=float)
        self.info = dict(info or {})
        problems = []
        if self.p_ask.shape != (len(self.complexities),):
            problems.append(f"p_ask needs one entry per complexity {list(self.complexities)}, got {self.p_ask.tolist()}")
        elif np.any(~np.isfinite(self.p_ask)) or np.any(self.p_ask < 0) or np.any(self.p_ask > 1):
            problems.append(f"p_ask must lie in [0, 1], got {self.p_ask.tolist()}")
        if kind not in COMPLEXITY_POLICY_KINDS:
            problems.append(f"unknown policy kind {kind!r}")
        if problems:
            raise ModelError(problems)

    @property
    def deterministic(self) -> bool:
        return bool(np.all((self.p_ask == 0) | (self.p_ask == 1)))

    def actions(self, beliefs: np.ndarray | None, complexities: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        complexities = np.asarray(complexities, dtype=np.int64)
        p = self.p_ask[complexities]
        if np.all((p == 0) | (p == 1)):
            return (p == 1).astype(np.int64)
        if rng is None:
            raise PolicyError([f"the {self.kind} policy is random: pass a numpy Generator as rng"])
        return (rng.random(p.shape) < p).astype(np.int64)

    def ask_intervals(self) -> dict[str, list[Interval]] | None:
        """All beliefs where it always asks, none where it never asks; ``None`` when it asks at random."""
        if not self.deterministic:
            return None
        return {cn: [(0.0, 1.0)] if p == 1 else [] for cn, p in zip(self.complexities, self.p_ask, strict=True)}

    def describe(self) -> str:
        parts = ", ".join(f"{cn}: {_describe_p(p)}" for cn, p in zip(self.complexities, self.p_ask, strict=True))
        return f"{self.kind} ({parts})"

    def to_dict(self) -> dict[str, Any]:
        return self._file(p_ask={cn: float(p) for cn, p in zip(self.complexities, self.p_ask, strict=True)}, info=self.info)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], source: str | None = None) -> ComplexityPolicy:
        cx = list(d.get("complexities") or [])
        p = d.get("p_ask")
        # the keys in any order (a JSON object has none: databases and sort_keys reorder them),
        # but exactly the policy's complexities
        if not isinstance(p, Mapping) or len(p) != len(cx) or set(p) != set(cx):
            raise ModelError([f"p_ask must map each of {cx} to a probability, got {p!r}"], source)
        return build([], source, lambda: cls(str(d.get("kind")), cx, [p[c] for c in cx], d.get("info")))


def _describe_p(p: float) -> str:
    if p == 0:
        return "never ask"
    if p == 1:
        return "always ask"
    return f"ask w.p. {p:g}"


def always_ask(complexities: Sequence[str] = ("low", "high")) -> ComplexityPolicy:
    """Ask in every trial."""
    return ComplexityPolicy("always-ask", complexities, [1.0] * len(complexities))


def never_ask(complexities: Sequence[str] = ("low", "high")) -> ComplexityPolicy:
    """Never ask."""
    return ComplexityPolicy("never-ask", complexities, [0.0] * len(complexities))


def randomized(p_ask: Mapping[str, float] | None = None) -> ComplexityPolicy:
    """The data-collection policy of Section V (default: ask w.p. 0.10 in low, 0.40 in high)."""
    p_ask = dict(PAPER_ASK_PROBABILITIES if p_ask is None else p_ask)
    return ComplexityPolicy("randomized", list(p_ask), list(p_ask.values()))
