"""The upper bound's pieces of the reachable-belief solver (:mod:`.reachable`): the fast
informed bound, the grid bound of each closed block of hidden states, and the sawtooth
interpolation's coefficients φ through belief points."""

from __future__ import annotations

from math import comb

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ..pomdp.belief import Branches, BranchModel
from .base import SolverError
from .numerics import howard
from .point import PointSolver


def fast_informed_bound(model: BranchModel, max_rounds: int = 200) -> np.ndarray:
    """The fast informed bound (Hauskrecht 2000) of a problem in branch form, as Q-vectors
    beta[c, a, t]: U(b) = Σ_c P(c) max_a beta[c, a]·b bounds the optimal value from above.

    beta[c, a, t] = R[c, a, t] + γ Σ_branch Σ_c' P(c') max_a' Σ_u M[c, a, branch, t, u] beta[c', a', u]
    (the next context is independent of the branch, so the choice of a' is per c').  Solved by
    policy iteration on the choices; the result is raised by its Bellman residual / (1 - γ),
    so that rounding cannot bring it below the fixed point."""
    M, R, pc, g = model.kernels, model.rewards, model.context_probs, model.discount
    N, A, Br, K, _ = M.shape
    n = N * A * K
    if not g < 1.0:
        raise SolverError([f"the reachable solver needs a discount below 1, got {g}"])

    def project(beta: np.ndarray) -> np.ndarray:  # [c, a, br, t, c', a'] = Σ_u M[c, a, br, t, u] beta[c', a', u]
        return np.einsum("cabtu,dfu->cabtdf", M, beta)

    w = g * np.einsum("cabtu,d->cabtdu", M, pc)  # [c, a, br, t, c', u]

    def chain(ch: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The linear system of fixed choices ``ch`` of a' per (c, a, br, t, c'): beta = R + P beta."""
        return np.einsum("cabtdu,cabtdf->catdfu", w, ch[..., None] == np.arange(A)).reshape(n, n), R.reshape(-1)

    def solve(P: np.ndarray, r: np.ndarray, _: np.ndarray) -> np.ndarray:
        return np.linalg.solve(np.eye(n) - P, r)

    ch = np.zeros((N, A, Br, K, N), dtype=np.int64)
    beta = howard(ch, chain, lambda b: project(b.reshape(N, A, K)), np.zeros(n), max_rounds, axis=-1, solve=solve)[0]
    beta = beta.reshape(N, A, K)
    residual = float(np.max(R + g * np.einsum("cabtd,d->cat", project(beta).max(axis=-1), pc) - beta))
    return beta + max(0.0, residual) / (1.0 - g)


def one_state_value(model: BranchModel, s: int) -> float:
    """The exact value of hidden state ``s`` when it is a closed block of its own: the belief never
    moves, so the value is the best reward per context, averaged over the contexts, discounted."""
    return float(model.context_probs @ model.rewards[:, :, s].max(axis=1)) / (1.0 - model.discount)


class BlockGrid:
    """The grid upper bound of one closed block of hidden states (Lovejoy's bound on Freudenthal's
    triangulation, certified, as the point solver computes it); one hidden state: its exact value."""

    def __init__(self, model: BranchModel, vertices: int):
        K = model.n_hidden
        if K == 1:
            self.value = one_state_value(model, 0)
            self.solver = None
            return
        r = 2
        while comb(2 * r + K - 1, K - 1) <= vertices:
            r *= 2
        self.solver = PointSolver()
        V, u = self.solver.grid_bound(model, r)
        # two hidden states: the triangulation is the grid on [0, 1], interpolation is np.interp
        order = np.argsort(V[:, -1])
        self.xs, self.us = V[order, -1], u[order]

    def upper_at(self, B: np.ndarray) -> np.ndarray:
        if self.solver is None:
            return np.full(len(B), self.value)
        if B.shape[1] == 2:
            return np.interp(B[:, 1], self.xs, self.us)
        return self.solver.upper_at(B)


def closed_blocks(model: BranchModel) -> list[np.ndarray]:
    """The closed blocks of hidden states (no transition between two blocks, under any context,
    action and branch): the supervisor types of a product problem."""
    link = (model.kernels.sum(axis=(0, 1, 2)) > 0) | np.eye(model.n_hidden, dtype=bool)
    n, labels = connected_components(sp.csr_matrix(link | link.T), directed=False)
    return [np.flatnonzero(labels == k) for k in range(n)]


def grid_blocks(model: BranchModel, vertices: int) -> list[tuple[np.ndarray, BlockGrid]]:
    """The closed blocks of hidden states (no transition between blocks: e.g. the supervisor types
    of a type mixture), each with its grid upper bound; empty when a block is too large for a grid
    of ``vertices`` vertices at resolution 2 (the bound is then the sawtooth alone)."""
    M = model.kernels
    out = []
    for idx in closed_blocks(model):
        if comb(2 + len(idx) - 1, len(idx) - 1) > vertices:
            return []
        sub = Branches.from_kernels(M[..., idx, :][..., idx])
        bm = BranchModel(model.context_probs, model.rewards[..., idx], sub, model.discount, np.full(len(idx), 1.0 / len(idx)))
        out.append((idx, BlockGrid(bm, vertices)))
    return out


def inverse_points(P: np.ndarray) -> np.ndarray:
    """1 / P[i, t] as (K, points), infinite outside each point's support."""
    with np.errstate(divide="ignore"):
        return np.ascontiguousarray(np.where(P > 0, 1.0 / np.where(P > 0, P, 1.0), np.inf).T)


def phi_of(B: np.ndarray, inv: np.ndarray) -> np.ndarray:
    """φ_i(b) = min over the support of point i of b(t) / b_i(t) (at most 1), for beliefs B (n, K)
    and points given by :func:`inverse_points`: (n, points).  The sawtooth bound through point i is
    U_corners(b) + φ_i(b) (v_i - U_corners(b_i))."""
    phi = np.full((len(B), inv.shape[1]), np.inf)
    with np.errstate(invalid="ignore"):
        for t in range(B.shape[1]):
            np.fmin(phi, B[:, t, None] * inv[t][None], out=phi)  # fmin: 0 * inf (outside the support) is skipped
    return np.minimum(phi, 1.0)


def phi_pairs(B: np.ndarray, P: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """φ of belief B[n] and point P[idx[n, j]]: (n, k)."""
    Pi = P[idx]  # (n, k, K)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(Pi > 0, B[:, None, :] / np.where(Pi > 0, Pi, 1.0), np.inf)
    return np.minimum(r.min(axis=2), 1.0)
