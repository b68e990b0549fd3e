"""Numerics of the eq.-3 belief MDP (the ``paper`` update) for two trust levels.

Eq. 3 is not a Bayes filter: each branch E' has a probability linear in x = P(trust = high)
and a next belief x' = f0 (1 - x) + f1 x that is not rescaled by it.  With W the linear
interpolation V of values on a grid, Q(x, C, a) is then piecewise quadratic in x, which gives

* :func:`paper_grid_values` -- the values of the grid MDP (Howard's policy iteration on a
  possibly non-uniform grid);
* :func:`paper_q` -- Q of the interpolated values at any beliefs;
* :func:`paper_residual` -- the exact extrema of the Bellman residual T V - V over [0, 1],
  which certify V (see :mod:`.certified_grid`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from ..model.core import ASK, AUTONOMOUS
from ..pomdp.problem import AssistancePOMDP
from .numerics import improve, policy_values

__all__ = ["Residual", "paper_grid_values", "paper_maps", "paper_q", "paper_residual", "residual_pieces"]


def paper_maps(pomdp: AssistancePOMDP) -> tuple[np.ndarray, np.ndarray]:
    """For each (c, a, e): branch probability p(x) = p0 (1-x) + p1 x and next belief
    f(x) = f0 (1-x) + f1 x, as arrays [c, a, e, 2]."""
    p0, p1, m0, m1 = pomdp.branches("paper").two_level()
    return np.stack([p0, p1], axis=-1), np.stack([m0, m1], axis=-1)


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
    p, f = paper_maps(pomdp)
    R = pomdp.expected_reward
    gamma = pomdp.discount
    pc = pomdp.complexity_probs
    N, G = pomdp.n_complexity, len(grid)
    x = grid
    r = R[:, :, 0, None] * (1 - x) + R[:, :, 1, None] * x  # [c, a, G]
    w = p[..., 0, None] * (1 - x) + p[..., 1, None] * x  # [c, a, e, G] branch probabilities
    nx = np.clip(f[..., 0, None] * (1 - x) + f[..., 1, None] * x, 0.0, 1.0)  # next beliefs
    j = np.clip(np.searchsorted(grid, nx.ravel(), side="right").reshape(nx.shape) - 1, 0, G - 2)
    t = (nx - grid[j]) / (grid[j + 1] - grid[j])
    wl, wr = w * (1 - t), w * t  # weights of grid[j] and grid[j + 1]

    def q_of(V: np.ndarray) -> np.ndarray:  # [c, a, G]
        return r + gamma * (wl * V[j] + wr * V[j + 1]).sum(axis=2)

    policy = r.argmax(axis=1) if guess is None else q_of(guess).argmax(axis=1)  # [c, G]
    V = np.zeros(G) if guess is None else np.asarray(guess, dtype=float)
    indptr = np.arange(0, G * N * 4 + 1, N * 4)
    for _ in range(max_iter):
        # the policy's rows: per (c, e), weights on grid[j] and grid[j + 1]
        jl = np.take_along_axis(j, policy[:, None, None, :], axis=1)[:, 0]  # [c, e, G]
        al = np.take_along_axis(wl, policy[:, None, None, :], axis=1)[:, 0] * (gamma * pc)[:, None, None]  # [c, e, G]
        ar = np.take_along_axis(wr, policy[:, None, None, :], axis=1)[:, 0] * (gamma * pc)[:, None, None]
        data = np.stack([al, ar], axis=-1).transpose(2, 0, 1, 3).reshape(-1)  # rows G, then (c, e, side)
        cols = np.stack([jl, jl + 1], axis=-1).transpose(2, 0, 1, 3).reshape(-1)
        P = sp.csr_matrix((data, cols, indptr), shape=(G, G))
        rr = pc @ np.take_along_axis(r, policy[:, None, :], axis=1)[:, 0]
        V = policy_values(P, rr, V)
        new_policy = improve(q_of(V), policy, axis=1)
        if new_policy is None:
            break
        policy = new_policy
    return V


def paper_q(pomdp: AssistancePOMDP, values: np.ndarray, x: np.ndarray, grid: np.ndarray | None = None) -> np.ndarray:
    """Q[c, a, ...] at beliefs x for the eq.-3 belief MDP with W = linear interpolation of values
    (all (c, a, E') branches interpolated in one pass)."""
    grid = np.linspace(0.0, 1.0, len(values)) if grid is None else grid
    p, f = paper_maps(pomdp)
    R = pomdp.expected_reward
    gamma = pomdp.discount
    x = np.asarray(x, dtype=float)
    z = x.reshape(-1)
    pr = p[..., 0, None] * (1 - z) + p[..., 1, None] * z  # [c, a, e, n]
    nx = f[..., 0, None] * (1 - z) + f[..., 1, None] * z
    w = np.interp(nx.ravel(), grid, values).reshape(nx.shape)  # each row is monotone in z
    out = R[:, :, 0, None] * (1 - z) + R[:, :, 1, None] * z + gamma * (pr * w).sum(axis=2)
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


def paper_residual(pomdp: AssistancePOMDP, grid: np.ndarray, values: np.ndarray) -> tuple[float, float]:
    """(ε+, ε-) = (sup, -inf) over x in [0, 1] of (T V - V)(x) for the eq.-3 belief MDP, where V
    is the linear interpolation of ``values`` on ``grid`` (see :func:`residual_pieces`)."""
    res = residual_pieces(pomdp, grid, values)
    return res.eps_plus, res.eps_minus


def residual_pieces(pomdp: AssistancePOMDP, grid: np.ndarray, values: np.ndarray) -> Residual:
    """The residual of :func:`paper_residual` with its pieces.  Exact up to rounding: the interval
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
    pts = np.unique(np.concatenate(cuts))
    pts = pts[np.concatenate([[True], np.diff(pts) > 1e-15])]
    pts[0], pts[-1] = 0.0, 1.0

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
        pts = np.unique(np.concatenate([pts] + roots))
        pts = pts[np.concatenate([[True], np.diff(pts) > 1e-15])]
        pts[0], pts[-1] = 0.0, 1.0
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
    out = []
    for r in (r1, r2):
        out.append(np.where((r > -half) & (r < half), r, np.nan))
    return out


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
