"""Trial order and study layouts from the command line: ``--order`` on every command that
reads a log, the duplicate-trial error that names it, a record per participant exploded, and
a rating file per block joined and counted once per block by ``validate``."""

from __future__ import annotations

import json
import re

import pandas as pd
import pytest

from cli_runner import run_cli
from trustseek.data import example_path


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """Three participants in 4 blocks of 5 trials, the trial number restarting in every block."""
    folder = tmp_path_factory.mktemp("layouts")
    frame = pd.read_csv(example_path(), dtype=str)
    frame = frame[frame.participant.isin(["P001", "P002", "P003"]) & (frame.trial.astype(int) <= 20)].copy()
    t = frame.trial.astype(int) - 1
    frame["block"], frame["trial"] = (t // 5 + 1).astype(str), (t % 5 + 1).astype(str)
    frame.to_csv(folder / "blocks.csv", index=False)
    assert run_cli(["preset", "paper", "--model-out", str(folder / "paper.json")])[0] == 0
    return folder


def commands(folder):
    log, model = str(folder / "blocks.csv"), str(folder / "paper.json")
    return {
        "fit": ["fit", log, "-r", "1", "--out", str(folder / "fit.json")],
        "decode": ["decode", log, "-m", model, "--out", str(folder / "post.csv")],
        "select": ["select", log, "--max-levels", "1", "--folds", "2"],
        "predict": ["predict", log, "-m", model, "--bootstrap", "0"],
        "validate": ["validate", log, "-m", model, "--rating", "true_trust", "--bootstrap", "0"],
        "fit-types": ["fit-types", log, "--types", "1", "-o", str(folder / "mix.json")],
        "select-types": ["select-types", log, "--types", "1"],
        "personalize": ["personalize", log, "-m", model, "-o", str(folder / "people")],
        "agnostic": ["agnostic", "--data", log],
    }


READERS = ["fit", "decode", "select", "predict", "validate", "fit-types", "select-types", "personalize", "agnostic"]


@pytest.mark.parametrize("command", READERS)
def test_every_command_that_reads_a_log_takes_order(study, command):
    assert sorted(commands(study)) == sorted(READERS)
    argv = commands(study)[command]
    code, output = run_cli(argv)
    text = " ".join(output.split())
    assert code == 2 and "duplicate trial indices" in text and "--order block,trial" in text, output
    assert "by participant, 3 ('P001' 15, 'P002' 15, 'P003' 15)" in text, output
    code, output = run_cli([*argv, "--order", "block,nowhere"])
    assert code == 2 and "order: no column 'nowhere'" in output, output


def test_a_fit_with_order_equals_the_numbered_logs(study, tmp_path):
    code, output = run_cli([*commands(study)["fit"][:4], "--order", "block", "--order", "trial", "--json"])
    assert code == 0, output
    numbered = pd.read_csv(example_path(), dtype=str)
    numbered[numbered.participant.isin(["P001", "P002", "P003"]) & (numbered.trial.astype(int) <= 20)].to_csv(
        tmp_path / "numbered.csv", index=False
    )
    code, reference = run_cli(["fit", str(tmp_path / "numbered.csv"), "-r", "1", "--json"])
    assert json.loads(output)["loglik"] == pytest.approx(json.loads(reference)["loglik"], rel=1e-12)


def test_validate_counts_a_rating_per_block_once(study, tmp_path):
    log = pd.read_csv(study / "blocks.csv", dtype=str)
    blocks = log[["participant", "block"]].drop_duplicates().reset_index(drop=True)
    blocks["trust"] = [str(1 + i % 5) for i in range(len(blocks))]
    blocks.to_csv(tmp_path / "ratings.csv", index=False)
    rating = {"column": "trust", "levels": [1, 2, 3, 4, 5]}
    argv = ["validate", str(study / "blocks.csv"), "-m", str(study / "paper.json"), "--bootstrap", "0", "--json"]
    for per, rated in ((None, len(log)), ("block", len(blocks))):
        mapping = {"order": ["block", "trial"], "join": {"file": "ratings.csv"}, "rating": {**rating, "per": per}}
        if per is None:
            del mapping["rating"]["per"]
        (tmp_path / "m.json").write_text(json.dumps(mapping))
        code, output = run_cli([*argv, "--mapping", str(tmp_path / "m.json")])
        assert code == 0, output
        assert json.loads(output[: output.rindex("}") + 1])["n_rated"] == rated


def test_a_record_per_participant_fits_from_the_command_line(study, tmp_path):
    log = pd.read_csv(study / "blocks.csv", dtype=str)
    fields = ["block", "trial", "complexity", "robot_action", "human_action", "experience"]
    recs = [{"pid": p, **{f: g[f].tolist() for f in fields}} for p, g in log.groupby("participant")]
    (tmp_path / "people.json").write_text(json.dumps(recs))
    (tmp_path / "m.json").write_text(json.dumps({"columns": {"participant": "pid"}, "explode": fields}))
    fit = ["fit", str(tmp_path / "people.json"), "-r", "1", "--order", "block,trial"]
    code, output = run_cli([*fit, "--mapping", str(tmp_path / "m.json")])
    assert code == 0 and re.search(r"log-likelihood", output), output
    code, output = run_cli(fit)
    assert code == 2 and '"explode"' in output and "Traceback" not in output, output
    pd.DataFrame(recs).to_parquet(tmp_path / "people.parquet")  # a pyarrow traceback and exit 1 before
    code, output = run_cli(["fit", str(tmp_path / "people.parquet"), "-r", "1", "--column", "participant=pid"])
    assert code == 2 and '"explode": ["block", "trial",' in " ".join(output.split()), output


def test_a_rating_copied_onto_a_blocks_trials_is_noticed_and_counted_once_with_rating_per(study, tmp_path):
    log = pd.read_csv(study / "blocks.csv", dtype=str)
    log["trust"] = log.groupby(["participant", "block"]).ngroup().map(lambda g: str(1 + g % 5))
    log.to_csv(tmp_path / "rated.csv", index=False)
    argv = ["validate", str(tmp_path / "rated.csv"), "-m", str(study / "paper.json"), "-b", "0", "--order", "block,trial"]
    code, output = run_cli([*argv, "--rating", "trust", "--json"])
    assert code == 0 and json.loads(output[: output.rindex("}") + 1])["n_rated"] == 60, output
    text = " ".join(output[output.rindex("}") + 1 :].split())
    assert "'trust' holds one value per 'block', on 60 trials of 12 blocks" in text and "--rating-per block" in text, text
    code, output = run_cli([*argv, "--rating", "trust", "--rating-per", "block", "--json"])
    assert code == 0 and json.loads(output[: output.rindex("}") + 1])["n_rated"] == 12, output
    assert "holds one value" not in output
    fit = ["fit", str(tmp_path / "rated.csv"), "-r", "1", "--order", "block,trial", "--rating", "trust"]
    code, output = run_cli([*fit, "--rating-levels", "1,2,3,4,5", "--rating-per", "block"])
    assert code == 0 and "holds one value" not in output, output
    code, output = run_cli([*fit, "--rating-levels", "1,2,3,4,5"])
    assert code == 0 and "'trust' holds one value per 'block'" in " ".join(output.split()), output
    log.loc[0, "trust"] = "5"  # block 1 of P001 rated 1 on its other trials
    log.to_csv(tmp_path / "rated.csv", index=False)
    code, output = run_cli([*argv, "--rating", "trust", "--rating-per", "block"])
    assert code == 2 and "rated.csv: column 'trust': different ratings within one block" in output, output
    assert "row 1" in output and "Traceback" not in output, output


def test_an_output_may_not_overwrite_the_file_a_mapping_joins(study, tmp_path):
    ratings = tmp_path / "ratings.csv"
    pd.DataFrame({"participant": ["P001"], "block": ["1"], "trust": ["3"]}).to_csv(ratings, index=False)
    (tmp_path / "m.json").write_text(json.dumps({"order": ["block", "trial"], "join": {"file": "ratings.csv"}}))
    before = ratings.read_bytes()
    argv = ["decode", str(study / "blocks.csv"), "-m", str(study / "paper.json"), "--mapping", str(tmp_path / "m.json")]
    code, output = run_cli([*argv, "--out", str(ratings)])
    assert code == 2 and "the file the --mapping file joins" in " ".join(output.split()), output
    assert ratings.read_bytes() == before


def test_a_folder_of_logs_one_per_participant_is_fitted_as_the_whole_log(tmp_path):
    frame = pd.read_csv(example_path())
    folder = tmp_path / "data"
    folder.mkdir()
    for pid, g in frame.groupby("participant"):
        g.drop(columns="participant").to_csv(folder / f"{pid}.csv", index=False)
    outputs = []
    for log in ([folder], sorted(folder.iterdir()), [example_path()]):  # the folder, its files (a shell's data/*.csv)
        code, output = run_cli(["fit", *map(str, log), "-r", "2", "--json"])
        assert code == 0, output
        outputs.append(json.loads(output))
    assert outputs[0]["loglik"] == outputs[1]["loglik"] == outputs[2]["loglik"]
    assert outputs[0]["model"] == outputs[1]["model"] == outputs[2]["model"]
    code, output = run_cli(
        ["decode", str(folder / "P001.csv"), str(folder / "P002.csv"), "-m", "paper", "-o", str(folder / "P002.csv")]
    )
    assert code == 2 and "--out" in output and "would overwrite the input" in output, output  # any of its files is an input
