"""Decoded trust against self-reported ratings (trustseek.estimation.validation, `trustseek validate`)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from cli_runner import run_cli
from trustseek.data.trials import DataError, example_path, read_trials
from trustseek.estimation.validation import parse_ratings, validate_ratings
from trustseek.model.presets import paper_model
from trustseek.simulation.designs import simulate_design

LOG = str(example_path("paper_trials.csv"))


@pytest.fixture(scope="module")
def rated() -> pd.DataFrame:
    """A simulated study whose every fourth trial carries a 1..7 rating, noisy and monotone in the true trust."""
    frame = simulate_design(paper_model(), 10, seed=11)
    rng = np.random.default_rng(0)
    high = (frame["true_trust"] == "high").to_numpy()
    r = np.clip(np.round(2.5 + 3.0 * high + rng.normal(0, 1.0, len(frame))), 1, 7)
    every_fourth = (frame["trial"].to_numpy() % 4) == 0
    frame["rating"] = np.where(every_fourth, r, np.nan)
    return frame


def test_ratings_from_the_true_trust_correlate_within_participants(rated):
    rep = validate_ratings(rated, paper_model(), parse_ratings(rated, "rating"), bootstrap=200, seed=1)
    assert rep.n_rated == int(rated["rating"].notna().sum())
    for m in ("smoothed", "filtered"):
        for method in ("spearman", "pearson"):
            w = rep.correlations[m]["within"][method]
            assert w["estimate"] > 0 and w["lower"] > 0, (m, method, w)
    assert rep.correlations["smoothed"]["pooled"]["spearman"]["lower"] > 0


def test_ratings_unrelated_to_trust_give_an_interval_around_zero(rated):
    noise = rated.copy()
    noise["rating"] = np.where(rated["rating"].notna(), np.random.default_rng(2).integers(1, 8, len(rated)), np.nan)
    rep = validate_ratings(noise, paper_model(), parse_ratings(noise, "rating"), bootstrap=200, seed=1)
    w = rep.correlations["smoothed"]["within"]["spearman"]
    assert w["lower"] < 0 < w["upper"]
    assert any("smoothed trust does not beat" in s for s in rep.statements())


def test_ordinal_labels_missing_cells_and_errors():
    frame = pd.DataFrame(
        {
            "participant": ["a"] * 5,
            "trial": [1, 2, 3, 4, 5],
            "r": ["low", "", "high", "NA", "medium"],
            "n": ["3", "x", "4", "", "2"],
        }
    )
    got = parse_ratings(frame, "r", ["low", "medium", "high"])
    np.testing.assert_array_equal(got, [1, np.nan, 3, np.nan, 2])
    with pytest.raises(DataError, match=r"3 ratings are not numbers .*--rating-labels.*trial 1: 'low'"):
        parse_ratings(frame, "r")
    with pytest.raises(DataError, match=r"1 ratings are not numbers.*trial 2: 'x'"):
        parse_ratings(frame, "n")
    with pytest.raises(DataError, match="not among the declared labels"):
        parse_ratings(frame, "r", ["low", "high"])
    with pytest.raises(DataError, match="not in the log"):
        parse_ratings(frame, "nope")
    frame["e"] = ""
    with pytest.raises(DataError, match="no trial has a rating"):
        parse_ratings(frame, "e")


def test_cli_validate_json_and_per_trial_file(tmp_path):
    model = tmp_path / "m.json"
    paper_model().save(model)
    out = tmp_path / "v.csv"
    args = ["validate", LOG, "-m", str(model), "--rating", "true_trust", "--rating-labels", "low,high", "-b", "30"]
    code, text = run_cli([*args, "--json", "-o", str(out), "--keep", "experience"])
    assert code == 0, text
    d = json.loads(text)
    assert d["n_rated"] == 639 and d["rating_labels"] == ["low", "high"]
    assert d["correlations"]["smoothed"]["within"]["spearman"]["estimate"] > 0.5
    got = pd.read_csv(out)
    assert got["experience"].tolist() == read_trials(LOG)["experience"].tolist()
    code, text = run_cli(args)
    assert code == 0 and "Spearman correlation with 'true_trust'" in text


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--rating", "nope"], "rating column 'nope' is not in the log"),
        ([], "no rating column: name the log's self-reported trust column with --rating"),
        (["--rating", "true_trust"], "ratings are not numbers (declare ordinal labels"),
        (["--rating", "true_trust", "--rating-labels", "low"], "expected at least 2 distinct labels"),
        (["--rating", "true_trust", "--keep", "experience"], "--keep carries log columns into --out"),
    ],
)
def test_cli_validate_bad_inputs_are_one_line_errors(tmp_path, args, message):
    model = tmp_path / "m.json"
    paper_model().save(model)
    code, text = run_cli(["validate", LOG, "-m", str(model), "-b", "0", *args])
    assert code == 2
    lines = [x for x in text.splitlines() if x.strip()]
    assert len(lines) == 1 and message in lines[0] and "Traceback" not in text


def test_a_constant_baseline_is_no_claim_and_no_nan(rated):
    """A baseline with one value (every experience reliable) has no correlation: the statements
    say it is not compared instead of 'does not beat ... +nan'."""
    constant = rated[rated["robot_action"] == "autonomous"].assign(human_action="rely", experience="reliable")
    rep = validate_ratings(constant, paper_model(), parse_ratings(constant, "rating"), bootstrap=50, seed=1)
    lines = rep.statements()
    assert not any("nan" in line for line in lines), lines
    assert any("reliable_fraction baseline are not compared" in line for line in lines), lines
