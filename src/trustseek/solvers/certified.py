"""Certified solutions of the two-level belief MDP: the certificate, the eq.-3 numerics and the
certified adaptive grid (docs/solvers.md, ``alpha`` and ``certified-grid``).

Both certified two-level solvers end with a computed value function (an envelope of alpha
vectors, or the linear interpolation of grid values) and an exact bound on its Bellman residual,
which bounds the optimal value from both sides.  :class:`CertifiedSolution` holds either and
reports thresholds with certified intervals: the optimal advantage Q(ask) - Q(autonomous) lies
within ±γ·gap of the computed one.

**The eq.-3 update (``paper``)** is not a Bayes filter: each branch E' has a probability linear in
x = P(trust = high) and a next belief x' = f0 (1 - x) + f1 x not rescaled by it, so Q of the
interpolated value V is piecewise quadratic and alpha vectors cannot represent it.  On each piece
between grid points, their preimages and the advantage's roots, T V - V is one quadratic, so its
supremum ε+ and infimum -ε- are exact (:func:`residual_pieces`), and
V - ε- / (1 - γ) <= W <= V + ε+ / (1 - γ).  :class:`CertifiedGridSolver` refines the grid where
the residual is large until (ε+ + ε-) / (1 - γ) meets the tolerance.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar, NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.optimize import brentq

from ..policies.alpha_vector import AlphaVectorPolicy
from ..policies.base import Policy
from ..policies.envelope import envelope_values, strip
from ..policies.grid_q import TABLE_POINTS, TrustAwarePolicy
from ..policies.regions import ask_intervals, threshold
from ..pomdp.problem import AssistancePOMDP
from ..vocab import ASK, AUTONOMOUS
from .base import Solver, one_blas_thread
from .numerics import howard

# --------------------------------------------------------------------------- the eq.-3 numerics


def paper_maps(pomdp: AssistancePOMDP) -> tuple[np.ndarray, np.ndarray]:
    """For each (c, a, e): branch probability p(x) = p0 (1-x) + p1 x and next belief
    f(x) = f0 (1-x) + f1 x, as arrays [c, a, e, 2]."""
    p0, p1, m0, m1 = pomdp.branches("paper").two_level()
    return np.stack([p0, p1], axis=-1), np.stack([m0, m1], axis=-1)


def paper_lines(pomdp: AssistancePOMDP, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """At beliefs x (n,): the rewards r[c, a, n], and for each (c, a, e) the branch probabilities
    p[c, a, e, n] and next beliefs f[c, a, e, n] of the eq.-3 update (each linear in x)."""

    def at(ends: np.ndarray) -> np.ndarray:
        return ends[..., 0, None] * (1 - x) + ends[..., 1, None] * x

    p, f = paper_maps(pomdp)
    return at(pomdp.expected_reward), at(p), at(f)


def paper_grid_values(
    pomdp: AssistancePOMDP, grid: np.ndarray, guess: np.ndarray | None = None, max_iter: int = 200
) -> np.ndarray:
    """W on a (possibly non-uniform) grid for the eq.-3 belief MDP with linear interpolation
    between grid points: Howard's policy iteration on the grid MDP.

    Every grid point has, per (C, a, E'), one next belief between two grid points, so the
    transition rows are stored as index and weight arrays; a policy's matrix is built
    directly in CSR form and evaluated from ``guess`` (:func:`~.numerics.policy_values`).
    The first policy is greedy in ``guess`` (in the reward without one); ties keep the
    current action, so the iteration terminates."""
    gamma, pc = pomdp.discount, pomdp.complexity_probs
    N, G = pomdp.n_complexity, len(grid)
    r, w, nx = paper_lines(pomdp, grid)
    nx = np.clip(nx, 0.0, 1.0)
    j = np.clip(np.searchsorted(grid, nx.ravel(), side="right").reshape(nx.shape) - 1, 0, G - 2)
    t = (nx - grid[j]) / (grid[j + 1] - grid[j])
    wl, wr = w * (1 - t), w * t  # weights of grid[j] and grid[j + 1]

    def q_of(V: np.ndarray) -> np.ndarray:  # [c, a, G]
        return r + gamma * (wl * V[j] + wr * V[j + 1]).sum(axis=2)

    indptr = np.arange(0, G * N * 4 + 1, N * 4)

    def chain(policy: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
        # the policy's rows: per (c, e), weights on grid[j] and grid[j + 1]
        jl = np.take_along_axis(j, policy[:, None, None, :], axis=1)[:, 0]  # [c, e, G]
        al = np.take_along_axis(wl, policy[:, None, None, :], axis=1)[:, 0] * (gamma * pc)[:, None, None]  # [c, e, G]
        ar = np.take_along_axis(wr, policy[:, None, None, :], axis=1)[:, 0] * (gamma * pc)[:, None, None]
        data = np.stack([al, ar], axis=-1).transpose(2, 0, 1, 3).reshape(-1)  # rows G, then (c, e, side)
        cols = np.stack([jl, jl + 1], axis=-1).transpose(2, 0, 1, 3).reshape(-1)
        return sp.csr_matrix((data, cols, indptr), shape=(G, G)), pc @ np.take_along_axis(r, policy[:, None, :], axis=1)[:, 0]

    policy = r.argmax(axis=1) if guess is None else q_of(guess).argmax(axis=1)  # [c, G]
    V = np.zeros(G) if guess is None else np.asarray(guess, dtype=float)
    return howard(policy, chain, q_of, V, max_iter)[0]


def paper_q(pomdp: AssistancePOMDP, values: np.ndarray, x: np.ndarray, grid: np.ndarray | None = None) -> np.ndarray:
    """Q[c, a, ...] at beliefs x for the eq.-3 belief MDP with W = linear interpolation of values
    (all (c, a, E') branches interpolated in one pass)."""
    grid = np.linspace(0.0, 1.0, len(values)) if grid is None else grid
    x = np.asarray(x, dtype=float)
    r, pr, nx = paper_lines(pomdp, x.reshape(-1))
    w = np.interp(nx.ravel(), grid, values).reshape(nx.shape)  # each row is monotone in x
    out = r + pomdp.discount * (pr * w).sum(axis=2)
    return out.reshape(out.shape[:2] + x.shape)


class Residual(NamedTuple):
    """The Bellman residual T V - V of an interpolated value: its supremum ε+ and minus its
    infimum ε- over [0, 1], and the pieces [lo, hi] with the residual's extrema on each."""

    eps_plus: float
    eps_minus: float
    lo: np.ndarray
    hi: np.ndarray
    sup: np.ndarray
    inf: np.ndarray


def residual_pieces(pomdp: AssistancePOMDP, grid: np.ndarray, values: np.ndarray) -> Residual:
    """The residual T V - V of V, the linear interpolation of ``values`` on ``grid``, for the eq.-3
    belief MDP: (ε+, ε-) = (sup, -inf) over [0, 1], with its pieces.  Exact up to rounding: the interval
    is cut at the grid points, their preimages under every belief map and the roots of every
    advantage Q(ask) - Q(autonomous), so that on each piece T V - V is a single quadratic."""
    f = paper_maps(pomdp)[1]
    N = pomdp.n_complexity
    cuts = [grid]
    for c in range(N):
        for a in range(2):
            for e in range(2):
                f0, f1 = f[c, a, e]
                if abs(f1 - f0) > 1e-15:
                    pre = (grid - f0) / (f1 - f0)
                    cuts.append(pre[(pre > 0) & (pre < 1)])
    pts = strip(np.unique(np.concatenate(cuts)), 1e-15)

    def coeffs(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[np.ndarray], list[np.ndarray]]:
        lo, hi = pts[:-1], pts[1:]
        mid = 0.5 * (lo + hi)
        w = hi - lo
        qp, qm = paper_q(pomdp, values, pts, grid), paper_q(pomdp, values, mid, grid)  # [c, a, n]
        vp, vm = np.interp(pts, grid, values), np.interp(mid, grid, values)
        qs = [qp[..., :-1], qm, qp[..., 1:]]  # at lo, mid, hi
        v = [vp[:-1], vm, vp[1:]]
        return lo, hi, mid, w, qs, v

    # pass 1: cut at the roots of each advantage
    lo, hi, mid, w, qs, v = coeffs(pts)
    roots = []
    for c in range(N):
        d = [q[c, ASK] - q[c, AUTONOMOUS] for q in qs]
        for rr in _quad_roots(d[0], d[1], d[2], w):
            ok = np.isfinite(rr)
            roots.append(mid[ok] + rr[ok])
    if roots:
        pts = strip(np.unique(np.concatenate([pts] + roots)), 1e-15)
        lo, hi, mid, w, qs, v = coeffs(pts)
    # pass 2: one quadratic per piece (the action active at the midpoint, per complexity)
    pc = pomdp.complexity_probs
    phi = []
    for k in range(3):
        q = qs[k]
        best = np.where(qs[1][:, ASK] > qs[1][:, AUTONOMOUS], q[:, ASK], q[:, AUTONOMOUS])  # [c, n]
        phi.append(pc @ best - v[k])
    sup, inf = _quad_extrema(phi[0], phi[1], phi[2], w)
    return Residual(float(np.max(sup)), float(-np.min(inf)), lo, hi, sup, inf)


def _quad_fit(y0: np.ndarray, y1: np.ndarray, y2: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Coefficients of y(u) = c0 + c1 u + c2 u^2 through (-w/2, y0), (0, y1), (w/2, y2)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        c1 = np.where(w > 0, (y2 - y0) / w, 0.0)
        c2 = np.where(w > 0, 2.0 * (y2 + y0 - 2.0 * y1) / (w * w), 0.0)
    return y1, c1, c2


def _quad_roots(y0: np.ndarray, y1: np.ndarray, y2: np.ndarray, w: np.ndarray) -> list[np.ndarray]:
    """Roots u in (-w/2, w/2) of the quadratic through three equally spaced values (nan if none)."""
    c0, c1, c2 = _quad_fit(y0, y1, y2, w)
    half = w / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        small = np.abs(c2) * half * half <= 1e-12 * (np.abs(c0) + np.abs(c1) * half + 1e-300)
        lin = np.where(small & (c1 != 0), -c0 / c1, np.nan)
        disc = c1 * c1 - 4 * c2 * c0
        sq = np.sqrt(np.where(disc >= 0, disc, np.nan))
        qq = -0.5 * (c1 + np.where(c1 >= 0, sq, -sq))
        r1 = np.where(small, lin, qq / c2)
        r2 = np.where(small, np.nan, np.where(qq != 0, c0 / qq, np.nan))
    return [np.where((r > -half) & (r < half), r, np.nan) for r in (r1, r2)]


def _quad_extrema(y0: np.ndarray, y1: np.ndarray, y2: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Max and min over [-w/2, w/2] of the quadratic through three equally spaced values."""
    c0, c1, c2 = _quad_fit(y0, y1, y2, w)
    half = w / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.where(c2 != 0, -c1 / (2 * c2), np.nan)
    inside = np.isfinite(u) & (np.abs(u) < half)
    uv = np.where(inside, u, 0.0)
    yv = np.where(inside, c0 + c1 * uv + c2 * uv * uv, y1)
    return np.maximum(np.maximum(y0, y2), yv), np.minimum(np.minimum(y0, y2), yv)


# --------------------------------------------------------------------------- certified solutions


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
        q = self._q(pomdp, np.asarray(x, dtype=float))
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


def policy_from_solution(sol: CertifiedSolution, pomdp: AssistancePOMDP, solver: str, target_gap: float | None = None) -> Policy:
    """Wrap a solution as a Policy with its certificate in ``info``: an AlphaVectorPolicy
    (alpha vectors) or a TrustAwarePolicy whose Q table is computed from the certified grid
    values."""
    q0 = sol.q_values(pomdp, np.array(float(pomdp.model.initial[-1])))
    low0 = float(q0.max(axis=-1) @ pomdp.complexity_probs)
    ths = sol.threshold_report(pomdp)
    info: dict[str, Any] = {
        "solver": solver,
        "method": sol.method,
        "iterations": sol.iterations,
        "bellman_residual": sol.gap * (1 - pomdp.discount),
        "error_bound": sol.gap,
        "seconds": sol.seconds,
        "discount": pomdp.discount,
        "certified_gap": sol.gap,  # the certificate: gap, bounds at the initial belief, thresholds
        "value_bounds_at_initial_belief": [low0, low0 + sol.gap],
        "thresholds": {k: v["threshold"] for k, v in ths.items()},
        "threshold_intervals": {k: v["interval"] for k, v in ths.items()},
        "target_gap": target_gap,
    }
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


# --------------------------------------------------------------------------- the certified adaptive grid


class CertifiedSolver(Solver):
    """A solver of certified two-level solutions: ``solve_bounds`` gives the solution, ``solve`` its
    policy, ``info`` holding the certificate."""

    trust_levels = 2

    @one_blas_thread()
    def solve(self, pomdp: AssistancePOMDP) -> Policy:
        return policy_from_solution(self.solve_bounds(pomdp), pomdp, self.name, self.tol)

    def solve_bounds(self, pomdp: AssistancePOMDP) -> CertifiedSolution:
        raise NotImplementedError


class CertifiedGridSolver(CertifiedSolver):
    """Certified solution of the eq.-3 belief MDP on an adaptively refined grid: its policy is a
    grid-Q policy from the certified value."""

    name = "certified-grid"
    belief_updates = ("paper",)
    instead: ClassVar[dict[str, str]] = {
        "trust_levels": "use the point solver (Bayes filter)",
        "belief_update": "the certified-grid solver certifies the eq.-3 update (belief update 'paper'); "
        "for the Bayes filter use the alpha solver",
    }

    grid = 1025  # the starting grid (refined adaptively) ...
    max_grid = 200_001  # ... up to this many points

    def __init__(self, belief_update: str = "paper", tol: float = 1e-6):
        self._targets(belief_update, tol)

    @one_blas_thread()
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
