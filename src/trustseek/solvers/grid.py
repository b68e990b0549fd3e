"""The grid solver: the belief MDP of Section IV-C on a uniform grid of beliefs (two trust levels).

Q(b, C, a) = r(b, C, a) + γ Σ_branch P(branch | b, C, a) W(b') and W(b) = Σ_C P(C) max_a Q(b, C, a),
a branch being (o, E') for the ``bayes`` update and E' for ``paper`` (eq. 3).  W is interpolated
linearly between the points of a uniform grid of P(trust = high), which makes the discretized
problem a finite MDP on the grid, solved by value iteration (until the certified error bound
γ/(1-γ)·‖W_{k+1} - W_k‖∞ <= ``tol``) or policy iteration (exact for the grid MDP); the Bellman
residual of the result is reported either way.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..policies.grid_q import TrustAwarePolicy, grid_cells
from ..pomdp.problem import AssistancePOMDP
from .base import Solver, SolverError, one_blas_thread
from .defaults import DEFAULT_GRID, METHODS
from .numerics import howard

#: policy iteration on grids of up to this many points uses dense linear algebra: the transition
#: matrices built dense for every (C, a) at once and dense linear solves (a few hundred points:
#: much faster than the sparse path, the same policy; the tests compare both)
DENSE_MAX = 256
#: the dense path first solves a grid of about a quarter of the points (at least this many) and
#: starts from its policy, which saves a few of the large solves without changing where it ends
COARSE_MIN = 21

#: per complexity and action, a sparse transition matrix between grid points
GridMatrices = list[list[sp.csr_matrix]]


def interpolation_matrix(points: np.ndarray, grid: np.ndarray, weights: np.ndarray) -> sp.csr_matrix:
    """Sparse (n, len(grid)) matrix from points and weights of shape (n, m): row i spreads each
    weights[i, k] linearly over the two grid points that bracket points[i, k] (a uniform grid on
    [0, 1]) and adds them up."""
    G = len(grid)
    n = points.shape[0]
    j, f = grid_cells(points.T.ravel(), G)
    w = weights.T.ravel()
    rows = np.tile(np.arange(n), points.shape[1])
    data = np.concatenate([w * (1.0 - f), w * f])
    cols = np.concatenate([j, j + 1])
    m = sp.csr_matrix((data, (np.concatenate([rows, rows]), cols)), shape=(n, G))
    m.eliminate_zeros()  # points on a grid point put weight 0 on its right neighbour
    return m


@dataclass
class GridSolution:
    """Q on the belief grid, plus how it was obtained."""

    grid: np.ndarray  # (G,) P(trust = high)
    q: np.ndarray  # (G, N, 2)
    belief_update: str
    method: str
    iterations: int
    residual: float  # Bellman residual ‖T W - W‖∞ of the returned W
    error_bound: float  # certified bound on ‖W - W*‖∞ for the grid MDP
    seconds: float
    history: list[float] = field(default_factory=list)  # ‖W_{k+1} - W_k‖∞ per iteration (value iteration)

    @property
    def value(self) -> np.ndarray:
        """V(b, C) = max_a Q(b, C, a), shape (G, N)."""
        return self.q.max(axis=2)


class GridSolver(Solver):
    """Value/policy iteration on a uniform belief grid, for models with two trust levels."""

    name = "grid"
    trust_levels = 2
    belief_update: str

    def __init__(
        self,
        grid: int = DEFAULT_GRID,
        belief_update: str = "bayes",
        method: str = "policy-iteration",
        tol: float = 1e-9,
        max_iter: int = 100_000,
        dense_max: int = DENSE_MAX,
    ):
        if grid < 3:
            raise SolverError([f"grid must have at least 3 points, got {grid}"])
        self._targets(belief_update, tol)
        if method not in METHODS:
            raise SolverError([f"unknown method {method!r}; expected one of {list(METHODS)}"])
        self.grid = int(grid)
        self.method = method
        self.max_iter = int(max_iter)
        self.dense_max = int(dense_max)

    def operators(
        self, pomdp: AssistancePOMDP
    ) -> tuple[np.ndarray, np.ndarray, GridMatrices, Callable[[np.ndarray], np.ndarray], Callable[[np.ndarray], np.ndarray]]:
        """The discretized belief MDP: (grid, rewards r[c, a] (G,), sparse transition matrices
        P[c][a] (G, G) on the grid, q_of, bellman), q_of(W) -> Q (G, N, 2) and the Bellman
        operator W -> T W, where W(b) = Σ_C P(C) max_a Q(b, C, a)."""
        self.check(pomdp)
        grid, beliefs, r = _grid_rewards(pomdp, self.grid)
        branches = pomdp.branches(self.belief_update)
        P = []
        for c in range(pomdp.n_complexity):
            row = []
            for a in range(2):
                p, nxt = branches.successors(beliefs, c, a)
                live = np.any(p > 0, axis=0)  # branches that can happen at all
                row.append(interpolation_matrix(nxt[:, live, 1], grid, p[:, live]))
            P.append(row)
        N, gamma = pomdp.n_complexity, pomdp.discount
        pc = pomdp.complexity_probs

        def q_of(W: np.ndarray) -> np.ndarray:
            return np.stack([np.stack([r[c, a] + gamma * (P[c][a] @ W) for a in range(2)], axis=1) for c in range(N)], axis=1)

        def bellman(W: np.ndarray) -> np.ndarray:
            return q_of(W).max(axis=2) @ pc

        return grid, r, P, q_of, bellman

    # -- solving ---------------------------------------------------------------
    @one_blas_thread()
    def solve(self, pomdp: AssistancePOMDP) -> TrustAwarePolicy:
        """The trust-aware policy: greedy in Q on the grid (``info`` says how it was obtained)."""
        sol = self.solve_grid(pomdp)
        info: dict[str, Any] = {
            "solver": self.name,
            "method": sol.method,
            "grid_points": len(sol.grid),
            "iterations": sol.iterations,
            "bellman_residual": sol.residual,
            "error_bound": sol.error_bound,
            "seconds": sol.seconds,
            "discount": pomdp.discount,
        }
        return TrustAwarePolicy(sol.grid, sol.q, pomdp.model, pomdp.complexities, sol.belief_update, info)

    def solve_grid(self, pomdp: AssistancePOMDP) -> GridSolution:
        """Q on the grid, with the iteration count, the Bellman residual and the error bound."""
        t0 = time.perf_counter()
        gamma, pc = pomdp.discount, pomdp.complexity_probs
        history: list[float] = []
        method = self.method
        if method == "policy-iteration" and self.grid <= self.dense_max:
            self.check(pomdp)
            method = "policy-iteration (dense)"
            grid, q_cag, W, it = dense_policy_iteration(pomdp, self.belief_update, self.grid)
            q = np.moveaxis(q_cag, 2, 0)  # (G, N, 2)
        else:
            grid, r, P, q_of, bellman = self.operators(pomdp)
            if method == "value-iteration":
                W = np.zeros(len(grid))
                it = 0
                while it < self.max_iter:
                    W_new = bellman(W)
                    it += 1
                    delta = float(np.max(np.abs(W_new - W)))
                    history.append(delta)
                    W = W_new
                    if gamma / (1 - gamma) * delta <= self.tol:
                        break
            else:
                W, _, it = policy_iteration(r, P, pc, gamma, max_iter=self.max_iter)
            q = q_of(W)
        residual = float(np.max(np.abs(q.max(axis=2) @ pc - W)))
        return GridSolution(
            grid=grid,
            q=q,
            belief_update=str(self.belief_update),
            method=method,
            iterations=it,
            residual=residual,
            error_bound=gamma / (1 - gamma) * residual,
            seconds=time.perf_counter() - t0,
            history=history,
        )


def _grid_rewards(pomdp: AssistancePOMDP, G: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The uniform grid of ``G`` points of P(trust = high), its beliefs (G, 2) and the rewards there, r[c, a, G]."""
    grid = np.linspace(0.0, 1.0, G)
    beliefs = np.stack([1.0 - grid, grid], axis=1)
    return grid, beliefs, np.einsum("gk,cak->cag", beliefs, pomdp.expected_reward)


def dense_policy_iteration(pomdp: AssistancePOMDP, update: str, G: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(grid, Q[c, a, G], W, iterations) of the grid MDP on ``G`` points by Howard's policy
    iteration with dense matrices, started from the policy of a grid of about G/4 points (its Q
    interpolated) when that grid has at least :data:`COARSE_MIN` points."""
    coarse = (G - 1) // 4 + 1
    start = None
    if coarse >= COARSE_MIN:
        grid_c, q_c, _, _ = _dense_howard(pomdp, update, coarse, None)
        grid = np.linspace(0.0, 1.0, G)
        q0 = np.stack([[np.interp(grid, grid_c, q_c[c, a]) for a in range(2)] for c in range(pomdp.n_complexity)])
        start = q0.argmax(axis=1)
    return _dense_howard(pomdp, update, G, start)


def _dense_howard(
    pomdp: AssistancePOMDP, update: str, G: int, policy: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(grid, Q[c, a, G], W, iterations) by Howard's policy iteration from ``policy`` [c, G]
    (default: the greedy one of the rewards), with dense linear solves."""
    N, gamma, pc = pomdp.n_complexity, pomdp.discount, pomdp.complexity_probs
    grid, beliefs, r = _grid_rewards(pomdp, G)
    dense = dense_transitions(pomdp, update, beliefs)  # [c, a, G, G]
    rows = np.arange(G)

    def chain(policy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        M = np.zeros((G, G))
        rr = np.zeros(G)
        for c in range(N):
            M += (gamma * pc[c]) * dense[c, policy[c], rows]
            rr += pc[c] * r[c, policy[c], rows]
        return M, rr

    def q_of(W: np.ndarray) -> np.ndarray:
        return r + gamma * (dense @ W)  # [c, a, G]

    def solve(M: np.ndarray, rr: np.ndarray, _: np.ndarray) -> np.ndarray:
        return np.asarray(np.linalg.solve(np.eye(G) - M, rr), dtype=float)

    start = r.argmax(axis=1) if policy is None else policy  # [c, G]
    W, _, it = howard(start, chain, q_of, np.zeros(G), 1000, solve=solve)
    return grid, q_of(W), W, it


def dense_transitions(pomdp: AssistancePOMDP, update: str, beliefs: np.ndarray) -> np.ndarray:
    """P[c, a, g, g']: from grid point g, the probability of each branch after (C, a) spread over
    the two grid points that bracket its successor (:func:`interpolation_matrix`'s weights,
    dense, summed by one ``bincount`` for every (C, a))."""
    G, N = len(beliefs), pomdp.n_complexity
    p, nxt = pomdp.branches(update).successors(beliefs)  # (G, c, a, br), (G, c, a, br, K)
    j, f = grid_cells(nxt[..., 1], G)
    start = ((np.arange(N)[:, None] * 2 + np.arange(2)) * G)[None, :, :, None] + np.arange(G)[:, None, None, None]
    at = (start * G + j).reshape(-1)  # row (c, a, g), column j
    weights = np.concatenate([(p * (1.0 - f)).reshape(-1), (p * f).reshape(-1)])
    return np.bincount(np.concatenate([at, at + 1]), weights, N * 2 * G * G).reshape(N, 2, G, G)


def policy_iteration(
    r: np.ndarray, P: GridMatrices, pc: np.ndarray, gamma: float, policy: np.ndarray | None = None, max_iter: int = 1000
) -> tuple[np.ndarray, np.ndarray, int]:
    """Howard's policy iteration on a finite belief MDP over G points.

    ``r[c, a]`` (G,) are the rewards, ``P[c][a]`` sparse (G, G) transition matrices to the
    next trial's points, ``pc`` P(C).  Starts from ``policy`` [c, G] (default: greedy in the
    one-step reward).  Returns (W, policy, iterations) with W(b) = Σ_C P(C) max_a Q(b, C, a).
    """
    N, G = len(pc), r.shape[-1]

    def chain(policy: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
        M = sp.csr_matrix((G, G))
        rr = np.zeros(G)
        for c in range(N):
            sel = policy[c]
            rows = sp.diags((sel == 0).astype(float)) @ P[c][0] + sp.diags((sel == 1).astype(float)) @ P[c][1]
            M = M + (gamma * pc[c]) * rows
            rr += pc[c] * np.where(sel == 0, r[c, 0], r[c, 1])
        return M.tocsr(), rr

    def q_of(W: np.ndarray) -> np.ndarray:
        return np.stack([np.stack([r[c, a] + gamma * (P[c][a] @ W) for a in range(2)]) for c in range(N)])  # [c, a, G]

    start = r.argmax(axis=1) if policy is None else np.asarray(policy)
    return howard(start, chain, q_of, np.zeros(G), max_iter)
