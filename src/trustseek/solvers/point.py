"""Point-based solver with lower and upper bounds at the initial belief, for any number of
trust levels (docs/solvers.md, ``point``).

* lower bound: L(b) = max_α α·b over alpha vectors, each the exact value of an executable
  controller (memoryless ones, then point-based policy iteration on a lattice of the simplex,
  the beliefs reachable from b0 in two trials and those met on simulated trajectories);
* upper bound: the Bellman fixed point with linear interpolation on Freudenthal's
  triangulation of the simplex (Lovejoy's bound), certified against rounding by its residual.

The resolution of the triangulation is doubled until U(b0) - L(b0) <= ``tol``.  The problem is
taken in branch form (a context seen before acting, branches (o, E') moving the belief), so a
flat POMDP is the case of one context.  The bounds rest on the convexity of the Bayes-filter value.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from math import comb
from typing import Any, ClassVar

import numpy as np
import scipy.sparse as sp

from ..policies.alpha_vector import AlphaVectorPolicy, FlatAlphaPolicy
from ..policies.base import Policy
from ..pomdp.belief import BranchModel
from ..pomdp.flat import FlatPOMDP
from ..pomdp.problem import AssistancePOMDP
from .base import Solver, SolverError, bayes_only, one_blas_thread
from .numerics import (
    controller_iteration,
    howard,
    memoryless_controllers,
    q_vectors,
    reachable_beliefs,
    sample_beliefs,
    unique_rows,
)


@dataclass
class PointSolution:
    """Bounds at the initial belief, the vectors of the lower bound and the upper bound's points
    (the point, types and reachable solvers)."""

    vectors: np.ndarray  # lower bound: L(b) = max_α α·b
    points: np.ndarray  # upper bound: belief points (the point solver: the triangulation's vertices) ...
    point_values: np.ndarray  # ... and their certified values
    lower: float
    upper: float
    seconds: float
    counts: dict[str, int]  # what the solver counts (its ``info``): rounds, trials, backups ...
    history: list[tuple[int, float, float, float]] = field(default_factory=list)  # (points or trial, seconds, lower, upper)
    beliefs: np.ndarray | None = None  # the beliefs the search visited (reachable)

    @property
    def gap(self) -> float:
        return self.upper - self.lower


def freudenthal_weights(B: np.ndarray, r: int) -> tuple[np.ndarray, np.ndarray]:
    """Vertex codes (n, K) and barycentric weights (n, K) of beliefs B in Freudenthal's
    triangulation at resolution r: the linear interpolation of vertex values (Lovejoy 1991)."""
    n, K = B.shape
    y = r * np.cumsum(B[:, ::-1], axis=1)[:, ::-1]  # y_i = r Σ_{j >= i} b_j, y_0 = r
    v = np.floor(y + 1e-12)
    v[:, 0] = r
    v = np.minimum(v, r)
    d = np.clip(y - v, 0.0, 1.0)
    d[:, 0] = 0.0
    order = np.argsort(-d[:, 1:], axis=1, kind="stable") + 1  # coordinates by decreasing d
    ds = np.take_along_axis(d, order, axis=1)  # (n, K-1) decreasing
    ds_next = np.concatenate([ds[:, 1:], np.zeros((n, 1))], axis=1)
    w = np.concatenate([1.0 - ds[:, :1], ds - ds_next], axis=1)  # (n, K)
    verts = np.empty((n, K, K), dtype=np.int64)
    cur = v.astype(np.int64)
    verts[:, 0] = cur
    for k in range(1, K):
        cur = cur.copy()
        cur[np.arange(n), order[:, k - 1]] += 1
        verts[:, k] = cur
    return verts, w


def _find(sorted_codes: np.ndarray, codes: np.ndarray) -> np.ndarray:
    """Positions of ``codes`` in ``sorted_codes`` (-1 where absent)."""
    i = np.minimum(np.searchsorted(sorted_codes, codes), len(sorted_codes) - 1)
    return np.where(sorted_codes[i] == codes, i, -1)


def _lattice_size(K: int, r: int) -> int:
    return comb(r + K - 1, K - 1)


def _vertex_code(verts: np.ndarray, r: int) -> np.ndarray:
    """Integer code of Freudenthal vertex coordinates (..., K) (v_0 = r is dropped).  Vertices
    outside the simplex (they only occur with weight zero, on a face) get code 0."""
    K = verts.shape[-1]
    mult = (r + 1) ** np.arange(K - 1)
    ok = np.all(verts[..., 1:] <= verts[..., :-1], axis=-1) & np.all(verts >= 0, axis=-1)
    return np.where(ok, (np.clip(verts[..., 1:], 0, r) * mult).sum(axis=-1), 0)


class PointSolver(Solver):
    """Point-based lower bound and Freudenthal-grid upper bound, refined until the gap at b0 is
    small (see the module).  The vertex count grows like r^(K-1), which is what limits the number
    of trust levels.  It solves the assistance POMDP (an alpha-vector policy) and flat POMDPs read
    from standard files (a flat alpha-vector policy)."""

    name = "point"
    belief_updates = ("bayes",)
    instead: ClassVar[dict[str, str]] = bayes_only("point")
    flat = True
    # the state of the last solve: the problem, the lower bound's vectors, the grid upper bound
    model: BranchModel
    vectors: np.ndarray
    grid_resolution: int
    vertices: np.ndarray
    vertex_values: np.ndarray
    lookup: np.ndarray

    def __init__(
        self,
        tol: float = 1e-3,
        max_seconds: float = 60.0,
        resolution: int | None = None,
        max_resolution: int | None = None,
        belief_update: str = "bayes",
    ):
        self._targets(belief_update, tol, max_seconds)
        self.resolution = resolution  # the first grid's (default: by the number of hidden states)
        self.max_resolution = max_resolution
        self.max_vertices = 100_000

    def _improve_lower(self, B: np.ndarray) -> None:
        """Point-based policy iteration on beliefs B (:func:`~.numerics.controller_iteration`)."""
        succ = self.model.branches.successors(B)
        self.vectors = controller_iteration(self.model, self.vectors, B, succ, B, self.tol * 1e-2, 30)

    # -- upper bound: Freudenthal grid, policy iteration ---------------------------------
    def _vertex_grid(self, r: int) -> tuple[np.ndarray, ...]:
        """The vertices V of the Freudenthal grid at resolution r sorted by code (vertex i has
        code lookup[i]), their successors' probabilities p (nV, N, A, Br) and beliefs S
        (nV, N, A, Br, K), and the vertices col and weights w that interpolate each successor."""
        K = self.model.n_hidden
        V = _simplex_lattice(K, r)  # the vertices: every belief with coordinates in multiples of 1/r
        own = np.round(np.cumsum(V[:, ::-1], axis=1)[:, ::-1] * r).astype(np.int64)
        codes = _vertex_code(own, r)
        order = np.argsort(codes, kind="stable")
        lookup, V = codes[order], V[order]
        p, S = self.model.branches.successors(V)
        verts, w = freudenthal_weights(S.reshape(-1, K), r)
        col = _find(lookup, _vertex_code(verts, r)).reshape(S.shape)
        if np.any(col < 0):
            raise RuntimeError("Freudenthal interpolation left the vertex set")
        return V, lookup, p, S, col, w.reshape(S.shape)

    def _upper(self, r: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Vertex beliefs, certified upper values and the code lookup at resolution r."""
        m = self.model
        V, lookup, p, S, col, w = self._vertex_grid(r)
        u, q_of = self._vertex_values(V, p, S, col, w, np.einsum("cat,nt->nca", m.rewards, V))
        # the operator H is monotone with modulus γ: u + max(H u - u)+ / (1 - γ) bounds its fixed point
        eta = max(0.0, float(np.max(q_of(u).max(axis=2) @ m.context_probs - u)))
        return V, u + eta / (1 - m.discount), lookup

    def _vertex_values(
        self, V: np.ndarray, p: np.ndarray, S: np.ndarray, col: np.ndarray, w: np.ndarray, rew: np.ndarray
    ) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]:
        """The fixed point u of the Bellman operator on the vertex values (successors ``S``, interpolated
        from the vertices ``col`` with weights ``w``; ``rew[n, c, a]`` the rewards at the vertices)
        by policy iteration, and the operator's Q: (u, q_of)."""
        m = self.model
        N, gamma, pc = m.n_contexts, m.discount, m.context_probs
        nV = len(V)
        wt = w * p[..., None]
        rows = np.broadcast_to(np.arange(nV)[:, None, None], (nV, *S.shape[3:]))
        ii = np.arange(nV)

        def q_of(u: np.ndarray) -> np.ndarray:
            return rew + gamma * np.einsum("ncabk,ncabk->nca", wt, u[col])

        def chain(acts: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
            rr = np.zeros(nV)
            Wm = sp.csr_matrix((nV, nV))
            for c in range(N):
                a = acts[:, c]
                rr += pc[c] * rew[ii, c, a]
                entries = (gamma * pc[c] * wt[ii, c, a]).ravel(), (rows.ravel(), col[ii, c, a].ravel())
                Wm = Wm + sp.csr_matrix(entries, shape=(nV, nV))
            return Wm, rr

        return howard(rew.argmax(axis=2), chain, q_of, np.zeros(nV), 500, axis=2)[0], q_of

    def grid_bound(self, model: BranchModel, r: int) -> tuple[np.ndarray, np.ndarray]:
        """Solve the grid upper bound of ``model`` at resolution r and keep it (``upper_at`` reads
        it): the vertex beliefs and their certified upper values."""
        self.model = model
        self.vertices, self.vertex_values, self.lookup = self._upper(r)
        self.grid_resolution = r
        return self.vertices, self.vertex_values

    def upper_at(self, B: np.ndarray) -> np.ndarray:
        """The certified upper bound at beliefs B (linear interpolation of the vertex values)."""
        r = self.grid_resolution
        verts, w = freudenthal_weights(np.atleast_2d(np.asarray(B, dtype=float)), r)
        return (w * self.vertex_values[_find(self.lookup, _vertex_code(verts, r))]).sum(axis=1)

    def lower_at(self, B: np.ndarray) -> np.ndarray:
        return (np.atleast_2d(np.asarray(B, dtype=float)) @ self.vectors.T).max(axis=1)

    @one_blas_thread()
    def solve_bounds(self, problem: AssistancePOMDP | FlatPOMDP) -> PointSolution:
        """Lower and upper bounds at the initial belief (the vectors and points behind them)."""
        self.check(problem)
        return self._bounds(problem.branch_model())

    def _start(self, model: BranchModel, b0: np.ndarray, reach: np.ndarray) -> np.ndarray:
        """The lower bound's first vectors: the memoryless controllers' values."""
        return memoryless_controllers(model)

    def _upper_at_start(self, b0: np.ndarray) -> float:
        """The upper bound reported at b0 after a round (the grid's interpolation there)."""
        return float(self.upper_at(b0)[0])

    def _bounds(self, model: BranchModel, t0: float | None = None) -> PointSolution:
        """Lower and upper bounds at the initial belief of a problem in branch form (the clock
        started at ``t0``, default now)."""
        t0 = time.perf_counter() if t0 is None else t0
        self.model = model
        K = model.n_hidden
        b0 = np.asarray(model.initial, dtype=float)
        reach = reachable_beliefs(b0, 2, model.branches.successors)  # two trials ahead
        self.vectors = self._start(model, b0, reach)
        r = self.resolution or {2: 64, 3: 16, 4: 8}.get(K, 4 if K <= 8 else 2)
        r_max = self.max_resolution or {2: 4096, 3: 512, 4: 64}.get(K, 16)
        if (r + 1) ** (K - 1) >= 2**62 or _lattice_size(K, r) > self.max_vertices:
            raise SolverError(
                f"{K} hidden states are too many for the grid upper bound of the {self.name} solver "
                f"({_lattice_size(K, r)} vertices at resolution {r})"
            )
        lat = {2: 256, 3: 16, 4: 6}.get(K, 3)  # the lower bound's lattice: at most this resolution
        rng = np.random.default_rng(0)
        history = []
        rounds = 0
        while True:
            rounds += 1
            t_round = time.perf_counter()
            V, u = self.grid_bound(model, r)
            t_upper = time.perf_counter() - t_round
            sampled = sample_beliefs(model, b0, rng, model.branches.successors, self.lower_at, 50)
            self._improve_lower(unique_rows(np.vstack([_simplex_lattice(K, min(r, lat)), reach, unique_rows(sampled, 9)])))
            lo = float(self.lower_at(b0)[0])
            up = self._upper_at_start(b0)
            history.append((len(V), time.perf_counter() - t0, lo, up))
            too_big = _lattice_size(K, 2 * r) > self.max_vertices or (2 * r + 1) ** (K - 1) >= 2**62
            now = time.perf_counter() - t0
            # do not start the next round past the limit (with a margin of 1.5)
            t_lower = time.perf_counter() - t_round - t_upper
            late = now + 1.5 * next_round_seconds(K, r, lat, t_upper, t_lower) > self.max_seconds
            if up - lo <= self.tol or r * 2 > r_max or too_big or late:
                break
            r *= 2
        counts = {"resolution": r, "iterations": rounds}
        return PointSolution(self.vectors.copy(), V.copy(), u.copy(), lo, up, time.perf_counter() - t0, counts, history)

    @one_blas_thread()
    def solve(self, problem: AssistancePOMDP | FlatPOMDP) -> Policy:
        """The policy of the lower bound's vectors, with the bounds at the initial belief in its
        ``info``: an AlphaVectorPolicy for the assistance POMDP (Bayes update), a FlatAlphaPolicy
        for a flat POMDP."""
        sol = self.solve_bounds(problem)
        K = sol.vectors.shape[1]
        beliefs = unique_rows(np.vstack([sol.points, _simplex_lattice(K, _q_lattice(K))]))
        qv = q_vectors(self.model, self.vectors, beliefs, self.model.branches.successors(beliefs)[1])
        return bounds_policy(self, problem, qv, sol, "point-based policy iteration + Freudenthal upper bound")


def bounds_policy(solver: Any, problem: AssistancePOMDP | FlatPOMDP, qv: list, sol: PointSolution, method: str) -> Policy:
    """The policy of a bounding solver's lower-bound Q-vectors ``qv`` with the bounds at the
    initial belief and the solver's own counts in its ``info``: an AlphaVectorPolicy for the
    assistance POMDP (Bayes update), a FlatAlphaPolicy for a flat POMDP."""
    info: dict[str, Any] = {
        "solver": solver.name,
        "method": method,
        **sol.counts,
        "bellman_residual": float("nan"),
        "error_bound": sol.gap,
        "certified_gap": sol.gap,
        "gap_at": "initial belief",
        "target_gap": solver.tol,
        "value_bounds_at_initial_belief": [sol.lower, sol.upper],
        "vectors": len(sol.vectors),
        "upper_points": len(sol.points),
        "seconds": sol.seconds,
        "discount": problem.discount,
    }
    if isinstance(problem, FlatPOMDP):
        return FlatAlphaPolicy(qv[0], sol.vectors, problem.states, problem.actions, info)
    return AlphaVectorPolicy(qv, sol.vectors, problem.model, problem.complexities, "bayes", info)


def next_round_seconds(K: int, r: int, lattice: int, t_upper: float, t_lower: float) -> float:
    """The expected time of the point solver's next round (resolution 2r) from this round's:
    its upper bound costs about (vertex growth) x this one's ``t_upper``, its lower bound about
    (growth of its belief lattice, which stops at resolution ``lattice``) x ``t_lower``.  The
    lower bound's beliefs do not grow with the grid, so a round whose time is mostly the lower
    bound is not expected to grow with the vertices."""
    growth = _lattice_size(K, 2 * r) / _lattice_size(K, r)
    growth_lower = _lattice_size(K, min(2 * r, lattice)) / _lattice_size(K, min(r, lattice))
    return growth * t_upper + growth_lower * t_lower


def _q_lattice(K: int, max_points: int = 5_000) -> int:
    """Resolution of the lattice of beliefs whose point backups give the policy's Q-vectors: 400
    for two hidden states, 20 for three, 5 beyond, lowered until the lattice has at most
    ``max_points`` beliefs (a flat POMDP may have many states)."""
    r = 400 if K == 2 else 20 if K == 3 else 5
    while r > 1 and _lattice_size(K, r) > max_points:
        r -= 1
    return r


def _simplex_lattice(K: int, n: int) -> np.ndarray:
    """All beliefs with coordinates in {0, 1/n, ..., 1} (the simplex lattice)."""
    if K == 2:
        x = np.linspace(0.0, 1.0, n + 1)
        return np.stack([1 - x, x], axis=1)
    # stars and bars: K - 1 bar positions among n + K - 1 slots
    rows = []
    for bars in itertools.combinations(range(n + K - 1), K - 1):
        edges = (-1, *bars, n + K - 1)
        rows.append([edges[i + 1] - edges[i] - 1 for i in range(K)])
    return np.array(rows, dtype=float) / n
