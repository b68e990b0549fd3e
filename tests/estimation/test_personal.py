"""Per-person models: MAP estimates shrunk toward the pooled model or the participant's type."""

import json
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize_scalar
from scipy.special import gammaln

from trustseek.estimation import encode, fit_trust_model, loglik, personal
from trustseek.estimation.options import FitOptions
from trustseek.estimation.personal import EB, NOTHING, ONE_DRAW, blocks, personalize
from trustseek.estimation.trust_iohmm import from_model
from trustseek.model.core import TrustModel, trust_model
from trustseek.model.presets import paper_conservative_mixture, paper_model
from trustseek.simulation.designs import simulate_design
from trustseek.simulation.populations import Supervisors


@pytest.fixture(scope="module")
def pooled_data():
    sup = Supervisors.dirichlet(paper_model(), 40, 20.0, rng=0)
    df = simulate_design(sup, 40, seed=1)
    return df, fit_trust_model(df, options=FitOptions(restarts=2)).model


def known_levels_model() -> TrustModel:
    """The paper's emissions at high trust made positive, trust high from the start and never
    changing: the levels are known, so the variational bound is the evidence itself."""
    p = paper_model()
    em = p.emission.copy()
    em[0, 0, 1] = [0.3, 0.7]
    em[1, 0, 1] = [0.2, 0.8]
    tr = np.broadcast_to(np.eye(2), p.transition.shape).copy()
    return trust_model(p.trust_levels, p.complexities, np.array([0.0, 1.0]), em, tr)


def dirichlet_multinomial(s: float, counts: np.ndarray, t: np.ndarray) -> float:
    """sum over rows of log p(sequence with these counts | Dirichlet(s t)) (no multinomial coefficient)."""
    a = s * t
    return float((gammaln(s) - gammaln(s + counts.sum(-1)) + (gammaln(a + counts) - gammaln(a)).sum(-1)).sum())


def test_with_known_levels_the_variational_bound_is_the_evidence_and_its_maximum_is_found():
    m = known_levels_model()
    df = simulate_design(Supervisors.dirichlet(m, 30, 5.0, rng=0), 30, seed=1)
    res = personalize(df, m, estimate="variational")
    auto = df[df["robot_action"] == "autonomous"]
    c = auto.groupby(["participant", "complexity", "human_action"]).size().unstack(fill_value=0)
    c = c.reindex(columns=["intervene", "rely"], fill_value=0)

    def evidence(s: float) -> float:
        return sum(
            dirichlet_multinomial(s, g.to_numpy(float), m.emission[["low", "high"].index(cx), 0, 1])
            for cx, g in c.groupby(level=1)
        )

    best = minimize_scalar(lambda x: -evidence(np.exp(x)), bounds=(np.log(1e-2), np.log(1e6)), method="bounded")
    assert res.strength["emission"] == pytest.approx(np.exp(best.x), rel=1e-3)
    assert res.score == pytest.approx(-best.fun, abs=1e-6)
    assert res.score_centre == pytest.approx(evidence(1e6), abs=1e-3)
    assert res.method == {"initial": ONE_DRAW, "emission": EB, "transition": NOTHING}
    assert res.estimate == "variational"
    assert not res.at_bound["emission"] and res.at_bound["transition"]
    # the truth is s = 5: within the spread of 30 participants' estimate
    assert 1.5 < res.strength["emission"] < 20


def test_variational_steps_never_lose_and_the_gradient_is_the_bound_s():
    pm = paper_model()
    df = simulate_design(Supervisors.dirichlet(pm, 12, 5.0, rng=2), 12, seed=3)
    prep = personal._Prepared.of(df, pm)
    evidence = prep.evidence()
    start = evidence.counts(prep.first)
    s = {"initial": 1e6, "emission": 8.0, "transition": 30.0}
    bounds = [evidence.run(s, start, 0.0, k).bound.sum() for k in range(1, 8)]
    assert np.all(np.diff(bounds) >= -1e-9) and bounds[-1] > bounds[0]
    done = evidence.run(s, start, 1e-13, 5000)
    for name in ("emission", "transition"):
        h = 1e-4
        up = evidence.run({**s, name: s[name] * np.exp(h)}, done.counts, 1e-13, 5000).bound.sum()
        down = evidence.run({**s, name: s[name] * np.exp(-h)}, done.counts, 1e-13, 5000).bound.sum()
        grad = evidence.rows[name].gradient(done.alpha[name], s[name]) * s[name]
        assert grad == pytest.approx((up - down) / (2 * h), rel=1e-3, abs=1e-4)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(0, 40), min_size=1, max_size=6), st.integers(1, 7))
def test_blocks_split_each_participant_into_consecutive_runs_of_near_equal_size(lengths, folds):
    T = max(lengths) + 2
    b = blocks(np.array(lengths), T, folds)
    for n, L in enumerate(lengths):
        own = b[:L, n]
        assert np.all(b[L:, n] >= folds)
        assert np.all(np.diff(own) >= 0) and np.all((own >= 0) & (own < folds))
        sizes = np.bincount(own, minlength=folds)
        assert sizes.max() - sizes.min() <= 1 and sizes.sum() == L


def test_each_block_is_scored_given_the_others():
    pm = paper_model()
    df = simulate_design(pm, 6, seed=8)
    prep = personal._Prepared.of(df, pm)
    cv = personal._CrossValidation(prep, 3, 1e-8, 1000)
    score = cv.score(dict.fromkeys(personal.TABLES, 1e12))  # the models are the centre
    spec, params = from_model(pm)
    seqs = prep.seqs
    b = blocks(seqs.lengths, seqs.y.shape[0], 3)
    for n in range(6):
        one = seqs.subset([n])
        expected = 0.0
        for f in range(3):
            rest = replace(one, y=np.where(b[: one.y.shape[0], [n]] == f, -1, one.y).astype(one.y.dtype))
            expected += loglik(one, spec, params) - loglik(rest, spec, params)
        assert score[n] == pytest.approx(expected, abs=1e-4)


def mean_error(models, truth, rows):
    """Mean absolute error of P(rely | trust, complexity, autonomous) over the participants."""
    return float(
        np.mean(
            [np.abs(m.emission[..., 0, :, 1] - t.emission[..., 0, :, 1])[rows].mean() for m, t in zip(models, truth, strict=True)]
        )
    )


@pytest.mark.parametrize("estimate", ["held-out", "variational"])
def test_no_individual_differences_keep_the_centre(estimate):
    pm = paper_model()
    df = simulate_design(pm, 40, seed=5)
    res = personalize(df, pm, estimate=estimate)
    assert all(res.at_bound.values()) and res.strength["emission"] >= 1e5
    for m in res.models:
        np.testing.assert_allclose(m.emission, pm.emission, atol=1e-3)
    assert res.score == pytest.approx(res.score_centre, abs=1e-3)
    assert any("no individual differences" in w for w in res.warnings)


@pytest.mark.parametrize("estimate", ["held-out", "variational"])
def test_individual_differences_give_a_finite_strength_and_models_nearer_each_person(estimate):
    pm = paper_model()
    sup = Supervisors.dirichlet(pm, 40, 5.0, rng=6)
    df = simulate_design(sup, 40, seed=7)
    res = personalize(df, pm, estimate=estimate)
    assert not res.at_bound["emission"] and 1.0 < res.strength["emission"] < 100.0
    assert res.score > res.score_centre + 1.0
    truth = [sup.model_of(n) for n in range(40)]
    rows = (pm.emission[..., 0, :, 1] > 0) & (pm.emission[..., 0, :, 1] < 1)  # P(rely) not fixed by the centre
    assert mean_error(res.models, truth, rows) < mean_error([pm] * 40, truth, rows) - 0.005


def test_two_types_around_the_pooled_model_are_seen_by_the_held_out_estimate():
    mix = paper_conservative_mixture(0.5)
    sup = Supervisors.from_mixture(mix, 40, rng=0)
    df = simulate_design(sup, 40, seed=1)
    pooled = fit_trust_model(df, options=FitOptions(restarts=2)).model
    res = personalize(df, pooled)
    assert not all(res.at_bound.values()) and res.score > res.score_centre + 5.0
    # new trials of the same people: their own models predict them better than the pooled one
    new = simulate_design(sup, 40, seed=2)
    spec, centre = from_model(pooled)
    seqs = encode(new, spec)
    own = sum(loglik(seqs.subset([n]), spec, from_model(m)[1]) for n, m in enumerate(res.models))
    assert own > loglik(seqs, spec, centre) + 5.0


def test_strong_prior_keeps_the_centre_and_none_moves_each_participant_toward_their_data(pooled_data):
    df, pooled = pooled_data
    strong = personalize(df, pooled, strength=1e7)
    for m in strong.models:
        np.testing.assert_allclose(m.emission, pooled.emission, atol=1e-3)
    weak = personalize(df, pooled, strength=0.5)
    # each participant's own model explains their trials at least as well as the centre
    assert np.all(weak.loglik >= weak.centre_loglik - 1e-6)
    assert weak.loglik.sum() > strong.loglik.sum() + 1.0
    assert weak.converged.all()
    # the models are each participant's: their log-likelihood is the one reported
    spec, params = from_model(weak.models[3])
    seqs = encode(df, spec)
    assert loglik(seqs.subset([3]), spec, params) == pytest.approx(weak.loglik[3], rel=1e-6)


def test_rows_a_participant_never_reaches_stay_at_the_centre(pooled_data):
    df, pooled = pooled_data
    one = df[(df["participant"] == df["participant"].iloc[0]) & (df["robot_action"] == "autonomous")]
    res = personalize(one, pooled, strength=1.0)
    m = res.models[0]
    # no asking in this log: the ask transition rows are the centre's
    np.testing.assert_allclose(m.transition[:, 1], pooled.transition[:, 1], atol=1e-12)


def test_empirical_bayes_runs_and_reports_the_strength(pooled_data, tmp_path):
    df, pooled = pooled_data
    res = personalize(df, pooled)
    assert set(res.strength) == {"initial", "emission", "transition"}
    assert all(1e-2 <= s <= 1e6 for s in res.strength.values())
    assert res.estimate == "held-out" and set(res.method.values()) <= {personal.CV.format(folds=5), NOTHING, ONE_DRAW}
    arrays = res.arrays()
    sup = Supervisors(**arrays)
    assert sup.n == len(res.models) and sup.model_of(2) == res.models[2]
    res.save(tmp_path / "people")
    table = (tmp_path / "people" / "participants.csv").read_text().splitlines()
    assert len(table) == len(res.models) + 1
    saved = json.loads((tmp_path / "people" / "strength.json").read_text())
    assert saved["strength"] == pytest.approx(res.strength) and saved["method"] == res.method
    assert saved["score"] == pytest.approx(res.score)
    assert len(list((tmp_path / "people").glob("*.json"))) == len(res.models) + 1


def test_with_types_each_participant_is_shrunk_toward_their_type():
    mix = paper_conservative_mixture(0.5)
    sup = Supervisors.from_mixture(mix, 60, rng=3)
    df = simulate_design(sup, 60, seed=4)
    res = personalize(df, mix, strength=50.0)
    truth = np.array(mix.names)[sup.index]
    assert (np.array(res.centre) == truth).mean() >= 0.9
    cons = [m for m, c in zip(res.models, res.centre, strict=True) if c == "conservative"]
    assert np.mean([m.emission[0, 0, 0, 1] for m in cons]) < 0.85  # P(rely | low trust, low complexity)
