"""Estimation commands: fit, decode, select."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from .. import estimation  # its names load on first use, when a command runs
from ..errors import TrustseekError
from ..estimation.options import FitOptions
from ..parallel import MAX_JOBS
from ._app import check_outputs, command, console, print_json, print_written, write_atomic
from ._options import (
    FROM_OPTIONS,
    AsForFitEmissionsOpt,
    AsForFitTransitionsOpt,
    LogArg,
    LogReading,
    MaxIterOpt,
    OneRowPerTrialLogArg,
    PrintJsonOpt,
    QuietOpt,
    RatingPerOpt,
    SeedOpt,
    SelectionJobsOpt,
    bootstrap_option,
    json_option,
    log_inputs,
    log_options,
    restarts_option,
    seed_option,
    tol_option,
    widen_option,
)
from ._output import (
    cells_table,
    check_plots_folder,
    fit_summary,
    print_intervals_note,
    print_selection,
    print_warnings,
    run_selection,
)
from ._progress import progress_bar
from ._reading import (
    POSTERIOR_SUFFIXES,
    general_inputs,
    keep_columns,
    load_types,
    named_inputs,
    note_copied_rating,
    read_for_types,
    read_with_inputs,
    widened_note,
    write_log,
)

_TransitionsOnOpt = typer.Option(
    None,
    "--transitions-on",
    help="Comma-separated inputs of the trust transitions (default: complexity, robot_action, experience; 'none' for "
    "none); the mapping's 'inputs' may be named too: the fit is then a general model (trustseek.iohmm/1).",
)
_EmissionsOnOpt = typer.Option(
    None,
    "--emissions-on",
    help="Comma-separated inputs of the human-action probabilities (default: complexity, robot_action; 'none' for "
    "none); the mapping's 'inputs' may be named too.",
)
_BootstrapOpt = bootstrap_option(
    0, "Participant-level bootstrap resamples for 95% intervals (0 = none; at least 200 advised, fewer warn)."
)
_PriorOpt = typer.Option(
    0.0, "--prior", min=0.0, help="Dirichlet pseudo-count added to every free cell (MAP); 0 = maximum likelihood."
)
_TolOpt = tol_option(1e-8, "Stop when the relative change of the log-likelihood is below this (> 0).")
_JobsOpt = typer.Option(
    None,
    "--jobs",
    "-j",
    min=1,
    max=MAX_JOBS,
    help="Threads for the fit and processes for the bootstrap (default: all cores); numbers do not depend on it.",
)
_OutOpt = typer.Option(
    None,
    "--out",
    "-o",
    help="Write the fitted trust model (JSON, same format as the presets; a general model for other inputs).",
)
_PosteriorsOpt = typer.Option(
    None, "--posteriors", help="Also write per-trial P(trust | data) and the Viterbi path (CSV/Parquet)."
)
_PlotsOpt = typer.Option(None, "--plots", help="Write the emission and transition figures (Fig. 4-6 style) into this directory.")
_FillFromOpt = typer.Option(
    None,
    "--fill-from",
    help="Take the rows the data never estimated (e.g. every ask row of a study without asking) from this model "
    "(a preset name, e.g. paper, or a JSON file with the same levels and complexities).",
)
_RatingOpt = typer.Option(
    None,
    "--rating",
    help="The log's self-reported trust rating column, fitted jointly as a second emission of the trust "
    "(empty cells: no rating); or give 'rating' in the mapping file.",
)
_RatingLevelsOpt = typer.Option(
    None, "--rating-levels", help="The rating's levels, lowest first, comma-separated (e.g. 1,2,3,4,5,6,7 or low,mid,high)."
)
_RatingBinsOpt = typer.Option(
    None, "--rating-bins", help="Bin a numeric rating at these edges, comma-separated (e.g. 0,25,50,75,100)."
)
_RatingsOnlyOpt = typer.Option(False, "--ratings-only", help="Leave the human actions out: fit the trust on the ratings alone.")


@command("fit")
@log_options(keep=True)
def fit(
    log: list[Path] = OneRowPerTrialLogArg,
    preset: str = typer.Option("paper", "--preset", help="Model structure preset (paper)."),
    levels: int = typer.Option(2, "--levels", "-k", min=2, max=8, help="Number of trust levels."),
    transitions_on: str | None = _TransitionsOnOpt,
    emissions_on: str | None = _EmissionsOnOpt,
    restarts: int = restarts_option(10, help="Random restarts; the best is kept."),
    bootstrap: int = _BootstrapOpt,
    prior: float = _PriorOpt,
    seed: int = seed_option("Random seed (restarts and bootstrap)."),
    tol: float = _TolOpt,
    max_iter: int = MaxIterOpt,
    jobs: int | None = _JobsOpt,
    out: Path | None = _OutOpt,
    posteriors: Path | None = _PosteriorsOpt,
    plots: Path | None = _PlotsOpt,
    fill_from: str | None = _FillFromOpt,
    as_json: bool = json_option("Print the fitted model and diagnostics as one JSON object."),
    rating: str | None = _RatingOpt,
    rating_levels: str | None = _RatingLevelsOpt,
    rating_bins: str | None = _RatingBinsOpt,
    ratings_only: bool = _RatingsOnlyOpt,
    rating_per: str | None = RatingPerOpt,
    reading: LogReading = FROM_OPTIONS,
    quiet: bool = QuietOpt,
) -> None:
    """Rows no trial informs are marked "not_estimated" in the model file; solve, plot-q and
    simulate refuse those a task can reach until they are supplied (--fill-from).  With a
    rating column (--rating or the mapping's 'rating') the fit is joint on the human actions
    and the ratings, and the model file carries P(rating | trust)."""
    _check_fit_paths(log, reading, fill_from, out, posteriors, plots)
    tr, em, needed = named_inputs(reading, transitions_on, emissions_on)
    rated = rating_entry(rating, rating_levels, rating_bins, rating_per)
    frame = reading.read(log, needed, rated, not ratings_only)
    options = FitOptions(restarts=restarts, seed=seed, tol=tol, max_iter=max_iter, n_jobs=jobs)
    settings: dict[str, Any] = {"levels": levels, "options": options, "bootstrap": bootstrap, "prior": prior}
    settings |= {"rating": _rated(frame, log, ratings_only), "actions": not ratings_only}
    general = general_inputs(tr, em)
    if general and fill_from is not None:
        named = ", ".join(dict.fromkeys((*em, *tr)))
        raise TrustseekError([f"--fill-from is for a trust model; a general model (inputs: {named}) has none"])
    with progress_bar(quiet or as_json) as bar:
        settings["progress"] = _progress(bar, options.starts, bootstrap)
        if general:
            result = estimation.fit_model(frame, em, tr, **settings)
        else:
            result = estimation.fit_trust_model(frame, preset=preset, transition_inputs=tr, emission_inputs=em, **settings)
    drawn = result.model  # the figures show only what the data estimated
    if fill_from is not None and result.model.not_estimated:
        from ..model.presets import load_model

        filled = result.model.not_estimated_rows()
        result.model = result.model.filled_from(load_model(fill_from))
        result.warnings.append(f"taken from {fill_from}: {', '.join(filled)}")
    write_atomic(out, result.model.save)
    write_atomic(posteriors, lambda tmp: write_log(keep_columns(result.posteriors(), frame, reading.keep), tmp))
    if plots is not None:
        paper_like = preset == "paper" and tr == estimation.PAPER_TRANSITION_INPUTS and em == estimation.PAPER_EMISSION_INPUTS
        _plot(result, drawn, plots, general, paper_like)
    if as_json:
        print_json({**result.to_dict(), "cells": result.cells()})
        return
    _print_fit(result, tr, em, general)
    figures = None if plots is None else f"{plots}/emissions.png, {plots}/transitions.png"
    if not general:
        print_written(("model", out), ("posteriors", posteriors), ("figures", figures))
        return
    print_written(
        ("figures", figures and f"{figures} (the tables by combination of the inputs)"),
        ("general model (trustseek.iohmm/1)", out and f"{out}; decode, predict and validate read it"),
        ("posteriors", posteriors),
    )


def rating_entry(rating: str | None, levels: str | None, bins: str | None, per: str | None = None) -> dict | None:
    """The mapping's rating entry from --rating, --rating-levels, --rating-bins and --rating-per
    (None without --rating)."""
    if rating is None:
        if levels is not None or bins is not None or per is not None:
            raise TrustseekError(
                ["--rating-levels, --rating-bins and --rating-per describe the column named by --rating: give --rating"]
            )
        return None
    entry: dict = {"column": rating}
    if per is not None:
        entry["per"] = per
    if levels is not None:
        entry["levels"] = [x.strip() for x in levels.split(",")]
    if bins is not None:
        try:
            entry["bins"] = [float(x) for x in bins.split(",")]
        except ValueError:
            raise TrustseekError([f"--rating-bins {bins!r}: expected comma-separated numbers, e.g. 0,25,50,75,100"]) from None
    return entry


def _check_fit_paths(log, reading: LogReading, fill_from, out, posteriors, plots) -> None:
    """fit's output options refused before the log is read."""
    inputs = (*log_inputs(log), *reading.inputs(), (fill_from, "--fill-from model"))
    check_outputs((out, "--out"), (posteriors, "--posteriors", POSTERIOR_SUFFIXES), inputs=inputs)
    check_plots_folder(plots)
    if reading.keep and posteriors is None:
        raise TrustseekError(["--keep carries log columns into --posteriors: give --posteriors"])


def _rated(frame, log: list[Path], ratings_only: bool) -> str | None:
    """The rating column fitted jointly ("rating") when the log has one; a note when the ratings
    look copied over a block's trials."""
    rated = "rating" if frame.attrs.get("rating_levels") else None
    if rated:
        note_copied_rating(frame, log, rated, shown=frame.attrs.get("rating_column"))
    if ratings_only and rated is None:
        raise TrustseekError(
            ["--ratings-only needs a rating column: --rating COLUMN --rating-levels ..., or the mapping's 'rating'"]
        )
    return rated


def _progress(bar, restarts: int, bootstrap: int):
    """A progress callback counting the restarts, then the bootstrap's replicates."""
    task = bar.add_task("restarts", total=restarts + bootstrap)

    def progress(done: int, total: int) -> None:
        bar.update(task, completed=done, total=total, description="bootstrap" if done > restarts else "restarts")

    return progress


def _plot(result, drawn, plots: Path, general: bool, paper_like: bool) -> None:
    """The emission and transition figures: a general model's tables by combination of its inputs;
    a trust model's with the paper's values as reference for a model of the paper's structure."""
    plots.mkdir(parents=True, exist_ok=True)
    if general:
        from ..plots.iohmm import plot_iohmm_emissions, plot_iohmm_transitions

        plot_iohmm_emissions(result.model, plots / "emissions.png")
        plot_iohmm_transitions(result.model, plots / "transitions.png")
        return
    from ..model.presets import paper_model
    from ..plots.model import plot_emissions, plot_transitions

    same = result.model.complexities == paper_model().complexities and result.model.n_trust == 2
    ref = paper_model() if paper_like and same else None
    plot_emissions(drawn, plots / "emissions.png", ci=result.ci, reference=ref)
    plot_transitions(drawn, plots / "transitions.png", ci=result.ci, reference=ref)


def _print_fit(result, tr, em, general: bool) -> None:
    """The fit's cells, summary, intervals and warnings."""
    n = f"{result.seqs.n_participants} participants, {result.seqs.n_trials} trials"
    summary = fit_summary(result, "restarts", len(result.restart_logliks))
    if general:
        inputs = f"emissions on {', '.join(em) or 'none'}; transitions on {', '.join(tr) or 'none'}"
        console.print(cells_table(f"Fitted model (inputs: {inputs}; {n})", result, estimation.MIN_EVENTS, escape_cells=True))
        print_intervals_note(result.intervals)
        console.print(summary, highlight=False)
    else:
        console.print(cells_table(f"Fitted trust model ({n})", result, estimation.MIN_EVENTS))
        console.print(summary)
        print_intervals_note(result.intervals)
    print_warnings(result.warnings)


@command("decode")
@log_options(keep=True)
def decode_cmd(
    log: list[Path] = LogArg,
    model: Path = typer.Option(
        ...,
        "--model",
        "-m",
        help="Trust model or general model JSON (from 'trustseek fit') or supervisor types (from 'trustseek fit-types').",
    ),
    out: Path = typer.Option(Path("posteriors.csv"), "--out", "-o", help="Output file (.csv or .parquet)."),
    reading: LogReading = FROM_OPTIONS,
) -> None:
    """Under supervisor types, also each participant's most probable ``type`` and P(type | trials)
    (``p_type_<name>``); the trust posteriors are averaged over the types.

    The log needs the columns the model depends on: a model fitted with fewer inputs
    (--transitions-on/--emissions-on) decodes a log without the others."""
    check_outputs((out, "--out", POSTERIOR_SUFFIXES), inputs=(*log_inputs(log), (model, "--model file"), *reading.inputs()))
    types = load_types(model)
    frame = read_for_types(log, types, reading)
    if types.n_types > 1:  # P(type | trials) and the type-averaged posteriors
        from ..estimation.mixture import decode_types

        post = decode_types(frame, types)
    else:
        post = estimation.decode(frame, types.models[0])
    post = keep_columns(post, frame, reading.keep)
    write_atomic(out, lambda tmp: write_log(post, tmp))
    console.print(f"wrote {len(post)} trials to {out}")


@command("select")
@log_options()
def select(
    log: list[Path] = LogArg,
    max_levels: int = typer.Option(4, "--max-levels", min=1, max=8, help="Compare 1..this many trust levels."),
    folds: int = typer.Option(5, "--folds", min=2, help="Folds over participants for the held-out log-likelihood."),
    restarts: int | None = restarts_option(
        None,
        help="Random starts per fit (default: max(10, free parameters / 4)); each fit also starts from the "
        "fit with one level fewer, each level split in two.",
    ),
    prior: float = typer.Option(0.0, "--prior", min=0.0, help="Dirichlet pseudo-count (MAP)."),
    seed: int = SeedOpt,
    tol: float = tol_option(1e-6, "Relative log-likelihood tolerance per fit (> 0)."),
    transitions_on: str | None = AsForFitTransitionsOpt,
    emissions_on: str | None = AsForFitEmissionsOpt,
    widen: bool = widen_option(8, "1..--max-levels"),
    jobs: int | None = SelectionJobsOpt,
    as_json: bool = PrintJsonOpt,
    reading: LogReading = FROM_OPTIONS,
    quiet: bool = QuietOpt,
) -> None:
    tr, em, frame = read_with_inputs(log, reading, transitions_on, emissions_on)
    options = FitOptions(restarts=restarts, seed=seed, tol=tol, n_jobs=1)
    how = {"folds": folds, "options": options, "widen": widen, "jobs": jobs, "prior": prior}
    rows = run_selection(estimation.select_levels, frame, quiet or as_json, tr, em, levels=tuple(range(1, max_levels + 1)), **how)
    warnings = estimation.selection_warnings(rows)
    warnings[:0] = widened_note(rows, "levels", max_levels)
    starts = " (random, and the fit with one level fewer split)"
    print_selection("Number of trust levels", "levels", rows, folds, warnings, as_json, starts=starts)
