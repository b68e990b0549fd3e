"""Checking a trust model against data: predict (one-step-ahead reliance), validate (self-reports)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import typer
from rich.markup import escape
from rich.table import Table

from ..errors import TrustseekError
from ..estimation.options import FitOptions
from ._app import check_outputs, command, console, make_table, print_json, print_written, write_atomic
from ._options import (
    FROM_OPTIONS,
    AsForFitEmissionsOpt,
    AsForFitTransitionsOpt,
    LogReading,
    MaxIterOpt,
    OneRowPerTrialLogArg,
    QuietOpt,
    RatingPerOpt,
    bootstrap_option,
    json_option,
    log_inputs,
    log_name,
    log_options,
    processes_option,
    restarts_option,
    seed_option,
    tol_option,
)
from ._progress import progress_task
from ._reading import (
    POSTERIOR_SUFFIXES,
    general_inputs,
    keep_columns,
    note_copied_rating,
    read_for_types,
    read_with_inputs,
    write_log,
)

BootstrapOpt = bootstrap_option(1000, "Participant-bootstrap resamples for the 95% intervals (0 = none).")


def _table(title: str, *columns: str) -> Table:
    return make_table(title, *columns, no_wrap=True, box=None, padding=(0, 2, 0, 0), header_style="bold underline")


def _pair(d: dict[str, Any], spec: str = ".3f") -> tuple[str, str]:
    """An estimate and its interval as two cells (a difference coloured by which side is better)."""
    est = f"{d['estimate']:{spec}}" if math.isfinite(d["estimate"]) else "-"
    ci = escape(f"[{d['lower']:{spec}}, {d['upper']:{spec}}]") if math.isfinite(d["lower"]) else ""
    colour = {"model": "green", "trust": "green", "baseline": "red"}.get(d.get("better", ""))
    return (f"[{colour}]{est}[/]", ci) if colour else (est, ci)


def _load(path: Path) -> Any:
    """A trust model or a general model (trustseek.iohmm/1), by the file's format; or a preset name (paper)."""
    from ..model.core import load_any_model
    from ..model.presets import MODEL_PRESETS, load_model

    if str(path) in MODEL_PRESETS and not path.exists():
        return load_model(str(path))

    return load_any_model(path)


@command("predict")
@log_options(keep=True)
def predict(
    log: list[Path] = OneRowPerTrialLogArg,
    model: Path | None = typer.Option(
        None,
        "--model",
        "-m",
        help="Score this trust (or general) model in-sample (JSON); without it, held-out participants by k-fold fits.",
    ),
    folds: int | None = typer.Option(None, "--folds", min=2, help="Folds of participants for the held-out fits (default 5)."),
    levels: int = typer.Option(2, "--levels", "-k", min=2, max=8, help="Trust levels of the held-out fits."),
    transitions_on: str | None = AsForFitTransitionsOpt,
    emissions_on: str | None = AsForFitEmissionsOpt,
    restarts: int = restarts_option(10, help="Random restarts of each held-out fit."),
    prior: float = typer.Option(0.0, "--prior", min=0.0, help="Dirichlet pseudo-count of the held-out fits (as for fit)."),
    seed: int = seed_option("Random seed (folds, restarts, bootstrap)."),
    tol: float = tol_option(1e-8, "Relative log-likelihood tolerance of each fit (> 0)."),
    max_iter: int = MaxIterOpt,
    jobs: int | None = processes_option("the held-out folds' fits"),
    bootstrap: int = BootstrapOpt,
    out: Path | None = typer.Option(None, "--out", "-o", help="Write the per-trial predictions (CSV or Parquet)."),
    as_json: bool = json_option("Print the scores as one JSON object."),
    reading: LogReading = FROM_OPTIONS,
    quiet: bool = QuietOpt,
) -> None:
    """Trials whose action the model fixes (the robot asked: P(intervene) = 1) are no prediction
    and are left out of the scores."""
    _check_trial_output(out, log, model, reading)
    from ..estimation import prediction as pr

    if model is not None:
        if folds is not None:
            raise TrustseekError(["--folds scores held-out fits; --model scores that model in-sample: give one of them"])
        m = _load(model)
        frame = read_for_types(log, m, reading)
        report = pr.predict_in_sample(frame, m, bootstrap=bootstrap, seed=seed)
    else:
        tr, em, frame = read_with_inputs(log, reading, transitions_on, emissions_on)
        preset: Any = "paper"
        if general_inputs(tr, em):  # inputs a trust model does not have: the general model's structure
            from ..estimation.trust_iohmm import general_spec

            preset = general_spec(frame, em, tr, levels, prior)
        k = 5 if folds is None else folds
        with progress_task(quiet or as_json, "held-out folds", k) as update:
            report = pr.predict_heldout(
                frame,
                preset=preset,
                folds=k,
                options=FitOptions(restarts=restarts, seed=seed, tol=tol, max_iter=max_iter, n_jobs=jobs),
                bootstrap=bootstrap,
                prior=prior,
                progress=update,
                levels=levels,
                transition_inputs=tr,
                emission_inputs=em,
            )
    write_atomic(out, lambda tmp: write_log(keep_columns(report.trials, frame, reading.keep), tmp))
    if as_json:
        print_json(report.to_dict())
        return
    _print_prediction(report, model, pr.METRICS)
    print_written(("per-trial predictions", out))


def _check_trial_output(out: Path | None, log: list[Path], model: Path | None, reading: LogReading) -> None:
    """--out (per-trial values) and --keep refused before anything is read."""
    check_outputs((out, "--out", POSTERIOR_SUFFIXES), inputs=(*log_inputs(log), (model, "--model file"), *reading.inputs()))
    if reading.keep and out is None:
        raise TrustseekError(["--keep carries log columns into --out: give --out"])


def _print_statements(lines: list[str], otherwise: str) -> None:
    """The report's statements, or ``otherwise`` when it has none."""
    for line in lines:
        console.print(escape(line), highlight=False)
    if not lines:
        console.print(otherwise)


def _print_prediction(report, model: Path | None, metrics: tuple[str, ...]) -> None:
    """The prediction's scores, one table per metric, its notes and statements."""
    how = (
        f"in-sample under {model}"
        if report.mode == "in-sample"
        else f"held-out participants, {report.folds}-fold (each fold predicted by a fit to the others)"
    )
    console.print(
        f"One-step-ahead P(rely), {how}: {report.n_scored} trials of {report.n_participants} participants", highlight=False
    )
    titles = {"log_loss": "log-loss (nats per trial; lower is better)", "brier": "Brier score (lower is better)"}
    titles["auc"] = "AUC (higher is better)"
    for m in metrics:
        table = _table(titles[m], "predictor", "estimate", "95% CI", "model - this", "95% CI")
        for name, per in report.metrics.items():
            d = report.differences.get(name, {}).get(m)
            table.add_row(name, *_pair(per[m]), *(_pair(d, "+.3f") if d else ("", "")))
        console.print(table)
    if report.bootstrap:
        console.print(f"intervals: 95% participant bootstrap, {report.bootstrap} resamples", highlight=False)
    console.print(escape(report.excluded_note()), highlight=False)
    note = report.misses_note()
    if note:
        console.print(f"[yellow]note:[/] {escape(note)}", highlight=False)
    _print_statements(
        report.statements(), "the model beats every baseline in every score (95% intervals of the differences exclude 0)"
    )


def _one_rating_per_block(frame, log: list[Path], rating: str, per: str | None, missing: list[str] | None) -> None:
    """--rating-per: the rating kept on each block's last trial; without it (and without the
    mapping's rating "per"), a note on stderr when the rating looks copied onto a block's trials."""
    from ..data import levels

    markers = frozenset(m.strip().lower() for m in missing or ())
    if per is not None:
        frame[rating] = levels.one_per_block(frame, rating, per, markers, log_name(log))
    else:
        note_copied_rating(frame, log, rating, markers)


@command("validate")
@log_options(keep=True)
def validate(
    log: list[Path] = typer.Argument(
        ...,
        help="Trial log with a self-reported trust rating column (every trial, or some); several files or a folder.",
    ),
    model: Path = typer.Option(..., "--model", "-m", help="Trust model or general model JSON (e.g. from 'trustseek fit')."),
    rating: str | None = typer.Option(
        None,
        "--rating",
        help="The log's rating column (default: the mapping's rating, or a column named 'rating'); empty cells are no rating.",
    ),
    rating_labels: str | None = typer.Option(
        None,
        "--rating-labels",
        help="Ordinal rating labels, lowest first, comma-separated (e.g. low,medium,high); default: numeric ratings.",
    ),
    rating_per: str | None = RatingPerOpt,
    bootstrap: int = BootstrapOpt,
    seed: int = seed_option("Random seed of the bootstrap."),
    out: Path | None = typer.Option(None, "--out", "-o", help="Write per trial the rating, decoded trust and baselines."),
    as_json: bool = json_option("Print the correlations as one JSON object."),
    reading: LogReading = FROM_OPTIONS,
) -> None:
    _check_trial_output(out, log, model, reading)
    labels = None if rating_labels is None else [x.strip() for x in rating_labels.split(",")]
    m = _load(model)
    frame = read_for_types(log, m, reading)
    from ..estimation import validation as va

    if rating is None:
        if "rating" not in frame.columns:
            raise TrustseekError(["no rating column: name the log's self-reported trust column with --rating COLUMN"])
        rating = "rating"
    if rating == "rating" and labels is None and frame.attrs.get("rating_levels"):
        labels = list(frame.attrs["rating_levels"])  # the mapping's rating: its declared levels
    _one_rating_per_block(frame, log, rating, rating_per, reading.missing)
    ratings = va.parse_ratings(frame, rating, labels, reading.missing or ())
    report = va.validate_ratings(frame, m, ratings, rating, labels, bootstrap=bootstrap, seed=seed)
    write_atomic(out, lambda tmp: write_log(keep_columns(report.trials, frame, reading.keep), tmp))
    if as_json:
        print_json(report.to_dict())
        return
    names = {
        "smoothed": "smoothed trust",
        "filtered": "filtered trust",
        "reliable_fraction": "reliable so far",
        "reliance": "reliance",
        "reliance_rate": "reliance so far",
    }
    rated = f"{report.n_rated} rated trials of {report.n_participants_rated} participants"
    for method in va.METHODS:
        table = _table(f"{method.capitalize()} correlation with {rating!r} ({rated})", "measure", *va.SCOPES)
        for key, per in report.correlations.items():
            table.add_row(names.get(key, key), *(" ".join(filter(None, _pair(per[s][method], ".2f"))) for s in va.SCOPES))
        console.print(table)
    console.print(
        "within: values and ratings centred on each participant's means, then pooled; between: participant means"
        + (f"; intervals: 95% participant bootstrap, {report.bootstrap} resamples" if report.bootstrap else ""),
        highlight=False,
    )
    _print_statements(
        report.statements(),
        "the decoded trust beats every baseline in every scope (Spearman; 95% intervals of the differences exclude 0)",
    )
    print_written(("per-trial values", out))
