"""The report section on trial scheduling (the paper's future work): how much choosing the order
of the low- and high-complexity items is worth, and what the optimal schedule does.

:func:`scheduling_section` computes every number of the section for a model (the paper's by
default, or a fitted one) and keeps the optimal policy and the simulated runs that its figure
is drawn from (``trustseek.plots.scheduling.plot_scheduling_section``; figures sit above this
layer). The report renders ``numbers`` and the figure.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..model.core import TrustModel
from ..model.presets import paper_model, paper_task
from ..model.task import Task
from ..policies.scheduling import SchedulePolicy
from ..pomdp.problem import AssistancePOMDP
from ..pomdp.scheduling import SchedulingProblem
from ..simulation.scheduling import ScheduleRuns, exact_values, iid_value, schedule_policies, simulate_schedules
from ..solvers.registry import make_solver
from ..statistics import mean_interval
from ..vocab import PAPER_BLOCK_COUNTS

BASELINE = "random + trust-aware"


@dataclass
class SchedulingSection:
    """The section's numbers (JSON-ready), the optimal schedule policy and the simulated runs."""

    numbers: dict[str, Any]
    optimal: SchedulePolicy
    runs: ScheduleRuns


def scheduling_section(
    model: TrustModel | None = None,
    task: Task | None = None,
    counts: tuple[int, ...] = PAPER_BLOCK_COUNTS,
    participants: int = 20000,
    seed: int = 0,
    windows: tuple[int, ...] = (1, 2, 3, 5),
    belief_update: str = "bayes",
) -> SchedulingSection:
    """The section's numbers: exact finite-horizon values of every schedule, their simulated
    discounted and cumulative rewards on the same supervisors with 95 % intervals, the paired
    gains over the paper's random order with its trust-aware policy, the value of seeing a
    window of w items, and a description of the optimal schedule."""
    model = model or paper_model()
    task = task or paper_task()
    pomdp = AssistancePOMDP(model, task)
    counts = tuple(counts)
    policies = schedule_policies(pomdp, counts, belief_update=belief_update)
    runs = simulate_schedules(model, task, policies, counts, participants, seed=seed)
    exact = exact_values(policies)
    base = runs.column(BASELINE)
    rows = []
    for j, name in enumerate(runs.names):
        rows.append(
            {
                "schedule": name,
                "exact_discounted": exact[name],
                "discounted": mean_interval(runs.discounted[:, j]),
                "cumulative": mean_interval(runs.cumulative[:, j]),
                "gain_discounted": mean_interval(runs.discounted[:, j] - runs.discounted[:, base]),
                "gain_cumulative": mean_interval(runs.cumulative[:, j] - runs.cumulative[:, base]),
                "asks": float(runs.action[j].sum(axis=1).mean()),
            }
        )
    window_values = {}
    for w in windows:
        if w < sum(counts):
            pol = make_solver("schedule", belief_update=belief_update).solve(SchedulingProblem(pomdp, counts, w))
            window_values[str(w)] = pol.info["value"]
    optimal = policies["optimal"]
    assert isinstance(optimal, SchedulePolicy)
    window_values["all"] = optimal.info["value"]
    out: dict[str, Any] = {
        "counts": dict(zip(task.complexities, counts, strict=True)),
        "participants": participants,
        "seed": seed,
        "discount": task.discount,
        "belief_update": belief_update,
        "schedules": rows,
        "window_values": window_values,
        "iid_value": iid_value(pomdp, sum(counts)) if belief_update == "bayes" else None,
        "explanation": explain(optimal, runs),
    }
    return SchedulingSection(out, optimal, runs)


def explain(policy: SchedulePolicy, runs: Any, name: str = "optimal") -> str:
    """A few sentences on what the schedule does in simulation: its item order and its asks."""
    j = runs.names.index(name)
    cx, act, bel = runs.complexity[j], runs.action[j], runs.belief[j]
    cn = policy.complexities
    T = cx.shape[1]
    modal = [cn[int(np.bincount(cx[:, t], minlength=len(cn)).argmax())] for t in range(T)]
    runs_text, start = [], 0
    for t in range(1, T + 1):
        if t == T or modal[t] != modal[start]:
            runs_text.append(f"{t - start} {modal[start]}")
            start = t
    same = float((cx == cx[0]).all(axis=1).mean())
    asks = {c: float(act[cx == k].mean()) if (cx == k).any() else None for k, c in enumerate(cn)}
    return (
        f"The most common order is {', then '.join(runs_text)} items "
        f"({same:.0%} of simulated sessions follow the first session's order exactly). "
        + " ".join(f"On {c} items it asks {p:.0%} of the time." for c, p in asks.items() if p is not None)
        + f" The mean belief in high trust falls from {bel[:, 0].mean():.2f} to {bel[:, -1].mean():.2f}."
    )
