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


def test_the_experience_rule_is_a_switch_too(advice):
    mapping = json.loads((advice / "advice.json").read_text())
    mapping["columns"]["robot_action"] = "mode"
    del mapping["experience_rule"]
    (advice / "rule.json").write_text(json.dumps(mapping))
    inputs = ["--transitions-on", "robot_action,experience", "--emissions-on", "none"]
    line = ["predict", str(advice / "advice.csv"), "--mapping", str(advice / "rule.json"), *inputs, "--folds", "2", "-r", "1"]
    code, output = run_cli([*line, "-b", "0"])
    assert code == 2 and "the experience rule" in output
    code, output = run_cli([*line, "-b", "0", "--no-experience-rule"])
    assert code == 0 and "--no-experience-rule: the paper's experience rule is not checked" in output, output
    assert json.loads((advice / "rule.json").read_text()) == mapping  # the user's mapping is left as it was
    fit = ["fit", str(advice / "advice.csv"), "--mapping", str(advice / "rule.json"), *inputs, "-r", "1"]
    code, output = run_cli([*fit, "--out", str(advice / "fitted.json"), "--no-experience-rule"])
    assert code == 0 and "--no-experience-rule: the paper's experience rule is not checked" in output, output


def test_types_personal_models_decoding_and_prediction_run_on_the_log(advice):
    log, mapping = str(advice / "advice.csv"), ["--mapping", str(advice / "advice.json")]
    mix, model = advice / "mix.json", advice / "m.json"
    lines = [
        ["fit-types", log, *mapping, *INPUTS, "--types", "2", "-r", "2", "-o", str(mix), "-q"],
        ["select-types", log, *mapping, *INPUTS, "--types", "1..2", "-r", "1", "--folds", "2", "-q", "--no-widen"],
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


@pytest.fixture(scope="module")
def named(tmp_path_factory):
    """A small log with only a reliance column, a named input (the aid's advice) and a rating on some trials."""
    folder = tmp_path_factory.mktemp("named")
    rng = np.random.default_rng(0)
    rows = []
    for p in range(10):
        for t in range(1, 13):
            advice = rng.choice(["agree", "disagree"])
            rating = int(rng.integers(1, 8)) if t % 3 == 0 else None
            rows.append({"pid": f"p{p}", "trial": t, "followed": int(rng.random() < (0.8 if advice == "agree" else 0.4)),
                         "advice": advice, "rating": rating})  # fmt: skip
    pd.DataFrame(rows).astype({"rating": "Int64"}).to_csv(folder / "log.csv", index=False)
    mapping = {
        "columns": {"participant": "pid", "human_action": "followed"},
        "labels": {"human_action": {"1": "rely", "0": "intervene"}},
        "inputs": {"advice": {"column": "advice", "levels": ["agree", "disagree"]}},
    }
    (folder / "map.json").write_text(json.dumps(mapping))
    return folder


def test_every_analysis_runs_on_a_log_with_only_reliance_and_a_named_input(named):
    log, mapping = str(named / "log.csv"), ["--mapping", str(named / "map.json")]
    inputs = ["--transitions-on", "none", "--emissions-on", "advice"]
    mix, model = named / "mix.json", named / "m.json"
    lines = [
        ["fit-types", log, *mapping, *inputs, "--types", "2", "-r", "2", "-o", str(mix), "--max-iter", "200"],
        ["select-types", log, *mapping, *inputs, "--types", "1..2", "-r", "1", "--folds", "2", "-q", "--no-widen"],
        ["decode", log, *mapping, "-m", str(mix), "-o", str(named / "post.csv")],
        ["fit", log, *mapping, *inputs, "-r", "1", "-o", str(model), "-q"],
        ["personalize", log, *mapping, "-m", str(mix), "-o", str(named / "people"), "--strength", "5"],
        ["predict", log, *mapping, "-m", str(model), "-b", "0"],
        ["validate", log, *mapping, "-m", str(model), "--rating", "rating", "-b", "0"],
    ]
    outputs = {}
    for line in lines:
        code, outputs[line[0]] = run_cli(line)
        assert code == 0, (line[0], outputs[line[0]])
    assert "general types (inputs: advice)" in " ".join(outputs["fit-types"].split())
    types = json.loads(mix.read_text())["types"]
    assert [t["model"]["format"] for t in types] == ["trustseek.iohmm/1"] * 2
    post = pd.read_csv(named / "post.csv")
    assert len(post) == 120 and {"p_type_type1", "p_type_type2", "p_trust_high"} <= set(post.columns)
    person = json.loads((named / "people" / "p0.json").read_text())
    assert person["format"] == "trustseek.iohmm/1" and list(person["inputs"]) == ["advice"]


def test_general_types_are_refused_for_planning_with_the_reason(named, tmp_path):
    from trustseek.model.core import TrustModel
    from trustseek.model.mixture import TypeMixture

    def general(rely: float) -> TrustModel:
        emission = np.array([[[1 - rely, rely]] * 2] * 2)
        return TrustModel(("low", "high"), "human_action", ("intervene", "rely"), {"advice": ("agree", "disagree")},
                          ("advice",), (), np.array([0.5, 0.5]), emission, np.array([[0.9, 0.1], [0.1, 0.9]]))  # fmt: skip

    TypeMixture(("type1", "type2"), np.array([0.5, 0.5]), (general(0.3), general(0.8))).save(tmp_path / "mix.json")
    code, output = run_cli(["fit-types", str(named / "log.csv"), "--mapping", str(named / "map.json"), "--emissions-on",
                            "advice", "--transitions-on", "none", "--plots", str(tmp_path / "figs")])  # fmt: skip
    assert code == 2 and "have no figures" in output and not (tmp_path / "figs").exists(), output
    code, output = run_cli(["solve", "--types", str(tmp_path / "mix.json")])
    assert code == 2 and "is not a trust model: planning" in " ".join(output.split()), output
    back = TypeMixture.from_dict(json.loads((tmp_path / "mix.json").read_text()), general=True)
    assert back.general and back.trust_levels == ("low", "high")
