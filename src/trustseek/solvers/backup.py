"""The exact Bellman backup of alpha vectors for two trust levels (``bayes`` update).

The complexity and the last experience are observed, so the belief that matters is one
number, x = P(trust = high), and a set of alpha vectors is a piecewise-linear convex function
of x.  Each Bayes branch (o, E') moves x by a monotone linear-fractional map, so the backup
of such a function is again one, and it is computed exactly with envelopes (no linear
programs): see :func:`exact_backup`.  Also the exact finite-horizon value built on it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ..policies.envelope import active_piece, envelope, envelope_values
from ..pomdp.belief import to_vector
from ..pomdp.problem import AssistancePOMDP
from .envelopes import cross_sum, max_of, strip

__all__ = ["Backup", "BranchLines", "branch_lines", "exact_backup", "finite_horizon_value", "finite_horizon_vectors"]


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
