"""Supervisor types, per-person models, decoding and prediction on a log that is not the
paper's task: an advice-taking study with only the decision to follow the aid and whether
the aid was right (the paper's experience rule does not hold there)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from cli_runner import run_cli
from trustseek.data.trials import example_path


@pytest.fixture(scope="module")
def advice(tmp_path_factory):
    """A log with the study's own columns, the aid right regardless of what the person did."""
    folder = tmp_path_factory.mktemp("advice")
    paper = pd.read_csv(example_path("paper_trials.csv"))
    rng = np.random.default_rng(1)
    log = pd.DataFrame(
        {
            "subject": paper.participant,
            "trial": paper.trial,
            "followed": (paper.human_action == "rely").astype(int),
            "aid_correct": (rng.random(len(paper)) < 0.7).astype(int),
            "mode": "autonomous",  # a constant column, mapped to robot_action where a command needs one
        }
    )
    log.to_csv(folder / "advice.csv", index=False)
    mapping = {
        "columns": {"participant": "subject", "human_action": "followed", "experience": "aid_correct"},
        "labels": {"human_action": {"1": "rely", "0": "intervene"}, "experience": {"1": "reliable", "0": "faulty"}},
        "experience_rule": False,
    }
    (folder / "advice.json").write_text(json.dumps(mapping))
    return folder


INPUTS = ["--transitions-on", "experience", "--emissions-on", "none"]


def test_the_experience_rule_is_the_mappings_to_turn_off(advice):
    mapping = json.loads((advice / "advice.json").read_text())
    mapping["columns"]["robot_action"] = "mode"
    (advice / "off.json").write_text(json.dumps(mapping))
    del mapping["experience_rule"]
    (advice / "on.json").write_text(json.dumps(mapping))
    fit = ["fit", str(advice / "advice.csv"), "--transitions-on", "robot_action,experience", "--emissions-on", "none", "-r", "1"]
    code, output = run_cli([*fit, "--mapping", str(advice / "on.json")])
    assert code == 2 and "the experience rule" in output
    code, output = run_cli([*fit, "--mapping", str(advice / "off.json")])
    assert code == 0 and "experience rule is not checked" in " ".join(output.split()), output


def test_types_personal_models_decoding_and_prediction_run_on_the_log(advice):
    log, mapping = str(advice / "advice.csv"), ["--mapping", str(advice / "advice.json")]
    mix, model = advice / "mix.json", advice / "m.json"
    lines = [
        ["fit-types", log, *mapping, *INPUTS, "--types", "2", "-r", "2", "-o", str(mix), "-q"],
        ["select-types", log, *mapping, *INPUTS, "--types", "1..2", "-r", "1", "--folds", "2", "-q"],
        ["decode", log, *mapping, "-m", str(mix), "-o", str(advice / "post.csv")],
        ["fit", log, *mapping, *INPUTS, "-r", "2", "-o", str(model), "-q"],
        ["personalize", log, *mapping, "-m", str(model), "-o", str(advice / "people")],
        ["predict", log, *mapping, "-m", str(model), "-b", "0"],
    ]
    for line in lines:
        code, output = run_cli(line)
        assert code == 0, (line[0], output)
    post = pd.read_csv(advice / "post.csv")
    assert len(post) == len(pd.read_csv(log)) and any(c.startswith("p_type_") for c in post.columns), list(post.columns)
