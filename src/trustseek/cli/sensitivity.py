"""The sensitivity command: how far the threshold and V move within the parameters' printed precision."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.markup import escape

from ._app import FIGURE_SUFFIXES, check_outputs, command, console, make_table, print_json, print_written, write_atomic
from ._options import JsonOpt, ModelOpt, TaskOpt, belief_update_option, model_and_task, processes_option, seed_option


@command("sensitivity")
def sensitivity(
    model: str = ModelOpt,
    task: str = TaskOpt,
    belief_update: str = belief_update_option("paper", " of the policy"),
    decimals: int = typer.Option(
        2,
        "--decimals",
        "-d",
        min=0,
        max=12,
        help="Printed decimals of each probability (each moves by ± half a unit of the last).",
    ),
    grid: int = typer.Option(401, "--grid", "-g", min=3, max=1_000_001, help="Belief grid points of each solve."),
    samples: int = typer.Option(
        256, "--samples", min=0, max=1_000_000, help="Latin-hypercube points that check the optimised joint range."
    ),
    starts: int = typer.Option(
        2, "--starts", min=1, max=1000, help="L-BFGS-B starts per extreme (the one-at-a-time corner first)."
    ),
    seed: int = seed_option("Seed of the sample and of random starts."),
    model_only: bool = typer.Option(False, "--model-only", help="Leave the task's success probabilities and discount fixed."),
    top: int = typer.Option(10, "--top", min=1, help="Parameters shown in the one-at-a-time table."),
    plot: Path | None = typer.Option(None, "--plot", help="Write a tornado plot of the threshold to this PNG, PDF or SVG file."),
    jobs: int | None = processes_option("the extremes"),
    as_json: bool = JsonOpt,
) -> None:
    from ..solvers.sensitivity import free_parameters
    from ..solvers.sensitivity import sensitivity as run_sensitivity

    check_outputs((plot, "--plot", FIGURE_SUFFIXES), inputs=((model, "--model file"), (task, "--task file")))
    m, t = model_and_task(model, task)
    res = run_sensitivity(
        m,
        t,
        decimals=decimals,
        belief_update=belief_update,
        grid=grid,
        samples=samples,
        starts=starts,
        seed=seed,
        parameters=free_parameters(m, t, decimals, include_task=not model_only),
        jobs=jobs,
    )
    if plot is not None:
        from ..plots.sensitivity import plot_tornado

        q = next(q for q in res.quantities if q.startswith("threshold"))
        write_atomic(plot, lambda tmp: plot_tornado(res, q, tmp))
    if as_json:
        d = res.to_dict()
        if plot is not None:
            d["plot"] = str(plot)
        print_json(d)
        return
    h = 0.5 * 10.0**-decimals
    console.print(
        f"{len(res.parameters)} free parameters, each ± {h:g} around its value (clipped to [0, 1]); "
        f"belief update {belief_update}, {grid}-point grid, {res.settings['evaluations']} solves."
    )
    summary = make_table(
        "Joint range over the box", "quantity", "printed values", "joint min", "joint max", f"sample of {samples}"
    )
    for q in res.quantities:
        lo, hi = res.range_of(q)
        s = res.sampled.get(q, {})
        sample = escape(f"[{s['min']:.4f}, {s['max']:.4f}]") if s.get("n") else "–"
        summary.add_row(escape(q), f"{res.nominal[q]:.4f}", f"{lo:.4f}", f"{hi:.4f}", sample)
    console.print(summary)
    for q in res.quantities:
        if not q.startswith("threshold"):
            continue
        rows = sorted(res.one_at_a_time, key=lambda r: -abs(r["at_upper"][q] - r["at_lower"][q]))[:top]
        columns = ("parameter", "value", "box", escape(f"{q} at lower"), escape(f"{q} at upper"))
        table = make_table(escape(f"One at a time: {q} (largest effects first)"), *columns)
        for r in rows:
            table.add_row(
                escape(r["name"]),
                f"{r['value']:.4g}",
                escape(f"[{r['lower']:.4g}, {r['upper']:.4g}]"),
                f"{r['at_lower'][q]:.4f}",
                f"{r['at_upper'][q]:.4f}",
            )
        console.print(table)
    print_written(("tornado plot", plot))
