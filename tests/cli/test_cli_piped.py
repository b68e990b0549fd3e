"""A selection table printed to a pipe is whole: not cut to the 80 columns of a pipe's console."""

from __future__ import annotations

from cli_runner import run_cli
from trustseek.data.trials import example_path

LOG = str(example_path("paper_trials.csv"))


def test_the_selection_tables_are_whole_when_piped():
    for line, header in (
        (["select", LOG, "--max-levels", "2", "-r", "1", "--folds", "2", "-q", "--no-widen"], "held-out LL (2-fold)"),
        (["select-types", LOG, "--types", "1..2", "-r", "1", "--folds", "2", "-q", "--no-widen"], "held-out LL (2-fold)"),
    ):
        code, output = run_cli(line, stdout=True)
        assert code == 0, output
        assert header in output and "log-likelihood" in output and "…" not in output, output
