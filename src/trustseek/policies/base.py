"""The ``Policy`` base class, which every policy kind extends, and what policies share.

A policy answers one question -- given the robot's belief over trust and the trial's
complexity, ``autonomous`` or ``ask``? -- vectorized (``actions``) or for one trial
(``action``).  Around it every policy also says where it asks (``ask_intervals`` /
``thresholds``), gives its Q-function and value when it has one, and writes itself as
JSON (``to_dict``; the ``kind`` field names the loader, see :mod:`.kinds`).  Where a policy asks,
through this interface: :func:`ask_bounds` (the simulator's threshold bounds) and
:func:`ask_regions` (the JSON view).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import TrustseekError
from ..model.core import TrustModel
from ..model.jsonfile import ModelError, json_safe
from ..pomdp.belief import to_vector
from ..vocab import VocabularyError, check_belief_update
from .regions import Interval, threshold

POLICY_FORMAT = "trustseek.policy/1"


class PolicyError(TrustseekError, ValueError):
    """A policy was asked for something it does not have (e.g. the Q-function of a policy
    that ignores the belief, or thresholds of a model with more than two trust levels)."""


class Policy:
    """What the robot does on the next trial; every policy kind is one of these.

    ``belief_update`` names the belief the policy reads (``bayes`` or ``paper``; ``None`` for
    a policy that ignores the belief) and ``model`` the trust model it is tracked with.
    Beliefs are rows over the trust levels (for ``action``, P(trust = high) as one number is
    accepted for two levels); complexities are indices (``action`` also takes names).
    """

    kind = ""
    complexities: tuple[str, ...] = ()
    belief_update: str | None = None
    model: TrustModel | None = None
    info: dict[str, Any]

    def complexity_index(self, complexity: int | str) -> int:
        """The index of a complexity given by name or index (KeyError when unknown)."""
        if isinstance(complexity, str):
            try:
                return self.complexities.index(complexity)
            except ValueError:
                raise KeyError(f"unknown complexity {complexity!r}; expected one of {list(self.complexities)}") from None
        c = int(complexity)
        if not 0 <= c < len(self.complexities):
            raise KeyError(f"complexity index {c} out of range for {list(self.complexities)}")
        return c

    def actions(self, beliefs: np.ndarray | None, complexities: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        """Actions (0 = autonomous, 1 = ask) for beliefs (n, K) and complexity indices (n,)."""
        raise NotImplementedError

    def action(self, belief: Any, complexity: int | str, rng: np.random.Generator | None = None) -> int:
        """The action of one trial."""
        n_trust = self.model.n_trust if self.model is not None else 2
        b = to_vector(belief, n_trust)[None, :] if belief is not None else np.full((1, n_trust), np.nan)
        return int(self.actions(b, np.array([self.complexity_index(complexity)]), rng)[0])

    def ask_intervals(self) -> dict[str, list[Interval]] | None:
        """Per complexity, the intervals of P(trust = high) where the policy asks (two trust
        levels); ``None`` for a policy that asks at random."""
        raise NotImplementedError

    def thresholds(self) -> dict[str, float | None] | None:
        """Per complexity, the belief in high trust below which the policy asks (``None``:
        never asks, 1.0: always asks, NaN: the ask region is not [0, θ)); ``None`` for a
        policy that asks at random."""
        intervals = self.ask_intervals()
        return None if intervals is None else {cn: threshold(iv) for cn, iv in intervals.items()}

    def q_values(self, b_high: Any) -> np.ndarray:
        """Q(b, C, a) at P(trust = high) = b_high (two trust levels), shape (..., N, 2)."""
        raise PolicyError([f"a {self.kind} policy has no Q-function"])

    def value(self, b_high: Any, complexity: int | str | None = None) -> np.ndarray:
        """V(b, C) = max_a Q(b, C, a) at P(trust = high) = b_high: shape (..., N), or (...)
        for one complexity."""
        v = self.q_values(b_high).max(axis=-1)
        return v if complexity is None else v[..., self.complexity_index(complexity)]

    def to_dict(self) -> dict[str, Any]:
        """The policy JSON (format ``trustseek.policy/1``)."""
        raise NotImplementedError

    def _file(self, **fields: Any) -> dict[str, Any]:
        """A policy file: its format, kind and complexities, then ``fields`` in their order."""
        return {"format": POLICY_FORMAT, "kind": self.kind, "complexities": list(self.complexities), **fields}

    def save(self, path: str | Path) -> None:
        """Write the policy JSON to a file."""
        Path(path).write_text(json.dumps(json_safe(self.to_dict()), indent=1, allow_nan=False) + "\n", encoding="utf-8")

    def describe(self) -> str:
        """One line for people."""
        return self.kind

    def overview(self) -> dict[str, Any]:
        """A JSON object naming the policy, small enough to print with results."""
        return self.to_dict()

    def _need_two_levels(self) -> None:
        if self.model is not None and self.model.n_trust != 2:
            raise PolicyError(
                [f"ask intervals, thresholds and Q(b_high) need two trust levels; this model has {self.model.n_trust}"]
            )


def planned_for(d: Mapping[str, Any], source: str | None) -> tuple[list[str], TrustModel, str]:
    """What a trust-aware policy file was planned for: its complexities, its trust model and its
    belief update (one of :data:`~trustseek.vocab.BELIEF_UPDATES`)."""
    model = TrustModel.from_dict(d.get("model"), source)
    try:
        update = check_belief_update(d.get("belief_update"), "belief_update")
    except VocabularyError as exc:
        raise ModelError(exc.problems, source) from None
    return list(d.get("complexities") or []), model, update


def ask_bounds(policy: Policy) -> np.ndarray | None:
    """Per complexity index, the bound θ_C such that the policy asks exactly when
    P(trust = high) < θ_C (``-inf``: never asks, ``+inf``: always asks), or ``None`` when its
    ask region is not an interval starting at 0 or when it asks at random.

    This is the policy's ``actions`` in one comparison per trial (what the simulator uses);
    the bounds are the ends of ``ask_intervals()``, so both agree except for beliefs within
    rounding error of a crossing itself."""
    intervals = policy.ask_intervals()
    if intervals is None:
        return None
    out = []
    for cn in policy.complexities:
        th = threshold(intervals[cn])
        if th is None:
            out.append(-np.inf)
        elif np.isnan(th):
            return None
        else:
            out.append(np.inf if th >= 1.0 else th)
    return np.array(out)


def ask_regions(policy: Policy) -> dict[str, Any]:
    """Where a policy asks, ready for JSON: its ``thresholds`` and ``ask_intervals`` (as lists) per
    complexity (for a policy that asks at random: thresholds ``None``, no intervals)."""
    intervals = policy.ask_intervals() or {}
    return {"thresholds": policy.thresholds(), "ask_intervals": {k: [list(iv) for iv in v] for k, v in intervals.items()}}
