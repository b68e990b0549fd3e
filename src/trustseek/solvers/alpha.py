"""The alpha solver: certified bounds for two trust levels (docs/solvers.md, ``alpha``).

With x = P(trust = high) the value over P(C) is W(x) = Σ_C P(C) max_a Q(x, C, a).  Under the
``bayes`` update W is convex and piecewise linear, the maximum of alpha vectors (lines in x), and
:func:`exact_backup` computes the exact Bellman backup of such a function with envelopes (each
branch (o, E') moves x by a monotone linear-fractional map; no linear programs).
:class:`AlphaSolver` runs policy iteration on finite-state controllers built from the backup's
vectors, so L(x) = max_α α·x is the value of executable policies, a certified lower bound, and

    W <= T L + γ δ / (1 - γ),  δ = sup_x (T L - L)(x)  (computed exactly),

a certified gap δ / (1 - γ); the grid solver's interpolated value is a second upper bound.
Under the ``paper`` update (eq. 3) alpha vectors cannot represent W; the solver runs the
certified adaptive grid (:class:`~.certified.CertifiedGridSolver`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ..policies.envelope import (
    active_piece,
    cross_sum,
    difference_extrema,
    envelope,
    envelope_values,
    max_of,
    refit,
    strip,
    thin,
    thin_mask,
)
from ..pomdp.belief import BranchModel, to_vector
from ..pomdp.problem import AssistancePOMDP
from .base import one_blas_thread
from .certified import CertifiedGridSolver, CertifiedSolution, CertifiedSolver
from .grid import GridSolver
from .numerics import evaluate_controller, memoryless_controllers

# --------------------------------------------------------------------------- the exact backup


@dataclass
class Backup:
    """The exact Bellman backup T L of a set of alpha vectors (two trust levels).

    ``vectors``/``xs``: the envelope of T L; ``actions[n, c]`` and ``successors[n, c, branch]``
    (index into the input vectors, -1 for an impossible branch) say how each vector is
    obtained.  ``q[c][a]`` = (vectors, xs) of the envelope of Q(x, C=c, a).
    """

    vectors: np.ndarray
    xs: np.ndarray
    actions: np.ndarray
    successors: np.ndarray
    q: list[list[tuple[np.ndarray, np.ndarray]]]


class BranchLines(NamedTuple):
    """Per (c, a, branch) of the Bayes branches, two trust levels: the branch matrices
    M[t, u] = P(o, E', T'=u | T=t, C=c, a) and the coefficients of the monotone belief map
    x -> x'(x) = (m0 (1-x) + m1 x) / (s0 (1-x) + s1 x), with its range [lo, hi], whether the
    branch can happen at all and whether its map moves at all."""

    M: np.ndarray
    possible: np.ndarray
    s0: np.ndarray
    s1: np.ndarray
    m0: np.ndarray
    m1: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    moving: np.ndarray


def branch_lines(pomdp: AssistancePOMDP) -> BranchLines:
    """The Bayes branches of ``pomdp`` as linear-fractional maps of x = P(trust = high)."""
    branches = pomdp.branches("bayes")
    s0, s1, m0, m1 = branches.two_level()
    with np.errstate(divide="ignore", invalid="ignore"):
        y0 = np.where(s0 > 0, m0 / np.where(s0 > 0, s0, 1.0), np.nan)
        y1 = np.where(s1 > 0, m1 / np.where(s1 > 0, s1, 1.0), np.nan)
    moving = (s0 > 0) & (s1 > 0) & (np.abs(y1 - y0) > 1e-15)  # the map is not constant
    return BranchLines(branches.move, (s0 + s1) > 0, s0, s1, m0, m1, np.fmin(y0, y1), np.fmax(y0, y1), moving)


def exact_backup(pomdp: AssistancePOMDP, vecs: np.ndarray, xs: np.ndarray | None = None) -> Backup:
    """One exact Bellman backup (``bayes`` update) of L(x) = max_j vecs[j]·(1-x, x).

    ``vecs`` must be an envelope with breakpoints ``xs`` (computed when not given).

    For each (C, a) the envelope of Q(·, C, a) is built in one pass: its breakpoints are the
    preimages of L's breakpoints under every branch's belief map (all branches at once), and
    on each piece every branch uses the line of L active at its next belief.  The actions are
    combined by the upper envelope and the complexities by a weighted cross-sum."""
    if xs is None:
        idx, xs = envelope(vecs)
        vecs = vecs[idx]
        remap = idx
    else:
        remap = np.arange(len(vecs))
    gamma = pomdp.discount
    R = pomdp.expected_reward  # [c, a, t]
    bl = branch_lines(pomdp)
    n_branch = bl.M.shape[2]
    ks = xs[1:-1]
    if len(ks):
        with np.errstate(divide="ignore", invalid="ignore"):
            pre = (bl.m0[..., None] - ks * bl.s0[..., None]) / (ks * (bl.s1 - bl.s0)[..., None] - (bl.m1 - bl.m0)[..., None])
        inside = bl.moving[..., None] & bl.possible[..., None] & (ks > bl.lo[..., None]) & (ks < bl.hi[..., None])
    q_env: list[list[tuple[np.ndarray, np.ndarray]]] = []
    w: Any = None  # (vectors, breakpoints, actions, successors) of the cross-sum so far
    for c in range(pomdp.n_complexity):
        per_a = []
        tags = []
        for a in range(2):
            bs = np.nonzero(bl.possible[c, a])[0]
            u = np.concatenate([[0.0, 1.0], pre[c, a][inside[c, a]]]) if len(ks) else np.array([0.0, 1.0])
            u.sort()
            u = strip(u)
            mids = 0.5 * (u[:-1] + u[1:])
            acc_v = np.broadcast_to(R[c, a], (len(mids), 2)).copy()
            acc_t = np.full((len(mids), n_branch), -1, dtype=np.int64)
            if len(bs):
                sb0, sb1 = bl.s0[c, a, bs][:, None], bl.s1[c, a, bs][:, None]
                num = bl.m0[c, a, bs][:, None] * (1 - mids) + bl.m1[c, a, bs][:, None] * mids
                den = sb0 * (1 - mids) + sb1 * mids
                y = num / den  # (branches, pieces): the next belief at each piece's middle
                act = active_piece(xs, y.ravel()).reshape(y.shape)
                # Σ_branch M_b α_act  (vectors of L projected through each branch), as one product
                lines = vecs[act.T].reshape(len(mids), -1)  # (pieces, (branch, u))
                acc_v += lines @ (gamma * bl.M[c, a, bs]).transpose(0, 2, 1).reshape(-1, 2)
                acc_t[:, bs] = remap[act].T
            per_a.append((acc_v, u))
            tags.append(acc_t)
        q_env.append(per_a)
        cv, xs_c, src, idx = max_of(per_a[0][0], per_a[0][1], per_a[1][0], per_a[1][1])
        cs = np.where(src[:, None] == 1, tags[1][np.minimum(idx, len(tags[1]) - 1)], tags[0][np.minimum(idx, len(tags[0]) - 1)])
        pc = pomdp.complexity_probs[c]
        if w is None:
            w = (pc * cv, xs_c, src[:, None], cs[:, None])
        else:
            u, i1, i2 = cross_sum(w[1], xs_c)
            w = (
                w[0][i1] + pc * cv[i2],
                u,
                np.concatenate([w[2][i1], src[i2][:, None]], axis=1),
                np.concatenate([w[3][i1], cs[i2][:, None]], axis=1),
            )
    return Backup(w[0], w[1], w[2].astype(np.int64), w[3], q_env)


def finite_horizon_vectors(pomdp: AssistancePOMDP, horizon: int) -> list[np.ndarray]:
    """Exact alpha vectors of the h-step value (h = 0..horizon, ``bayes`` update, two trust
    levels): V_0 = 0 and V_h = T V_{h-1}; returns the envelope vectors for each h."""
    vecs = np.zeros((1, 2))
    out = [vecs]
    for _ in range(horizon):
        vecs = exact_backup(pomdp, vecs).vectors
        out.append(vecs)
    return out


def finite_horizon_value(pomdp: AssistancePOMDP, horizon: int, belief: Any, complexity: int | None = None) -> float:
    """The exact h-step value at a belief (P(trust = high) or a vector), either for a known
    complexity of the first trial or averaged over P(C)."""
    b = to_vector(belief, 2)
    if horizon == 0:
        return 0.0
    bk = exact_backup(pomdp, finite_horizon_vectors(pomdp, horizon - 1)[-1])
    if complexity is None:
        return float(envelope_values(bk.vectors, bk.xs, np.array([b[1]]))[0])
    return float(max(envelope_values(v, xs, np.array([b[1]]))[0] for v, xs in bk.q[complexity]))


# --------------------------------------------------------------------------- the solver

MAX_ITER = 2000  # backups at most
THIN = 0.1  # lines worth less than THIN * tol * (1 - γ) are dropped from L
SEED_POINTS = 257  # beliefs of the starting controller


class AlphaSolver(CertifiedSolver):
    """Certified solver for two trust levels (``bayes``: alpha vectors, an AlphaVectorPolicy;
    ``paper``: the certified grid, a TrustAwarePolicy on a fine grid)."""

    name = "alpha"

    def __init__(self, belief_update: str = "bayes", tol: float = 1e-6, upper_grid: int = 201):
        self._targets(belief_update, tol)
        self.upper_grid = int(upper_grid)  # points of the grid solver's upper bound (0: none)

    @one_blas_thread()
    def solve_bounds(self, pomdp: AssistancePOMDP) -> CertifiedSolution:
        """The certified solution (lower bound, Q envelopes, gap)."""
        self.check(pomdp)
        if self.belief_update == "paper":
            return CertifiedGridSolver(tol=self.tol).solve_bounds(pomdp)
        return self._solve_bayes(pomdp)

    def _solve_bayes(self, pomdp: AssistancePOMDP) -> CertifiedSolution:
        t0 = time.perf_counter()
        gamma = pomdp.discount
        model = pomdp.branch_model()
        base = memoryless_controllers(model)
        vecs = np.vstack([base, _grid_controller(pomdp, model, SEED_POINTS, base)])
        idx, xs = envelope(vecs)
        vecs = vecs[idx]
        history: list[float] = []
        it = 0
        eta = THIN * self.tol * (1 - gamma)
        while True:
            vecs, xs = thin(vecs, xs, eta)
            bk = exact_backup(pomdp, vecs, xs)
            sup, inf = difference_extrema(bk.vectors, bk.xs, vecs, xs)
            delta = max(0.0, sup)
            # L is made of policy values, so T L >= L up to rounding and thinning; measure it too
            below = max(0.0, -inf)
            gap = (delta + below) / (1 - gamma)
            history.append(gap)
            if gap <= self.tol or it >= MAX_ITER:
                break
            it += 1
            # every vector of the backup is the value of "act, then follow a node of L"; the
            # controller's nodes: the vectors of T L, less those worth under eta
            new = [vecs, bk.vectors]
            nodes, nxs, keep = refit(bk.vectors, bk.xs, np.nonzero(thin_mask(bk.vectors, eta))[0])
            succ = _repoint(pomdp, nodes, nxs, bk.actions[keep])
            ev = evaluate_controller(model, bk.actions[keep], succ, guess=nodes, rtol=1e-11)
            if np.all(np.isfinite(ev)):
                new.append(ev)
            # L <- the upper envelope of L, T L and the controller's values (one sort by slope)
            allv = np.vstack(new)
            idx, xs = envelope(allv)
            vecs = allv[idx]
        if self.upper_grid and gap > self.tol:
            # the grid solver's interpolated value: an independent upper bound (V is convex)
            grid_sol = GridSolver(grid=self.upper_grid, belief_update="bayes").solve_grid(pomdp)
            up_grid = grid_sol.value @ pomdp.complexity_probs + grid_sol.error_bound
            # sup of min(U_alpha, U_grid) - L: all three are piecewise linear between these points
            pts = np.union1d(np.union1d(xs, bk.xs), grid_sol.grid)
            up_alpha = envelope_values(bk.vectors, bk.xs, pts) + gamma * (delta + below) / (1 - gamma)
            up = np.minimum(up_alpha, np.interp(pts, grid_sol.grid, up_grid))
            gap = min(gap, float(np.max(up - envelope_values(vecs, xs, pts))) + below / (1 - gamma))
        return CertifiedSolution(
            belief_update="bayes",
            method="policy-iteration",
            lower=(vecs, xs),
            q=bk.q,
            gap=float(gap),
            iterations=it,
            seconds=time.perf_counter() - t0,
            history=history,
            residuals=(delta, below),  # sup(T L - L), sup(L - T L)
        )


def _grid_controller(pomdp: AssistancePOMDP, model: BranchModel, points: int, base: np.ndarray) -> np.ndarray:
    """Values of a controller on ``points`` beliefs: greedy actions of a one-step lookahead on the
    memoryless controllers' values ``base``, successors = the nearest belief of the set (a cheap start)."""
    x = np.linspace(0.0, 1.0, points)
    b = np.stack([1 - x, x], axis=1)
    M = model.kernels  # [c, a, branch, t, u]
    N, n_branch = pomdp.n_complexity, M.shape[2]
    nbs = [np.einsum("nt,abtu->nabu", b, M[c]) for c in range(N)]  # (n, a, branch, u) per c: unnormalized
    guess = base[(b @ base.T).argmax(axis=1)]  # the best known vector at each belief
    acts = np.zeros((points, N), dtype=np.int64)
    succ = np.full((points, N, n_branch), -1, dtype=np.int64)
    for c, nb in enumerate(nbs):
        z = nb.sum(axis=-1)
        val = np.where(z > 0, (nb @ base.T).max(axis=-1), 0.0)
        q = b @ pomdp.expected_reward[c].T + pomdp.discount * val.sum(axis=2)
        acts[:, c] = q.argmax(axis=1)
        na = nb[np.arange(points), acts[:, c]]  # (n, branch, u)
        za = na.sum(axis=-1)
        nx = np.where(za > 0, na[..., 1] / np.where(za > 0, za, 1.0), 0.0)
        succ[:, c] = np.where(za > 0, np.rint(nx * (points - 1)).astype(np.int64), -1)
    return evaluate_controller(model, acts, succ, guess=guess, rtol=1e-11)


def _repoint(pomdp: AssistancePOMDP, vecs: np.ndarray, xs: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """Successors of each node (a vector of the envelope) at its witness belief (the middle of
    the interval where it is maximal): the node of the envelope active at each next belief."""
    N = actions.shape[1]
    bl = branch_lines(pomdp)
    mids = 0.5 * (xs[:-1] + xs[1:])[:, None, None]
    tab = np.stack([bl.s0, bl.s1 - bl.s0, bl.m0, bl.m1 - bl.m0]).reshape(4, N * 2, -1)  # [coef, (c, a), branch]
    g = tab[:, np.arange(N)[None, :] * 2 + actions]  # (coef, node, c, branch) for the node's action
    # branch probability z and next belief num / z at the witness, per (node, c, branch)
    z = g[0] + mids * g[1]
    num = g[2] + mids * g[3]
    ok = z > 0
    x = (num / np.where(ok, z, 1.0)).transpose(1, 2, 0)  # (c, branch, node): monotone along nodes,
    act = active_piece(xs, x.ravel()).reshape(x.shape).transpose(2, 0, 1)  # which makes the search fast
    return np.where(ok, act, -1)
