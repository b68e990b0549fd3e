"""select widens the range compared while the best is the largest compared, and says so."""

from __future__ import annotations

import json

import pandas as pd

from cli_runner import run_cli
from trustseek.data.trials import example_path


def test_select_compares_more_levels_while_the_best_is_the_largest_compared(tmp_path):
    log = pd.read_csv(example_path("paper_trials.csv"))
    log[log["participant"].isin(log["participant"].unique()[:4])].to_csv(tmp_path / "four.csv", index=False)
    line = ["select", str(tmp_path / "four.csv"), "--max-levels", "1", "-r", "1", "--folds", "2", "-q", "--json"]
    code, output = run_cli(line, stdout=True)
    assert code == 0, output
    out = json.loads(output)
    assert [r["levels"] for r in out["levels"]] == [1, 2] and out["levels"][1]["widened"]
    assert any("compared up to 2" in w and "--no-widen" in w for w in out["warnings"]), out["warnings"]
    code, output = run_cli([*line, "--no-widen"], stdout=True)
    assert code == 0 and [r["levels"] for r in json.loads(output)["levels"]] == [1]
