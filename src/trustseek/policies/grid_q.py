"""The grid-Q policy (``trust-aware``): greedy in Q(b, C, a) tabulated on a belief grid.

For two trust levels the belief is x = P(trust = high); Q is stored at G uniform points of
[0, 1] and interpolated linearly in between, which is how the grid solver represents its
solution and how the paper's policy (Fig. 7) is drawn.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..model.core import TrustModel
from ..model.jsonfile import ModelError
from ..vocab import ACTIONS, ASK, AUTONOMOUS
from .base import Policy, PolicyError, planned_for
from .regions import Interval, ask_intervals

TABLE_POINTS = 4001  # points of a Q table made from another policy's Q-function


def grid_cells(x: Any, G: int) -> tuple[np.ndarray, np.ndarray]:
    """The cell j and the position f in it of each x (clipped to [0, 1]) on the uniform grid of
    ``G`` points: x lies between points j and j + 1, at f in [0, 1]."""
    pos = np.clip(np.asarray(x, dtype=float), 0.0, 1.0) * (G - 1)
    j = np.minimum(np.floor(pos).astype(np.int64), G - 2)
    return j, pos - j


@dataclass(eq=False, repr=False)
class TrustAwarePolicy(Policy):
    """Greedy in the solved Q(b, C, a) on a belief grid over P(trust = high) (two trust levels);
    ties go to ``autonomous``."""

    kind = "trust-aware"
    grid: np.ndarray
    q: np.ndarray
    model: TrustModel = field()  # field(): required, not the base class default
    complexities: tuple[str, ...] = field()
    belief_update: str = field()
    info: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.grid = np.asarray(self.grid, dtype=float)
        self.q = np.asarray(self.q, dtype=float)
        self.complexities = tuple(self.complexities)
        self.info = dict(self.info or {})
        if self.q.shape != (len(self.grid), len(self.complexities), 2):
            raise ModelError([f"q has shape {self.q.shape}, expected {(len(self.grid), len(self.complexities), 2)}"])

    @classmethod
    def tabulate(cls, policy: Policy, points: int = TABLE_POINTS) -> TrustAwarePolicy:
        """A grid-Q policy holding another policy's Q-function at ``points`` uniform beliefs (two
        trust levels; raises PolicyError for a policy without a Q-function)."""
        grid = np.linspace(0.0, 1.0, points)
        q = policy.q_values(grid)
        if policy.model is None or policy.belief_update is None:
            raise PolicyError([f"a {policy.kind} policy has no belief to tabulate its Q-function over"])
        return cls(grid, q, policy.model, policy.complexities, policy.belief_update, policy.info)

    # -- the Q-function ------------------------------------------------------
    def q_values(self, b_high: Any) -> np.ndarray:
        """Q at P(trust = high) = b_high, linearly interpolated; shape (..., N, 2)."""
        j, f = grid_cells(b_high, len(self.grid))
        f = f[..., None, None]
        return self.q[j] * (1 - f) + self.q[j + 1] * f

    def actions(self, beliefs: np.ndarray | None, complexities: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        beliefs = np.asarray(beliefs, dtype=float)
        complexities = np.asarray(complexities, dtype=np.int64)
        j, f = grid_cells(beliefs[..., -1], len(self.grid))
        d = self.q[:, :, ASK] - self.q[:, :, AUTONOMOUS]  # (G, N): advantage of asking
        adv = d[j, complexities] * (1 - f) + d[j + 1, complexities] * f
        return np.where(adv > 0, ASK, AUTONOMOUS).astype(np.int64)

    def ask_intervals(self) -> dict[str, list[Interval]]:
        """Per complexity, the belief intervals where the policy asks (ends found by linear
        interpolation of the advantage Q(ask) - Q(autonomous) between grid points)."""
        d = self.q[:, :, ASK] - self.q[:, :, AUTONOMOUS]
        return {cn: ask_intervals(self.grid, d[:, c]) for c, cn in enumerate(self.complexities)}

    # -- description and JSON ------------------------------------------------
    def describe(self) -> str:
        ths = self.thresholds() or {}
        parts = ", ".join(f"{k}: {'never asks' if v is None else f'{v:.3f}'}" for k, v in ths.items())
        return f"{self.kind} ({self.belief_update} belief, thresholds {parts})"

    def overview(self) -> dict[str, Any]:
        return {"kind": self.kind, "thresholds": self.thresholds(), "belief_update": self.belief_update}

    def to_dict(self) -> dict[str, Any]:
        assert self.model is not None
        return self._file(
            belief_update=self.belief_update,
            thresholds=self.thresholds(),
            info=self.info,
            model=self.model.to_dict(),
            grid={"points": len(self.grid)},
            q={
                cn: {an: [round(float(v), 12) for v in self.q[:, c, a]] for a, an in enumerate(ACTIONS)}
                for c, cn in enumerate(self.complexities)
            },
        )

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], source: str | None = None) -> TrustAwarePolicy:
        cx, model, bu = planned_for(d, source)
        q: Any = d.get("q")
        try:
            arr = np.array([[q[c][a] for a in ACTIONS] for c in cx], dtype=float).transpose(2, 0, 1)
        except (KeyError, TypeError, ValueError):
            raise ModelError(
                [f"q must map each complexity {cx} and action {list(ACTIONS)} to a list of numbers"], source
            ) from None
        grid = np.linspace(0.0, 1.0, arr.shape[0])
        return cls(grid, arr, model, tuple(cx), bu, d.get("info") or {})
