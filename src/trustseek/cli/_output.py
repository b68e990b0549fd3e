"""What the estimation commands print and check alike: warnings, a fit's cells and summary, a
selection table, the --plots folder (light at import: rich only)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from rich.markup import escape
from rich.table import Table

from ..errors import TrustseekError
from ._app import PACKAGE, check_output, console, make_table, print_json
from ._progress import progress_task


def check_plots_folder(plots: Path | None) -> None:
    """--plots refused before anything is read when it names a file, or a new folder whose own
    folder does not exist or is not writable (as every other output: a typo is not a tree of new
    folders), or a folder inside the package; an existing folder is written into (figures of the same name are replaced)."""
    if plots is None:
        return
    if not plots.exists() or plots.resolve().is_relative_to(PACKAGE):
        check_output(plots, "--plots", directory=True)
    elif not plots.is_dir():
        raise TrustseekError([f"--plots {plots}: exists and is not a folder"])
    elif not os.access(plots, os.W_OK | os.X_OK):
        raise TrustseekError([f"--plots {plots}: the folder is not writable"])


def print_warnings(warnings: list[str]) -> None:
    for w in warnings:
        console.print(f"[yellow]warning:[/] {escape(w)}", highlight=False)


def print_wide(table: Table) -> None:
    """A table printed whole, when piped too (a pipe's console is 80 columns wide)."""
    from rich.console import Console

    (console if console.is_terminal else Console(width=400)).print(table)


def run_selection(select, frame, quiet: bool, tr: tuple[str, ...], em: tuple[str, ...], **how):
    """A model selection (``select_levels``, ``select_types``) on the inputs ``tr`` and ``em``,
    with its progress bar; ``how`` its other arguments."""
    with progress_task(quiet, "model selection") as update:
        return select(frame, progress=lambda what, d, t: update(d, t, what), transition_inputs=tr, emission_inputs=em, **how)


def print_selection(
    title: str, key: str, rows: list[dict], folds: int, warnings: list[str], as_json: bool, starts: str = "", extra=None
) -> None:
    """A model selection (``select``, ``select-types``) as JSON, or its table, legend and warnings:
    per compared size ``key`` its log-likelihood, starts that reached the best (``starts`` says
    which), parameters, AIC, BIC and held-out score, the best by each criterion starred; ``extra``
    maps further column names to a cell function."""
    if as_json:
        print_json({key: rows, "warnings": warnings})
        return
    extra = extra or {}
    columns = (key, "log-likelihood", "reached best", "parameters", "AIC", "BIC", f"held-out LL ({folds}-fold)", *extra)
    table = make_table(title, *columns, left=0)
    for r in rows:
        table.add_row(
            str(r[key]),
            f"{r['loglik']:.3f}",
            f"{r['reached_best']} of {r['starts']}",
            str(r["n_params"]),
            f"{r['aic']:.2f}",
            f"{r['bic']:.2f}" + (" *" if r["best_bic"] else ""),
            f"{r['heldout_loglik']:.3f}" + (" *" if r["best_heldout"] else ""),
            *(cell(r) for cell in extra.values()),
        )
    print_wide(table)
    legend = f"* best by that criterion; reached best: starts{starts} within 0.01 of the best log-likelihood"
    console.print(legend, highlight=False)
    print_warnings(warnings)


def cells_table(title: str, result: Any, min_events: float, escape_cells: bool = False) -> Table:
    """A fit's cells, one row each: estimate, interval (with a bootstrap) and expected events, those
    below ``min_events`` marked not identified."""
    iv = result.intervals
    interval = () if iv is None else (f"{iv.level:.0%} CI ({iv.replicates} resamples)",)
    table = make_table(title, "cell", "estimate", *interval, "events")
    for c in result.cells():
        row = [escape(c["cell"]) if escape_cells else c["cell"], f"{c['estimate']:.3f}"]
        if iv is not None:
            ci = escape(f"[{c['lower']:.3f}, {c['upper']:.3f}]")
            row.append(f"{ci} [yellow]widened[/]" if c.get("widened") else ci)
        ev = f"{c['events']:.1f}"
        row.append(ev if c["events"] >= min_events else f"[yellow]{ev} (not identified)[/]")
        table.add_row(*row)
    return table


def fit_summary(result: Any, starts: str, count: int) -> str:
    """The log-likelihood, free parameters, AIC and BIC of a fit, and its starts (best first) with
    how many of ``count`` came within 0.01 of the best."""
    from ..estimation.selection import reached_best

    lls = ", ".join(f"{x:.3f}" for x in sorted(result.restart_logliks, reverse=True))
    return (
        f"log-likelihood {result.loglik:.4f}; {result.n_params} free parameters; AIC {result.aic:.2f}; BIC {result.bic:.2f}\n"
        f"{starts} (best first): {lls}; {reached_best(result.restart_logliks)} of {count} within 0.01 of the best"
    )


def print_intervals_note(iv: Any) -> None:
    if iv is not None:
        console.print(f"intervals: bootstrap over {iv.replicates} resamples of the participants ({iv.method})", highlight=False)
