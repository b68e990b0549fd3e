"""Numerics shared by the solvers: policy evaluation (:func:`policy_values`: BiCGSTAB from a warm
start, checked by its residual, a direct sparse solve as the fallback), Howard's improvement step
(:func:`improve`) and policy iteration (:func:`howard`), the best of a set of vectors at many
beliefs (:func:`best_vectors`, :func:`best_at`), the point-based backup and its greedy controller,
point-based policy iteration (:func:`controller_iteration`), the exact evaluation of a
finite-state controller on a POMDP in branch form (:func:`evaluate_controller`), and the beliefs
reachable from b0 or met on simulated trajectories."""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..pomdp.belief import BranchModel

BLOCK_ROWS = 1 << 15  # beliefs per block of best_vectors (with 500 vectors: 130 MB of products)


def best_vectors(X: np.ndarray, G: np.ndarray, rows: int = BLOCK_ROWS) -> np.ndarray:
    """``(X @ G.T).argmax(axis=1)``: the index of the vector of ``G`` best at each row of ``X``,
    computed ``rows`` rows at a time.  The whole product would hold len(X) x len(G) numbers at
    once (2.7 GB for the 767,000 successors of a 4-state grid at resolution 64 against 447
    vectors), and allocating that much costs more than the arithmetic."""
    out = np.empty(len(X), dtype=np.intp)
    for start in range(0, len(X), rows):
        out[start : start + rows] = (X[start : start + rows] @ G.T).argmax(axis=1)
    return out


def policy_values(
    P: sp.csr_matrix,
    rhs: np.ndarray,
    guess: np.ndarray | None = None,
    *,
    tol: float | None = None,
    check: float | None = None,
    maxiter: int = 10_000,
) -> np.ndarray:
    """Solve x = rhs + P x.  BiCGSTAB on (I - P) x = rhs (as an operator: I - P is never formed),
    started from ``guess``, stops when ‖rhs - (I - P) x‖₂ <= ``tol``; a result that is not finite
    or whose largest residual exceeds ``check`` is replaced by a direct sparse solve.

    By default both are near machine precision relative to the rewards (the values are about
    1/(1-γ) times larger): tol = 1e-14 ‖rhs‖₂ + 1e-13 s and check = 1e-9 s, s = max(1, ‖rhs‖∞)."""
    scale = max(1.0, float(np.max(np.abs(rhs))))
    tol = 1e-14 * float(np.sqrt(rhs @ rhs)) + 1e-13 * scale if tol is None else tol
    check = 1e-9 * scale if check is None else check
    n = len(rhs)
    A = spla.LinearOperator((n, n), matvec=lambda y: y - P @ y, dtype=float)
    x0 = np.zeros(n) if guess is None else np.asarray(guess, dtype=float).reshape(-1)
    x, _ = spla.bicgstab(A, rhs, x0=x0, rtol=0.0, atol=tol, maxiter=maxiter)
    if not np.all(np.isfinite(x)) or np.max(np.abs(x - P @ x - rhs)) > check:
        x = spla.spsolve(sp.identity(n, format="csc") - P.tocsc(), rhs)
    return np.asarray(x)


def improve(q: np.ndarray, policy: np.ndarray, axis: int) -> np.ndarray | None:
    """One Howard improvement step: the greedy actions of ``q`` (actions along ``axis``; the
    other axes as in ``policy``), keeping the current action unless another one is better by
    more than rounding.  ``None`` when no action changes (the policy is optimal)."""
    cur = np.take_along_axis(q, np.expand_dims(policy, axis), axis=axis).squeeze(axis)
    better = q.max(axis=axis) > cur + 1e-12 * (1 + np.abs(cur))
    if not np.any(better):
        return None
    return np.where(better, q.argmax(axis=axis), policy)


def howard(
    policy: np.ndarray,
    chain: Callable[[np.ndarray], tuple[Any, np.ndarray]],
    q_of: Callable[[np.ndarray], np.ndarray],
    values: np.ndarray,
    max_iter: int,
    axis: int = 1,
    solve: Callable[[Any, np.ndarray, np.ndarray], np.ndarray] | None = None,
    t_end: float = math.inf,
) -> tuple[np.ndarray, np.ndarray, int]:
    """Howard's policy iteration from ``policy``: ``chain(policy)`` gives the discounted transition
    matrix P and the rewards r of following it, whose values x = r + P x are solved from the last
    ones (by :func:`policy_values`, or ``solve(P, r, values)``), and the policy improves greedily in
    ``q_of(values)`` (actions along ``axis``: :func:`improve`).  Stops when no action changes, after
    ``max_iter`` rounds or past ``t_end``: (values, policy, rounds)."""
    solve = solve or policy_values
    rounds = 0
    while rounds < max_iter:
        rounds += 1
        P, r = chain(policy)
        values = solve(P, r, values)
        new = improve(q_of(values), policy, axis)
        if new is None or time.perf_counter() > t_end:
            break
        policy = new
    return values, policy, rounds


def evaluate_controller(
    model: BranchModel, actions: np.ndarray, successors: np.ndarray, guess: np.ndarray | None = None, rtol: float = 1e-15
) -> np.ndarray:
    """Exact values α[n, t] of a finite-state controller: node n takes actions[n, c] in context c
    and moves to node successors[n, c, branch] after each branch (-1: no successor, for a branch
    that cannot happen).  Solves (I - γ P) α = r: dense for small controllers, a sparse direct
    solve for medium ones without a guess, otherwise :func:`policy_values` started from
    ``guess``.  P is built directly in CSR form (rows (n, t) in order, the entries of a row in
    (c, branch, t2) order), so no sorting or duplicate summing is needed."""
    M = model.kernels  # [c, a, br, t, u]
    n, N = actions.shape
    k = model.n_hidden
    cidx = np.arange(N)[None, :]
    rhs = np.einsum("c,nct->nt", model.context_probs, model.rewards[cidx, actions])  # (n, k)
    # weights [n, c, br, t, u] viewed as rows (n, t) with slots (c, br, u); zero slots
    # (impossible branches, zero kernel entries, no successor) are dropped
    Mg = M * (model.discount * model.context_probs)[:, None, None, None, None]
    W = np.moveaxis(Mg[cidx, actions], 3, 1)  # (n, t, c, br, u)
    nz = (W != 0) & (successors >= 0)[:, None, :, :, None]
    data = W[nz]
    cols = np.broadcast_to((successors.astype(np.int64) * k)[:, None, :, :, None] + np.arange(k), W.shape)[nz]
    size = n * k
    counts = nz.reshape(size, -1).sum(axis=1)
    b = rhs.reshape(-1)
    if size <= 200:  # small: dense
        D = np.zeros((size, size))
        np.add.at(D, (np.repeat(np.arange(size), counts), cols), -data)
        D[np.diag_indices(size)] += 1.0
        return np.linalg.solve(D, b).reshape(n, k)
    indptr = np.zeros(size + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    P = sp.csr_matrix((data, cols, indptr), shape=(size, size))
    if guess is None and size <= 600:
        return np.asarray(spla.spsolve(sp.identity(size, format="csc") - P.tocsc(), b)).reshape(n, k)
    scale = max(1.0, float(np.max(np.abs(b))))
    tol, check = max(rtol, 1e-15) * scale * np.sqrt(size), max(1e-10, 10 * rtol) * scale
    x = policy_values(P, b, guess, tol=tol, check=check, maxiter=2000)
    return x.reshape(n, k)


def memoryless_controllers(model: BranchModel, limit: int = 64) -> np.ndarray:
    """Values of the memoryless controllers "always take action a_c in context c", one vector
    each (one controller of independent self-looping nodes, evaluated by one solve); with more
    than ``limit`` combinations, only the controllers that take one action everywhere."""
    N, A = model.n_contexts, model.n_actions
    combos = list(itertools.product(range(A), repeat=N)) if limit >= A**N else [tuple([a] * N) for a in range(A)]
    n = len(combos)
    acts = np.array(combos, dtype=np.int64).reshape(n, N)
    succ = np.broadcast_to(np.arange(n)[:, None, None], (n, N, model.kernels.shape[2])).copy()
    return evaluate_controller(model, acts, succ)


def best_at(vectors: np.ndarray, beliefs: np.ndarray) -> np.ndarray:
    """The vectors best at some belief of ``beliefs`` (n, K), in their order: a pruned lower bound."""
    return vectors[np.unique((beliefs @ vectors.T).argmax(axis=1))]


def point_backup(model: BranchModel, vectors: np.ndarray, best: np.ndarray) -> np.ndarray:
    """g[n, c, a, t] = R[c, a, t] + γ Σ_branch M[c, a, branch] α_best: the point-based backup of
    the alpha vectors ``vectors`` at n beliefs, ``best[n, c, a, branch]`` the vector used after
    each branch (the one best at the next belief)."""
    return model.rewards[None] + model.discount * np.einsum("cabtu,ncabu->ncat", model.kernels, vectors[best])


def greedy_controller(
    model: BranchModel, S: np.ndarray, p: np.ndarray, g: np.ndarray, actions: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The controller of n nodes, one per belief, whose node takes ``actions[n, c]`` and after
    each branch goes to the node best at the next belief: (its one-step values alpha (n, K) from
    the backup ``g`` (:func:`point_backup`), its successors (n, c, branch), -1 where the branch
    cannot happen).  ``S`` (n, c, a, branch, K) and ``p`` (n, c, a, branch) are the beliefs'
    successors and their probabilities."""
    n, N, _, Br, K = S.shape
    ii, cc = np.arange(n)[:, None], np.arange(N)[None, :]
    alpha = np.einsum("c,nct->nt", model.context_probs, g[ii, cc, actions])
    succ = (S[ii, cc, actions].reshape(-1, K) @ alpha.T).argmax(axis=1).reshape(n, N, Br)
    return alpha, np.where(p[ii, cc, actions] > 0, succ, -1)


def controller_iteration(
    model: BranchModel,
    vectors: np.ndarray,
    B: np.ndarray,
    successors: tuple[np.ndarray, np.ndarray],
    keep_at: np.ndarray,
    min_gain: float,
    rounds: int,
    also: np.ndarray | None = None,
    t_end: float = math.inf,
) -> np.ndarray:
    """Point-based policy iteration on beliefs B (n, K), their ``successors`` = (p (n, c, a, branch),
    S (n, c, a, branch, K)): each round every belief is a node of a controller acting greedily in
    the point backup of ``vectors`` (with ``also`` (n, c), a second controller taking those
    actions), going after each branch to the node best at the next belief; the controllers are
    evaluated exactly and their values join ``vectors``, which keeps those best at a belief of
    ``keep_at``.  Stops when the greedy controller repeats (its actions, and its successors
    without ``also``), the gain at B is at most ``min_gain``, or past ``t_end``.  Every vector is
    a controller's value, so the lower bound holds whenever it stops."""
    p, S = successors
    n, N, A, Br, K = S.shape
    Sf = S.reshape(-1, K)
    prev = None
    for _ in range(rounds):
        g = point_backup(model, vectors, (Sf @ vectors.T).argmax(axis=1).reshape(n, N, A, Br))
        acts = np.einsum("ncat,nt->nca", g, B).argmax(axis=2)
        before = (B @ vectors.T).max(axis=1)
        new, key = [], None
        for a in (acts,) if also is None else (acts, also):
            alpha, succ = greedy_controller(model, S, p, g, a)
            key = key or (acts.tobytes(), succ.tobytes() if also is None else b"")
            ev = evaluate_controller(model, a, succ, guess=alpha)
            new += [alpha, ev] if np.all(np.isfinite(ev)) else [alpha]
        vectors = best_at(np.vstack([vectors, *new]), keep_at)
        gain = float(np.max((B @ vectors.T).max(axis=1) - before))
        if key == prev or gain <= min_gain or time.perf_counter() > t_end:
            break
        prev = key
    return vectors


def q_vectors(model: BranchModel, vectors: np.ndarray, beliefs: np.ndarray, S: np.ndarray, prune: bool = False) -> list:
    """Q lower-bound vectors per (context, action): point backups of ``vectors`` at ``beliefs``
    (``S``: their successors (n, c, a, branch, K)) without near-duplicates, with ``prune`` only
    those best at one of the beliefs."""
    n, N, A, Br, K = S.shape
    g = point_backup(model, vectors, best_vectors(S.reshape(-1, K), vectors).reshape(n, N, A, Br))
    rows = [[unique_rows(g[:, c, a], decimals=12) for a in range(A)] for c in range(N)]
    return [[best_at(q, beliefs) for q in row] for row in rows] if prune else rows


def sample_beliefs(
    model: BranchModel,
    b0: np.ndarray,
    rng: np.random.Generator,
    successors: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    bound: Callable[[np.ndarray], np.ndarray],
    length: int,
    trajectories: int = 8,
) -> np.ndarray:
    """Beliefs met on simulated trajectories from b0 (PBVI-style belief expansion): the context
    and the branch drawn with their probabilities, the action greedy in a one-step lookahead on
    ``bound`` (a function of beliefs (n, K)); ``successors(B)`` as in :func:`reachable_beliefs`."""
    B = np.repeat(b0[None], trajectories, axis=0)
    idx = np.arange(trajectories)
    out = []
    for _ in range(length):
        p, S = successors(B)  # (n, N, A, Br), (n, N, A, Br, K)
        c = rng.choice(model.n_contexts, size=trajectories, p=model.context_probs)
        value = bound(S.reshape(-1, model.n_hidden)).reshape(p.shape)
        q = np.einsum("cat,nt->nca", model.rewards, B) + model.discount * (p * value).sum(axis=-1)
        a = q[idx, c].argmax(axis=1)
        pb = p[idx, c, a]  # (n, Br)
        u = rng.random(trajectories)[:, None]
        br = np.minimum((np.cumsum(pb, axis=1) / pb.sum(axis=1, keepdims=True) < u).sum(axis=1), pb.shape[1] - 1)
        B = S[idx, c, a, br]
        out.append(B)
    return np.vstack(out)


def unique_rows(B: np.ndarray, decimals: int = 13) -> np.ndarray:
    """Rows of B without near-duplicates, keeping the first occurrence and the order."""
    _, idx = np.unique(np.round(B, decimals), axis=0, return_index=True)
    return B[np.sort(idx)]


def reachable_beliefs(
    b0: np.ndarray,
    depth: int,
    successors: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    decimals: int = 13,
) -> np.ndarray:
    """b0 and the beliefs reachable from it in up to ``depth`` trials (any context, action and
    branch of positive probability), equal to ``decimals`` decimals merged; ``successors(B)``
    gives (p[n, c, a, branch], next[n, c, a, branch, K]) of beliefs B."""
    out, front = [b0[None]], b0[None]
    for _ in range(depth):
        p, S = successors(front)
        front = unique_rows(S[p > 0].reshape(-1, len(b0)), decimals)
        out.append(front)
    return unique_rows(np.vstack(out), decimals)
