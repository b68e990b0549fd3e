"""Reachable-belief solver: heuristic search from the initial belief with certified bounds (in
the manner of HSVI2 and SARSOP), for any number of hidden states (docs/solvers.md).

The point solver bounds the value on a triangulation of the whole simplex (r^(K-1) vertices);
this solver visits only the beliefs reachable from b0, which for a supervisor of unknown type
are few:

* **lower bound** L(b) = max_α α·b: memoryless controllers, point-based backups at the visited
  beliefs and point-based policy iteration over them; every vector is a controller's value;
* **upper bound** U(b): the sawtooth interpolation of belief-value points above the corner values
  of the fast informed bound, never above that bound or the blocks' grid bounds
  (:mod:`.upper_bounds`); points come from Bellman backups of U;
* **search**: trials from b0, greedy in U, down the (context, branch) of largest weighted excess
  gap p · (U - L - ε γ^-d), backed up in reverse, until U(b0) - L(b0) <= ``tol`` or ``max_seconds``.

The bounds rest on the convexity of the Bayes-filter value.
"""

from __future__ import annotations

import math
import time
from functools import partial
from math import comb
from typing import ClassVar

import numpy as np
import scipy.sparse as sp

from ..policies.base import Policy
from ..pomdp.belief import BranchModel
from ..pomdp.flat import FlatPOMDP
from ..pomdp.problem import AssistancePOMDP
from . import numerics
from .base import Solver, bayes_only, one_blas_thread
from .point import PointSolution, bounds_policy
from .upper_bounds import BlockGrid, fast_informed_bound, grid_blocks, inverse_points, phi_of, phi_pairs


class ReachableSolver(Solver):
    """Heuristic search over the beliefs reachable from b0 with a lower bound of alpha vectors
    and a sawtooth upper bound, until the gap at b0 is at most ``tol`` (see the module)."""

    name = "reachable"
    belief_updates = ("bayes",)
    instead: ClassVar[dict[str, str]] = bayes_only("reachable")
    flat = discounted = True

    grid_vertices = 4000  # the most vertices of a block's grid bound
    refine = 4  # points re-evaluated with the block bound beyond them
    decimals = 3  # visited beliefs equal to this many decimals are one (the first met)
    seed_depth = 3  # the search starts with every belief this many trials from b0

    def __init__(self, tol: float = 1e-3, max_seconds: float = 60.0, belief_update: str = "bayes"):
        self._targets(belief_update, tol, max_seconds)

    # -- set-up ------------------------------------------------------------------------
    def _setup(self, model: BranchModel) -> None:
        self.model = model
        M = model.kernels
        N, A, Br, K, _ = M.shape
        self.shape = (N, A, Br, K)
        # b @ flat -> unnormalized next beliefs of every (c, a, branch)
        self.moves = np.ascontiguousarray(np.moveaxis(M, 3, 0).reshape(K, -1))
        self.rewards, self.context_probs, self.discount = model.rewards, model.context_probs, model.discount
        self.vectors = numerics.memoryless_controllers(model)
        self.beta = fast_informed_bound(model)
        self.corners = self.context_probs @ self.beta.max(axis=1)  # U at the corners
        self.blocks = grid_blocks(model, self.grid_vertices)
        # several blocks: the grid over the whole simplex too (it sees what the blocks cannot: the
        # value of not knowing the block), when a resolution of at least 4 fits the vertex budget
        self.whole = None
        if len(self.blocks) > 1 and comb(4 + K - 1, K - 1) <= self.grid_vertices:
            self.whole = BlockGrid(model, self.grid_vertices)
        if self.blocks:
            self.corners = np.minimum(self.corners, self._base(np.eye(K)))
        self.points = np.zeros((0, K))
        self.point_values = np.zeros(0)
        self._refresh_points()

    def _refresh_points(self) -> None:
        """Cached forms of the upper bound's points for the sawtooth.  A point at a corner of the
        simplex lowers that corner's value instead (every interpolation then uses it)."""
        corner = np.isclose(self.points.max(axis=1), 1.0, rtol=0.0, atol=1e-15) if len(self.points) else np.zeros(0, dtype=bool)
        if np.any(corner):
            t = self.points[corner].argmax(axis=1)
            np.minimum.at(self.corners, t, self.point_values[corner])
            self.points, self.point_values = self.points[~corner], self.point_values[~corner]
        P = self.points
        self.inverse = inverse_points(P)
        self.excess = self.point_values - P @ self.corners  # <= 0: how far below the corners' plane

    # -- bounds at beliefs -------------------------------------------------------------
    def lower_at(self, B: np.ndarray) -> np.ndarray:
        return (np.atleast_2d(B) @ self.vectors.T).max(axis=1)

    def upper_at(self, B: np.ndarray) -> np.ndarray:
        B = np.atleast_2d(B)
        out = self._basefun(B)
        if len(self.points):
            lin = B @ self.corners
            saw = lin[:, None] + phi_of(B, self.inverse) * self.excess[None]  # through each point, corners beyond
            out = np.minimum(out, saw.min(axis=1))
            if self.blocks:
                # the few best points again, with the block bound beyond them instead of the corners
                k = min(self.refine, len(self.points))
                idx = (
                    np.argpartition(saw, k - 1, axis=1)[:, :k]
                    if k < len(self.points)
                    else np.broadcast_to(np.arange(k), saw.shape)
                )
                phi = phi_pairs(B, self.points, idx)
                out = np.minimum(out, self._through(B, self.points, idx, phi, self.point_values[idx]).min(axis=1))
        return out

    def _basefun(self, B: np.ndarray) -> np.ndarray:
        """The bound without points: the corners' plane, the fast informed bound and the block bound."""
        fib = np.einsum("c,nc->n", self.context_probs, np.einsum("nt,cat->nca", B, self.beta).max(axis=2))
        out = np.minimum(B @ self.corners, fib)
        if self.whole is not None:
            out = np.minimum(out, self.whole.upper_at(B))
        return np.minimum(out, self._base(B)) if self.blocks else out

    def _through(self, B: np.ndarray, P: np.ndarray, idx: np.ndarray, phi: np.ndarray, vals: np.ndarray) -> np.ndarray:
        """φ v_i + (1 - φ) U0(b') with b = φ b_i + (1 - φ) b': the bound at B[n] through point
        P[idx[n, j]] of value vals[n, j] (φ = phi[n, j]), U0 the bound without points beyond it.
        Convexity of the value makes it valid for any valid U0."""
        n, k = idx.shape
        rest = np.clip(1.0 - phi, 0.0, 1.0)
        far = rest > 1e-9
        Bp = np.where(
            far[..., None],
            (B[:, None, :] - phi[..., None] * P[idx]) / np.where(far, rest, 1.0)[..., None],
            B[:, None, :],
        )
        Bp = np.clip(Bp, 0.0, None)
        Bp /= Bp.sum(axis=2, keepdims=True)
        u0 = self._basefun(Bp.reshape(-1, B.shape[1])).reshape(n, k)
        return np.where(far, phi * vals + rest * u0, vals)

    def _base(self, B: np.ndarray) -> np.ndarray:
        """The block bound: Σ over the closed blocks of hidden states of the block's mass times the
        block's grid upper bound at the belief within the block."""
        out = np.zeros(len(B))
        for idx, grid in self.blocks:
            mass = B[:, idx].sum(axis=1)
            ok = mass > 0
            if np.any(ok):
                out[ok] += mass[ok] * grid.upper_at(B[ok][:, idx] / mass[ok, None])
        return out

    def _successors(self, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(p[c, a, br], next[c, a, br, t]) of one belief."""
        p, nxt = self._successors_many(b[None])
        return p[0], nxt[0]

    # -- backups -----------------------------------------------------------------------
    def _backup(self, b: np.ndarray, p: np.ndarray, nxt: np.ndarray) -> tuple[np.ndarray, float]:
        """(new lower-bound vector, new upper value) at b, from the successors (p, nxt)."""
        N, A, Br, K = self.shape
        S = nxt.reshape(-1, K)
        best = (S @ self.vectors.T).argmax(axis=1).reshape(N, A, Br)
        g = self.rewards + self.discount * np.einsum("cabtu,cabu->cat", self.model.kernels, self.vectors[best])
        acts = (g @ b).argmax(axis=1)
        alpha = np.einsum("c,ct->t", self.context_probs, g[np.arange(N), acts])
        q_up = self.rewards @ b + self.discount * (p * self.upper_at(S).reshape(N, A, Br)).sum(axis=2)
        return alpha, float(self.context_probs @ q_up.max(axis=1))

    def _update(self, b: np.ndarray) -> None:
        p, nxt = self._successors(b)
        alpha, up = self._backup(b, p, nxt)
        if alpha @ b > self.lower_at(b)[0] + 1e-12 * (1 + abs(alpha @ b)):
            self.vectors = np.vstack([self.vectors, alpha])
        if up < self.upper_at(b)[0] - 1e-12 * (1 + abs(up)):
            self.points = np.vstack([self.points, b])
            self.point_values = np.append(self.point_values, up)
            self._refresh_points()

    # -- consolidation over the visited beliefs ----------------------------------------------
    def _improve_lower(self, B: np.ndarray, t_end: float = math.inf) -> None:
        """Point-based policy iteration on the visited beliefs (:func:`~.numerics.controller_iteration`),
        with a second controller taking the actions greedy in the upper bound (near-optimal once it
        is close): long loops of beliefs (a supervisor who keeps relying) are valued at once."""
        N, A, Br, K = self.shape
        p, S = self._successors_many(B)
        ub = self.upper_at(S.reshape(-1, K)).reshape(len(B), N, A, Br)
        up_acts = (np.einsum("cat,nt->nca", self.rewards, B) + self.discount * (p * ub).sum(axis=3)).argmax(axis=2)
        at = np.vstack([B, np.eye(K)])
        self.vectors = numerics.controller_iteration(self.model, self.vectors, B, (p, S), at, self.tol * 1e-3, 20, up_acts, t_end)

    def _improve_upper(self, B: np.ndarray, candidates: int = 8, rounds: int = 30, t_end: float = math.inf) -> None:
        """The upper values of the visited beliefs as the fixed point of the Bellman operator on
        the sawtooth through them.  Each successor of a visited belief is bounded either by the
        current upper bound (a constant) or through one of ``candidates`` visited beliefs
        (affine in its value); with those choices fixed, the values solve a small MDP (policy
        iteration over the actions, one sparse solve each), whose fixed point is above the
        optimal value; the choices are then re-made at the new values, which can only lower
        them.  The result is raised by its Bellman residual / (1 - γ) against rounding, which
        also makes it a bound when the iterations stop early: after ``t_end``."""
        N, A, Br, K = self.shape
        n = len(B)
        p, S = self._successors_many(B)
        m = n * N * A * Br
        Sf = S.reshape(m, K)
        const = self.upper_at(Sf)  # the current bound: valid, and the fallback of every successor
        base_s = Sf @ self.corners
        base_b = B @ self.corners
        inv = inverse_points(B)
        v = np.minimum(self.upper_at(B), np.inf)
        # candidate points of every successor: those giving the smallest sawtooth at the start
        cand = np.empty((m, candidates), dtype=np.int64)
        phis = np.empty((m, candidates))
        step = max(1, 2_000_000 // max(1, n * K))
        for lo in range(0, m, step):
            sl = slice(lo, min(m, lo + step))
            phi = phi_of(Sf[sl], inv)  # (chunk, n)
            saw = base_s[sl, None] + phi * (v - base_b)[None]
            k = min(candidates, n)
            idx = np.argpartition(saw, k - 1, axis=1)[:, :k] if k < n else np.broadcast_to(np.arange(n), (len(phi), n))
            cand[sl, :k] = idx
            phis[sl, :k] = np.take_along_axis(phi, idx, axis=1)
            if k < candidates:
                cand[sl, k:] = idx[:, :1]
                phis[sl, k:] = phis[sl, :1]
        rew = np.einsum("cat,nt->nca", self.rewards, B)
        # the affine bound of successor s through candidate point j: a0[s, j] + phis[s, j] v_j
        if self.blocks:
            a0c = np.empty((m, candidates))
            for lo in range(0, m, 4096):
                sl = slice(lo, min(m, lo + 4096))
                a0c[sl] = self._through(Sf[sl], B, cand[sl], phis[sl], np.zeros(cand[sl].shape))
        else:
            a0c = base_s[:, None] - phis * base_b[cand]
        # weight of successor s in the value of its belief: P(c) γ P(branch)
        wt = (self.discount * p * self.context_probs[None, :, None, None]).reshape(m)
        rows_of = np.repeat(np.arange(n), N * A * Br)
        ar = np.arange(m)

        def choose(v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            """The affine bound a + b v[col] of every successor that is smallest at v (b = 0: the constant)."""
            vals = a0c + phis * v[cand]
            j = vals.argmin(axis=1)
            use = vals[ar, j] < const
            col = np.where(use, cand[ar, j], 0)
            slope = np.where(use, phis[ar, j], 0.0)
            return np.where(use, a0c[ar, j], const), slope, col

        def q_of(v: np.ndarray, aff: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> np.ndarray:
            a0, slope, col = choose(v) if aff is None else aff
            val = a0 + slope * v[col]
            return rew + self.discount * (p * val.reshape(n, N, A, Br)).sum(axis=3)

        def chain(acts: np.ndarray, aff: tuple[np.ndarray, np.ndarray, np.ndarray]) -> tuple[sp.csr_matrix, np.ndarray]:
            """The values' linear system when the actions ``acts`` and the successors' bounds ``aff`` are fixed."""
            a0, slope, col = aff
            sel = np.zeros((n, N, A, Br), dtype=bool)
            sel[np.arange(n)[:, None], np.arange(N)[None, :], acts] = True
            sel = sel.reshape(m)
            rhs = np.einsum("c,nc->n", self.context_probs, rew[np.arange(n)[:, None], np.arange(N)[None, :], acts])
            rhs = rhs + np.bincount(rows_of[sel], weights=(wt * a0)[sel], minlength=n)
            lin = sel & (slope > 0)
            return sp.csr_matrix(((wt * slope)[lin], (rows_of[lin], col[lin])), shape=(n, n)), rhs

        acts = q_of(v).argmax(axis=2)
        for _ in range(rounds):
            aff = choose(v)
            _, slope, col = aff
            v, acts = numerics.howard(acts, partial(chain, aff=aff), partial(q_of, aff=aff), v, 50, axis=2, t_end=t_end)[:2]
            again = choose(v)
            if (np.array_equal(again[2], col) and np.array_equal(again[1] > 0, slope > 0)) or time.perf_counter() > t_end:
                break
        q = q_of(v)
        eta = max(0.0, float(np.max(np.einsum("c,nc->n", self.context_probs, q.max(axis=2)) - v)))
        v = v + eta / (1 - self.discount)
        better = v < self.upper_at(B) - 1e-12 * (1 + np.abs(v))
        if np.any(better):
            self.points = np.vstack([self.points, B[better]])
            self.point_values = np.concatenate([self.point_values, v[better]])
            self._refresh_points()

    def _successors_many(self, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(p[n, c, a, br], next[n, c, a, br, t]) of beliefs B."""
        N, A, Br, K = self.shape
        nb = (B @ self.moves).reshape(len(B), N, A, Br, K)
        p = nb.sum(axis=-1)
        ok = p > 1e-300
        nxt = np.where(ok[..., None], nb / np.where(ok, p, 1.0)[..., None], 1.0 / K)
        return np.where(ok, p, 0.0), nxt

    # -- pruning -----------------------------------------------------------------------
    def _prune(self, B: np.ndarray) -> None:
        """Keep the vectors best at some visited belief or corner, and the upper points that
        improve on the others at their own belief."""
        K = self.shape[3]
        at = np.vstack([B, np.eye(K)])
        self.vectors = numerics.best_at(self.vectors, at)
        n = len(self.points)
        if 1 < n <= 4000:
            order = np.argsort(self.excess, kind="stable")  # deepest below the corners first
            P, v, ex = self.points[order], self.point_values[order], self.excess[order]
            base = P @ self.corners
            saw = base[:, None] + phi_of(P, self.inverse)[:, order] * ex[None]  # [i, j]: the sawtooth of point j at point i
            keep = np.zeros(n, dtype=bool)
            for i in range(n):
                others = saw[i, keep]
                bound = others.min() if len(others) else np.inf
                keep[i] = v[i] < bound - 1e-12 * (1 + abs(v[i]))
            self.points, self.point_values = P[keep], v[keep]
            self._refresh_points()

    # -- search ------------------------------------------------------------------------
    def _trial(self, b0: np.ndarray, eps: float, depth_cap: int, t_end: float) -> list[np.ndarray]:
        """One trial from b0: the beliefs met, in order (the backups follow in reverse)."""
        N, A, Br, K = self.shape
        path = [b0]
        b = b0
        seen = {np.round(b0, self.decimals).tobytes()}
        threshold = eps
        for _d in range(depth_cap):
            p, nxt = self._successors(b)
            S = nxt.reshape(-1, K)
            ub = self.upper_at(S).reshape(N, A, Br)
            q_up = self.rewards @ b + self.discount * (p * ub).sum(axis=2)
            acts = q_up.argmax(axis=1)
            ci = np.arange(N)
            threshold /= self.discount
            lb = self.lower_at(S).reshape(N, A, Br)
            excess = self.context_probs[:, None] * p[ci, acts] * (ub[ci, acts] - lb[ci, acts] - threshold)
            if time.perf_counter() > t_end:
                break
            # the branch of largest weighted excess that does not close a loop of the trial
            nxt_b = None
            for k in np.argsort(-excess, axis=None):
                c, br = np.unravel_index(int(k), excess.shape)
                if excess[c, br] <= 0:
                    break
                cand = nxt[c, acts[c], br]
                key = np.round(cand, self.decimals).tobytes()
                if key not in seen:
                    seen.add(key)
                    nxt_b = cand
                    break
            if nxt_b is None:
                break
            b = nxt_b
            path.append(b)
        return path

    @one_blas_thread()
    def solve_bounds(self, problem: AssistancePOMDP | FlatPOMDP) -> PointSolution:
        """Lower and upper bounds at the initial belief (the vectors and points behind them)."""
        self.check(problem)
        return self._bounds(problem.branch_model())

    def _bounds(self, model: BranchModel) -> PointSolution:
        t0 = time.perf_counter()
        t_end = t0 + self.max_seconds
        self._setup(model)
        b0 = np.asarray(model.initial, dtype=float)
        width = float(np.max(self.corners) - np.min(self.vectors.max(axis=0).min()))
        span = max(width, self.tol)
        depth_cap = max(1, math.ceil(math.log(self.tol / (2 * span)) / math.log(self.discount)) + 1)
        visited: list[np.ndarray] = list(numerics.reachable_beliefs(b0, self.seed_depth, self._successors_many, self.decimals))
        history = []
        trials = backups = consolidated = 0
        cost = backup_seconds = 0.0
        rng = np.random.default_rng(0)
        lo, up = float(self.lower_at(b0)[0]), float(self.upper_at(b0)[0])
        while up - lo > self.tol and time.perf_counter() < t_end:
            trials += 1
            path = self._trial(b0, self.tol, depth_cap, t_end)
            b_start = time.perf_counter()
            for b in reversed(path):
                self._update(b)
                backups += 1
            backup_seconds += time.perf_counter() - b_start
            visited.extend(path[1:])
            B = numerics.unique_rows(np.array(visited), self.decimals)
            visited = list(B)
            # a consolidation is not started past the limit: the next one costs about (size
            # ratio)^2 x the last one; the first, about two backups per visited belief (each
            # bounds the successors of its belief, as the consolidation does for all at once)
            expected = cost * (len(B) / consolidated) ** 2 if consolidated else 2 * len(B) * backup_seconds / max(backups, 1)
            if len(B) >= 1.3 * consolidated and time.perf_counter() + expected < t_end:
                # values over the visited beliefs at once (loops of beliefs included), with the
                # beliefs met on a few trajectories of the greedy policy (what the lower bound needs)
                c0 = time.perf_counter()
                sampled = numerics.sample_beliefs(self.model, b0, rng, self._successors_many, self.upper_at, 60)
                B = numerics.unique_rows(np.vstack([B, sampled]), self.decimals)
                visited = list(B)
                self._improve_upper(B, t_end=t_end)
                self._improve_lower(B, t_end=t_end)
                self._prune(B)
                consolidated, cost = len(B), time.perf_counter() - c0
            lo, up = float(self.lower_at(b0)[0]), float(self.upper_at(b0)[0])
            history.append((trials, time.perf_counter() - t0, lo, up))
        B = numerics.unique_rows(np.array(visited), self.decimals)
        self._prune(B)
        lo, up = float(self.lower_at(b0)[0]), float(self.upper_at(b0)[0])
        counts = {"trials": trials, "backups": backups, "iterations": trials, "beliefs_visited": len(B)}
        vectors, points, values = self.vectors.copy(), self.points.copy(), self.point_values.copy()
        return PointSolution(vectors, points, values, lo, up, time.perf_counter() - t0, counts, history, B)

    @one_blas_thread()
    def solve(self, problem: AssistancePOMDP | FlatPOMDP) -> Policy:
        """The policy greedy in the lower bound's Q-vectors, with the bounds at the initial belief
        in its ``info``: an AlphaVectorPolicy for the assistance POMDP, a FlatAlphaPolicy for a
        flat POMDP."""
        sol = self.solve_bounds(problem)
        K = sol.vectors.shape[1]
        assert sol.beliefs is not None
        at = numerics.unique_rows(np.vstack([sol.beliefs, np.eye(K), np.full((1, K), 1.0 / K)]))
        qv = numerics.q_vectors(self.model, self.vectors, at, self._successors_many(at)[1], prune=True)
        method = "heuristic search over reachable beliefs: alpha-vector lower bound, sawtooth upper bound"
        return bounds_policy(self, problem, qv, sol, method)
