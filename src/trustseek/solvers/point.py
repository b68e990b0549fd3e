"""Point-based solver with lower and upper bounds, for any number of trust levels.

With K trust levels the belief is a point of the (K-1)-simplex.  The value at the
initial belief b0 is bracketed from both sides:

* lower bound: a set Γ of alpha vectors, L(b) = max_α α·b.  Every vector is the
  value of an executable policy (memoryless controllers to start, then
  point-based controllers evaluated exactly: one node per sampled belief, its
  greedy actions, and per branch the node best at the next belief), so L ≤ V.
  The beliefs are a lattice of the simplex, those reachable from b0 in two trials
  and those met on simulated trajectories (seeded);
* upper bound: the fixed point of the Bellman operator with linear interpolation
  on Freudenthal's triangulation of the simplex (Lovejoy's bound), solved by
  policy iteration; interpolation over-estimates a convex value, so it is an
  upper bound, certified against the rounding of the solve by its residual.

The resolution of the triangulation is doubled until U(b0) - L(b0) <= ``tol``.

The structure is the mixed-observability one of the assistance POMDP: a
context c (the complexity, drawn i.i.d. from P(C) and seen before acting), a
hidden part t (trust), and branches (o, E') whose unnormalized kernel
M[c, a, branch, t, t'] moves the belief.  A flat POMDP (e.g. a ``.pomdp`` file)
is the special case of one context and branches = observations.  The bounds
rest on the convexity of the Bayes-filter value; for the eq.-3 update use the
``alpha`` solver (two trust levels).
"""

from __future__ import annotations

import itertools
import time
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
from .base import SolverBase, SolverError, bayes_only, one_blas_thread
from .numerics import (
    best_at,
    best_vectors,
    evaluate_controller,
    greedy_controller,
    improve,
    memoryless_controllers,
    point_backup,
    policy_values,
    reachable_beliefs,
    unique_rows,
)

__all__ = ["PointSolution", "PointSolver", "bounds_policy", "freudenthal_weights", "next_round_seconds"]


@dataclass
class PointSolution:
    """Bounds at the initial belief, the vectors of the lower bound and the upper-bound points."""

    vectors: np.ndarray  # lower bound: L(b) = max_α α·b
    points: np.ndarray  # upper bound: the vertices of the triangulation ...
    point_values: np.ndarray  # ... and their certified values (linear interpolation)
    lower: float
    upper: float
    iterations: int
    seconds: float
    history: list[tuple[int, float, float, float]] = field(default_factory=list)  # (points, seconds, lower, upper)

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


class PointSolver(SolverBase):
    """Point-based lower bound and Freudenthal-grid upper bound, refined until the gap at b0 is small.

    * Lower bound: point-based policy iteration.  On a set of beliefs (the grid vertices, b0 and
      the beliefs reachable from b0 in a few trials) every belief is a controller node with its
      greedy actions and, for every branch, the node that is best at the next belief; the
      controller is evaluated exactly (one sparse linear solve) and its values join Γ.
    * Upper bound: the fixed point of the Bellman operator with linear interpolation on
      Freudenthal's triangulation of the simplex at resolution r (policy iteration, exact for the
      grid problem); linear interpolation over-estimates the convex value, so the fixed point is
      an upper bound, and it is certified against the rounding of the solve by its Bellman residual.
    * The resolution is doubled until U(b0) - L(b0) <= tol.  The vertex count grows like
      r^(K-1), which is what limits the number of trust levels.

    It solves the assistance POMDP (an alpha-vector policy) and flat POMDPs read from standard
    files (a flat alpha-vector policy).
    """

    name = "point"
    belief_updates = ("bayes",)
    # the state of the last solve: the problem, the lower-bound vectors, the upper bound
    model: BranchModel
    G: np.ndarray
    r: int
    u: np.ndarray
    lookup: np.ndarray
    V: np.ndarray
    instead: ClassVar[dict[str, str]] = bayes_only("point")

    def __init__(
        self,
        tol: float = 1e-3,
        max_seconds: float = 60.0,
        resolution: int | None = None,
        max_resolution: int | None = None,
        depth: int = 2,
        lower_lattice: int | None = None,
        seed: int = 0,
        belief_update: str = "bayes",
    ):
        self._targets(belief_update, tol, max_seconds)
        self.resolution = resolution
        self.max_resolution = max_resolution
        self.depth = int(depth)
        self.seed = seed
        self.max_vertices = 100_000
        self.lower_lattice = lower_lattice  # beliefs of the lower bound: this lattice and the reachable set

    def unsupported(self, problem: Any) -> list[str]:
        if isinstance(problem, FlatPOMDP):
            return [] if problem.discount < 1.0 else [f"the point solver needs a discount below 1, got {problem.discount}"]
        return super().unsupported(problem)

    # -- lower bound: point-based controller evaluation -----------------------------
    def _improve_lower(self, B: np.ndarray, S: np.ndarray, p: np.ndarray, rounds: int = 30) -> None:
        m = self.model
        n, N, A, Br, K = S.shape
        Sf = S.reshape(-1, K)
        prev = None
        for _ in range(rounds):
            best = (Sf @ self.G.T).argmax(axis=1).reshape(n, N, A, Br)
            g = point_backup(m, self.G, best)
            acts = np.einsum("ncat,nt->nca", g, B).argmax(axis=2)  # (n, N)
            # controller: node i, successors = node best at the next belief among the new vectors
            alpha, succ = greedy_controller(m, S, p, g, acts)
            key = (acts.tobytes(), succ.tobytes())
            before = (B @ self.G.T).max(axis=1)
            ev = evaluate_controller(m, acts, succ, guess=alpha)
            if not np.all(np.isfinite(ev)):
                ev = alpha
            self.G = best_at(np.vstack([self.G, alpha, ev]), B)
            gain = float(np.max((B @ self.G.T).max(axis=1) - before))
            if key == prev or gain <= self.tol * 1e-2:
                break
            prev = key

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
        K, N, gamma, pc = m.n_hidden, len(m.context_probs), m.discount, m.context_probs
        V, lookup, p, S, col, w = self._vertex_grid(r)
        nV, Br = len(V), S.shape[3]
        wt = w * p[..., None]
        rew = np.einsum("cat,nt->nca", m.rewards, V)
        rows = np.broadcast_to(np.arange(nV)[:, None, None], (nV, Br, K))
        ii = np.arange(nV)

        def q_of(u: np.ndarray) -> np.ndarray:
            return rew + gamma * np.einsum("ncabk,ncabk->nca", wt, u[col])

        acts = rew.argmax(axis=2)
        u = np.zeros(nV)
        for _ in range(500):
            rr = np.zeros(nV)
            Wm = sp.csr_matrix((nV, nV))
            for c in range(N):
                a = acts[:, c]
                rr += pc[c] * rew[ii, c, a]
                entries = (gamma * pc[c] * wt[ii, c, a]).ravel(), (rows.ravel(), col[ii, c, a].ravel())
                Wm = Wm + sp.csr_matrix(entries, shape=(nV, nV))
            u = policy_values(Wm, rr, u)
            new_acts = improve(q_of(u), acts, axis=2)
            if new_acts is None:
                break
            acts = new_acts
        # H is monotone with modulus γ: u + max(H u - u)+ / (1 - γ) bounds its fixed point
        eta = max(0.0, float(np.max(q_of(u).max(axis=2) @ pc - u)))
        return V, u + eta / (1 - gamma), lookup

    def grid_bound(self, model: BranchModel, r: int) -> tuple[np.ndarray, np.ndarray]:
        """Solve the grid upper bound of ``model`` at resolution r and keep it (``upper_at`` reads
        it): the vertex beliefs and their certified upper values."""
        self.model = model
        V, u, lookup = self._upper(r)
        self.r, self.u, self.lookup, self.V = r, u, lookup, V
        return V, u

    def upper_at(self, B: np.ndarray) -> np.ndarray:
        """The certified upper bound at beliefs B (linear interpolation of the vertex values)."""
        verts, w = freudenthal_weights(np.atleast_2d(np.asarray(B, dtype=float)), self.r)
        return (w * self.u[_find(self.lookup, _vertex_code(verts, self.r))]).sum(axis=1)

    def lower_at(self, B: np.ndarray) -> np.ndarray:
        return (np.atleast_2d(np.asarray(B, dtype=float)) @ self.G.T).max(axis=1)

    def _sampled(self, b0: np.ndarray, rng: np.random.Generator, trajectories: int = 8, length: int = 50) -> np.ndarray:
        """Beliefs met along simulated trajectories from b0 (complexity and branch drawn with their
        probabilities, actions greedy in the current lower bound): PBVI-style belief expansion."""
        m = self.model
        K, N = m.n_hidden, len(m.context_probs)
        B = np.repeat(b0[None], trajectories, axis=0)
        out = []
        idx = np.arange(trajectories)
        for _ in range(length):
            p, S = self.model.branches.successors(B)  # (n, N, A, Br), (n, N, A, Br, K)
            c = rng.choice(N, size=trajectories, p=m.context_probs)
            # greedy action of the one-step lookahead on the lower bound
            lb = (S.reshape(-1, K) @ self.G.T).max(axis=1).reshape(p.shape)
            qa = np.einsum("cat,nt->nca", m.rewards, B) + m.discount * (p * lb).sum(axis=-1)
            a = qa[idx, c].argmax(axis=1)
            pb = p[idx, c, a]  # (n, Br)
            u = rng.random(trajectories)[:, None]
            br = np.minimum((np.cumsum(pb, axis=1) / pb.sum(axis=1, keepdims=True) < u).sum(axis=1), pb.shape[1] - 1)
            B = S[idx, c, a, br]
            out.append(B)
        return unique_rows(np.vstack(out), decimals=9)

    # -- solve -------------------------------------------------------------------------
    @one_blas_thread
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
        reach = reachable_beliefs(b0, self.depth, model.branches.successors)
        self.G = self._start(model, b0, reach)
        r = self.resolution or {2: 64, 3: 16, 4: 8}.get(K, 4 if K <= 8 else 2)
        r_max = self.max_resolution or {2: 4096, 3: 512, 4: 64}.get(K, 16)
        if (r + 1) ** (K - 1) >= 2**62 or _lattice_size(K, r) > self.max_vertices:
            raise SolverError(
                f"{K} hidden states are too many for the grid upper bound of the {self.name} solver "
                f"({_lattice_size(K, r)} vertices at resolution {r})"
            )
        lat = self.lower_lattice or {2: 256, 3: 16, 4: 6}.get(K, 3)
        rng = np.random.default_rng(self.seed)
        history = []
        rounds = 0
        while True:
            rounds += 1
            t_round = time.perf_counter()
            V, u = self.grid_bound(model, r)
            t_upper = time.perf_counter() - t_round
            B = unique_rows(np.vstack([_simplex_lattice(K, min(r, lat)), reach, self._sampled(b0, rng)]))
            p, S = self.model.branches.successors(B)
            self._improve_lower(B, S, p)
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
        return PointSolution(self.G.copy(), V.copy(), u.copy(), lo, up, rounds, time.perf_counter() - t0, history)

    def q_vectors(self, beliefs: np.ndarray) -> list[list[np.ndarray]]:
        """Q lower-bound vectors per (context, action): point backups of L at ``beliefs``."""
        m = self.model
        S = self.model.branches.successors(beliefs)[1]
        n, N, A, Br, K = S.shape
        g = point_backup(m, self.G, best_vectors(S.reshape(-1, K), self.G).reshape(n, N, A, Br))
        return [[unique_rows(g[:, c, a], decimals=12) for a in range(A)] for c in range(N)]

    @one_blas_thread
    def solve(self, problem: AssistancePOMDP | FlatPOMDP) -> Policy:
        """The policy of the lower bound's vectors, with the bounds at the initial belief in its
        ``info``: an AlphaVectorPolicy for the assistance POMDP (Bayes update), a FlatAlphaPolicy
        for a flat POMDP."""
        sol = self.solve_bounds(problem)
        K = sol.vectors.shape[1]
        qv = self.q_vectors(unique_rows(np.vstack([sol.points, _simplex_lattice(K, _q_lattice(K))])))
        method = "point-based policy iteration + Freudenthal upper bound"
        return bounds_policy(self, problem, qv, sol, method, resolution=self.r, iterations=sol.iterations)


def bounds_policy(solver: Any, problem: AssistancePOMDP | FlatPOMDP, qv: list, sol: Any, method: str, **counts: Any) -> Policy:
    """The policy of a bounding solver's lower-bound Q-vectors ``qv`` with the bounds at the
    initial belief (``sol``: its vectors, points, lower, upper, gap, seconds) and the solver's
    own ``counts`` in its ``info``: an AlphaVectorPolicy for the assistance POMDP (Bayes update),
    a FlatAlphaPolicy for a flat POMDP (the point and reachable solvers)."""
    info: dict[str, Any] = {
        "solver": solver.name,
        "method": method,
        **counts,
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
