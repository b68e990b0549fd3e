"""Alpha-vector solver with certified bounds, for two trust levels.

The complexity and the last experience are observed, so the belief that matters
is one number, x = P(trust = high), and the value over P(C) is

    W(x) = Σ_C P(C) max_a Q(x, C, a),
    Q(x, C, a) = r(x, C, a) + γ Σ_branch P(branch | x, C, a) W(x'_branch).

``bayes`` update (the exact filter).  W is piecewise linear and convex, the
maximum of *alpha vectors* (α(low), α(high)), i.e. lines in x.  In one dimension
the exact Bellman backup of such a function is computed with upper envelopes
(a branch's envelope of projected vectors, cross-sums over branches and over
complexities, the maximum over actions), so no linear programs are needed.
:class:`AlphaSolver` runs policy iteration on finite-state controllers: every
vector of the exact backup becomes a controller node (an action per complexity
and a successor node per (C, o, E')), the successors are re-pointed to the best
node at the node's witness belief, and the controller is evaluated exactly by
one linear solve.  Every vector kept is the value of an executable policy, so
L(x) = max_α α·x is a certified lower bound on W, and T L ≥ L.  The contraction
of the Bellman operator T then gives the upper bound

    W ≤ T L + γ δ / (1 - γ),  δ = sup_x (T L - L)(x)  (computed exactly),

so the certified gap is δ / (1 - γ).  The grid solver's interpolated value is a
second, independent upper bound (linear interpolation over-estimates a convex
function); the reported gap uses the smaller of the two.

``paper`` update (eq. 3).  It is not a Bayes filter: the branch probability is
linear in x while the next belief x' = x P(T'=high | T=high) + (1-x) P(T'=high | T=low)
is not rescaled by it, so Q contains products (linear × piecewise linear) and W is
neither linear nor convex.  Alpha vectors cannot represent it.  Instead the
solver certifies the grid solution V (linear interpolation on G points): on every
piece between grid points, their preimages under the belief maps and the roots of
the advantage, (T V - V)(x) is one quadratic, so its supremum ε+ and infimum
-ε- over the whole of [0, 1] are computed exactly, and

    V - ε- / (1 - γ)  ≤  W  ≤  V + ε+ / (1 - γ).

The grid is refined until the gap (ε+ + ε-) / (1 - γ) meets the tolerance.

Thresholds come from the lower-bound Q, with an uncertainty interval: the
advantage D = Q(ask) - Q(autonomous) of the optimal Q lies within ±γ·gap of the
computed one, so the threshold lies where |D| ≤ γ·gap.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import brentq

from ..model.core import ASK, AUTONOMOUS
from ..policies.alpha_vector import AlphaVectorPolicy
from ..policies.envelope import WIDTH_EPS as _WIDTH_EPS
from ..policies.envelope import active_piece as _active
from ..policies.envelope import envelope, envelope_values
from ..policies.grid_q import TrustAwarePolicy
from ..pomdp.belief import to_vector
from ..pomdp.problem import AssistancePOMDP
from ..vocab import check_belief_update

POLICY_TABLE_POINTS = 4001  # uniform Q table of the policy for the paper update


# --------------------------------------------------------------------------- 1-D envelopes


def _union(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Sorted union of two sorted breakpoint arrays (exact duplicates removed)."""
    u = np.concatenate([a, b])
    u.sort(kind="mergesort")
    return u[np.concatenate([[True], u[1:] != u[:-1]])]


def _cross_sum(xs1: np.ndarray, xs2: np.ndarray):
    """Pieces of the sum of two envelopes: breakpoints and the active index in each."""
    u = _union(xs1, xs2)
    keep = np.concatenate([[True], np.diff(u) > _WIDTH_EPS])
    u = u[keep]
    if u[-1] < 1.0:
        u[-1] = 1.0
    if len(u) < 2:
        u = np.array([0.0, 1.0])
    mids = 0.5 * (u[:-1] + u[1:])
    return u, _active(xs1, mids), _active(xs2, mids)


@dataclass
class Backup:
    """The exact Bellman backup T L of a set of alpha vectors (two trust levels).

    ``vectors``/``xs``: the envelope of T L; ``actions[n, c]`` and ``successors[n, c, o, e]``
    (index into the input vectors, -1 for an impossible branch) say how each vector is
    obtained.  ``q[c][a]`` = (vectors, xs) of the envelope of Q(x, C=c, a).
    """

    vectors: np.ndarray
    xs: np.ndarray
    actions: np.ndarray
    successors: np.ndarray
    q: list[list[tuple[np.ndarray, np.ndarray]]]


def _branch_maps(pomdp: AssistancePOMDP):
    """Per (c, a, branch): the branch matrices M[t, u] = P(o, E', T'=u | T=t, C=c, a) and the
    coefficients of the monotone belief map x -> x'(x) = (m0 (1-x) + m1 x) / (s0 (1-x) + s1 x),
    with its range [lo, hi] and whether it moves at all."""
    branches = pomdp.branches("bayes")
    s0, s1, m0, m1 = branches.two_level()
    possible = (s0 + s1) > 0  # [c, a, b]
    with np.errstate(divide="ignore", invalid="ignore"):
        y0 = np.where(s0 > 0, m0 / np.where(s0 > 0, s0, 1.0), np.nan)
        y1 = np.where(s1 > 0, m1 / np.where(s1 > 0, s1, 1.0), np.nan)
    moving = (s0 > 0) & (s1 > 0) & (np.abs(y1 - y0) > 1e-15)  # the map is not constant
    return branches.move, possible, s0, s1, m0, m1, np.fmin(y0, y1), np.fmax(y0, y1), moving


def _strip(u: np.ndarray) -> np.ndarray:
    """Sorted breakpoints with pieces narrower than _WIDTH_EPS removed, from 0 to 1."""
    u = u[np.concatenate([[True], np.diff(u) > _WIDTH_EPS])]
    u[0], u[-1] = 0.0, 1.0
    return u


def max_of(v1, xs1, v2, xs2):
    """The upper envelope of two envelopes: (vectors, breakpoints, source (0/1), index)."""
    u = _union(xs1, xs2)
    mids = 0.5 * (u[:-1] + u[1:])
    i1, i2 = _active(xs1, mids), _active(xs2, mids)
    a, b = v1[i1], v2[i2]
    d0 = a[:, 0] - b[:, 0]
    ds = (a[:, 1] - a[:, 0]) - (b[:, 1] - b[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(ds != 0, -d0 / ds, np.nan)
    inside = (r > u[:-1] + _WIDTH_EPS) & (r < u[1:] - _WIDTH_EPS)
    if np.any(inside):
        u = _union(u, r[inside])  # the crossings lie strictly inside their pieces: still sorted
    u = _strip(u)
    mids = 0.5 * (u[:-1] + u[1:])
    i1, i2 = _active(xs1, mids), _active(xs2, mids)
    val1 = v1[i1, 0] * (1 - mids) + v1[i1, 1] * mids
    val2 = v2[i2, 0] * (1 - mids) + v2[i2, 1] * mids
    src = (val2 > val1).astype(np.int64)
    idx = np.where(src == 1, i2, i1)
    vec = np.where(src[:, None] == 1, v2[i2], v1[i1])
    # merge consecutive pieces of the same line
    new = np.concatenate([[True], (src[1:] != src[:-1]) | (idx[1:] != idx[:-1])])
    return vec[new], np.concatenate([u[:-1][new], [1.0]]), src[new], idx[new]


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
    N = pomdp.n_complexity
    M, possible, s0, s1, m0, m1, lo, hi, moving = _branch_maps(pomdp)
    n_branch = M.shape[2]
    n_o, n_e = pomdp.kernel.shape[3], pomdp.kernel.shape[4]
    ks = xs[1:-1]
    if len(ks):
        with np.errstate(divide="ignore", invalid="ignore"):
            pre = (m0[..., None] - ks * s0[..., None]) / (ks * (s1 - s0)[..., None] - (m1 - m0)[..., None])
        inside = moving[..., None] & possible[..., None] & (ks > lo[..., None]) & (ks < hi[..., None])
    q_env: list[list[tuple[np.ndarray, np.ndarray]]] = []
    w_vecs = w_xs = w_act = w_succ = None
    for c in range(N):
        per_a = []
        tags = []
        for a in range(2):
            bs = np.nonzero(possible[c, a])[0]
            u = np.concatenate([[0.0, 1.0], pre[c, a][inside[c, a]]]) if len(ks) else np.array([0.0, 1.0])
            u.sort()
            u = _strip(u)
            mids = 0.5 * (u[:-1] + u[1:])
            acc_v = np.broadcast_to(R[c, a], (len(mids), 2)).copy()
            acc_t = np.full((len(mids), n_branch), -1, dtype=np.int64)
            if len(bs):
                sb0, sb1 = s0[c, a, bs][:, None], s1[c, a, bs][:, None]
                num = m0[c, a, bs][:, None] * (1 - mids) + m1[c, a, bs][:, None] * mids
                den = sb0 * (1 - mids) + sb1 * mids
                y = num / den  # (branches, pieces): the next belief at each piece's middle
                act = _active(xs, y.ravel()).reshape(y.shape)
                # Σ_branch M_b α_act  (vectors of L projected through each branch), as one product
                lines = vecs[act.T].reshape(len(mids), -1)  # (pieces, (branch, u))
                acc_v += lines @ (gamma * M[c, a, bs]).transpose(0, 2, 1).reshape(-1, 2)
                acc_t[:, bs] = remap[act].T
            per_a.append((acc_v, u))
            tags.append(acc_t.reshape(len(mids), n_o, n_e))
        q_env.append(per_a)
        cv, xs_c, src, idx = max_of(per_a[0][0], per_a[0][1], per_a[1][0], per_a[1][1])
        ca = src
        cs = np.where(src[:, None, None] == 1, tags[1][np.minimum(idx, len(tags[1]) - 1)], tags[0][np.minimum(idx, len(tags[0]) - 1)])
        pc = pomdp.complexity_probs[c]
        if w_vecs is None:
            w_vecs, w_xs = pc * cv, xs_c
            w_act, w_succ = ca[:, None], cs[:, None]
        else:
            u, i1, i2 = _cross_sum(w_xs, xs_c)
            w_vecs = w_vecs[i1] + pc * cv[i2]
            w_act = np.concatenate([w_act[i1], ca[i2][:, None]], axis=1)
            w_succ = np.concatenate([w_succ[i1], cs[i2][:, None]], axis=1)
            w_xs = u
    return Backup(w_vecs, w_xs, w_act.astype(np.int64), w_succ, q_env)


def thin(vecs: np.ndarray, xs: np.ndarray, eta: float) -> tuple[np.ndarray, np.ndarray]:
    """Drop envelope lines whose removal lowers the envelope by less than ``eta`` (never two
    neighbours at once).  The result is below the input by at most ``eta``: still a lower bound."""
    keep = _thin_mask(vecs, eta)
    if keep.all():
        return vecs, xs
    return _refit(vecs, xs, np.nonzero(keep)[0])[:2]


def _thin_mask(vecs: np.ndarray, eta: float) -> np.ndarray:
    """The lines of an envelope that :func:`thin` keeps (a boolean mask)."""
    keep = np.ones(len(vecs), dtype=bool)
    if len(vecs) < 3 or eta <= 0:
        return keep
    a = vecs[:, 0]
    b = vecs[:, 1] - vecs[:, 0]
    x = (a[:-2] - a[2:]) / (b[2:] - b[:-2])  # where the neighbours of line k meet
    err = (a[1:-1] + b[1:-1] * x) - (a[:-2] + b[:-2] * x)
    keep[1:-1] = ~((err < eta) & (np.arange(1, len(vecs) - 1) % 2 == 0))
    return keep


def _refit(vecs: np.ndarray, xs: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The envelope of the kept lines (indices, in order) of an envelope: (lines, breakpoints,
    their indices in ``vecs``).  No two dropped lines are neighbours, so the kept lines stay in
    order and meet their new neighbours inside [0, 1]; degenerate cases are re-enveloped."""
    if len(keep) == len(vecs):
        return vecs, xs, keep
    nv = vecs[keep]
    a, b = nv[:, 0], nv[:, 1] - nv[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        nxs = np.concatenate([[0.0], (a[:-1] - a[1:]) / (b[1:] - b[:-1]), [1.0]])
    if not (np.all(np.isfinite(nxs)) and np.all(np.diff(nxs) > 0)):  # parallel neighbours
        idx, nxs = envelope(nv)
        return nv[idx], nxs, keep[idx]
    return nv, nxs, keep


def sup_difference(v1, xs1, v2, xs2) -> float:
    """sup over [0, 1] of env1(x) - env2(x) (both piecewise linear: attained at a breakpoint)."""
    return difference_extrema(v1, xs1, v2, xs2)[0]


def difference_extrema(v1, xs1, v2, xs2) -> tuple[float, float]:
    """(sup, inf) over [0, 1] of env1(x) - env2(x), both attained at a breakpoint of one of them."""
    pts = _union(xs1, xs2)
    d = envelope_values(v1, xs1, pts) - envelope_values(v2, xs2, pts)
    return float(np.max(d)), float(np.min(d))


# --------------------------------------------------------------------------- controllers


def evaluate_controller(
    pomdp: AssistancePOMDP, actions: np.ndarray, successors: np.ndarray, guess: np.ndarray | None = None, rtol: float = 1e-15
) -> np.ndarray:
    """Exact value α[n, t] of a finite-state controller: node n takes actions[n, c] in
    complexity c and moves to successors[n, c, o, e] after (o, E').  Works for any number
    of trust levels.  Solves (I - γ P) α = r: dense for small controllers, a sparse direct
    solve for medium ones without a guess, otherwise BiCGSTAB (started from ``guess``, checked,
    with a direct fallback).  P is built directly in CSR form (rows (n, t) in order, the entries of a
    row in (c, o, E', u) order), so no sorting or duplicate summing is needed."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    K = pomdp.kernel  # [c, a, t, o, e, u]
    R = pomdp.expected_reward
    pc = pomdp.complexity_probs
    gamma = pomdp.discount
    n, N = actions.shape
    k = pomdp.n_trust
    cidx = np.arange(N)[None, :]
    rhs = np.einsum("c,nct->nt", pc, R[cidx, actions])  # (n, k)
    # weights [n, c, t, o, e, u] viewed as rows (n, t) with slots (c, o, e, u); zero slots
    # (impossible branches, zero kernel entries, no successor) are dropped
    Kg = K * (gamma * pc)[:, None, None, None, None, None]
    W = np.moveaxis(Kg[cidx, actions], 2, 1)  # (n, t, c, o, e, u)
    nz = (W != 0) & (successors >= 0)[:, None, :, :, :, None]
    data = W[nz]
    cols = (successors.astype(np.int64) * k)[:, None, :, :, :, None] + np.arange(k)
    cols = np.broadcast_to(cols, W.shape)[nz]
    size = n * k
    counts = nz.reshape(size, -1).sum(axis=1)
    rows = np.repeat(np.arange(size), counts)
    b = rhs.reshape(-1)
    if size <= 200:  # small: dense
        D = np.zeros((size, size))
        np.add.at(D, (rows, cols), -data)
        D[np.diag_indices(size)] += 1.0
        return np.linalg.solve(D, b).reshape(n, k)
    indptr = np.zeros(size + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    P = sp.csr_matrix((data, cols, indptr), shape=(size, size))
    if guess is None and size <= 600:
        A = sp.identity(size, format="csc") - P.tocsc()
        return np.asarray(spla.spsolve(A, b)).reshape(n, k)
    scale = max(1.0, float(np.max(np.abs(b))))
    x0 = np.zeros(size) if guess is None else guess.reshape(-1).astype(float)
    x = _bicgstab(lambda y: y - P @ y, b, x0, max(rtol, 1e-15) * scale * np.sqrt(size), 2000)
    if not np.all(np.isfinite(x)) or np.max(np.abs(x - P @ x - b)) > max(1e-10, 10 * rtol) * scale:
        x = spla.spsolve(sp.identity(size, format="csc") - P.tocsc(), b)
    return np.asarray(x).reshape(n, k)


def _bicgstab(matvec, b: np.ndarray, x: np.ndarray, tol: float, maxiter: int) -> np.ndarray:
    """Plain BiCGSTAB (van der Vorst) on a matvec; stops when ‖b - A x‖₂ <= tol."""
    r = b - matvec(x)
    rhat = r.copy()
    rho = alpha = omega = 1.0
    v = p = np.zeros_like(b)
    for _ in range(maxiter):
        if np.sqrt(r @ r) <= tol:
            break
        rho_new = rhat @ r
        if rho_new == 0.0:
            break
        beta = (rho_new / rho) * (alpha / omega)
        p = r + beta * (p - omega * v)
        v = matvec(p)
        den = rhat @ v
        if den == 0.0:
            break
        alpha = rho_new / den
        s = r - alpha * v
        if np.sqrt(s @ s) <= tol:
            x = x + alpha * p
            break
        t = matvec(s)
        tt = t @ t
        if tt == 0.0:
            x = x + alpha * p
            break
        omega = (t @ s) / tt
        x = x + alpha * p + omega * s
        r = s - omega * t
        rho = rho_new
    return x


def _one_node_controllers(pomdp: AssistancePOMDP, limit: int = 64) -> np.ndarray:
    """Values of the memoryless controllers 'always take action a_C in complexity C' (one
    controller of independent self-looping nodes, evaluated by one solve)."""
    N = pomdp.n_complexity
    combos = list(itertools.product((AUTONOMOUS, ASK), repeat=N))
    if len(combos) > limit:
        combos = [tuple([AUTONOMOUS] * N), tuple([ASK] * N)]
    n = len(combos)
    acts = np.array(combos, dtype=np.int64).reshape(n, N)
    n_o, n_e = pomdp.kernel.shape[3], pomdp.kernel.shape[4]
    succ = np.broadcast_to(np.arange(n)[:, None, None, None], (n, N, n_o, n_e)).copy()
    return evaluate_controller(pomdp, acts, succ)


def _grid_controller(pomdp: AssistancePOMDP, points: int, base: np.ndarray | None = None, rounds: int = 1) -> np.ndarray:
    """Values of a controller on a few beliefs: greedy actions of a one-step lookahead on the
    values known so far (first the one-node controllers'), successors = the nearest belief of
    the set (a cheap start); ``rounds`` times, each round looking ahead on the last values."""
    if points < 2:
        return np.zeros((0, 2))
    base = _one_node_controllers(pomdp) if base is None else base
    x = np.linspace(0.0, 1.0, points)
    b = np.stack([1 - x, x], axis=1)
    M = pomdp.branches("bayes").move  # [c, a, (o, e), t, u]
    N = pomdp.n_complexity
    nbs = [np.einsum("nt,abtu->nabu", b, M[c]).reshape(points, 2, 2, 2, 2) for c in range(N)]  # (n, a, o, e, u) per c
    ev = np.zeros((0, 2))
    for _ in range(max(1, rounds)):
        look = np.vstack([base, ev])
        guess = look[(b @ look.T).argmax(axis=1)]  # the best known vector at each belief
        acts = np.zeros((points, N), dtype=np.int64)
        succ = np.full((points, N, 2, 2), -1, dtype=np.int64)
        for c, nb in enumerate(nbs):
            z = nb.sum(axis=-1)
            val = np.where(z > 0, (nb @ look.T).max(axis=-1), 0.0)
            q = b @ pomdp.expected_reward[c].T + pomdp.discount * val.sum(axis=(2, 3))
            acts[:, c] = q.argmax(axis=1)
            na = nb[np.arange(points), acts[:, c]]  # (n, o, e, u)
            za = na.sum(axis=-1)
            nx = np.where(za > 0, na[..., 1] / np.where(za > 0, za, 1.0), 0.0)
            succ[:, c] = np.where(za > 0, np.rint(nx * (points - 1)).astype(np.int64), -1)
        ev = evaluate_controller(pomdp, acts, succ, guess=guess, rtol=1e-11)
    return ev


def _repoint(pomdp: AssistancePOMDP, vecs: np.ndarray, xs: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """Successors of each node (a vector of the envelope) at its witness belief (the middle of
    the interval where it is maximal): the node of the envelope active at each next belief."""
    n, N = actions.shape
    n_o, n_e = pomdp.kernel.shape[3], pomdp.kernel.shape[4]
    _, _, s0, s1, m0, m1, _, _, _ = _branch_maps(pomdp)
    mids = 0.5 * (xs[:-1] + xs[1:])[:, None, None]
    tab = np.stack([s0, s1 - s0, m0, m1 - m0]).reshape(4, N * 2, -1)  # [coef, (c, a), branch]
    g = tab[:, np.arange(N)[None, :] * 2 + actions]  # (coef, node, c, branch) for the node's action
    # branch probability z and next belief num / z at the witness, per (node, c, branch)
    z = g[0] + mids * g[1]
    num = g[2] + mids * g[3]
    ok = z > 0
    x = (num / np.where(ok, z, 1.0)).transpose(1, 2, 0)  # (c, branch, node): monotone along nodes,
    act = _active(xs, x.ravel()).reshape(x.shape).transpose(2, 0, 1)  # which makes the search fast
    return np.where(ok, act, -1).reshape(n, N, n_o, n_e)


# --------------------------------------------------------------------------- the solver


@dataclass
class AlphaSolution:
    """Certified bounds for the two-level belief MDP."""

    belief_update: str
    method: str
    lower: tuple[np.ndarray, np.ndarray] | None  # (vectors, xs) of L (bayes)
    q: list[list[tuple[np.ndarray, np.ndarray]]] | None  # Q envelopes of T L (bayes)
    gap: float  # certified sup_x (U - L)(x)
    iterations: int
    seconds: float
    history: list[float] = field(default_factory=list)  # certified gap per iteration
    grid_solution: Any = None  # GridSolution used (paper update) or as an extra upper bound
    residuals: tuple[float, float] = (0.0, 0.0)  # (sup, -inf) of T V - V for the bounded function V

    def advantage(self, pomdp: AssistancePOMDP, x: np.ndarray, c: int) -> np.ndarray:
        """D(x) = Q(x, C=c, ask) - Q(x, C=c, autonomous) of the computed Q."""
        x = np.asarray(x, dtype=float)
        if self.q is not None:
            qa = [envelope_values(v, xs, x) for v, xs in self.q[c]]
            return qa[ASK] - qa[AUTONOMOUS]
        g, v = self.grid_solution
        q = _paper_q(pomdp, v, x, g)
        return q[c, ASK] - q[c, AUTONOMOUS]

    def value(self, pomdp: AssistancePOMDP, x) -> np.ndarray:
        """Lower bound on W(x) (certified)."""
        x = np.asarray(x, dtype=float)
        if self.lower is not None:
            return envelope_values(self.lower[0], self.lower[1], x) - self.residuals[1] / (1 - pomdp.discount)
        g, v = self.grid_solution
        return np.interp(x, g, v) - self.residuals[1] / (1 - pomdp.discount)

    def q_values(self, pomdp: AssistancePOMDP, x) -> np.ndarray:
        """Lower bounds on Q(x, C, a); shape (..., N, 2)."""
        x = np.asarray(x, dtype=float)
        gam = pomdp.discount
        if self.q is not None:
            return np.stack(
                [np.stack([envelope_values(v, xs, x) for v, xs in per_a], axis=-1) for per_a in self.q], axis=-2
            ) - gam * self.residuals[1] / (1 - gam)
        g, v = self.grid_solution
        q = _paper_q(pomdp, v, x, g) - gam * self.residuals[1] / (1 - gam)
        return np.moveaxis(q, (0, 1), (-2, -1))

    def threshold_report(self, pomdp: AssistancePOMDP, points: int = 4001) -> dict[str, dict[str, Any]]:
        """Per complexity: the threshold (None = never asks, 1.0 = always asks, nan = the ask
        region is not an interval [0, θ)) and its certified uncertainty interval."""
        margin = pomdp.discount * self.gap
        grid = np.linspace(0.0, 1.0, points)
        if self.q is not None:
            pts = [np.union1d(grid, np.union1d(self.q[c][0][1], self.q[c][1][1])) for c in range(pomdp.n_complexity)]
        else:
            pts = [grid] * pomdp.n_complexity
        out = {}
        for c, cn in enumerate(pomdp.complexities):
            x = pts[c]

            def f(z, shift=0.0, c=c):
                return float(self.advantage(pomdp, np.array([z]), c)[0]) - shift

            d = self.advantage(pomdp, x, c)
            ask = d > 0
            if not np.any(ask):
                out[cn] = {"threshold": None, "interval": None, "ask_intervals": []}
                continue
            changes = np.nonzero(ask[1:] != ask[:-1])[0]
            roots = [brentq(f, x[i], x[i + 1], xtol=1e-15) if d[i] != d[i + 1] else float(x[i]) for i in changes]
            edges = ([0.0] if ask[0] else []) + roots + ([1.0] if ask[-1] else [])
            ivs = [(float(edges[2 * k]), float(edges[2 * k + 1])) for k in range(len(edges) // 2)]
            if len(ivs) == 1 and ask[0]:
                th = ivs[0][1]
                lo = _bracket(f, x, d, th, +margin, left=True)
                hi = _bracket(f, x, d, th, -margin, left=False)
                out[cn] = {"threshold": th, "interval": [lo, hi], "ask_intervals": ivs}
            else:
                out[cn] = {"threshold": float("nan"), "interval": None, "ask_intervals": ivs}
        return out


def _bracket(f, x, d, th, level, left: bool) -> float:
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


class AlphaSolver:
    """Certified solver for two trust levels (``bayes``: alpha vectors; ``paper``: certified grid)."""

    def __init__(
        self,
        belief_update: str = "bayes",
        tol: float = 1e-6,
        method: str = "policy-iteration",
        max_iter: int = 2000,
        upper_grid: int = 201,
        grid: int = 1025,  # starting grid of the paper update (refined adaptively)
        max_grid: int = 200_001,
        thin: float = 0.1,
        seed_points: int = 257,
        seed_rounds: int = 1,
    ):
        check_belief_update(belief_update)
        if method not in ("policy-iteration", "value-iteration"):
            raise ValueError(f"unknown method {method!r}; expected 'policy-iteration' or 'value-iteration'")
        if not tol > 0:
            raise ValueError(f"tol must be positive, got {tol}")
        self.belief_update = belief_update
        self.tol = float(tol)
        self.method = method
        self.max_iter = int(max_iter)
        self.upper_grid = int(upper_grid)
        self.grid = int(grid)
        self.max_grid = int(max_grid)
        self.seed_points = int(seed_points)  # beliefs of the starting controller
        self.seed_rounds = int(seed_rounds)  # its rounds of greedy improvement
        self.thin = float(thin)  # lines worth less than thin * tol * (1 - γ) are dropped from L

    def _check(self, pomdp: AssistancePOMDP) -> None:
        if pomdp.n_trust != 2:
            raise ValueError(
                f"the alpha solver handles two trust levels; this model has {pomdp.n_trust}. "
                "Use the point solver (--solver point) for more trust levels."
            )

    def solve(self, pomdp: AssistancePOMDP):
        """The optimal policy: an :class:`AlphaVectorPolicy` (bayes) or a certified
        TrustAwarePolicy on a fine grid (paper); ``info`` holds the certificate."""
        sol = self.solve_bounds(pomdp)
        return policy_from_solution(sol, pomdp, self.tol)

    def solve_bounds(self, pomdp: AssistancePOMDP) -> AlphaSolution:
        self._check(pomdp)
        if self.belief_update == "bayes":
            return self._solve_bayes(pomdp)
        return self._solve_paper(pomdp)

    # -- bayes ---------------------------------------------------------------
    def _solve_bayes(self, pomdp: AssistancePOMDP) -> AlphaSolution:
        t0 = time.perf_counter()
        gamma = pomdp.discount
        base = _one_node_controllers(pomdp)
        vecs = np.vstack([base, _grid_controller(pomdp, self.seed_points, base, self.seed_rounds)])
        idx, xs = envelope(vecs)
        vecs = vecs[idx]
        history: list[float] = []
        it = 0
        gap = np.inf
        eta = self.thin * self.tol * (1 - gamma)
        while True:
            vecs, xs = thin(vecs, xs, eta)
            bk = exact_backup(pomdp, vecs, xs)
            sup, inf = difference_extrema(bk.vectors, bk.xs, vecs, xs)
            delta = max(0.0, sup)
            # L is made of policy values, so T L >= L up to rounding and thinning; measure it too
            below = max(0.0, -inf)
            gap = (delta + below) / (1 - gamma)
            history.append(gap)
            if gap <= self.tol or it >= self.max_iter:
                break
            it += 1
            # every vector of the backup is the value of "act, then follow a node of L"
            new = [vecs, bk.vectors]
            if self.method == "policy-iteration":
                # the controller's nodes: the vectors of T L, less those worth under eta
                keep = np.nonzero(_thin_mask(bk.vectors, eta))[0]
                nodes, nxs, keep = _refit(bk.vectors, bk.xs, keep)
                succ = _repoint(pomdp, nodes, nxs, bk.actions[keep])
                ev = evaluate_controller(pomdp, bk.actions[keep], succ, guess=nodes, rtol=1e-11)
                if np.all(np.isfinite(ev)):
                    new.append(ev)
            # L <- the upper envelope of L, T L and the controller's values (one sort by slope)
            allv = np.vstack(new)
            idx, xs = envelope(allv)
            vecs = allv[idx]
        grid_sol = None
        if self.upper_grid and gap > self.tol:
            # the grid solver's interpolated value: an independent upper bound (V is convex)
            from .grid import GridSolver

            grid_sol = GridSolver(grid=self.upper_grid, belief_update="bayes").solve_grid(pomdp)
            up_grid = grid_sol.value @ pomdp.complexity_probs + grid_sol.error_bound
            up_alpha = lambda z: envelope_values(bk.vectors, bk.xs, z) + gamma * (delta + below) / (1 - gamma)  # noqa: E731
            # sup of min(U_alpha, U_grid) - L: all three are piecewise linear between these points
            pts = np.union1d(np.union1d(xs, bk.xs), grid_sol.grid)
            up = np.minimum(up_alpha(pts), np.interp(pts, grid_sol.grid, up_grid))
            gap = min(gap, float(np.max(up - envelope_values(vecs, xs, pts))) + below / (1 - gamma))
        return AlphaSolution(
            belief_update="bayes",
            method=self.method,
            lower=(vecs, xs),
            q=bk.q,
            gap=float(gap),
            iterations=it,
            seconds=time.perf_counter() - t0,
            history=history,
            grid_solution=grid_sol,
            residuals=(delta, below),  # sup(T L - L), sup(L - T L)
        )

    # -- paper ---------------------------------------------------------------
    def _solve_paper(self, pomdp: AssistancePOMDP) -> AlphaSolution:
        t0 = time.perf_counter()
        gamma = pomdp.discount
        grid = np.linspace(0.0, 1.0, self.grid)
        history = []
        values = None
        target = self.tol * (1 - gamma) / 2  # residual allowed on each side
        while True:
            values = paper_grid_values(pomdp, grid, values)
            eps_plus, eps_minus, lo, hi, sup, inf = paper_residual(pomdp, grid, values, pieces=True)
            gap = (max(eps_plus, 0.0) + max(eps_minus, 0.0)) / (1 - gamma)
            history.append(gap)
            if gap <= self.tol or len(grid) >= self.max_grid:
                break
            # refine where the residual is large: split those cells into 8 parts, or up to 64
            # where the residual is far above the budget (the interpolation error is first order
            # at the kinks of W, so halving a cell roughly halves its residual)
            over = np.maximum(sup, -inf) / (0.5 * target)
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
            grid, values = grid[order], values[order]
        return AlphaSolution(
            belief_update="paper",
            method="certified-adaptive-grid",
            lower=None,
            q=None,
            gap=float(gap),
            iterations=len(history),
            seconds=time.perf_counter() - t0,
            history=history,
            grid_solution=(grid, values),
            residuals=(max(eps_plus, 0.0), max(eps_minus, 0.0)),
        )


def paper_grid_values(pomdp: AssistancePOMDP, grid: np.ndarray, guess: np.ndarray | None = None, max_iter: int = 200) -> np.ndarray:
    """W on a (possibly non-uniform) grid for the eq.-3 belief MDP with linear interpolation
    between grid points: Howard's policy iteration on the grid MDP.

    Every grid point has, per (C, a, E'), one next belief between two grid points, so the
    transition rows are stored as index and weight arrays; a policy's matrix is built
    directly in CSR form and evaluated by BiCGSTAB started from ``guess`` (checked, with a
    direct fallback).  The first policy is greedy in ``guess`` (in the reward without one);
    ties keep the current action, so the iteration terminates."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    p, f = _paper_maps(pomdp)
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

    def q_of(V):  # [c, a, G]
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
        scale = max(1.0, float(np.max(np.abs(rr))))
        V = _bicgstab(lambda y: y - P @ y, rr, V, 1e-14 * float(np.sqrt(rr @ rr)) + 1e-13 * scale, 10_000)
        if not np.all(np.isfinite(V)) or np.max(np.abs(V - P @ V - rr)) > 1e-9 * scale:
            V = np.asarray(spla.spsolve(sp.identity(G, format="csc") - P.tocsc(), rr))
        q = q_of(V)
        cur = np.take_along_axis(q, policy[:, None, :], axis=1)[:, 0]
        better = q.max(axis=1) > cur + 1e-12 * (1 + np.abs(cur))
        if not np.any(better):
            break
        policy = np.where(better, q.argmax(axis=1), policy)
    return V


# --------------------------------------------------------------------------- paper update: exact residual


def _paper_maps(pomdp: AssistancePOMDP):
    """For each (c, a, e): branch probability p(x) = p0 (1-x) + p1 x and next belief
    f(x) = f0 (1-x) + f1 x, as arrays [c, a, e, 2]."""
    p0, p1, m0, m1 = pomdp.branches("paper").two_level()
    return np.stack([p0, p1], axis=-1), np.stack([m0, m1], axis=-1)


def _paper_q(pomdp: AssistancePOMDP, values: np.ndarray, x: np.ndarray, grid: np.ndarray | None = None) -> np.ndarray:
    """Q[c, a, ...] at beliefs x for the eq.-3 belief MDP with W = linear interpolation of values
    (all (c, a, E') branches interpolated in one pass)."""
    grid = np.linspace(0.0, 1.0, len(values)) if grid is None else grid
    p, f = _paper_maps(pomdp)
    R = pomdp.expected_reward
    gamma = pomdp.discount
    x = np.asarray(x, dtype=float)
    z = x.reshape(-1)
    pr = p[..., 0, None] * (1 - z) + p[..., 1, None] * z  # [c, a, e, n]
    nx = f[..., 0, None] * (1 - z) + f[..., 1, None] * z
    w = np.interp(nx.ravel(), grid, values).reshape(nx.shape)  # each row is monotone in z
    out = R[:, :, 0, None] * (1 - z) + R[:, :, 1, None] * z + gamma * (pr * w).sum(axis=2)
    return out.reshape(out.shape[:2] + x.shape)


def paper_residual(pomdp: AssistancePOMDP, grid: np.ndarray, values: np.ndarray, pieces: bool = False):
    """(ε+, ε-) = (sup, -inf) over x in [0, 1] of (T V - V)(x) for the eq.-3 belief MDP, where V
    is the linear interpolation of ``values`` on ``grid``.  Exact up to rounding: the interval is
    cut at the grid points, their preimages under every belief map and the roots of every
    advantage Q(ask) - Q(autonomous), so that on each piece T V - V is a single quadratic."""
    p, f = _paper_maps(pomdp)
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

    def coeffs(pts):
        lo, hi = pts[:-1], pts[1:]
        mid = 0.5 * (lo + hi)
        w = hi - lo
        qp, qm = _paper_q(pomdp, values, pts, grid), _paper_q(pomdp, values, mid, grid)  # [c, a, n]
        vp, vm = np.interp(pts, grid, values), np.interp(mid, grid, values)
        qs = [qp[..., :-1], qm, qp[..., 1:]]  # at lo, mid, hi
        v = [vp[:-1], vm, vp[1:]]
        return lo, hi, mid, w, qs, v

    # pass 1: cut at the roots of each advantage
    lo, hi, mid, w, qs, v = coeffs(pts)
    roots = []
    for c in range(N):
        d = [q[c, ASK] - q[c, AUTONOMOUS] for q in qs]
        r = _quad_roots(d[0], d[1], d[2], w)
        for rr in r:
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
    if pieces:
        return float(np.max(sup)), float(-np.min(inf)), lo, hi, sup, inf
    return float(np.max(sup)), float(-np.min(inf))


def _quad_fit(y0, y1, y2, w):
    """Coefficients of y(u) = c0 + c1 u + c2 u^2 through (-w/2, y0), (0, y1), (w/2, y2)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        c1 = np.where(w > 0, (y2 - y0) / w, 0.0)
        c2 = np.where(w > 0, 2.0 * (y2 + y0 - 2.0 * y1) / (w * w), 0.0)
    return y1, c1, c2


def _quad_roots(y0, y1, y2, w):
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


def _quad_extrema(y0, y1, y2, w):
    """Max and min over [-w/2, w/2] of the quadratic through three equally spaced values."""
    c0, c1, c2 = _quad_fit(y0, y1, y2, w)
    half = w / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.where(c2 != 0, -c1 / (2 * c2), np.nan)
    inside = np.isfinite(u) & (np.abs(u) < half)
    uv = np.where(inside, u, 0.0)
    yv = np.where(inside, c0 + c1 * uv + c2 * uv * uv, y1)
    return np.maximum(np.maximum(y0, y2), yv), np.minimum(np.minimum(y0, y2), yv)


# --------------------------------------------------------------------------- finite horizon


def finite_horizon_vectors(pomdp: AssistancePOMDP, horizon: int) -> list[np.ndarray]:
    """Exact alpha vectors of the h-step value (h = 0..horizon, ``bayes`` update, two trust
    levels): V_0 = 0 and V_h = T V_{h-1}; returns the envelope vectors for each h."""
    vecs = np.zeros((1, 2))
    out = [vecs]
    for _ in range(horizon):
        bk = exact_backup(pomdp, vecs)
        vecs = bk.vectors
        out.append(vecs)
    return out


def finite_horizon_value(pomdp: AssistancePOMDP, horizon: int, belief, complexity: int | None = None) -> float:
    """The exact h-step value at a belief (P(trust = high) or a vector), either for a known
    complexity of the first trial or averaged over P(C)."""
    b = to_vector(belief, 2)
    if horizon == 0:
        return 0.0
    vecs = finite_horizon_vectors(pomdp, horizon - 1)[-1]
    bk = exact_backup(pomdp, vecs)
    if complexity is None:
        return float(envelope_values(bk.vectors, bk.xs, np.array([b[1]]))[0])
    return float(max(envelope_values(v, xs, np.array([b[1]]))[0] for v, xs in bk.q[complexity]))


def certificate(sol: AlphaSolution, pomdp: AssistancePOMDP) -> dict[str, Any]:
    """The machine-readable certificate: gap, bounds at the initial belief and at b = 1, thresholds."""
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


def policy_from_solution(sol: AlphaSolution, pomdp: AssistancePOMDP, target_gap: float | None = None):
    """Wrap a solution as a Policy: AlphaVectorPolicy (bayes) or TrustAwarePolicy (paper)."""
    info = {
        "solver": "alpha",
        "method": sol.method,
        "iterations": sol.iterations,
        "bellman_residual": sol.gap * (1 - pomdp.discount),
        "error_bound": sol.gap,
        "seconds": sol.seconds,
        "discount": pomdp.discount,
    }
    info.update(certificate(sol, pomdp))
    info["target_gap"] = target_gap
    if sol.q is not None:
        info["vectors"] = int(len(sol.lower[0]))
        return AlphaVectorPolicy(
            [[v for v, _ in per_a] for per_a in sol.q], sol.lower[0], pomdp.model, pomdp.complexities, sol.belief_update, info
        )
    g, v = sol.grid_solution
    info["adaptive_grid_points"] = len(g)
    table = np.linspace(0.0, 1.0, POLICY_TABLE_POINTS)  # Q of the certified solution on a uniform table
    q = np.moveaxis(_paper_q(pomdp, v, table, g), -1, 0)
    return TrustAwarePolicy(table, q, pomdp.model, pomdp.complexities, sol.belief_update, info)
