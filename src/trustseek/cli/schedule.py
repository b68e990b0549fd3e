"""The ``schedule`` command: solve trial scheduling, and compare schedules."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from ..solvers.defaults import DEFAULT_SCHEDULE_GRID, ORDERS, REPRESENTATIONS
from ..vocab import PAPER_BLOCK_COUNTS
from ._app import FIGURE_SUFFIXES, check_outputs, command, console, make_table, print_json, print_written, write_atomic
from ._options import (
    JsonOpt,
    ModelOpt,
    PolicyOutOpt,
    TaskOpt,
    belief_update_option,
    model_and_task,
    parse_counts,
    people_option,
    seed_option,
)
from ._progress import progress_task


@command("schedule")
def schedule(
    model: str = ModelOpt,
    task: str = TaskOpt,
    counts: str = typer.Option(
        ",".join(map(str, PAPER_BLOCK_COUNTS)), "--counts", "-n", help="Items per complexity: 17,17 or low=17,high=17."
    ),
    window: int = typer.Option(0, "--window", "-w", min=0, help="Items the robot sees ahead (0: every item, full control)."),
    belief_update: str = belief_update_option("bayes"),
    representation: str = typer.Option(
        "grid", "--representation", help=f"Value functions: {' or '.join(REPRESENTATIONS)} (alpha: exact, bayes only)."
    ),
    grid: int = typer.Option(
        DEFAULT_SCHEDULE_GRID, "--grid", "-g", min=2, max=1_000_001, help="Belief grid points (grid representation)."
    ),
    order: str = typer.Option("optimal", "--order", help=f"Item order: {', '.join(ORDERS)}."),
    ask_first_hard: bool = typer.Option(False, "--ask-first-hard", help="Always ask on the first high-complexity item."),
    out: Path | None = PolicyOutOpt,
    compare: bool = typer.Option(
        False, "--compare", help="Also compare the schedules (random order + trust-aware, optimal, heuristics)."
    ),
    participants: int = people_option(20_000, "--participants", help="--compare: simulated participants.", least=2),
    seed: int = seed_option("--compare: random seed."),
    figure: Path | None = typer.Option(None, "--figure", help="--compare: write the schedule figure (PNG, PDF or SVG) here."),
    as_json: bool = JsonOpt,
) -> None:
    from ..policies.scheduling import SchedulePolicy
    from ..pomdp.problem import AssistancePOMDP
    from ..pomdp.scheduling import SchedulingProblem
    from ..solvers.registry import make_solver

    inputs = ((model, "--model file"), (task, "--task file"))
    check_outputs((out, "--out", (".json",)), (figure, "--figure", FIGURE_SUFFIXES), inputs=inputs)
    m, t = model_and_task(model, task)
    pomdp = AssistancePOMDP(m, t)
    n = parse_counts(counts, pomdp.complexities)
    problem = SchedulingProblem.build(pomdp, n, window or None)
    policy = make_solver(
        "schedule",
        belief_update=belief_update,
        representation=representation,
        schedule_grid=grid,
        order=order,
        ask_first_hard=ask_first_hard,
    ).solve(problem)
    assert isinstance(policy, SchedulePolicy)
    x0 = float(m.initial[-1])
    first = None
    if problem.full_control:
        k, a = policy.choose(x0, problem.counts)
        first = {"complexity": pomdp.complexities[k], "robot_action": ("autonomous", "ask")[a]}
    summary: dict[str, Any] = {
        "problem": problem.describe(),
        "policy": policy.overview(),
        "value": policy.info["value"],
        "states": policy.info["states"],
        "seconds": policy.info["seconds"],
        "first_choice": first,
    }
    write_atomic(out, policy.save)
    if out is not None:
        summary["policy_file"] = str(out)
    if compare or figure is not None:
        from ..reproduction.scheduling import scheduling_section

        # one call of 18 s at the default 20,000 participants (12 min at 1,000,000): said while it runs
        with progress_task(as_json, f"comparing the schedules on {participants:,} simulated participants"):
            section = scheduling_section(m, t, problem.counts, participants, seed, belief_update=belief_update)
        summary["comparison"] = section.numbers
        if figure is not None:
            from ..plots.scheduling import plot_scheduling_section

            write_atomic(figure, lambda tmp: plot_scheduling_section(section, tmp))
            section.numbers["figure"] = str(figure)
    if as_json:
        print_json(summary)
        return
    console.print(f"{policy.describe()}")
    console.print(
        f"expected discounted reward from b0 = {x0:g}: {summary['value']:.4f} "
        f"({summary['states']} states, {summary['seconds'] * 1000:.0f} ms)"
    )
    if first is not None:
        console.print(f"first trial: a {first['complexity']} item, {first['robot_action']}")
    print_written(("policy", out))
    if "comparison" in summary:
        _print_comparison(summary["comparison"])


def _print_comparison(sec: dict[str, Any]) -> None:
    title = f"Schedules ({sec['participants']} simulated participants, same supervisors and queues)"
    table = make_table(title, "schedule", "exact", "discounted [95% CI]", "gain over random + trust-aware", "cumulative", "asks")
    for r in sec["schedules"]:
        d, g, c = r["discounted"], r["gain_discounted"], r["cumulative"]
        ex = "-" if r["exact_discounted"] is None else f"{r['exact_discounted']:.3f}"
        table.add_row(
            r["schedule"],
            ex,
            f"{d['mean']:.3f} [{d['low']:.3f}, {d['high']:.3f}]",
            f"{g['mean']:+.3f} [{g['low']:+.3f}, {g['high']:+.3f}]",
            f"{c['mean']:.2f}",
            f"{r['asks']:.2f}",
        )
    console.print(table)
    wv = ", ".join(f"w={w}: {v:.3f}" for w, v in sec["window_values"].items())
    console.print(f"value by window: {wv}")
    console.print(sec["explanation"])
    if "figure" in sec:
        console.print(f"figure written to {sec['figure']}")
