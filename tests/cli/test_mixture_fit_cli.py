"""The supervisor-type commands: fit-types, select-types, personalize, decode under types; bad inputs
are one line and exit code 2."""

import json

import pandas as pd
import pytest

from cli_runner import run_cli
from trustseek.model.mixture import TypeMixture
from trustseek.model.presets import paper_conservative_mixture
from trustseek.simulation.designs import simulate_design
from trustseek.simulation.populations import Supervisors


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    mix = paper_conservative_mixture(0.5)
    df = simulate_design(Supervisors.from_mixture(mix, 40, rng=2), 40, seed=3)
    df["participant"] = "subject-" + df["participant"].astype(str)  # the study's own participant values
    path = tmp_path_factory.mktemp("types") / "log.csv"
    df.to_csv(path, index=False)
    return path


def test_fit_types_writes_types_posteriors_and_figures(log, tmp_path):
    out, post, figs = tmp_path / "m.json", tmp_path / "post.csv", tmp_path / "figs"
    code, text = run_cli(["fit-types", str(log), "--types", "2", "-r", "3", "--tol", "1e-6", "-o", str(out),
                          "--type-posteriors", str(post), "--plots", str(figs), "-j", "1"])  # fmt: skip
    assert code == 0, text
    assert "type1" in text and "log-likelihood" in text
    mix = TypeMixture.load(out)
    assert mix.names == ("type1", "type2") and mix.weights.sum() == pytest.approx(1.0)
    table = pd.read_csv(post)
    assert table["participant"].str.startswith("subject-").all() and len(table) == 40
    assert set(table["type"]) <= {"type1", "type2"}
    assert sorted(p.name for p in figs.iterdir()) == [
        "emissions_type1.png", "emissions_type2.png", "transitions_type1.png", "transitions_type2.png", "types.png"
    ]  # fmt: skip
    code, text = run_cli(["decode", str(log), "-m", str(out), "-o", str(tmp_path / "dec.csv")])
    assert code == 0, text
    dec = pd.read_csv(tmp_path / "dec.csv")
    assert {"type", "p_type_type1", "p_type_type2", "p_trust_low", "viterbi_trust"} <= set(dec.columns)
    per = dec.groupby("participant")["type"].first()
    assert (per.reindex(table["participant"]).to_numpy() == table["type"].to_numpy()).all()


def test_fit_types_json(log):
    code, text = run_cli(["fit-types", str(log), "--types", "2", "-r", "2", "--tol", "1e-5", "--differ", "emission", "--json"])
    assert code == 0, text
    d = json.loads(text)
    assert d["differ"] == ["emission"] and len(d["restart_logliks"]) == 2
    assert d["mixture"]["format"] == "trustseek.mixture/1"


def test_select_types_and_personalize(log, tmp_path):
    code, text = run_cli(["select-types", str(log), "--types", "1..2", "--folds", "2", "-r", "2", "--json", "--no-widen"])
    assert code == 0, text
    d = json.loads(text)
    assert [r["types"] for r in d["types"]] == [1, 2]
    code, text = run_cli(
        ["personalize", str(log), "-m", "paper+conservative", "-o", str(tmp_path / "people"), "--strength", "20"]
    )
    assert code == 0, text
    index = pd.read_csv(tmp_path / "people" / "participants.csv")
    assert len(index) == 40 and set(index["centre"]) <= {"paper", "conservative"}
    assert (tmp_path / "people" / index["file"].iloc[0]).exists()


@pytest.mark.parametrize(
    "args, message",
    [
        (["fit-types", "{log}", "--differ", "emissions"], "differ"),
        (["select-types", "{log}", "--types", "3..x"], "--types"),
        (["select-types", "{log}", "--types", "0..2"], "--types"),
        (["fit-types", "{log}", "--type-posteriors", "{tmp}/p.txt"], "--type-posteriors"),
        (["personalize", "{log}", "-m", "nonesuch", "-o", "{tmp}/people"], "nonesuch"),
        (["fit-types", "{tmp}/missing.csv"], "missing.csv"),
    ],
)
def test_bad_inputs_are_one_line_and_exit_2(log, tmp_path, args, message):
    code, text = run_cli([a.format(log=log, tmp=tmp_path) for a in args], stdout=False)
    assert code == 2, text
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and message in text, text
