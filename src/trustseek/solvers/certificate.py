"""Certified solutions of the two-level belief MDP, their thresholds, and the policies made of them.

Both certified two-level solvers (``alpha`` for the Bayes filter, ``certified-grid`` for
eq. 3) end with a computed value function -- an envelope of alpha vectors, or the linear
interpolation of values on a grid -- and an exact bound on its Bellman residual, which
bounds the optimal value from both sides.  :class:`CertifiedSolution` holds either, answers
Q, the value and the advantage of asking at any belief, and reports thresholds with their
certified uncertainty intervals: the optimal advantage D = Q(ask) - Q(autonomous) lies
within ±γ·gap of the computed one, so the threshold lies where |D| <= γ·gap.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import brentq

from ..model.core import ASK, AUTONOMOUS
from ..policies.alpha_vector import AlphaVectorPolicy
from ..policies.base import Policy
from ..policies.envelope import envelope_values
from ..policies.grid_q import TABLE_POINTS, TrustAwarePolicy
from ..policies.thresholds import ask_intervals, threshold
from ..pomdp.problem import AssistancePOMDP
from .eq3 import paper_q

__all__ = ["CertifiedSolution", "certificate", "policy_from_solution"]


@dataclass
class CertifiedSolution:
    """Certified bounds for the two-level belief MDP.

    The bounded function is the envelope ``lower`` of alpha vectors with the Q envelopes ``q``
    of its backup (``bayes``), or the linear interpolation of ``grid_solution`` = (grid, values)
    (``paper``).  ``residuals`` = (sup, -inf) of its Bellman residual; ``gap`` bounds the
    distance between the certified lower and upper bounds on the value, at every belief."""

    belief_update: str
    method: str
    lower: tuple[np.ndarray, np.ndarray] | None  # (vectors, xs) of L (bayes)
    q: list[list[tuple[np.ndarray, np.ndarray]]] | None  # Q envelopes of T L (bayes)
    gap: float  # certified sup_x (U - L)(x)
    iterations: int
    seconds: float
    history: list[float] = field(default_factory=list)  # certified gap per iteration
    grid_solution: tuple[np.ndarray, np.ndarray] | None = None  # (grid, values) certified (paper)
    residuals: tuple[float, float] = (0.0, 0.0)  # (sup, -inf) of T V - V for the bounded function V

    def _q(self, pomdp: AssistancePOMDP, x: np.ndarray) -> np.ndarray:
        """Q[c, a, ...] of the computed (bounded) function at beliefs x."""
        if self.q is not None:
            return np.stack([np.stack([envelope_values(v, xs, x) for v, xs in per_a]) for per_a in self.q])
        assert self.grid_solution is not None
        g, v = self.grid_solution
        return paper_q(pomdp, v, x, g)

    def advantage(self, pomdp: AssistancePOMDP, x: np.ndarray, c: int) -> np.ndarray:
        """D(x) = Q(x, C=c, ask) - Q(x, C=c, autonomous) of the computed Q."""
        x = np.asarray(x, dtype=float)
        if self.q is not None:
            qa = [envelope_values(v, xs, x) for v, xs in self.q[c]]
            return qa[ASK] - qa[AUTONOMOUS]
        q = self._q(pomdp, x)
        return q[c, ASK] - q[c, AUTONOMOUS]

    def value(self, pomdp: AssistancePOMDP, x: Any) -> np.ndarray:
        """Lower bound on W(x) (certified)."""
        x = np.asarray(x, dtype=float)
        shift = self.residuals[1] / (1 - pomdp.discount)
        if self.lower is not None:
            return envelope_values(self.lower[0], self.lower[1], x) - shift
        assert self.grid_solution is not None
        g, v = self.grid_solution
        return np.interp(x, g, v) - shift

    def q_values(self, pomdp: AssistancePOMDP, x: Any) -> np.ndarray:
        """Lower bounds on Q(x, C, a); shape (..., N, 2)."""
        x = np.asarray(x, dtype=float)
        gam = pomdp.discount
        q = self._q(pomdp, x) - gam * self.residuals[1] / (1 - gam)
        return np.moveaxis(q, (0, 1), (-2, -1))

    def threshold_report(self, pomdp: AssistancePOMDP, points: int = 4001) -> dict[str, dict[str, Any]]:
        """Per complexity: the threshold (None = never asks, 1.0 = always asks, nan = the ask
        region is not an interval [0, θ)), its certified uncertainty interval and the ask
        intervals (ends found by root finding on the computed advantage)."""
        margin = pomdp.discount * self.gap
        grid = np.linspace(0.0, 1.0, points)
        out = {}
        for c, cn in enumerate(pomdp.complexities):
            x = grid if self.q is None else np.union1d(grid, np.union1d(self.q[c][0][1], self.q[c][1][1]))

            def f(z: float, shift: float = 0.0, c: int = c) -> float:
                return float(self.advantage(pomdp, np.array([z]), c)[0]) - shift

            d = self.advantage(pomdp, x, c)

            def root(i: int, x: np.ndarray = x, d: np.ndarray = d, f: Callable[..., float] = f) -> float:
                return float(brentq(f, x[i], x[i + 1], xtol=1e-15)) if d[i] != d[i + 1] else float(x[i])

            ivs = ask_intervals(x, d, root)
            th = threshold(ivs)
            if th is not None and np.isfinite(th):
                lo = _bracket(f, x, d, th, +margin, left=True)
                hi = _bracket(f, x, d, th, -margin, left=False)
                out[cn] = {"threshold": th, "interval": [lo, hi], "ask_intervals": ivs}
            else:
                out[cn] = {"threshold": th, "interval": None, "ask_intervals": ivs}
        return out


def _bracket(f: Callable[..., float], x: np.ndarray, d: np.ndarray, th: float, level: float, left: bool) -> float:
    """The nearest point to θ (left or right of it) where the advantage equals ``level``."""
    if th >= 1.0:
        return 1.0
    if left:
        idx = np.nonzero((x < th) & (d >= level))[0]
        if len(idx) == 0:
            return 0.0
        i = idx[-1]
        j = i + 1
        if d[j] >= level or x[j] > th:
            j = np.searchsorted(x, th)
            if f(x[j], level) >= 0:
                return float(x[j])
        return float(brentq(f, x[i], x[j], args=(level,), xtol=1e-15))
    idx = np.nonzero((x > th) & (d <= level))[0]
    if len(idx) == 0:
        return 1.0
    j = idx[0]
    i = j - 1
    if f(x[i], level) <= 0:
        return float(x[i])
    return float(brentq(f, x[i], x[j], args=(level,), xtol=1e-15))


def certificate(sol: CertifiedSolution, pomdp: AssistancePOMDP) -> dict[str, Any]:
    """The machine-readable certificate: gap, bounds at the initial belief, thresholds."""
    pc = pomdp.complexity_probs
    b0 = float(pomdp.model.initial[-1])
    q0 = sol.q_values(pomdp, np.array(b0))
    low0 = float(q0.max(axis=-1) @ pc)
    ths = sol.threshold_report(pomdp)
    return {
        "certified_gap": sol.gap,
        "value_bounds_at_initial_belief": [low0, low0 + sol.gap],
        "thresholds": {k: v["threshold"] for k, v in ths.items()},
        "threshold_intervals": {k: v["interval"] for k, v in ths.items()},
    }


def policy_from_solution(sol: CertifiedSolution, pomdp: AssistancePOMDP, solver: str, target_gap: float | None = None) -> Policy:
    """Wrap a solution as a Policy with its certificate in ``info``: an AlphaVectorPolicy
    (alpha vectors) or a TrustAwarePolicy whose Q table is computed from the certified grid
    values."""
    info: dict[str, Any] = {
        "solver": solver,
        "method": sol.method,
        "iterations": sol.iterations,
        "bellman_residual": sol.gap * (1 - pomdp.discount),
        "error_bound": sol.gap,
        "seconds": sol.seconds,
        "discount": pomdp.discount,
    }
    info.update(certificate(sol, pomdp))
    info["target_gap"] = target_gap
    if sol.q is not None and sol.lower is not None:
        info["vectors"] = len(sol.lower[0])
        return AlphaVectorPolicy(
            [[v for v, _ in per_a] for per_a in sol.q], sol.lower[0], pomdp.model, pomdp.complexities, sol.belief_update, info
        )
    assert sol.grid_solution is not None
    g, v = sol.grid_solution
    info["adaptive_grid_points"] = len(g)
    table = np.linspace(0.0, 1.0, TABLE_POINTS)  # Q of the certified solution on a uniform table
    q = np.moveaxis(paper_q(pomdp, v, table, g), -1, 0)
    return TrustAwarePolicy(table, q, pomdp.model, pomdp.complexities, sol.belief_update, info)
