"""Per-person models: MAP estimates shrunk toward the pooled model or the participant's type."""

import json

import numpy as np
import pytest

from trustseek.estimation import encode, fit_trust_model, kernels, loglik
from trustseek.estimation.personal import dirichlet_multinomial, estimate_strength, personalize
from trustseek.estimation.trust_iohmm import from_trust_model
from trustseek.model.presets import paper_conservative_mixture, paper_model
from trustseek.simulation.designs import simulate_design
from trustseek.simulation.populations import Supervisors

pytestmark = pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not installed")


@pytest.fixture(scope="module")
def pooled_data():
    sup = Supervisors.dirichlet(paper_model(), 40, 20.0, rng=0)
    df = simulate_design(sup, 40, seed=1)
    return df, fit_trust_model(df, restarts=2).model


@pytest.mark.parametrize("s", [2.0, 20.0, 200.0])
def test_strength_is_recovered_from_dirichlet_multinomial_counts(s):
    rng = np.random.default_rng(int(s))
    t = np.array([0.2, 0.3, 0.5])
    p = rng.dirichlet(s * t, size=800)
    c = np.array([rng.multinomial(40, q) for q in p], dtype=float)
    est, at_bound = estimate_strength(c, np.broadcast_to(t, c.shape), np.ones(c.shape, dtype=bool))
    assert not at_bound
    assert est == pytest.approx(s, rel=0.35)


def test_homogeneous_counts_put_the_strength_at_its_bound():
    rng = np.random.default_rng(1)
    t = np.array([0.4, 0.6])
    c = rng.multinomial(30, t, size=500).astype(float)
    est, at_bound = estimate_strength(c, np.broadcast_to(t, c.shape), np.ones(c.shape, dtype=bool))
    assert at_bound and est > 1e4
    # rows with fewer than two usable cells, or no counts, add nothing
    mask = np.zeros(c.shape, dtype=bool)
    mask[:, 0] = True
    assert dirichlet_multinomial(3.0, c, np.broadcast_to(t, c.shape), mask) == 0.0


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
    spec, params = from_trust_model(weak.models[3])
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
    arrays = res.arrays()
    sup = Supervisors(**arrays)
    assert sup.n == len(res.models) and sup.model_of(2) == res.models[2]
    res.save(tmp_path / "people")
    table = (tmp_path / "people" / "participants.csv").read_text().splitlines()
    assert len(table) == len(res.models) + 1
    assert json.loads((tmp_path / "people" / "strength.json").read_text())["strength"] == pytest.approx(res.strength)
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
