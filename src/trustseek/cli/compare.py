"""The compare-types command: pooled, type-aware, oracle and trust-agnostic policies on a
population of supervisor types (the paper's Remark 1)."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.markup import escape

from ..errors import TrustseekError
from ._app import FIGURE_SUFFIXES, check_output, check_positive, command, console, make_table, print_json, write_atomic
from ._options import JsonOpt, QuietOpt, TaskOpt, parse_counts, people_option, restarts_option, seed_option
from ._progress import progress_bar


@command("compare-types")
def compare_types(
    mixture: str = typer.Option(
        "paper+conservative",
        "--mixture",
        "--types",
        "-m",
        help="Supervisor types: a preset (paper+conservative) or a mixture JSON file (e.g. from 'trustseek fit-types'); "
        "--types as in solve and simulate.",
    ),
    share: float | None = typer.Option(
        None, "--share", min=0.0, max=1.0, help="Share of the last type of two, e.g. 0.3 (default: the mixture's weights)."
    ),
    task: str = TaskOpt,
    participants: int = people_option(2_000, "--participants", "-n", help="Simulated people per population and block."),
    fit_participants: int = people_option(
        200, "--fit-participants", help="People of experiment 1 that the pooled model is fitted to (paper design).", least=2
    ),
    block: list[str] = typer.Option(
        ["17,17", "68,68"],
        "--block",
        "-b",
        help="Trials per complexity in a block, e.g. 17,17 or low=17,high=17 (repeat for several lengths).",
    ),
    restarts: int = restarts_option(4, "--restarts", help="EM restarts of the pooled fit."),
    gap: float = typer.Option(
        0.03, "--gap", min=0.0, help="Certified bound gap of each trust-aware solve at its initial belief."
    ),
    max_seconds: float = typer.Option(
        600.0, "--max-seconds", min=0.0, help="Safety time limit of each solve (the gap reached is kept)."
    ),
    seed: int = seed_option("Seed of every simulation and fit."),
    plot: Path | None = typer.Option(None, "--plot", help="Write the figure to this PNG, PDF or SVG file."),
    as_json: bool = JsonOpt,
    quiet: bool = QuietOpt,
) -> None:
    from ..model.presets import load_mixture, load_task
    from ..reproduction.supervisor_types import types_section
    from ..simulation.populations import check_size

    check_positive(gap, "--gap")  # the solver refuses them too, but only after the pooled fit
    check_positive(max_seconds, "--max-seconds")
    mix = load_mixture(mixture)
    if share is not None:
        if mix.n_types != 2:
            raise TrustseekError([f"--share needs a mixture of two types; {mixture} has {mix.n_types}"])
        mix = mix.with_weights([1 - share, share])
    t = load_task(task)
    counts = [parse_counts(b, t.complexities, "--block") for b in block]
    for c in counts:  # before the pooled fit and the solves, not after them
        check_size(participants, sum(c), "--participants, --block")
    check_output(plot, "--plot", FIGURE_SUFFIXES)
    steps = ["pooled fit", "policies", "one-type policies", *[f"blocks of {sum(c)} trials" for c in counts]]
    with progress_bar(quiet or as_json) as bar:
        tid = bar.add_task("compare-types", total=len(steps))
        sec = types_section(
            mix,
            t,
            participants=participants,
            block_counts=counts,
            fit_participants=fit_participants,
            restarts=restarts,
            seed=seed,
            gap=gap,
            max_seconds=max_seconds,
            progress=lambda _s: bar.advance(tid),
        )
    if plot is not None:
        from ..plots.type_comparison import plot_types_section

        write_atomic(plot, lambda tmp: plot_types_section(sec.numbers, tmp))
    if as_json:
        print_json(sec.numbers)
        return
    for pop in sec.numbers["populations"]:
        title = f"{pop['population']}, {pop['trials']} trials: cumulative reward per block [95 % CI]"
        policies = list(pop["groups"][0]["reward"])
        tab = make_table(title, "group", *policies, "type-aware − pooled", title_justify="center")
        for g in pop["groups"]:
            d = next(d for d in g["differences"] if d["policy"] == "type-aware" and d["against"] == "pooled trust-aware")
            tab.add_row(
                f"{g['group']} (n = {g['participants']})",
                *[f"{g['reward'][p]['mean']:.2f} [{g['reward'][p]['low']:.2f}, {g['reward'][p]['high']:.2f}]" for p in policies],
                f"{d['mean']:+.2f} [{d['low']:+.2f}, {d['high']:+.2f}]",
            )
        console.print(tab)
    for v in sec.numbers["verdicts"]:
        console.print(escape(v))
