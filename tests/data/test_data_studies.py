"""Logs as studies write them, each fitted by a mapping file alone.

Every log here is generated from the shipped canonical log: renamed columns and labels,
block-wise or timestamp trial order, 0-based trial numbers with gaps, attention checks and
practice trials to drop, decision/advice/truth columns instead of reliance and experience,
"NA" cells, a between-subject condition and per-trial ratings, in CSV, Parquet, JSON lines
and JSON arrays.  The encoded sequences and the fitted log-likelihood must equal those of
the canonical log.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cli_runner import run_cli
from trustseek.data import DataError, example_path, read_trials
from trustseek.estimation import encode, fit_trust_model, paper_spec
from trustseek.estimation.options import FitOptions

FLIP = {"left": "right", "right": "left"}


@pytest.fixture(scope="module")
def canonical() -> pd.DataFrame:
    frame = read_trials(example_path())
    # a participant's last trial: autonomous, relied on, reliable (a study logging feedback on the next row
    # cannot say more about it; see the shifted-feedback log)
    last = frame.groupby("participant", observed=True)["trial"].transform("max") == frame["trial"]
    frame.loc[last, ["robot_action", "human_action", "experience"]] = ["autonomous", "rely", "reliable"]
    unrecorded = np.random.default_rng(11).random(len(frame)) < 0.05
    frame.loc[unrecorded & ~last.to_numpy(), "human_action"] = np.nan  # not recorded ("NA" in the study logs)
    assert frame["human_action"].isna().sum() > 10
    return frame


@pytest.fixture(scope="module")
def reference(canonical):
    seqs = encode(canonical, paper_spec())
    fit = fit_trust_model(canonical, options=FitOptions(restarts=1, seed=3, max_iter=60))
    return seqs, fit.loglik


def study_columns(canonical: pd.DataFrame, seed: int = 0) -> pd.DataFrame:
    """The canonical log as a study logs it: truth, the aid's advice and the decision instead of
    experience and reliance; a between-subject condition and per-trial ratings; other names."""
    rng = np.random.default_rng(seed)
    n = len(canonical)
    truth = rng.choice(["left", "right"], n)
    reliable = (canonical["experience"] == "reliable").to_numpy()
    advice = np.where(reliable, truth, [FLIP[t] for t in truth])
    relied = (canonical["human_action"] == "rely").to_numpy()
    decision = np.where(relied, advice, [FLIP[a] for a in advice]).astype(object)
    decision[canonical["human_action"].isna().to_numpy()] = "NA"
    ids = canonical["participant"].astype(str).to_numpy()
    condition = {p: rng.choice(["transparent", "opaque"]) for p in dict.fromkeys(ids)}
    return pd.DataFrame(
        {
            "subject": ids,
            "trial": canonical["trial"].to_numpy(),
            "difficulty": np.where(canonical["complexity"] == "high", "hard", "easy"),
            "robot": np.where(canonical["robot_action"] == "ask", "query", "auto"),
            "truth": truth,
            "advice": advice,
            "decision": decision,
            "condition": [condition[p] for p in ids],
            "rating": rng.integers(1, 8, n),
        }
    )


BASE_MAPPING = {
    "columns": {
        "participant": "subject",
        "complexity": "difficulty",
        "robot_action": "robot",
        "human_action": "relied",
        "experience": "aid_correct",
    },
    "derived": {"relied": {"equal": ["decision", "advice"]}, "aid_correct": {"equal": ["advice", "truth"]}},
    "labels": {
        "complexity": {"low": ["easy"], "high": ["hard"]},
        "robot_action": {"autonomous": ["auto"], "ask": ["query"]},
        "human_action": {"true": "rely", "false": "intervene"},
        "experience": {"true": "reliable", "false": "faulty"},
    },
    "missing": ["NA"],
}


def insert_checks(log: pd.DataFrame, rng: np.random.Generator, every: int = 9) -> pd.DataFrame:
    """Attention-check rows (marked, with junk in the trial columns) after every ``every``-th trial."""
    log = log.assign(attention_check=0)
    checks = log.iloc[every - 1 :: every].copy()
    checks["attention_check"] = 1
    checks["decision"] = "pressed space"
    checks["difficulty"] = "check"
    checks["rating"] = rng.integers(1, 8, len(checks))
    out = pd.concat([log, checks]).sort_index(kind="stable").reset_index(drop=True)
    return out


def zero_based_with_gaps(log: pd.DataFrame) -> pd.DataFrame:
    """Trials numbered from 0 with the checks' numbers left out (gaps where checks were removed)."""
    log = log.copy()
    position = log.groupby("subject", sort=False).cumcount()
    log["trial"] = position  # checks keep their numbers, so the real trials have gaps once they are dropped
    return log


def fit_mapped(path: Path, mapping: dict, tmp_path: Path):
    mfile = tmp_path / "mapping.json"
    mfile.write_text(json.dumps(mapping))
    frame = read_trials(path, mfile)
    return frame, encode(frame, paper_spec()), fit_trust_model(frame, options=FitOptions(restarts=1, seed=3, max_iter=60)).loglik


def assert_same(reference, seqs, loglik):
    ref, ref_ll = reference
    assert sorted(seqs.participants) == sorted(ref.participants)
    seqs = seqs.subset([seqs.participants.index(p) for p in ref.participants])  # rows in any order: align
    np.testing.assert_array_equal(seqs.y, ref.y)
    np.testing.assert_array_equal(seqs.ue, ref.ue)
    np.testing.assert_array_equal(seqs.ut[:-1][seqs.has_successor()], ref.ut[:-1][ref.has_successor()])
    assert loglik == pytest.approx(ref_ll, rel=1e-9, abs=1e-9)


def test_zero_based_gaps_na_cells_semicolon_csv(canonical, reference, tmp_path):
    rng = np.random.default_rng(1)
    log = zero_based_with_gaps(insert_checks(study_columns(canonical), rng))
    path = tmp_path / "study.csv"
    log.to_csv(path, sep=";", index=False)
    mapping = {**BASE_MAPPING, "drop": [{"column": "attention_check", "values": [1]}]}
    frame, seqs, loglik = fit_mapped(path, mapping, tmp_path)
    assert_same(reference, seqs, loglik)
    kept = log[log["attention_check"] == 0]
    assert frame["trial"].tolist() == kept["trial"].tolist()  # the log's own numbers, gaps and all
    assert frame.attrs["dropped"] == [("attention_check in [1]", int((log["attention_check"] == 1).sum()))]
    assert frame["condition"].astype(str).tolist() == kept["condition"].tolist()  # carried through
    assert frame["rating"].astype(str).tolist() == kept["rating"].astype(str).tolist()


def test_blockwise_order_shuffled_json_lines(canonical, reference, tmp_path):
    rng = np.random.default_rng(2)
    log = study_columns(canonical)
    log["block"] = (log["trial"] - 1) // 10 + 1
    log["trial_in_block"] = (log["trial"] - 1) % 10 + 1
    log = insert_checks(log.drop(columns="trial"), rng, every=7).rename(columns={"attention_check": "practice"})
    log["practice"] = np.where(log["practice"] == 1, "yes", "no")
    log = log.sample(frac=1.0, random_state=4)  # rows in any order
    path = tmp_path / "study.jsonl"
    with path.open("w") as fh:
        for rec in log.to_dict(orient="records"):
            if rec["decision"] == "NA":
                rec["decision"] = None  # a JSON null
            fh.write(json.dumps({k: (v.item() if hasattr(v, "item") else v) for k, v in rec.items()}) + "\n")
    mapping = {**BASE_MAPPING, "order": ["block", "trial_in_block"], "drop": [{"column": "practice", "values": ["yes"]}]}
    frame, seqs, loglik = fit_mapped(path, mapping, tmp_path)
    assert_same(reference, seqs, loglik)
    assert frame.attrs["dropped"][0][1] == int((log["practice"] == "yes").sum())


def test_timestamp_order_parquet(canonical, reference, tmp_path):
    log = study_columns(canonical)
    start = pd.Timestamp("2024-05-01T09:00:00")
    log["time"] = [
        (start + pd.Timedelta(hours=i) + pd.Timedelta(seconds=int(t) * 37)).isoformat()
        for i, t in zip(pd.factorize(log["subject"])[0], log["trial"], strict=True)
    ]
    log = log.drop(columns="trial").sample(frac=1.0, random_state=5)
    path = tmp_path / "study.parquet"
    log.to_parquet(path, index=False)
    _frame, seqs, loglik = fit_mapped(path, {**BASE_MAPPING, "order": "time"}, tmp_path)
    assert_same(reference, seqs, loglik)


def test_shifted_feedback_json_array(canonical, reference, tmp_path):
    """The aid's correctness logged on the next trial's row (feedback shown when it starts)."""
    log = study_columns(canonical)
    correct = (log["advice"] == log["truth"]).to_numpy()
    prev = np.r_[False, correct[:-1]]
    first = log.groupby("subject", sort=False).cumcount().to_numpy() == 0
    log["feedback"] = np.where(first, None, np.where(prev, "correct", "wrong"))
    log = log.drop(columns="truth")
    path = tmp_path / "study.json"
    path.write_text(
        json.dumps([{k: (v.item() if hasattr(v, "item") else v) for k, v in r.items()} for r in log.to_dict("records")])
    )
    mapping = {
        **BASE_MAPPING,
        "derived": {
            "relied": {"equal": ["decision", "advice"]},
            "aid_correct": {"shift": "feedback", "by": -1, "fill": "correct"},
        },
        "labels": {**BASE_MAPPING["labels"], "experience": {"reliable": ["correct"], "faulty": ["wrong"]}},
    }
    _frame, seqs, loglik = fit_mapped(path, mapping, tmp_path)
    assert_same(reference, seqs, loglik)
    np.testing.assert_array_equal(seqs.ut, reference[0].ut)  # the fill is the last trial's experience here


def test_numbers_read_alike_from_every_format(tmp_path):
    """'1.0' in a CSV, 1.0 in Parquet and JSON all match the label "1"."""
    rows = [
        {"p": "A", "t": 1, "cx": 1.0, "ra": "autonomous", "ha": 1.0, "ex": 1.0},
        {"p": "A", "t": 2, "cx": 0.0, "ra": "autonomous", "ha": 0.0, "ex": 0.0},
    ]
    mapping = {
        "columns": {
            "participant": "p",
            "trial": "t",
            "complexity": "cx",
            "robot_action": "ra",
            "human_action": "ha",
            "experience": "ex",
        },
        "labels": {
            "complexity": {"0": "low", "1": "high"},
            "human_action": {"1": "rely", "0": "intervene"},
            "experience": {"1": "reliable", "0": "faulty"},
        },
    }
    frames = []
    df = pd.DataFrame(rows)
    df.to_parquet(tmp_path / "a.parquet", index=False)
    (tmp_path / "a.csv").write_text("p,t,cx,ra,ha,ex\nA,1,1.0,autonomous,1.0,1.0\nA,2,0.0,autonomous,0.0,0.0\n")
    (tmp_path / "a.jsonl").write_text("\n".join(json.dumps(r) for r in rows) + "\n")
    (tmp_path / "a.json").write_text(json.dumps(rows))
    for name in ("a.parquet", "a.csv", "a.jsonl", "a.json"):
        frames.append(read_trials(tmp_path / name, mapping)[["participant", "trial", "complexity", "human_action", "experience"]])
    for f in frames[1:]:
        pd.testing.assert_frame_equal(f, frames[0])
    assert frames[0]["complexity"].tolist() == ["high", "low"]


def test_missing_markers_are_not_recorded_only_where_the_model_allows(tmp_path):
    text = "participant,trial,complexity,robot_action,human_action,experience\nA,1,low,autonomous,NA,reliable\nA,2,NA,autonomous,rely,reliable\n"
    path = tmp_path / "log.csv"
    path.write_text(text)
    with pytest.raises(DataError) as exc:
        read_trials(path, {"missing": ["NA"]})
    lines = exc.value.problems
    assert any("column 'complexity': empty value" in line and "row 2" in line for line in lines)
    assert not any("human_action" in line for line in lines)
    path.write_text(text.replace("A,2,NA", "A,2,high"))
    frame = read_trials(path, {"missing": ["NA"]})
    assert frame["human_action"].isna().tolist() == [True, False]
    with pytest.raises(DataError, match="NaN"):  # without the marker, NA stays an error
        read_trials(path)


def test_drop_rules_and_order_problems_are_located(tmp_path):
    text = (
        "subject,block,tib,complexity,robot_action,human_action,experience,practice\n"
        "A,1,1,low,autonomous,rely,reliable,1\n"
        "A,1,1,low,autonomous,rely,reliable,0\n"
        "A,1,1,high,autonomous,rely,reliable,0\n"
        "A,2,x,high,autonomous,rely,reliable,0\n"
    )
    path = tmp_path / "log.csv"
    path.write_text(text)
    mapping = {"columns": {"participant": "subject"}, "order": ["block", "tib"], "drop": [{"column": "practice", "values": [1]}]}
    with pytest.raises(DataError) as exc:
        read_trials(path, mapping)
    text_out = "\n".join(exc.value.problems)
    assert "column 'tib': not a number or a timestamp" in text_out and "row 4 'x'" in text_out
    path.write_text(text.replace("A,2,x", "A,2,1"))
    with pytest.raises(DataError) as exc:
        read_trials(path, mapping)
    (line,) = exc.value.problems
    assert "row 3: same block / tib as row 2" in line  # rows named as in the file, the dropped row 1 counted
    path.write_text(text.replace("A,2,x", "A,2,1").replace("A,1,1,high", "A,1,2,high"))
    frame = read_trials(path, mapping)
    assert frame["trial"].tolist() == [1, 2, 3] and frame.attrs["dropped"] == [("practice in [1]", 1)]


@pytest.mark.parametrize(
    "mapping, expected",
    [
        ({"derived": {"x": {"equal": ["a"]}}}, "'equal' takes a list of two column names"),
        ({"derived": {"x": {"shift": "a", "by": 0}}}, "'by' must be a non-zero integer"),
        ({"derived": {"x": {"mean": "a"}}}, "derived column 'x'"),
        ({"drop": [{"column": "a"}]}, "drop rule 1"),
        ({"order": ["block"], "columns": {"trial": "t"}}, "either 'order' or a 'trial' column"),
        ({"missing": [1]}, "missing: expected a list of texts"),
        ({"delimiter": ";;"}, "delimiter: expected one character"),
        ({"labels": {"human_action": {"rely": ["1", "yes"], "intervene": "x"}}}, "human_action:intervene='x'"),
    ],
)
def test_bad_mappings_are_named(mapping, expected):
    from trustseek.data import ColumnMapping

    with pytest.raises(DataError) as exc:
        ColumnMapping.from_dict(mapping)
    assert any(expected in line for line in exc.value.problems), exc.value.problems


def test_cli_outputs_keep_the_study_names_and_carry_columns(canonical, tmp_path):
    """decode and fit --posteriors write the log's participant and trial values (0-based, gaps) and
    the --keep columns; the dropped rows are counted; --missing and --delimiter work as flags."""
    from trustseek.model import paper_model

    rng = np.random.default_rng(7)
    log = zero_based_with_gaps(insert_checks(study_columns(canonical), rng))
    path = tmp_path / "study.txt"
    log.to_csv(path, sep="|", index=False)
    mapping = {k: v for k, v in BASE_MAPPING.items() if k != "missing"}
    mapping["drop"] = [{"column": "attention_check", "values": [1]}]
    mfile = tmp_path / "mapping.json"
    mfile.write_text(json.dumps(mapping))
    model = tmp_path / "model.json"
    paper_model().save(model)
    kept = log[log["attention_check"] == 0]
    flags = ["--mapping", str(mfile), "--missing", "NA", "--delimiter", "|"]
    code, err = run_cli(
        [
            "decode",
            str(path),
            "--model",
            str(model),
            "--out",
            str(tmp_path / "post.csv"),
            *flags,
            "--keep",
            "condition",
            "--keep",
            "rating",
        ],
        stdout=False,
    )
    assert code == 0, err
    assert f"dropped {int((log['attention_check'] == 1).sum())} rows" in err.replace("\n", " ")
    post = pd.read_csv(tmp_path / "post.csv")
    assert post["participant"].tolist() == kept["subject"].tolist()
    assert post["trial"].tolist() == kept["trial"].tolist()
    assert post["condition"].tolist() == kept["condition"].tolist()
    assert post["rating"].tolist() == kept["rating"].tolist()
    code, err = run_cli(
        [
            "fit",
            str(path),
            "--restarts",
            "1",
            "--max-iter",
            "5",
            "--posteriors",
            str(tmp_path / "fp.csv"),
            *flags,
            "--keep",
            "condition",
        ],
        stdout=False,
    )
    assert code == 0, err
    fp = pd.read_csv(tmp_path / "fp.csv")
    assert fp["trial"].tolist() == kept["trial"].tolist() and fp["condition"].tolist() == kept["condition"].tolist()
    code, err = run_cli(
        ["decode", str(path), "--model", str(model), "--out", str(tmp_path / "p2.csv"), *flags, "--keep", "nope"], stdout=False
    )
    assert code == 2 and "--keep 'nope'" in err
    code, err = run_cli(
        ["decode", str(path), "--model", str(model), "--out", str(tmp_path / "p3.csv"), "--mapping", str(mfile)], stdout=False
    )
    assert code == 2 and "NaN" in err  # without --missing NA, the NA cells are refused


def test_the_shipped_study_mapping_fits_a_study_log(canonical, reference, tmp_path):
    rng = np.random.default_rng(9)
    log = study_columns(canonical)
    log["block"] = (log["trial"] - 1) // 10 + 1
    log["trial_in_block"] = (log["trial"] - 1) % 10 + 1
    log = insert_checks(log.drop(columns="trial"), rng, every=11)
    practice = log.groupby("subject", sort=False).head(3).assign(phase="practice", block=0)
    log = pd.concat([practice, log.assign(phase="main")], ignore_index=True)
    path = tmp_path / "study.csv"
    log.to_csv(path, index=False)
    frame = read_trials(path, example_path("study_mapping.json"))
    assert_same(
        reference, encode(frame, paper_spec()), fit_trust_model(frame, options=FitOptions(restarts=1, seed=3, max_iter=60)).loglik
    )
    practice_only = (log["phase"] == "practice") & (log["attention_check"] == 0)  # each rule counts what is left
    assert [k for _, k in frame.attrs["dropped"]] == [int(log["attention_check"].sum()), int(practice_only.sum())]


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(
    seed=st.integers(0, 2**32 - 1),
    block=st.integers(1, 12),
    zero=st.booleans(),
    gap=st.integers(0, 5),
    shuffle=st.booleans(),
    fmt=st.sampled_from(["csv", "tsv", "jsonl", "json", "parquet"]),
)
def test_any_trial_numbering_encodes_like_the_canonical_log(
    canonical, reference, tmp_path_factory, seed, block, zero, gap, shuffle, fmt
):
    """Gapped numbers from 0 or 1, or a block/trial-within-block split, in any row order and
    format: the same sequences as the canonical log."""
    rng = np.random.default_rng(seed)
    log = study_columns(canonical, seed % 7)
    t = log["trial"].to_numpy() - 1
    if gap:  # random gaps between consecutive trials
        steps = 1 + rng.integers(0, gap + 1, len(t))
        steps[t == 0] = 0
        t = pd.Series(steps).groupby(log["subject"].to_numpy(), sort=False).cumsum().to_numpy()
    log["trial"] = t + (0 if zero else 1)
    mapping = dict(BASE_MAPPING)
    if block > 1:
        log["blk"], log["tib"] = log["trial"] // block, log["trial"] % block
        log = log.drop(columns="trial")
        mapping["order"] = ["blk", "tib"]
    if shuffle:
        log = log.sample(frac=1.0, random_state=int(seed % 1000))
    folder = tmp_path_factory.mktemp("log")
    path = folder / f"study.{fmt}"
    if fmt in ("csv", "tsv"):
        log.to_csv(path, sep="," if fmt == "csv" else "\t", index=False)
    elif fmt == "parquet":
        log.to_parquet(path, index=False)
    else:
        records = [{k: (v.item() if hasattr(v, "item") else v) for k, v in r.items()} for r in log.to_dict("records")]
        text = "\n".join(json.dumps(r) for r in records) if fmt == "jsonl" else json.dumps(records)
        path.write_text(text)
    frame = read_trials(path, mapping)
    seqs = encode(frame, paper_spec())
    ref = reference[0]
    seqs = seqs.subset([seqs.participants.index(p) for p in ref.participants])
    np.testing.assert_array_equal(seqs.y, ref.y)
    np.testing.assert_array_equal(seqs.ue, ref.ue)
    np.testing.assert_array_equal(seqs.ut[:-1][seqs.has_successor()], ref.ut[:-1][ref.has_successor()])


def test_broken_json_logs_are_located(tmp_path):
    good = {
        "participant": "A",
        "trial": 1,
        "complexity": "low",
        "robot_action": "autonomous",
        "human_action": "rely",
        "experience": "reliable",
    }
    path = tmp_path / "log.jsonl"
    path.write_text(json.dumps(good) + "\n{not json\n" + json.dumps({**good, "trial": 2}) + "\n[1, 2]\n")
    with pytest.raises(DataError) as exc:
        read_trials(path)
    assert exc.value.problems == [
        "lines that are not JSON: line 2: Expecting property name enclosed in double quotes",
        "records that are not objects: line 4",
    ]
    path.write_text(json.dumps(good) + "\n[1, 2]\n")
    with pytest.raises(DataError, match="records that are not objects: line 2"):
        read_trials(path)
    path = tmp_path / "log.json"
    path.write_text(json.dumps([good, 3]))
    with pytest.raises(DataError, match="records that are not objects: record 2"):
        read_trials(path)
    path.write_text(json.dumps(good))
    with pytest.raises(DataError, match="must be an array of records"):
        read_trials(path)
    path.write_text(json.dumps([good, {**good, "trial": "two"}]))  # mixed types in a column
    with pytest.raises(DataError, match=r"column 'trial': value is not an integer .*: row 2 'two'"):
        read_trials(path)
