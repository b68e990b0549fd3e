"""One-step-ahead prediction of the human action (trustseek.estimation.prediction, `trustseek predict`)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cli_runner import run_cli
from trustseek.data.trials import example_path, read_trials
from trustseek.estimation import encode, from_model, loglik, posteriors
from trustseek.estimation.baselines import features
from trustseek.estimation.options import FitOptions
from trustseek.estimation.prediction import (
    filter_beliefs,
    fold_assignment,
    predict_heldout,
    predict_in_sample,
)
from trustseek.estimation.spec import FitError, Params
from trustseek.model.presets import paper_model
from trustseek.simulation.designs import simulate_design
from trustseek.vocab import ACTIONS, EXPERIENCES, HUMAN_ACTIONS

LOG = str(example_path("paper_trials.csv"))


@pytest.fixture(scope="module")
def study() -> pd.DataFrame:
    return simulate_design(paper_model(), 12, seed=3)


def _random_params(rng: np.random.Generator, K: int = 2, C: int = 2) -> Params:
    em = rng.dirichlet(np.ones(2), size=(C * 2, K))
    em[1::2] = [1.0, 0.0]  # ask rows: P(intervene) = 1, as the paper preset fixes
    return Params(rng.dirichlet(np.ones(K)), em, rng.dirichlet(np.ones(K), size=(C * 4, K)))


def _random_log(rng: np.random.Generator, lengths: list[int]) -> pd.DataFrame:
    rows = []
    for i, n in enumerate(lengths):
        for t in range(1, n + 1):
            a = ACTIONS[int(rng.random() < 0.3)]
            o = "intervene" if a == "ask" else HUMAN_ACTIONS[int(rng.random() < 0.7)]
            e = "faulty" if o == "intervene" and a == "autonomous" else EXPERIENCES[int(rng.random() < 0.8)]
            c = ("low", "high")[int(rng.random() < 0.5)]
            if a == "ask":
                e = "faulty" if c == "low" else "reliable"
            rows.append((f"P{i}", t, c, a, o if rng.random() > 0.1 else None, e))
    return pd.DataFrame(rows, columns=["participant", "trial", "complexity", "robot_action", "human_action", "experience"])


def test_the_model_that_generated_a_study_beats_the_constant_rate_in_log_loss(study):
    r = predict_in_sample(study, paper_model(), bootstrap=200, seed=1)
    m, c = r.metrics["model"]["log_loss"], r.metrics["constant"]["log_loss"]
    assert m["estimate"] < c["estimate"]
    d = r.differences["constant"]["log_loss"]
    assert d["upper"] < 0 and d["better"] == "model"
    assert r.metrics["model"]["auc"]["lower"] > 0.5
    assert not any("constant baseline in log-loss" in s for s in r.statements())


def test_ask_trials_are_counted_apart_and_not_scored(study):
    r = predict_in_sample(study, paper_model(), bootstrap=0)
    asked = (study["robot_action"] == "ask") & study["human_action"].notna()
    assert r.n_determined == int(asked.sum()) > 0
    assert r.determined_matched == r.n_determined  # every ask ended in an intervention
    t = r.trials
    assert (t.loc[asked.to_numpy(), "fixed_by_model"]).all()
    assert not t.loc[asked.to_numpy(), "scored"].any()
    assert (t.loc[asked.to_numpy(), "p_rely_model"] == 0).all()
    assert r.n_scored == int((~asked & study["human_action"].notna()).sum())
    assert r.trials["participant"].tolist() == study["participant"].astype(str).tolist()


def test_the_filter_predicts_with_the_likelihood_chain_rule_and_ends_at_the_smoothed_posterior():
    rng = np.random.default_rng(5)
    frame = _random_log(rng, [9, 14, 5])
    spec, _ = from_model(paper_model())
    params = _random_params(rng)
    seqs = encode(frame, spec)
    f = filter_beliefs(seqs, params)
    obs = seqs.y >= 0
    p_obs = np.where(seqs.y == 1, f.p_rely, 1 - f.p_rely)
    assert np.log(p_obs[obs]).sum() == pytest.approx(loglik(seqs, spec, params), rel=1e-10)
    gamma = posteriors(seqs, spec, params)[0]
    last = seqs.lengths - 1
    cols = np.arange(seqs.n_participants)
    np.testing.assert_allclose(f.posterior[last, cols], gamma[last, cols], atol=1e-10)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), length=st.integers(2, 25), cut=st.integers(0, 23), K=st.integers(2, 3))
def test_changing_later_trials_does_not_change_earlier_predictions(seed, length, cut, K):
    rng = np.random.default_rng(seed)
    t = min(cut, length - 2)  # trials 0..t are kept, t+1.. changed
    frame = _random_log(rng, [length, 4])
    other = _random_log(np.random.default_rng(seed + 1), [length, 4])
    changed = frame.copy()
    later = (changed["participant"] == "P0") & (changed["trial"] > t + 1)
    for c in ("complexity", "robot_action", "human_action", "experience"):
        changed.loc[later, c] = other.loc[later, c]
    spec, _ = from_model(paper_model())
    params = _random_params(rng, K)
    spec = spec.with_levels([f"l{k}" for k in range(K)])
    a, b = encode(frame, spec), encode(changed, spec)
    fa, fb = filter_beliefs(a, params), filter_beliefs(b, params)
    np.testing.assert_array_equal(fa.p_rely[: t + 1], fb.p_rely[: t + 1])
    np.testing.assert_array_equal(fa.prior[: t + 1], fb.prior[: t + 1])
    np.testing.assert_array_equal(fa.posterior[: t + 1], fb.posterior[: t + 1])
    sizes = params.emission.shape[0], params.transition.shape[0]
    ga, gb = features(frame, a, fa.determined, *sizes), features(changed, b, fb.determined, *sizes)
    for name in ("rate_n", "rate_k", "last", "reliable_logit", "ue", "ut_prev"):
        np.testing.assert_array_equal(getattr(ga, name)[: t + 1], getattr(gb, name)[: t + 1])


def test_folds_are_by_participant_seeded_and_balanced():
    f = fold_assignment(11, 4, seed=2)
    assert sorted(np.bincount(f).tolist()) == [2, 3, 3, 3]
    assert np.array_equal(f, fold_assignment(11, 4, seed=2))
    assert not np.array_equal(f, fold_assignment(11, 4, seed=3))
    with pytest.raises(FitError, match="more than the 3 participants"):
        fold_assignment(3, 4)


def test_held_out_folds_use_each_participant_once_and_never_train_on_it():
    frame = simulate_design(paper_model(), 6, seed=4, n_trials=(12, 10))
    opts = {"folds": 3, "options": FitOptions(restarts=1, seed=0, tol=1e-4, max_iter=60), "bootstrap": 20, "prior": 0.5}
    r = predict_heldout(frame, **opts)
    per = r.trials.groupby("participant", observed=True)["fold"].agg(["nunique", "first"])
    assert (per["nunique"] == 1).all() and len(per) == 6
    assert sorted(per["first"].value_counts().tolist()) == [2, 2, 2]
    assert r.trials["p_rely_model"].notna().all()
    # a held-out participant's later trials change: the prediction of its first trial (only the
    # fit to the other folds behind it) stays, so the participant was not in its fold's training
    who = frame["participant"].iloc[0]
    changed = frame.copy()
    later = (changed["participant"] == who) & (changed["trial"] > 1) & (changed["robot_action"] == "autonomous")
    changed.loc[later, "human_action"] = "intervene"
    changed.loc[later, "experience"] = "faulty"
    r2 = predict_heldout(changed, **opts)
    t = r.trials
    fold = t.loc[t["participant"] == who, "fold"].iloc[0]
    kept = (t["fold"] == fold) & ((t["participant"] != who) | (t["trial"] == 1))
    np.testing.assert_array_equal(r2.trials.loc[kept, "p_rely_model"], t.loc[kept, "p_rely_model"])
    # the other folds were fitted with the participant: their predictions move
    assert not np.array_equal(r2.trials.loc[t["fold"] != fold, "p_rely_model"], t.loc[t["fold"] != fold, "p_rely_model"])


def test_the_folds_fits_over_processes_are_the_fits_in_one():
    """The folds' fits run side by side in processes; in one process, one after another, each fold
    must still get its own seed: sharing one SeedSequence moved the later folds' starts (their
    log-likelihoods off by 1e-13 to 1e-10, the predictions by 1e-7)."""
    frame = read_trials(example_path())
    runs = [
        predict_heldout(frame, folds=3, options=FitOptions(restarts=3, seed=0, tol=1e-8, n_jobs=jobs), bootstrap=0)
        for jobs in (1, 2)
    ]
    pd.testing.assert_frame_equal(runs[0].trials, runs[1].trials, check_exact=True)


def test_cli_predict_in_sample_json_and_per_trial_file(tmp_path):
    model = tmp_path / "m.json"
    paper_model().save(model)
    out = tmp_path / "pred.csv"
    code, text = run_cli(["predict", LOG, "-m", str(model), "-b", "50", "--json", "-o", str(out), "--keep", "true_trust"])
    assert code == 0, text
    d = json.loads(text)
    assert d["mode"] == "in-sample" and d["n_participants"] == 9
    assert set(d["metrics"]) == {
        "model", "constant", "participant_rate", "last_action", "reliable_fraction", "one_level", "inputs_logistic"
    }  # fmt: skip
    got = pd.read_csv(out)
    log = read_trials(LOG)
    assert got["true_trust"].tolist() == log["true_trust"].tolist()
    assert got["trial"].tolist() == log["trial"].tolist()
    code, text = run_cli(["predict", LOG, "-m", str(model), "-b", "20"])
    assert code == 0 and "not scored" in text and "log-loss" in text


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--folds", "12"], "--folds 12 is more than the 9 participants"),
        (["-m", "{model}", "--folds", "3"], "give one of them"),
        (["-m", "{model}", "--keep", "true_trust"], "--keep carries log columns into --out"),
    ],
)
def test_cli_predict_bad_inputs_are_one_line_errors(tmp_path, args, message):
    model = tmp_path / "m.json"
    paper_model().save(model)
    code, text = run_cli(["predict", LOG, "-b", "0", *[a.format(model=model) for a in args]])
    assert code == 2
    lines = [x for x in text.splitlines() if x.strip()]
    assert len(lines) == 1 and message in lines[0] and "Traceback" not in text


def test_without_resamples_there_is_no_judgement(study):
    r = predict_in_sample(study, paper_model(), bootstrap=0)
    assert np.isnan(r.metrics["model"]["auc"]["lower"])
    assert r.statements() == [
        "no bootstrap resamples (--bootstrap 0): no intervals, so no judgement whether the model beats a baseline"
    ]


def test_an_undefined_score_is_no_claim_and_no_nan(tmp_path):
    """Every scored action the same: AUC is undefined, and predict says so instead of 'does not beat ... +nan'."""
    from trustseek.model.presets import paper_model

    model = tmp_path / "paper.json"
    paper_model().save(model)
    frame = pd.read_csv(example_path("paper_trials.csv"))
    frame = frame[frame.robot_action == "autonomous"].assign(human_action="rely")
    f = tmp_path / "rely.csv"
    frame.to_csv(f, index=False)
    code, output = run_cli(["predict", str(f), "-m", str(model), "-b", "20"])
    text = " ".join(output.split())
    assert code == 0 and "nan" not in text and "are not compared in AUC: the score is undefined" in text, output
