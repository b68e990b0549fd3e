"""Supervisor-type commands: fit-types, select-types, personalize."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import typer
from rich.markup import escape
from rich.table import Table

from ..errors import TrustseekError
from ..estimation.options import FitOptions
from ..parallel import MAX_JOBS
from ._app import check_output, check_outputs, command, console, make_table, print_json, print_written, write_atomic
from ._options import (
    FROM_OPTIONS,
    LogArg,
    LogReading,
    OneRowPerTrialLogArg,
    PrintJsonOpt,
    QuietOpt,
    SeedOpt,
    SelectionJobsOpt,
    bootstrap_option,
    json_option,
    log_inputs,
    log_options,
    restarts_option,
    tol_option,
    widen_option,
)
from ._output import check_plots_folder, fit_summary, print_selection, print_warnings, run_selection
from ._progress import bar_task, progress_bar
from ._reading import POSTERIOR_SUFFIXES, load_types, read_for_types, read_with_inputs, widened_note, write_log

TransitionsOnOpt = typer.Option(
    None, "--transitions-on", help="Inputs of the trust transitions (as for fit: complexity, robot_action, experience)."
)
EmissionsOnOpt = typer.Option(
    None, "--emissions-on", help="Inputs of the human-action probabilities (as for fit: complexity, robot_action)."
)
DifferOpt = typer.Option(
    "all",
    "--differ",
    help="What differs between types: 'all', or some of initial, emission, transition, comma-separated (the rest is "
    "shared by every type).",
)


def _check_differ(differ: str) -> None:
    """--differ refused before the log is read when it names no part of the model."""
    from ..estimation.mixture_em import parse_differ

    parse_differ(differ)


def parse_types(text: str) -> tuple[int, ...]:
    """``1..4`` or ``1,2,3``: the numbers of types to compare."""
    from ..estimation.selection import MAX_TYPES

    ends: tuple[int, ...]
    try:
        if ".." in text:
            a, b = (int(x) for x in text.split("..", 1))
            ends = (a, b) if a <= b else ()
        else:
            ends = tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise TrustseekError([f"--types: expected e.g. 1..4 or 1,2,3, got {text!r}"]) from None
    # the ends are checked before a range is made of them: 1..1000000000 is refused at once
    if not ends or min(ends) < 1 or max(ends) > MAX_TYPES:
        raise TrustseekError([f"--types: numbers of types between 1 and {MAX_TYPES}, e.g. 1..4; got {text!r}"])
    if ".." in text:
        return tuple(range(ends[0], ends[1] + 1))
    if len(set(ends)) != len(ends):
        raise TrustseekError([f"--types: a number of types is given twice, e.g. 1,2,3; got {text!r}"])
    return ends


@command("fit-types")
@log_options()
def fit_types(
    log: list[Path] = OneRowPerTrialLogArg,
    types: int = typer.Option(2, "--types", "-m", min=1, max=12, help="Number of supervisor types."),
    differ: str = DifferOpt,
    transitions_on: str | None = TransitionsOnOpt,
    emissions_on: str | None = EmissionsOnOpt,
    restarts: int = restarts_option(10, help="Starts (half from the perturbed pooled fit, half random)."),
    bootstrap: int = bootstrap_option(0, "Participant bootstrap resamples for 95% intervals."),
    seed: int = SeedOpt,
    tol: float = tol_option(1e-8, "Relative log-likelihood tolerance (> 0)."),
    max_iter: int = typer.Option(1000, "--max-iter", min=1, help="E-step cap per start."),
    jobs: int | None = typer.Option(None, "--jobs", "-j", min=1, max=MAX_JOBS, help="Threads (fit) and processes (bootstrap)."),
    out: Path | None = typer.Option(None, "--out", "-o", help="Write the types (JSON trustseek.mixture/1)."),
    type_posteriors: Path | None = typer.Option(
        None, "--type-posteriors", help="Write P(type | trials) per participant (CSV/Parquet)."
    ),
    plots: Path | None = typer.Option(None, "--plots", help="Write per-type figures into this directory."),
    as_json: bool = json_option("Print the fit as one JSON object."),
    reading: LogReading = FROM_OPTIONS,
    quiet: bool = QuietOpt,
) -> None:
    outputs = ((out, "--out"), (type_posteriors, "--type-posteriors", POSTERIOR_SUFFIXES))
    check_outputs(*outputs, inputs=(*log_inputs(log), *reading.inputs()))
    check_plots_folder(plots)
    _check_differ(differ)
    tr, em, frame = read_with_inputs(log, reading, transitions_on, emissions_on)
    named = [c for c in (*em, *tr) if c not in ("complexity", "robot_action", "experience")]
    if plots is not None and named:
        raise TrustseekError([f"--plots draws trust-model types; types of the named inputs {named} have no figures here"])
    from ..estimation.mixture import fit_types as fit_mixture

    with progress_bar(quiet or as_json) as bar:
        fit = fit_mixture(
            frame,
            types,
            options=FitOptions(restarts=restarts, seed=seed, tol=tol, max_iter=max_iter, n_jobs=jobs),
            differ=differ,
            progress=bar_task(bar, "starts", restarts),
            transition_inputs=tr,
            emission_inputs=em,
        )
        intervals = _bootstrap_types(fit, bootstrap, seed, jobs, bar)
    mixture = fit.mixture()
    write_atomic(out, mixture.save)
    post = fit.posterior_frame()
    write_atomic(type_posteriors, lambda tmp: write_log(post, tmp))
    if plots is not None:
        from ..plots.supervisor_types import plot_types

        written = plot_types(mixture, plots, None if intervals is None else intervals.cells)
    if as_json:
        print_json(_types_json(fit, mixture, post, intervals))
        return
    _print_types(fit, mixture, post, intervals)
    if intervals is not None:
        print_warnings(intervals.notes())
    figures = None if plots is None else ", ".join(str(p) for p in written)
    print_written(("types", out), ("type posteriors", type_posteriors), ("figures", figures))


def _bootstrap_types(fit, bootstrap: int, seed: int, jobs: int | None, bar):
    """The types' bootstrap intervals (None without --bootstrap), with a progress bar of their own."""
    if bootstrap <= 0:
        return None
    from ..estimation.mixture import TYPE_REFITS, bootstrap_types

    options = replace(TYPE_REFITS, seed=seed, n_jobs=jobs)
    return bootstrap_types(fit, bootstrap, options=options, progress=bar_task(bar, "bootstrap", bootstrap))


def _types_json(fit, mixture, post, intervals) -> dict:
    d = fit.to_dict()
    d["mixture"] = mixture.to_dict()
    d["type_counts"] = post["type"].value_counts().reindex(list(fit.names), fill_value=0).to_dict()
    if intervals is not None:
        d["weight_intervals"] = intervals.weights
        d["interval_notes"] = intervals.notes()
        d["intervals"] = {
            n: {t: {"lower": lo.tolist(), "upper": hi.tolist()} for t, (lo, hi) in c.items()} for n, c in intervals.cells.items()
        }
    return d


def _print_types(fit, mixture, post, intervals) -> None:
    """The types' table, the fit's summary, the legend and the warnings."""
    console.print(_types_table(fit, mixture, post, intervals))
    if mixture.general:
        console.print(
            f"general types (inputs: {', '.join(mixture.models[0].used_inputs) or 'none'}): decode and personalize "
            "read them; planning needs trust models",
            highlight=False,
        )
    console.print(fit_summary(fit, "starts", len(fit.runs)), highlight=False)
    console.print(
        "people: participants whose most probable type it is; rely: "
        + ("P(rely | T, inputs)" if mixture.general else "P(rely | T, C, autonomous)")
        + "; types are ordered "
        "by their mean P(rely) over the estimated emission rows, lowest first",
        highlight=False,
    )
    print_warnings(fit.warnings)


def _types_table(fit, mixture, post, intervals) -> Table:
    """The fitted types, one row each: weight (and interval), people, P(T1 = highest level), P(rely) cells."""
    heads, rely_of = _rely_cells(mixture)
    title = f"{fit.n_types} supervisor types ({fit.seqs.n_participants} participants, {fit.seqs.n_trials} trials; "
    top = f"P(T1={mixture.trust_levels[-1]})"
    out = make_table(f"{title}{', '.join(fit.differ)} differ)", "type", "weight", "people", top, *map(escape, heads))
    counts = post["type"].value_counts()
    for name, w, m in zip(fit.names, fit.weights, mixture.models, strict=True):
        weight = f"{w:.3f}"
        if intervals is not None:
            lo, hi = intervals.weights[name]
            weight += escape(f" [{lo:.2f}, {hi:.2f}]")
        rely = [f"{x:.2f}" for x in rely_of(m)]
        out.add_row(name, weight, str(int(counts.get(name, 0))), f"{m.initial[-1]:.2f}", *rely)
    return out


def _rely_cells(mixture):
    """The table's P(rely) columns: per complexity and trust level without asking (trust models), or
    per combination of the emission inputs and level (general models); and each type's values."""
    m0 = mixture.models[0]
    levels = mixture.trust_levels
    if mixture.general:
        rely = m0.output_categories.index("rely") if "rely" in m0.output_categories else -1
        combos = range(m0.emission.shape[0])
        heads = [
            f"rely {' '.join(f'{c}={v}' for c, v in m0.combination('emission', u).items())} T={t}".replace("  ", " ")
            for u in combos
            for t in levels
        ]
        return heads, lambda m: [m.emission[u, k, rely] for u in combos for k in range(len(levels))]
    cells = [(i, k) for i in range(len(m0.complexities)) for k in range(len(levels))]
    heads = [f"rely C={m0.complexities[i]} T={levels[k]}" for i, k in cells]
    return heads, lambda m: [m.emission[i, 0, k, 1] for i, k in cells]


@command("select-types")
@log_options()
def select_types(
    log: list[Path] = LogArg,
    types: str = typer.Option("1..4", "--types", help="Numbers of types to compare, e.g. 1..4 or 1,2,3."),
    differ: str = DifferOpt,
    transitions_on: str | None = TransitionsOnOpt,
    emissions_on: str | None = EmissionsOnOpt,
    folds: int = typer.Option(5, "--folds", min=2, help="Folds over participants for the held-out log-likelihood."),
    restarts: int = restarts_option(10, help="Starts per fit (and the fit with one type fewer, split)."),
    seed: int = SeedOpt,
    tol: float = tol_option(1e-6, "Relative log-likelihood tolerance per fit (> 0)."),
    jobs: int | None = SelectionJobsOpt,
    widen: bool = widen_option(12, "the numbers given"),
    as_json: bool = PrintJsonOpt,
    reading: LogReading = FROM_OPTIONS,
    quiet: bool = QuietOpt,
) -> None:
    values = parse_types(types)
    _check_differ(differ)
    from ..estimation import selection

    tr, em, frame = read_with_inputs(log, reading, transitions_on, emissions_on)
    options = FitOptions(restarts=restarts, seed=seed, tol=tol, n_jobs=1)
    how = {"folds": folds, "options": options, "widen": widen, "jobs": jobs, "differ": differ}
    rows = run_selection(selection.select_types, frame, quiet or as_json, tr, em, types=values, **how)
    warnings = widened_note(rows, "types", max(values)) + selection.type_selection_warnings(rows)
    weights = {"weights": lambda r: ", ".join(f"{w:.2f}" for w in r["weights"])}
    print_selection("Number of supervisor types", "types", rows, folds, warnings, as_json, extra=weights)


@command("personalize")
@log_options()
def personalize(
    log: list[Path] = LogArg,
    model: str = typer.Option(
        ..., "--model", "-m", help="The centre: a trust model or types JSON (e.g. from fit / fit-types), or a preset name."
    ),
    out: Path = typer.Option(..., "--out", "-o", help="A new or empty folder: a model JSON per participant, participants.csv."),
    strength: float | None = typer.Option(
        None, "--strength", min=0.0, help="Prior strength s (pseudo-counts per row); default: estimated per table."
    ),
    estimate: str = typer.Option(
        "held-out",
        "--estimate",
        help="How s is estimated: held-out (log-likelihood of blocks of each participant's trials) or variational "
        "(variational empirical Bayes, which shrinks more).",
    ),
    tol: float = tol_option(1e-8, "Relative tolerance of each participant's EM (> 0)."),
    as_json: bool = json_option("Print the strengths and the per-participant summary as JSON."),
    reading: LogReading = FROM_OPTIONS,
) -> None:
    if estimate not in ("held-out", "variational"):
        raise TrustseekError([f"--estimate must be held-out or variational, got {estimate!r}"])
    check_output(out, "--out", directory=True)
    from ..estimation.personal import personalize as run

    centre = load_types(Path(model))
    frame = read_for_types(log, centre, reading)  # the columns it uses
    centre_model = centre if centre.n_types > 1 else centre.models[0]
    res = run(frame, centre_model, strength=strength, options=FitOptions(tol=tol, n_jobs=1), estimate=estimate)
    write_atomic(out, res.save, directory=True)
    if as_json:
        print_json({**res.summary(), "participants": res.frame().to_dict(orient="records")})
        return
    s = ", ".join(f"{k} {v:.3g}" + (" (at bound)" if res.at_bound[k] else "") for k, v in res.strength.items())
    console.print(f"prior strength per table: {s}", highlight=False)
    for k, how in res.method.items():
        console.print(f"  {k}: {how}", highlight=False)
    if res.estimate != "given":
        what = "held-out log-likelihood" if res.estimate == "held-out" else "variational bound on the log evidence"
        console.print(
            f"{what}: {res.score:.3f} at these strengths, {res.score_centre:.3f} at the centre "
            f"({res.score - res.score_centre:+.3f})",
            highlight=False,
        )
    gain = float((res.loglik - res.centre_loglik).sum())
    console.print(
        f"{len(res.models)} participants; log-likelihood under their own models {res.loglik.sum():.3f} "
        f"(under the centre {res.centre_loglik.sum():.3f}, +{gain:.3f})",
        highlight=False,
    )
    print_warnings(res.warnings)
    console.print(f"models written to {out}/ (participants.csv lists each participant's file)")
