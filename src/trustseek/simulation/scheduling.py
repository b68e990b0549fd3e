"""Evaluating trial schedules: exact finite-horizon values, and simulation with common random numbers.

:data:`SCHEDULES`: the paper's random order with its stationary trust-aware policy; random order
with the asks optimal for the finite session; full control (the optimal schedule and asks);
heuristic orders (easy first, hard first, alternating) with finite-horizon-optimal asks; and
asking on the first hard item.  Every schedule but the first is a :class:`SchedulePolicy` whose
exact value is the solver's.  :func:`simulate_schedules` runs schedule and plain policies on the
same supervisors: one random queue of items per participant, the same three uniforms on trial t
whatever the schedule does, so differences are paired.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..model.core import TrustModel
from ..model.task import Task
from ..policies.base import Policy
from ..policies.scheduling import SchedulePolicy
from ..pomdp.belief import ScalarBelief
from ..pomdp.problem import AssistancePOMDP
from ..pomdp.scheduling import SchedulingProblem
from ..solvers.alpha import finite_horizon_value
from ..solvers.defaults import DEFAULT_SCHEDULE_GRID
from ..solvers.registry import make_solver
from .engine import Tables
from .populations import SimulationError, Supervisors, check_participants
from .trial_orders import schedule_counts

#: name -> (window (0: full control), order, ask on the first hard item); None: the paper's policy
SCHEDULES: dict[str, tuple[int, str, bool] | None] = {
    "random + trust-aware": None,
    "random + finite-horizon": (1, "optimal", False),
    "optimal": (0, "optimal", False),
    "easy first": (0, "easy-first", False),
    "hard first": (0, "hard-first", False),
    "alternating": (0, "alternating", False),
    "ask on first hard": (1, "optimal", True),
}


def schedule_policies(
    pomdp: AssistancePOMDP,
    counts: tuple[int, ...],
    belief_update: str = "bayes",
    representation: str = "grid",
    grid: int = DEFAULT_SCHEDULE_GRID,
    names: tuple[str, ...] | None = None,
) -> dict[str, Policy]:
    """The policies of :data:`SCHEDULES` (or those named) for ``counts`` items."""
    out: dict[str, Policy] = {}
    for name in names or tuple(SCHEDULES):
        if name not in SCHEDULES:
            raise SimulationError([f"unknown schedule {name!r}; expected one of {list(SCHEDULES)}"])
        spec = SCHEDULES[name]
        if spec is None:
            out[name] = make_solver("grid", belief_update=belief_update).solve(pomdp)
            continue
        window, order, ask_first = spec
        problem = SchedulingProblem(pomdp, counts, window or None)
        solver = make_solver(
            "schedule",
            belief_update=belief_update,
            representation=representation,
            schedule_grid=grid,
            order=order,
            ask_first_hard=ask_first,
        )
        out[name] = solver.solve(problem)
    return out


def exact_values(policies: Mapping[str, Policy]) -> dict[str, float | None]:
    """The exact expected discounted reward of each schedule policy at the initial belief (the
    finite-horizon value; None for a plain policy, which is only simulated)."""
    return {n: (float(p.info["value"]) if isinstance(p, SchedulePolicy) else None) for n, p in policies.items()}


def iid_value(pomdp: AssistancePOMDP, trials: int) -> float:
    """The optimal finite-horizon value when the complexities are i.i.d. from P(C) instead of a
    random order of fixed counts (exact alpha vectors, ``bayes`` update)."""
    return finite_horizon_value(pomdp, trials, pomdp.model.initial)


@dataclass
class ScheduleRuns:
    """Per participant and schedule: rewards and what happened on each trial."""

    names: list[str]
    discounted: np.ndarray  # (n, S)
    cumulative: np.ndarray  # (n, S)
    complexity: np.ndarray  # (S, n, T) int8
    action: np.ndarray  # (S, n, T) int8
    belief: np.ndarray  # (S, n, T): P(trust = high) before each trial

    def column(self, name: str) -> int:
        return self.names.index(name)


def simulate_schedules(
    model: TrustModel,
    task: Task,
    policies: Mapping[str, Policy],
    counts: tuple[int, ...],
    n_participants: int,
    seed: int = 0,
) -> ScheduleRuns:
    """Run every policy on the same ``n_participants`` supervisors drawn from ``model`` (two
    trust levels): the same queue of items and the same uniforms on trial t.  A schedule
    policy picks among the first ``window`` items of its queue (every remaining item with
    full control); a plain policy takes the items in queue order."""
    check_participants(n_participants)
    if model.n_trust != 2:
        raise SimulationError([f"schedule simulation needs two trust levels; this model has {model.n_trust}"])
    m, T = n_participants, sum(counts)
    ss = np.random.SeedSequence(seed)
    s_queue, s_sup = ss.spawn(2)
    queue0 = schedule_counts(m, counts, np.random.default_rng(s_queue), task.complexities).astype(np.int64)
    u_all = np.random.default_rng(s_sup).random((T + 1, 3, m))
    tab = Tables(Supervisors.pooled(model, 1), task)
    S = len(policies)
    out = ScheduleRuns(
        list(policies),
        np.zeros((m, S)),
        np.zeros((m, S)),
        np.zeros((S, m, T), dtype=np.int8),
        np.zeros((S, m, T), dtype=np.int8),
        np.zeros((S, m, T)),
    )
    idx = np.arange(m)
    for j, (name, pol) in enumerate(policies.items()):
        sb = ScalarBelief(pol.model or model, pol.belief_update or "bayes")
        x = np.full(m, sb.x0)
        trust = (u_all[T, 0] >= model.initial[0]).astype(np.int64)
        taken = np.zeros((m, T), dtype=bool)
        remaining = np.tile(np.asarray(counts, dtype=np.int64), (m, 1))
        window = pol.window if isinstance(pol, SchedulePolicy) else 1
        for t in range(T):
            free = ~taken
            rank = np.cumsum(free, axis=1) - 1
            vis = free & (rank < (T if window is None else window))
            if isinstance(pol, SchedulePolicy):
                visible = np.stack([(vis & (queue0 == k)).sum(axis=1) for k in range(len(counts))], axis=1)
                c, a = pol.choices(x, remaining, None if window is None else visible)
            else:
                pos = np.argmax(vis, axis=1)
                c = queue0[idx, pos]
                a = np.asarray(pol.actions(np.stack([1 - x, x], axis=1), c), dtype=np.int64)
            # take the first visible item of the chosen complexity off the queue
            pos = np.argmax(vis & (queue0 == c[:, None]), axis=1)
            if not np.all(vis[idx, pos] & (queue0[idx, pos] == c)):
                raise SimulationError([f"{name}: a pick that is not among the visible items"])
            taken[idx, pos] = True
            remaining[idx, c] -= 1
            ca = c * 2 + a
            o, e, trust = tab.trial(u_all[t], ca, ca, trust)
            r = tab.reward[(a * 2 + o) * 2 + e]
            out.complexity[j, :, t], out.action[j, :, t], out.belief[j, :, t] = c, a, x
            out.discounted[:, j] += task.discount**t * r
            out.cumulative[:, j] += r
            x = sb.step(x, ca, o, e)
    return out
