"""Self-reported trust ratings as a second emission of the hidden trust: the model's rating table,
the rating column of a trial log, the joint fit on actions and ratings, and ratings alone."""

from __future__ import annotations

import functools
import json
import re
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cli_runner import run_cli
from trustseek.data.trials import ColumnMapping, DataError, read_trials
from trustseek.estimation import FitError, encode, fit_trust_model
from trustseek.estimation.fit import decode, trust_loglik
from trustseek.estimation.options import FitOptions
from trustseek.estimation.ratings import compose_joint, split_counts, split_joint
from trustseek.estimation.result import FitResult
from trustseek.estimation.trust_iohmm import preset_spec
from trustseek.model import ModelError, RatingTable, TrustModel, paper_model, paper_task
from trustseek.pomdp import AssistancePOMDP
from trustseek.simulation import add_ratings, simulate_design
from trustseek.vocab import ACTIONS, EXPERIENCES, HUMAN_ACTIONS

LEVELS = ("1", "2", "3", "4", "5")
RATING = RatingTable(LEVELS, np.array([[0.35, 0.30, 0.20, 0.10, 0.05], [0.05, 0.10, 0.20, 0.30, 0.35]]))
TRUTH = paper_model().replace(rating=RATING)


def errors(result: FitResult, truth: TrustModel) -> np.ndarray:
    """Absolute error of every estimated cell against ``truth``."""
    out = []
    for c in result.cells():
        table = truth.rating.probs if c["table"] == "rating" and truth.rating is not None else getattr(truth, c["table"])
        out.append(abs(c["estimate"] - float(table[tuple(c["index"])])))
    return np.array(out)


# --------------------------------------------------------------------------- the model's table


def test_model_file_round_trip_and_files_without_ratings():
    d = TRUTH.to_dict()
    assert d["rating"]["levels"] == list(LEVELS)
    assert d["rating"]["probs"]["high"]["5"] == pytest.approx(0.35)
    back = TrustModel.from_dict(json.loads(json.dumps(d)))
    assert back == TRUTH and back.rating is not None
    plain = TrustModel.from_dict(paper_model().to_dict())
    assert plain.rating is None and "rating" not in plain.to_dict()
    assert plain != TRUTH


def test_rating_table_problems_all_reported():
    d = TRUTH.to_dict()
    d["rating"]["probs"]["low"]["1"] = 1.5
    d["rating"]["probs"]["high"]["9"] = 0.1
    del d["rating"]["probs"]["high"]["3"]
    d["rating"]["probs"]["medium"] = {}
    with pytest.raises(ModelError) as exc:
        TrustModel.from_dict(d)
    text = "\n".join(exc.value.problems)
    assert "rating[T=low][1] = 1.5 is outside [0, 1]" in text
    assert "rating[T=high] has unknown entry '9'" in text
    assert "rating[T=high][3] is missing" in text
    assert "rating.probs has unknown entry 'medium'" in text
    with pytest.raises(ModelError) as exc:
        paper_model().replace(rating=RatingTable(("a", "a"), np.array([[0.5, 0.6], [1.0, 0.0], [1.0, 0.0]])))
    text = "\n".join(exc.value.problems)
    assert "duplicate" in text and "shape (3, 2), expected (2, 2)" in text
    with pytest.raises(ModelError, match=r"rating\[T=high\] sums to 0.9"):
        paper_model().replace(rating=RatingTable(("a", "b"), np.array([[0.5, 0.5], [0.5, 0.4]])))


def test_pomdp_and_simulator_ignore_the_rating_table():
    task = paper_task()
    a, b = AssistancePOMDP(TRUTH, task), AssistancePOMDP(paper_model(), task)
    for name in ("emission", "trust_transition", "expected_reward", "kernel"):
        assert np.array_equal(getattr(a, name), getattr(b, name))
    with_r = simulate_design(TRUTH, 30, seed=4, n_trials=(5, 5))
    without = simulate_design(paper_model(), 30, seed=4, n_trials=(5, 5))
    pd.testing.assert_frame_equal(with_r, without)


def test_simulated_ratings_follow_the_table_and_the_schedule():
    frame = simulate_design(TRUTH, 400, seed=2, n_trials=(10, 10), rating_every=5)
    rated = frame["rating"].notna()
    assert set(frame.loc[rated, "trial"]) == {5, 10, 15, 20}
    assert list(frame["rating"].cat.categories) == list(LEVELS)
    for k, t in enumerate(TRUTH.trust_levels):
        got = frame.loc[rated & (frame["true_trust"] == t), "rating"].value_counts(normalize=True).reindex(list(LEVELS))
        assert np.abs(got.to_numpy() - RATING.probs[k]).max() < 0.05
    with pytest.raises(Exception, match="no rating table"):
        add_ratings(frame, paper_model())


# --------------------------------------------------------------------------- the joint emission


def test_joint_table_factorises_and_counts_marginalise():
    rng = np.random.default_rng(0)
    action = rng.dirichlet(np.ones(2), size=(3, 2))  # (U, K, M)
    rating = rng.dirichlet(np.ones(4), size=2)  # (K, R)
    J = compose_joint(action, rating).reshape(3, 2, 3, 5)
    assert np.allclose(J[:, :, :2, :4], action[:, :, :, None] * rating[None, :, None, :])
    assert np.allclose(J[:, :, 2, :4], np.broadcast_to(rating, (3, 2, 4))) and np.allclose(J[:, :, :2, 4], action)
    a2, r2 = split_joint(J.reshape(3, 2, 15), 2, 4)
    assert np.allclose(a2, action) and np.allclose(r2, rating)
    counts = rng.random((3, 2, 15))
    ca, cr = split_counts(counts, 2, 4)
    c = counts.reshape(3, 2, 3, 5)
    assert np.allclose(ca, c[:, :, :2, :].sum(-1)) and np.allclose(cr, c[:, :, :, :4].sum((0, 2)))


def forward_loglik(frame: pd.DataFrame, model: TrustModel, rating: str | None) -> float:
    """An independent forward algorithm: per trial the emission is P(o | T, C, a) (1 when the
    action is missing) times P(r | T) (1 when the rating is missing)."""
    C = model.complexities
    total = 0.0
    for _, g in frame.sort_values(["participant", "trial"]).groupby("participant", observed=True, sort=False):
        alpha = np.asarray(model.initial, dtype=float)
        prev = None
        for row in g.itertuples(index=False):
            c, a = C.index(row.complexity), ACTIONS.index(row.robot_action)
            if prev is not None:
                pc, pa, pe = prev
                alpha = alpha @ model.transition[pc, pa, pe]
            e = np.ones(model.n_trust)
            if isinstance(row.human_action, str):
                e = e * model.emission[c, a, :, HUMAN_ACTIONS.index(row.human_action)]
            r = getattr(row, rating) if rating else None
            if model.rating is not None and isinstance(r, str):
                e = e * model.rating.probs[:, model.rating.levels.index(r)]
            alpha = alpha * e
            s = alpha.sum()
            total += np.log(s)
            alpha = alpha / s
            prev = (c, a, EXPERIENCES.index(row.experience))
    return total


def test_fit_loglik_equals_an_independent_forward_algorithm():
    frame = simulate_design(TRUTH, 25, seed=3, n_trials=(4, 4), rating_every=3, p_unobserved=0.3)
    assert frame["human_action"].isna().any() and (frame["human_action"].isna() & frame["rating"].notna()).any()
    res = fit_trust_model(frame, options=FitOptions(restarts=2, seed=1, tol=1e-6), rating="rating")
    ref = forward_loglik(frame, res.model, "rating")
    assert res.loglik == pytest.approx(ref, abs=1e-8)
    assert trust_loglik(frame, res.model, "rating") == pytest.approx(ref, abs=1e-8)
    # the actions-only likelihood of the same model leaves the ratings out
    assert trust_loglik(frame, res.model) == pytest.approx(forward_loglik(frame, res.model, None), abs=1e-8)
    # initial, rely rows, the 6 transition rows with data (the design never asks in low complexity
    # with a reliable experience, nor in high with a faulty one), rating rows
    assert res.n_params == 1 + 4 + 6 * 2 + 2 * 4


def test_missing_ratings_contribute_probability_one():
    frame = simulate_design(TRUTH, 40, seed=5, n_trials=(6, 6), p_unobserved=0.2)
    frame["rating"] = pd.Categorical([None] * len(frame), categories=list(LEVELS), ordered=True)
    assert trust_loglik(frame, TRUTH, "rating") == pytest.approx(trust_loglik(frame, paper_model()), abs=1e-9)
    post_r = decode(frame, TRUTH, "rating")
    post = decode(frame, paper_model())
    assert np.allclose(post_r["p_trust_high"], post["p_trust_high"], atol=1e-12)


def test_ratings_move_the_decoded_trust():
    frame = simulate_design(TRUTH, 30, seed=6, n_trials=(5, 5), rating_every=1)
    frame["rating"] = pd.Categorical(["5"] * len(frame), categories=list(LEVELS), ordered=True)
    hi = decode(frame, TRUTH, "rating")["p_trust_high"].to_numpy()
    frame["rating"] = pd.Categorical(["1"] * len(frame), categories=list(LEVELS), ordered=True)
    lo = decode(frame, TRUTH, "rating")["p_trust_high"].to_numpy()
    assert hi.mean() > lo.mean() + 0.1
    with pytest.raises(FitError, match="no rating table"):
        trust_loglik(frame, paper_model(), "rating")


# --------------------------------------------------------------------------- recovery


@pytest.mark.parametrize("every", [1, 5])
def test_joint_fit_recovers_the_generating_model(every):
    frame = simulate_design(TRUTH, 1000, seed=1, n_trials=(10, 10), rating_every=every)
    res = fit_trust_model(frame, options=FitOptions(restarts=4, seed=0, n_jobs=1), rating="rating")
    err = errors(res, TRUTH)
    assert len(err) == 27  # 17 action-model cells the design reaches + 2 x 5 rating cells
    assert err.mean() <= 0.03
    assert res.model.rating is not None and res.model.rating.levels == LEVELS
    assert res.runs[res.best].ended == "stationary"


def test_ratings_only_fit():
    frame = simulate_design(TRUTH, 600, seed=2, n_trials=(10, 10), rating_every=1)
    res = fit_trust_model(frame, options=FitOptions(restarts=4, seed=0, n_jobs=1), rating="rating", actions=False)
    assert res.model.rating is not None
    assert np.abs(res.model.rating.probs - RATING.probs).max() < 0.05  # levels named by the mean rating
    # no human action counted: every emission row is marked never estimated, and left uniform
    marked = {idx for t, idx in res.model.not_estimated if t == "emission"}
    assert marked == {(0, 0), (1, 0)}  # the ask rows are fixed (P(intervene | ask) = 1)
    assert np.allclose(res.model.emission[:, 0], 0.5)
    assert not any(c["table"] == "emission" for c in res.cells())
    with pytest.raises(FitError, match="needs a rating column"):
        fit_trust_model(frame, actions=False)


def test_rating_levels_must_be_declared_and_values_inside_them():
    frame = simulate_design(TRUTH, 10, seed=2, n_trials=(3, 3), rating_every=1)
    frame["score"] = frame["rating"].astype(object)
    with pytest.raises(FitError, match="declare its levels"):
        fit_trust_model(frame, rating="score")
    frame.loc[4, "score"] = "9"
    with pytest.raises(FitError, match=r"row 5, column 'score': value '9' is not one of"):
        fit_trust_model(frame, rating="score", rating_levels=LEVELS, options=FitOptions(restarts=1))
    frame["score"] = frame["rating"].astype(object).map(lambda v: None if v is None or v != v else int(v))
    seqs = encode(frame, replace(preset_spec("paper", frame), rating="score", rating_levels=LEVELS))
    assert (seqs.y >= 0).sum() == len(frame)  # numeric ratings match their levels by text


# --------------------------------------------------------------------------- the trial log's rating column


def _log(n: int = 6) -> pd.DataFrame:
    return _simulated_log(n).copy()


@functools.cache
def _simulated_log(n: int) -> pd.DataFrame:
    frame = simulate_design(TRUTH, n, seed=8, n_trials=(3, 3), rating_every=2)
    frame = frame.drop(columns=["true_trust"]).rename(columns={"participant": "pid", "rating": "trust_score"})
    frame["trust_score"] = frame["trust_score"].astype(object)
    return frame


MAPPING = {"columns": {"participant": "pid"}, "rating": {"column": "trust_score", "levels": [1, 2, 3, 4, 5]}}


def test_mapping_rating_levels_labels_and_bins():
    frame = _log()
    out = read_trials(frame, MAPPING)
    assert out["rating"].cat.ordered and list(out["rating"].cat.categories) == list(LEVELS)
    assert out["rating"].isna().tolist() == frame["trust_score"].isna().tolist()
    assert "trust_score" not in out.columns
    labelled = frame.assign(
        trust_score=frame["trust_score"].map({"1": "nil", "2": "little", "3": "some", "4": "much", "5": "full"})
    )
    words = {"column": "trust_score", "levels": ["nil", "little", "some", "much", "full"]}
    got = read_trials(labelled, {**MAPPING, "rating": words})["rating"]
    assert got.cat.codes.tolist() == out["rating"].cat.codes.tolist()
    mapped = {
        "column": "trust_score",
        "levels": ["low", "high"],
        "labels": {"1": "low", "2": "low", "3": "low", "4": "high", "5": "high"},
    }
    got = read_trials(frame, {**MAPPING, "rating": mapped})["rating"]
    assert (got.cat.codes == np.where(out["rating"].cat.codes < 0, -1, (out["rating"].cat.codes >= 3).astype(int))).all()
    slider = frame.assign(trust_score=frame["trust_score"].map(lambda v: None if v is None or v != v else 20.0 * int(v) - 10))
    got = read_trials(slider, {**MAPPING, "rating": {"column": "trust_score", "bins": [0, 20, 40, 60, 80, 100]}})["rating"]
    assert got.cat.codes.tolist() == out["rating"].cat.codes.tolist()
    assert list(got.cat.categories) == ["0-20", "20-40", "40-60", "60-80", "80-100"]
    rt = ColumnMapping.from_dict(json.loads(json.dumps(ColumnMapping.from_dict(MAPPING).to_dict())))
    assert rt.rating == MAPPING["rating"]


@pytest.mark.parametrize(
    "entry, message",
    [
        ({"column": "x"}, "declare the levels"),
        ({"column": "x", "levels": [1]}, "at least 2 distinct levels"),
        ({"column": "x", "levels": [1, 1]}, "at least 2 distinct levels"),
        ({"column": "x", "bins": [0, 5, 3]}, "increasing finite edges"),
        ({"column": "x", "bins": [0, 1, 2], "levels": ["a"]}, "2 bins need 2 level names"),
        ({"column": "x", "levels": ["a", "b"], "labels": {"z": "c"}}, "label z='c' is not one of the levels"),
        ({"levels": ["a", "b"]}, "'column' must name"),
        ("x", "expected"),
    ],
)
def test_mapping_rating_entry_problems(entry, message):
    with pytest.raises(DataError, match=message):
        ColumnMapping.from_dict({"rating": entry})


def test_missing_rating_column_is_reported():
    with pytest.raises(DataError, match="missing column 'nope' \\(the mapping's rating column\\)"):
        read_trials(_log(), {**MAPPING, "rating": {"column": "nope", "levels": [1, 2]}})


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture], derandomize=True)
@given(
    bad=st.dictionaries(
        st.integers(0, 35),
        st.one_of(st.sampled_from(["0", "6", "3.5", "high", "-1", "x7"]), st.integers(6, 99).map(str)),
        min_size=1,
        max_size=12,
    )
)
def test_corrupt_rating_cells_are_located(bad):
    frame = _log(6)
    assert len(frame) == 36
    for row, value in bad.items():
        frame.loc[row, "trust_score"] = value
    with pytest.raises(DataError) as exc:
        read_trials(frame, MAPPING)
    (line,) = [x for x in exc.value.problems if "trust_score" in x]
    rows = sorted(bad)
    assert "rating outside the declared levels" in line
    if len(rows) > 1:
        assert f"in {len(rows)} rows" in line
    shown = [int(r) for r in re.findall(r"row (\d+) '", line)]
    assert shown == [r + 1 for r in rows[:5]]
    assert f"row {rows[0] + 1} {bad[rows[0]]!r}" in line


# --------------------------------------------------------------------------- the command line


def test_fit_and_validate_by_mapping_alone(tmp_path):
    frame = simulate_design(TRUTH, 120, seed=11, n_trials=(10, 10), rating_every=2)
    frame = frame.drop(columns=["true_trust"]).rename(columns={"participant": "pid", "rating": "trust_score"})
    log, mapping, model = tmp_path / "log.csv", tmp_path / "map.json", tmp_path / "model.json"
    frame.to_csv(log, index=False)
    mapping.write_text(json.dumps(MAPPING))
    code, out = run_cli(["fit", str(log), "--mapping", str(mapping), "-r", "2", "--tol", "1e-6", "-o", str(model), "--json"])
    assert code == 0, out
    fitted = TrustModel.load(model)
    assert fitted.rating is not None and fitted.rating.levels == LEVELS
    assert np.abs(fitted.rating.probs - RATING.probs).max() < 0.1
    d = json.loads(out[: out.rindex("}") + 1])
    assert any(c["table"] == "rating" for c in d["cells"]) and d["spec"]["rating"] == "rating"
    # the same fit from flags instead of the mapping's rating entry
    flags = ["--column", "participant=pid", "--rating", "trust_score", "--rating-levels", "1,2,3,4,5"]
    code2, out2 = run_cli(["fit", str(log), *flags, "-r", "2", "--tol", "1e-6", "--json"])
    assert code2 == 0, out2
    assert json.loads(out2[: out2.rindex("}") + 1])["loglik"] == pytest.approx(d["loglik"])
    code3, out3 = run_cli(["fit", str(log), *flags, "--ratings-only", "-r", "2", "--tol", "1e-6", "--json"])
    assert code3 == 0, out3
    assert json.loads(out3[: out3.rindex("}") + 1])["loglik"] > d["loglik"]  # the ratings alone: fewer events
    # a ratings-only study need not have a human-action column
    frame.drop(columns=["human_action"]).to_csv(tmp_path / "no_actions.csv", index=False)
    code7, out7 = run_cli(
        ["fit", str(tmp_path / "no_actions.csv"), *flags, "--ratings-only", "-r", "2", "--tol", "1e-6", "--json"]
    )
    assert code7 == 0, out7
    assert json.loads(out7[: out7.rindex("}") + 1])["loglik"] == pytest.approx(json.loads(out3[: out3.rindex("}") + 1])["loglik"])
    code4, out4 = run_cli(["validate", str(log), "-m", str(model), "--mapping", str(mapping), "--bootstrap", "0", "--json"])
    assert code4 == 0, out4
    assert "rating" in out4
    code5, out5 = run_cli(["fit", str(log), "--column", "participant=pid", "--rating-levels", "1,2"])
    assert code5 == 2 and "give --rating" in out5
    code6, out6 = run_cli(["fit", str(log), "--column", "participant=pid", "--ratings-only"])
    assert code6 == 2 and "--ratings-only needs a rating column" in out6
