"""``trustseek personalize``: how each strength was chosen and the criterion, in text and JSON; bad
inputs are one line and exit code 2."""

import json

import pytest

from cli_runner import run_cli
from trustseek.model.presets import paper_model
from trustseek.simulation.designs import simulate_design
from trustseek.simulation.populations import Supervisors


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    df = simulate_design(Supervisors.dirichlet(paper_model(), 20, 5.0, rng=1), 20, seed=2)
    path = tmp_path_factory.mktemp("people") / "log.csv"
    df.to_csv(path, index=False)
    return path


def test_the_held_out_estimate_is_reported(log, tmp_path):
    code, text = run_cli(["personalize", str(log), "-m", "paper", "-o", str(tmp_path / "people")])
    assert code == 0, text
    assert "emission: held-out log-likelihood, 5 blocks of trials per participant" in text
    assert "held-out log-likelihood:" in text and "at the centre" in text
    saved = json.loads((tmp_path / "people" / "strength.json").read_text())
    assert saved["estimate"] == "held-out"
    assert f"{saved['score']:.3f} at these strengths, {saved['score_centre']:.3f} at the centre" in " ".join(text.split())


def test_the_variational_estimate_in_json(log, tmp_path):
    code, text = run_cli(
        ["personalize", str(log), "-m", "paper", "-o", str(tmp_path / "p"), "--estimate", "variational", "--json"]
    )
    assert code == 0, text
    d = json.loads(text)
    assert d["estimate"] == "variational" and d["method"]["emission"] == "variational empirical Bayes"
    assert isinstance(d["score"], float) and len(d["participants"]) == 20
    assert set(d["strength"]) == {"initial", "emission", "transition"}


def test_a_given_strength_is_reported_as_given(log, tmp_path):
    code, text = run_cli(["personalize", str(log), "-m", "paper", "-o", str(tmp_path / "p"), "--strength", "7", "--json"])
    assert code == 0, text
    d = json.loads(text)
    assert d["estimate"] == "given" and set(d["method"].values()) == {"given"} and d["score"] is None
    assert d["strength"] == {"initial": 7.0, "emission": 7.0, "transition": 7.0}


def test_an_unknown_estimate_is_one_line_and_exit_2(log, tmp_path):
    code, text = run_cli(["personalize", str(log), "-m", "paper", "-o", str(tmp_path / "p"), "--estimate", "bayes"], stdout=False)
    assert code == 2, text
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and "--estimate" in text
    assert not (tmp_path / "p").exists()
