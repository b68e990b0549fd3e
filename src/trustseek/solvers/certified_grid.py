"""The certified adaptive grid for the eq.-3 update (``paper``), two trust levels.

Eq. 3 is not a Bayes filter: the branch probability is linear in x while the next belief
x' = x P(T'=high | T=high) + (1-x) P(T'=high | T=low) is not rescaled by it, so Q contains
products (linear × piecewise linear) and W is neither linear nor convex; alpha vectors
cannot represent it.  Instead the solver certifies a grid value V (linear interpolation on
G points): on every piece between grid points, their preimages under the belief maps and
the roots of the advantage, (T V - V)(x) is one quadratic, so its supremum ε+ and infimum
-ε- over the whole of [0, 1] are computed exactly (:func:`~.eq3.residual_pieces`), and

    V - ε- / (1 - γ)  ≤  W  ≤  V + ε+ / (1 - γ).

The grid is refined where the residual is large until the gap (ε+ + ε-) / (1 - γ) meets the
tolerance.  The policy is a grid-Q policy whose Q table is computed from the certified value.
"""

from __future__ import annotations

import time
from typing import ClassVar

import numpy as np

from ..policies.base import Policy
from ..pomdp.problem import AssistancePOMDP
from .base import SolverBase, one_blas_thread
from .certificate import CertifiedSolution, policy_from_solution
from .eq3 import paper_grid_values, residual_pieces

__all__ = ["CertifiedGridSolver"]


class CertifiedGridSolver(SolverBase):
    """Certified solution of the eq.-3 belief MDP on an adaptively refined grid."""

    name = "certified-grid"
    trust_levels = 2
    belief_updates = ("paper",)
    instead: ClassVar[dict[str, str]] = {
        "trust_levels": "use the point solver (Bayes filter)",
        "belief_update": "the certified-grid solver certifies the eq.-3 update (belief update 'paper'); "
        "for the Bayes filter use the alpha solver",
    }

    def __init__(self, belief_update: str = "paper", tol: float = 1e-6, grid: int = 1025, max_grid: int = 200_001):
        self._targets(belief_update, tol)
        self.grid = int(grid)  # the starting grid (refined adaptively)
        self.max_grid = int(max_grid)

    @one_blas_thread
    def solve(self, pomdp: AssistancePOMDP) -> Policy:
        """A grid-Q policy from the certified value; ``info`` holds the certificate."""
        return policy_from_solution(self.solve_bounds(pomdp), pomdp, self.name, self.tol)

    @one_blas_thread
    def solve_bounds(self, pomdp: AssistancePOMDP) -> CertifiedSolution:
        """The certified grid values, refined until the gap meets the tolerance."""
        self.check(pomdp)
        t0 = time.perf_counter()
        gamma = pomdp.discount
        grid = np.linspace(0.0, 1.0, self.grid)
        history = []
        values = None
        target = self.tol * (1 - gamma) / 2  # residual allowed on each side
        while True:
            values = paper_grid_values(pomdp, grid, values)
            res = residual_pieces(pomdp, grid, values)
            gap = (max(res.eps_plus, 0.0) + max(res.eps_minus, 0.0)) / (1 - gamma)
            history.append(gap)
            if gap <= self.tol or len(grid) >= self.max_grid:
                break
            grid, values = _refine(grid, values, res.lo, res.hi, np.maximum(res.sup, -res.inf) / (0.5 * target))
        return CertifiedSolution(
            belief_update="paper",
            method="certified-adaptive-grid",
            lower=None,
            q=None,
            gap=float(gap),
            iterations=len(history),
            seconds=time.perf_counter() - t0,
            history=history,
            grid_solution=(grid, values),
            residuals=(max(res.eps_plus, 0.0), max(res.eps_minus, 0.0)),
        )


def _refine(
    grid: np.ndarray, values: np.ndarray, lo: np.ndarray, hi: np.ndarray, over: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Split the cells that hold pieces [lo, hi] whose residual is ``over`` times the budget
    (> 1): into 8 parts, or up to 64 where the residual is far above the budget (the
    interpolation error is first order at the kinks of W, so halving a cell roughly halves its
    residual).  The values are interpolated onto the new points (a warm start)."""
    bad = over > 1.0
    cells = np.clip(np.searchsorted(grid, 0.5 * (lo[bad] + hi[bad]), side="right") - 1, 0, len(grid) - 2)
    worst = np.zeros(len(grid) - 1)
    np.maximum.at(worst, cells, over[bad])
    cells = np.nonzero(worst)[0]
    parts = np.clip(2.0 ** np.ceil(np.log2(np.maximum(0.5 * worst[cells], 1.0))), 8, 64).astype(np.int64)
    first = np.repeat(grid[cells], parts - 1)
    h = np.repeat(grid[cells + 1] - grid[cells], parts - 1)
    k = np.arange(len(first)) - np.repeat(np.cumsum(parts - 1) - (parts - 1), parts - 1) + 1
    new = first + h * (k / np.repeat(parts, parts - 1))
    values = np.interp(np.concatenate([grid, new]), grid, values)
    grid = np.concatenate([grid, new])
    order = np.argsort(grid)
    return grid[order], values[order]
