"""The scheduling solver: backward induction over the remaining items, a belief value function
at each (remaining, visible) state (two trust levels; docs/scheduling.md).

With V_s(x) the optimal value of state s = (remaining, visible) at x = P(trust = high),

    W_u(x)        = Σ_{s'} P(s' | u) V_{s'}(x)                       (afterstate u: the next item arrives)
    Q_s(x, k, a)  = r(x, k, a) + γ Σ_branches P(branch | x, k, a) W_{after(s, k)}(x'),
    V_s(x)        = max over visible k and actions a of Q_s(x, k, a),   V = 0 with no items left,

as exact envelopes of alpha vectors (``alpha``, the ``bayes`` update: :func:`~.alpha.exact_backup`)
or values on a uniform grid of x (``grid``, either update).  ``order`` restricts the picks to a
rule and ``ask_first_hard`` forces an ask on the first high-complexity item (the heuristics the
evaluation compares the optimal schedule with).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from ..policies.envelope import cross_sum, envelope_values, max_of
from ..policies.scheduling import PieceQ, SchedulePolicy
from ..pomdp.problem import AssistancePOMDP
from ..pomdp.scheduling import SchedulingProblem, State, schedule_size, state_key
from .alpha import exact_backup
from .base import Solver, SolverError, one_blas_thread
from .defaults import DEFAULT_SCHEDULE_GRID, ORDERS, REPRESENTATIONS

MAX_VALUES = 50_000_000  # the largest schedule policy solved (Q values; the paper's 41/30 items: 1 M, about 1 s)
#: the alpha representation's budget of stored pieces (breakpoints and alpha vectors): its envelopes
#: grow with the items left (17 + 17 on the paper's model: 2 M pieces in about 1 s; 25 + 25: 36 M, 16 s
#: and 1.1 GB; 41 + 30 ran past two minutes and 7 GB), so a solve past it stops with the reason
MAX_PIECES = 20_000_000

#: Q of an action the rule forbids (stored finite so that policy files stay valid JSON)
FORBIDDEN = -1e9

Envelope = tuple[np.ndarray, np.ndarray]  # (vectors in order, breakpoints)


def allowed_picks(problem: SchedulingProblem, state: State, order: str) -> list[int]:
    """The complexities the rule ``order`` lets the robot pick in ``state``."""
    picks = problem.picks(state)
    if order == "optimal" or len(picks) == 1:
        return picks
    if order == "easy-first":
        return [min(picks)]
    if order == "hard-first":
        return [max(picks)]
    if order == "alternating":
        N = len(state[0])
        t = problem.trial(state)
        return [next((t + i) % N for i in range(N) if (t + i) % N in picks)]
    raise SolverError([f"unknown order {order!r}; expected one of {list(ORDERS)}"])


def forced_ask(problem: SchedulingProblem, state: State, k: int) -> bool:
    """Whether picking complexity ``k`` in ``state`` is the session's first high-complexity item."""
    hard = len(problem.counts) - 1
    return k == hard and state[0][hard] == problem.counts[hard]


class ScheduleSolver(Solver):
    """Backward induction over the counts for a :class:`SchedulingProblem` (two trust levels)."""

    name = "schedule"
    trust_levels = 2

    def __init__(
        self,
        belief_update: str = "bayes",
        representation: str = "grid",
        grid: int = DEFAULT_SCHEDULE_GRID,
        order: str = "optimal",
        ask_first_hard: bool = False,
    ):
        problems = []
        if representation not in REPRESENTATIONS:
            problems.append(f"unknown representation {representation!r}; expected one of {list(REPRESENTATIONS)}")
        if order not in ORDERS:
            problems.append(f"unknown order {order!r}; expected one of {list(ORDERS)}")
        if int(grid) != grid or grid < 2:
            problems.append(f"the grid needs at least 2 points, got {grid!r}")
        if problems:
            raise SolverError(problems)
        self.belief_update: str = belief_update
        self.representation = representation
        self.grid = int(grid)
        self.order = order
        self.ask_first_hard = bool(ask_first_hard)

    def unsupported(self, problem: Any) -> list[str]:
        if isinstance(problem, AssistancePOMDP):
            return [
                "the schedule solver needs a scheduling problem (item counts and a window, "
                "SchedulingProblem); for the unscheduled problem use the grid solver (two trust levels) "
                "or the point solver (any number)"
            ]
        if not isinstance(problem, SchedulingProblem):
            return [f"the schedule solver needs a SchedulingProblem, got a {type(problem).__name__}: use the point solver"]
        reasons = []
        if problem.pomdp.n_trust != 2:
            reasons.append(
                f"the schedule solver needs two trust levels; this model has {problem.pomdp.n_trust}: "
                "use the point solver for the unscheduled problem"
            )
        if self.representation == "alpha" and self.belief_update != "bayes":
            reasons.append(
                f"alpha vectors are exact for the bayes update only; for {self.belief_update!r} use the grid representation"
            )
        items = f"{sum(problem.counts):,} items {list(problem.counts)}"
        if self.representation == "grid":
            size = schedule_size(problem.counts, problem.window, self.grid)
            if size > MAX_VALUES:
                reasons.append(
                    f"{items} make up to {size:,} values to compute, more than {MAX_VALUES:,} (about a minute): "
                    "fewer items, a window, or a coarser grid"
                )
        elif (size := schedule_size(problem.counts, problem.window, 2)) > MAX_PIECES:  # >= 2 breakpoints, 2 vectors
            reasons.append(
                f"the alpha vectors of {items} make at least {size:,} pieces, more than {MAX_PIECES:,}: "
                "use the grid representation, or fewer items"
            )
        reasons += [r for r in super().unsupported(problem.pomdp) if "trust levels" not in r]
        return reasons

    @one_blas_thread()
    def solve(self, problem: SchedulingProblem) -> SchedulePolicy:
        self.check(problem)
        t0 = time.perf_counter()
        pomdp = problem.pomdp
        backup: Callable[[Any], list[tuple[PieceQ, Any]]]
        if self.representation == "alpha":
            mix, value, backup = _alpha_ops(pomdp, problem.counts)
        else:
            mix, value, backup = _grid_ops(pomdp, self.belief_update, self.grid)
        V: dict[State, Any] = {}
        Qu: dict[State, list[tuple[PieceQ, Any]]] = {}
        table: dict[State, dict[int, PieceQ]] = {}
        for s in reversed(problem.states()):
            per_k: dict[int, PieceQ] = {}
            parts = []
            for k in allowed_picks(problem, s, self.order):
                u = problem.after(s, k)
                if u not in Qu:
                    Qu[u] = backup(mix([(V[s2], p) for s2, p in problem.arrivals(u)]))
                fn, lines = Qu[u][k]
                acts: tuple[int, ...] = (0, 1)
                if self.ask_first_hard and forced_ask(problem, s, k):
                    vals = fn.values.copy()
                    vals[:, 0] = FORBIDDEN
                    fn, acts = PieceQ(fn.xs, vals), (1,)
                per_k[k] = fn
                parts.append((fn, lines, acts))
            table[s] = per_k
            V[s] = value(parts)
        info = {
            "solver": self.name,
            "representation": self.representation,
            "order": self.order,
            "ask_first_hard": self.ask_first_hard,
            "discount": pomdp.discount,
            "task": pomdp.task.to_dict(),
            "states": len(table),
            "start": {state_key(s): p for s, p in problem.start()},
        }
        policy = SchedulePolicy(table, pomdp.model, pomdp.complexities, self.belief_update, problem.counts, problem.window, info)
        policy.info["value"] = policy.start_value()
        policy.info["seconds"] = time.perf_counter() - t0
        if self.representation == "grid":
            policy.info["grid"] = self.grid
        return policy


# --------------------------------------------------------------------------- alpha vectors


def _alpha_ops(pomdp: AssistancePOMDP, counts: tuple[int, ...]):
    """(mix, value, backup) on envelopes of alpha vectors (exact, bayes update); the backups stop
    when their pieces pass :data:`MAX_PIECES`."""
    zero: Envelope = (np.zeros((1, 2)), np.array([0.0, 1.0]))
    pieces = [0]

    def mix(parts: list[tuple[Envelope, float]]) -> Envelope:
        if not parts:
            return zero
        vecs, xs = parts[0][0][0] * parts[0][1], parts[0][0][1]
        for (v2, xs2), p in parts[1:]:
            u, i1, i2 = cross_sum(xs, xs2)
            vecs, xs = vecs[i1] + p * v2[i2], u
        return vecs, xs

    def value(parts: list[tuple[PieceQ, Any, tuple[int, ...]]]) -> Envelope:
        # the upper envelope of every allowed Q(·, k, a), one envelope at a time
        envs = [(lines[a], fn_xs[a]) for _, (lines, fn_xs), acts in parts for a in acts]
        vecs, xs = envs[0]
        for v2, xs2 in envs[1:]:
            vecs, xs, _, _ = max_of(vecs, xs, v2, xs2)
        return vecs, xs

    def backup(w: Envelope) -> list[tuple[PieceQ, Any]]:
        bk = exact_backup(pomdp, w[0], w[1])
        out = []
        for c in range(pomdp.n_complexity):
            xs_c = np.unique(np.concatenate([bk.q[c][a][1] for a in range(2)]))
            vals = np.stack([envelope_values(*bk.q[c][a], xs_c) for a in range(2)], axis=1)
            out.append((PieceQ(xs_c, vals), ([bk.q[c][a][0] for a in range(2)], [bk.q[c][a][1] for a in range(2)])))
            pieces[0] += xs_c.size + sum(len(bk.q[c][a][0]) for a in range(2))
        if pieces[0] > MAX_PIECES:
            raise SolverError(
                [
                    f"the alpha vectors of {sum(counts):,} items {list(counts)} grew past {MAX_PIECES:,} pieces "
                    "before the solve ended (they grow with the items left): use the grid representation, "
                    "or fewer items"
                ]
            )
        return out

    return mix, value, backup


# --------------------------------------------------------------------------- the belief grid


def _grid_ops(pomdp: AssistancePOMDP, update: str, points: int):
    """(mix, value, backup) on values at a uniform grid of x (linear interpolation)."""
    g = np.linspace(0.0, 1.0, points)
    p0, p1, m0, m1 = pomdp.branches(update).two_level()  # [c, a, br]
    G = g[:, None, None, None]
    prob = p0 * (1 - G) + p1 * G  # (G, c, a, br)
    nxt = m0 * (1 - G) + m1 * G
    if update == "bayes":
        nxt = np.where(prob > 0, nxt / np.where(prob > 0, prob, 1.0), 0.0)
    nxt = np.clip(nxt, 0.0, 1.0)
    R = pomdp.expected_reward  # [c, a, t]
    r = R[..., 0] * (1 - g[:, None, None]) + R[..., 1] * g[:, None, None]  # (G, c, a)
    gamma = pomdp.discount

    def mix(parts: list[tuple[np.ndarray, float]]) -> np.ndarray:
        return sum((p * v for v, p in parts), np.zeros(points))

    def value(parts: list[tuple[PieceQ, Any, tuple[int, ...]]]) -> np.ndarray:
        return np.max([fn.values[:, a] for fn, _, acts in parts for a in acts], axis=0)

    def backup(w: np.ndarray) -> list[tuple[PieceQ, Any]]:
        q = r + gamma * (prob * np.interp(nxt, g, w)).sum(axis=-1)  # (G, c, a)
        return [(PieceQ(g, q[:, c, :]), None) for c in range(pomdp.n_complexity)]

    return mix, value, backup
