"""The policy for a supervisor of unknown type, and the ``types`` solver that uses the types
(docs/solvers.md, ``types``).

``solve_type_aware(mixture, task)`` builds the POMDP over (type, trust)
(:func:`trustseek.pomdp.supervisor_types.type_aware_problem`) and solves it with a registered
solver; an alpha-vector result comes back as a
:class:`~trustseek.policies.alpha_vector.TypeAwarePolicy`, which keeps the mixture.  A person's
own policy is the same solve from their type belief (``type_belief``).

:class:`TypeAwareSolver` is the point solver with two changes, both drawn from the closed blocks
of hidden states (the types, between which there is no transition) found in the kernel:

* **upper bound**: the Freudenthal grid's Bellman fixed point with each successor valued at
  min(interpolation, base bound); the base bound (:class:`TypeBound`) is the smallest of the
  fast informed bound, the type revealed now, Σ_m w_m V̄_m(p_m) (V̄_m each two-state type's
  certified ``alpha`` value, tabulated), and the type revealed after one trial.  At b0 the bound
  looks a few trials ahead (:meth:`TypeAwareSolver.lookahead_upper`);
* **lower bound**: seeded with each type's optimal policy as a controller evaluated on the whole
  product.

A problem without two-state blocks gets the fast informed bound as the only cap.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import scipy.sparse as sp

from ..model.core import TrustModel, trust_model
from ..model.mixture import TypeMixture
from ..model.task import Task
from ..policies.alpha_vector import AlphaVectorPolicy, TypeAwarePolicy
from ..policies.base import Policy
from ..policies.envelope import envelope_values
from ..pomdp.belief import BranchModel
from ..pomdp.flat import FlatPOMDP
from ..pomdp.problem import AssistancePOMDP
from ..pomdp.supervisor_types import type_aware_problem
from . import numerics
from .alpha import AlphaSolver
from .base import bayes_only, one_blas_thread
from .defaults import DEFAULT_TYPE_AWARE_SOLVER
from .point import PointSolution, PointSolver
from .registry import make_solver
from .type_bounds import base_many
from .upper_bounds import closed_blocks, fast_informed_bound, one_state_value

#: intervals of the uniform grid on which each type's value bound is tabulated
TABLE_INTERVALS = 4096


@dataclass
class TypeBound:
    """The base upper bound of a problem in branch form (see the module).

    ``lo[m]``/``hi[m]``: the two hidden states of block m (equal for a one-state block; both
    empty when the bound does not use blocks); ``vt[m, j]``: V̄_m at p = j / TABLE_INTERVALS;
    ``qt[m, c, a, j]``: Q̄_m; ``beta``: the fast informed bound's Q-vectors;
    ``controllers``: per block, the values of its controller's nodes on the whole problem."""

    pc: np.ndarray
    beta: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    vt: np.ndarray
    qt: np.ndarray
    controllers: list[np.ndarray]

    def __call__(self, B: np.ndarray) -> np.ndarray:
        """The base bound at beliefs B (n, states)."""
        B = np.ascontiguousarray(np.atleast_2d(np.asarray(B, dtype=float)))
        return base_many(B, self.pc, self.beta, self.lo, self.hi, self.vt, self.qt)


def type_bound(problem: AssistancePOMDP | FlatPOMDP, model: BranchModel, block_tol: float = 1e-6) -> TypeBound:
    """The base bound of ``problem`` (its branch form ``model``): with the types' bounds when
    every closed block has at most two hidden states and the problem is an assistance POMDP,
    otherwise the fast informed bound alone."""
    beta = fast_informed_bound(model)
    pc = np.ascontiguousarray(model.context_probs, dtype=float)
    blocks = closed_blocks(model)
    empty = TypeBound(pc, beta, np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros((0, 1, 1, 2)), [])
    if not isinstance(problem, AssistancePOMDP) or len(blocks) < 2 or max(len(b) for b in blocks) > 2:
        return empty
    xs = np.linspace(0.0, 1.0, TABLE_INTERVALS + 1)
    N, A = model.n_contexts, model.n_actions
    lo, hi, vts, qts, ctrl = [], [], [], [], []
    g = model.discount
    for idx in blocks:
        if len(idx) == 1:
            s = int(idx[0])
            val = one_state_value(model, s)
            lo.append(s)
            hi.append(s)
            vts.append(np.full(len(xs), val))
            qts.append(np.broadcast_to((model.rewards[:, :, s] + g * val)[..., None], (N, A, len(xs))).copy())
            ctrl.append(numerics.memoryless_controllers(model))
            continue
        sub = _block_problem(problem, idx)
        sol = AlphaSolver(tol=block_tol, upper_grid=0).solve_bounds(sub)
        assert sol.lower is not None
        vecs, bx = sol.lower
        vbar = envelope_values(vecs, bx, xs) + sol.gap
        bm = sub.branch_model()
        X = np.stack([1.0 - xs, xs], axis=1)
        p, S = bm.branches.successors(X)  # (n, N, A, Br), (n, N, A, Br, 2)
        vn = np.interp(S[..., 1], xs, vbar)
        q = np.einsum("cat,nt->can", bm.rewards, X) + g * np.einsum("ncab,ncab->can", p, vn)
        lo.append(int(idx[0]))
        hi.append(int(idx[1]))
        vts.append(vbar)
        qts.append(q)
        ctrl.append(_block_controller(model, bm, vecs))
    return TypeBound(
        pc,
        beta,
        np.array(lo, dtype=np.int64),
        np.array(hi, dtype=np.int64),
        np.ascontiguousarray(np.array(vts)),
        np.ascontiguousarray(np.array(qts)),
        ctrl,
    )


def _block_problem(problem: AssistancePOMDP, idx: np.ndarray) -> AssistancePOMDP:
    """The assistance POMDP of one closed block of trust levels (one supervisor type)."""
    m = problem.model
    init = m.initial[idx]
    init = init / init.sum() if init.sum() > 0 else np.full(len(idx), 1.0 / len(idx))
    sub = trust_model(
        trust_levels=tuple(m.trust_levels[i] for i in idx),
        complexities=m.complexities,
        initial=init,
        emission=m.emission[:, :, idx],
        transition=m.transition[..., idx, :][..., idx],
    )
    return AssistancePOMDP(sub, problem.task)


def _block_controller(model: BranchModel, block: BranchModel, vecs: np.ndarray, points: int = 513) -> np.ndarray:
    """A controller for one block from its alpha vectors ``vecs`` (one node per belief of a lattice
    of ``points``: the point backup of the vectors there, and after each branch the node best at
    the next belief), evaluated exactly on the whole problem ``model``: (nodes, states)."""
    x = np.linspace(0.0, 1.0, points)
    B = np.stack([1.0 - x, x], axis=1)
    p, S = block.branches.successors(B)  # (n, N, A, Br), (n, N, A, Br, 2)
    n, N, A, Br, _ = S.shape
    g = numerics.point_backup(block, vecs, (S.reshape(-1, 2) @ vecs.T).argmax(axis=1).reshape(n, N, A, Br))
    acts = np.einsum("ncat,nt->nca", g, B).argmax(axis=2)
    succ = numerics.greedy_controller(block, S, p, g, acts)[1]
    ev = numerics.evaluate_controller(model, acts, succ)
    return ev if np.all(np.isfinite(ev)) else np.zeros((0, model.n_hidden))


class TypeAwareSolver(PointSolver):
    """Point-based bounds for a product of supervisor types: the grid upper bound capped by the
    types' bound, the lower bound seeded with each type's controller (see the module)."""

    name = "types"

    instead: ClassVar[dict[str, str]] = bayes_only("types")
    discounted = True

    @one_blas_thread()
    def solve_bounds(self, problem: AssistancePOMDP | FlatPOMDP) -> PointSolution:
        self.check(problem)
        t0 = time.perf_counter()
        model = problem.branch_model()
        self.bound = type_bound(problem, model)
        self.setup_seconds = time.perf_counter() - t0
        return self._bounds(model, t0)

    @one_blas_thread()
    def solve(self, problem: AssistancePOMDP | FlatPOMDP) -> Policy:
        """The point solver's policy of the lower bound's vectors; ``info`` also says how many
        closed blocks (types) the upper bound used and the seconds spent on them."""
        policy = super().solve(problem)
        policy.info["method"] = "point-based policy iteration + Freudenthal upper bound capped by the types' bound"
        policy.info["type_blocks"] = len(self.bound.lo)
        policy.info["type_bound_seconds"] = self.setup_seconds
        return policy

    def upper_at(self, B: np.ndarray) -> np.ndarray:
        B = np.atleast_2d(np.asarray(B, dtype=float))
        out = self.bound(B)
        if len(getattr(self, "vertex_values", ())):
            out = np.minimum(out, super().upper_at(B))
        return out

    def lookahead_upper(self, b0: np.ndarray, max_nodes: int = 5000, max_depth: int = 6) -> float:
        """The upper bound at b0 improved by looking ahead: the beliefs reachable from b0 are
        expanded level by level (equal beliefs merged) while a level has at most ``max_nodes``
        beliefs, to at most ``max_depth`` trials; each belief's bound is then min(U(b), H U(b)) from the deepest level up, where
        H is the Bellman backup over its successors.  H is monotone and U is above the optimal
        value, so every such value is too."""
        m = self.model
        fan = int(np.prod(m.kernels.shape[:3]))  # successors of one belief: contexts x actions x branches
        levels = [np.atleast_2d(np.asarray(b0, dtype=float))]
        links = []
        while len(levels) <= max_depth and len(levels[-1]) * fan <= 40 * max_nodes:
            p, S = m.branches.successors(levels[-1])  # (n, N, A, Br), (n, N, A, Br, K)
            live = p > 1e-300
            nxt, inverse = np.unique(np.round(S[live], 12), axis=0, return_inverse=True)
            if len(nxt) > max_nodes:
                break
            links.append((p, live, inverse.reshape(-1)))
            levels.append(S[live][np.unique(inverse.reshape(-1), return_index=True)[1]])
        values = self.upper_at(levels[-1])
        for depth in range(len(links) - 1, -1, -1):
            B = levels[depth]
            p, live, inverse = links[depth]
            succ = np.zeros(p.shape)
            succ[live] = values[inverse]
            q = np.einsum("cat,nt->nca", m.rewards, B) + m.discount * (p * succ).sum(axis=3)
            values = np.minimum(self.upper_at(B), q.max(axis=2) @ m.context_probs)
        return float(values[0])

    def _vertex_values(
        self, V: np.ndarray, p: np.ndarray, S: np.ndarray, col: np.ndarray, w: np.ndarray, rew: np.ndarray
    ) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]:
        """The fixed point of the Bellman operator whose successor values are min(interpolation,
        base bound), by policy iteration over the actions and the choice of the smaller bound."""
        m = self.model
        K, N, gamma, pc = m.n_hidden, m.n_contexts, m.discount, m.context_probs
        nV, Br = len(V), p.shape[3]
        cap = self.bound(S.reshape(-1, K)).reshape(p.shape)
        ii = np.arange(nV)

        def successor_values(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            interp = np.einsum("ncabk,ncabk->ncab", w, u[col])
            return np.minimum(interp, cap), interp < cap

        def q_of(u: np.ndarray) -> np.ndarray:
            return rew + gamma * np.einsum("ncab,ncab->nca", p, successor_values(u)[0])

        u = self.bound(V)
        acts = q_of(u).argmax(axis=2)
        rows = np.broadcast_to(ii[:, None, None], (nV, Br, K))
        for _ in range(500):
            use = successor_values(u)[1]
            rr = np.zeros(nV)
            data, cols, rws = [], [], []
            for c in range(N):
                a = acts[:, c]
                pa = p[ii, c, a]
                ua = use[ii, c, a]
                rr += pc[c] * (rew[ii, c, a] + gamma * np.where(ua, 0.0, pa * cap[ii, c, a]).sum(axis=1))
                wt = gamma * pc[c] * (pa * ua)[..., None] * w[ii, c, a]
                data.append(wt.ravel())
                cols.append(col[ii, c, a].ravel())
                rws.append(rows.ravel())
            W = sp.csr_matrix((np.concatenate(data), (np.concatenate(rws), np.concatenate(cols))), shape=(nV, nV))
            new_u = numerics.policy_values(W, rr, u)
            new_acts = numerics.improve(q_of(new_u), acts, axis=2)
            same_choice = np.array_equal(successor_values(new_u)[1], use)
            u = new_u
            if new_acts is None and same_choice:
                break
            if new_acts is not None:
                acts = new_acts
        return u, q_of

    def _start(self, model: BranchModel, b0: np.ndarray, reach: np.ndarray) -> np.ndarray:
        """The memoryless controllers and each type's own controller, keeping the vectors best at
        some belief reachable from b0 or at a corner."""
        self.vertex_values = np.zeros(0)  # no grid bound yet: upper_at is the types' bound alone
        G = np.vstack([numerics.memoryless_controllers(model), *self.bound.controllers])
        K = model.n_hidden
        return numerics.best_at(G, np.vstack([reach, np.eye(K)])) if len(G) > 1 else G

    def _upper_at_start(self, b0: np.ndarray) -> float:
        return self.lookahead_upper(b0)


def solve_type_aware(
    mixture: TypeMixture | TrustModel,
    task: Task,
    solver: str = DEFAULT_TYPE_AWARE_SOLVER,
    gap: float = 1e-3,
    type_belief: Sequence[float] | np.ndarray | None = None,
    **options: Any,
) -> Policy:
    """The policy of the (type, trust) POMDP of ``mixture`` and ``task``, solved by the registered
    solver ``solver`` to a bound gap ``gap`` at the initial belief (``options`` go to the solver).

    ``type_belief`` starts the types from that distribution instead of the mixture's weights
    (a returning person's warm start).  The result is a :class:`TypeAwarePolicy` when the
    solver returns alpha vectors; any other policy is returned as the solver built it (its
    model is the product model)."""
    if isinstance(mixture, TrustModel):
        mixture = TypeMixture.single(mixture)
    if type_belief is not None:
        mixture = mixture.with_weights(list(np.asarray(type_belief, dtype=float).reshape(-1)))
    policy = make_solver(solver, gap=gap, **options).solve(type_aware_problem(mixture, task))
    if type(policy) is AlphaVectorPolicy:
        out = TypeAwarePolicy.from_alpha(mixture, policy)
        out.info["types"] = list(mixture.names)
        out.info["type_weights"] = mixture.weights.tolist()
        return out
    return policy
