"""The (type, trust) product of a supervisor-type mixture: its model, its belief and the type
posterior of a person's earlier trials."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trustseek.model import TypeMixture, conservative_model, paper_conservative_mixture, paper_model, paper_task, trust_model
from trustseek.policies import never_ask
from trustseek.pomdp.belief import BayesUpdate
from trustseek.pomdp.supervisor_types import (
    TypeBeliefError,
    product_model,
    trust_given_type,
    trust_marginal,
    type_aware_problem,
    type_belief_from_log,
    type_marginal,
    warm_start_belief,
)
from trustseek.simulation import Supervisors, simulate


def _midway() -> TypeMixture:
    """Three types: the paper's, the conservative one and their average."""
    p, c = paper_model(), conservative_model()
    mid = trust_model(
        p.trust_levels,
        p.complexities,
        (p.initial + c.initial) / 2,
        (p.emission + c.emission) / 2,
        (p.transition + c.transition) / 2,
    )
    return TypeMixture(("paper", "conservative", "midway"), np.array([0.5, 0.3, 0.2]), (p, c, mid))


def test_product_levels_are_named_type_slash_trust_in_type_major_order():
    pm = product_model(paper_conservative_mixture(0.3))
    assert pm.trust_levels == ("paper/low", "paper/high", "conservative/low", "conservative/high")


def test_product_model_is_the_types_side_by_side():
    mix = _midway()
    pm = product_model(mix)
    K = 2
    np.testing.assert_allclose(pm.initial, np.concatenate([w * m.initial for w, m in zip(mix.weights, mix.models, strict=True)]))
    for i, m in enumerate(mix.models):
        blk = slice(i * K, (i + 1) * K)
        np.testing.assert_array_equal(pm.emission[:, :, blk], m.emission)
        np.testing.assert_array_equal(pm.transition[..., blk, blk], m.transition)
        # the type never changes: no mass leaves the type's block
        assert np.all(pm.transition[..., blk, :].sum(axis=-1) == pytest.approx(1.0))
        np.testing.assert_array_equal(np.delete(pm.transition[..., blk, :], np.arange(blk.start, blk.stop), axis=-1), 0.0)
    # the problem is an ordinary assistance POMDP over M*K levels
    assert type_aware_problem(mix, paper_task()).n_trust == 6


def test_a_single_type_product_is_the_model():
    pm = product_model(paper_model())
    assert pm.trust_levels == ("pooled/low", "pooled/high")
    np.testing.assert_array_equal(pm.transition, paper_model().transition)
    np.testing.assert_array_equal(pm.initial, paper_model().initial)


def test_marginals_and_warm_start():
    mix = _midway()
    b = warm_start_belief(mix, [0.2, 0.0, 0.8])
    np.testing.assert_allclose(type_marginal(b, 3), [0.2, 0.0, 0.8])
    np.testing.assert_allclose(trust_given_type(b, 3)[[0, 2]], [mix.models[0].initial, mix.models[2].initial])
    np.testing.assert_allclose(trust_given_type(b, 3)[1], [0.5, 0.5])  # a type of probability zero
    np.testing.assert_allclose(trust_marginal(b, 3), 0.2 * mix.models[0].initial + 0.8 * mix.models[2].initial)
    np.testing.assert_allclose(warm_start_belief(mix), product_model(mix).initial)
    with pytest.raises(TypeBeliefError):
        warm_start_belief(mix, [0.0, 0.0, 0.0])
    with pytest.raises(TypeBeliefError):
        type_marginal(np.ones(5) / 5, 3)


events = st.lists(st.tuples(st.integers(0, 1), st.integers(0, 1), st.integers(-1, 1), st.integers(0, 1)), min_size=1, max_size=25)


@settings(max_examples=60, deadline=None)
@given(events=events, w=st.lists(st.floats(0.01, 1.0), min_size=3, max_size=3))
def test_product_filter_is_the_per_type_filters_reweighted_by_the_type_likelihoods(events, w):
    """b(m, ·) after a trial = P(m) P(o | m, b_m) b_m' / Σ: each type's own Bayes filter, its weight
    times the probability that type gave the human action, renormalised."""
    mix = _midway().with_weights(w)
    product = BayesUpdate(product_model(mix))
    per_type = [BayesUpdate(m) for m in mix.models]
    b = product.initial()
    weights = mix.weights.copy()
    beliefs = [m.initial.copy() for m in mix.models]
    for c, a, o, e in events:
        if o >= 0:
            lik = np.array([bm @ m.emission[c, a, :, o] for bm, m in zip(beliefs, mix.models, strict=True)])
            if (weights * lik).sum() <= 0:  # impossible under every type: the filter keeps its prior
                lik = np.ones(3)
            weights = weights * lik / (weights * lik).sum()
        beliefs = [u.update(bm, c, a, o, e) for u, bm in zip(per_type, beliefs, strict=True)]
        b = product.update(b, c, a, o, e)
        np.testing.assert_allclose(type_marginal(b, 3), weights, atol=1e-12)
        np.testing.assert_allclose(trust_given_type(b, 3)[weights > 1e-9], np.array(beliefs)[weights > 1e-9], atol=1e-9)


def _log_of(mixture: TypeMixture, type_index: int, trials: int, seed: int) -> pd.DataFrame:
    """A simulated log of one supervisor of the given type under a policy that never asks."""
    sup = Supervisors.from_models([mixture.models[type_index]], 1)
    return simulate(sup, paper_task(), never_ask(paper_task().complexities), trials=trials, seed=seed).trials()


@pytest.mark.parametrize("true_type", [0, 1, 2])
def test_the_type_posterior_of_a_long_log_concentrates_on_the_generating_type(true_type):
    mix = _midway()
    post = type_belief_from_log(mix, _log_of(mix, true_type, 600, seed=11 + true_type))
    assert post.argmax() == true_type
    assert post[true_type] > 0.95


def test_sessions_restart_trust_and_keep_the_type_belief():
    mix = paper_conservative_mixture(0.3)
    one = _log_of(mix, 1, 8, seed=5)
    two = _log_of(mix, 1, 8, seed=6)
    log = pd.concat([one.assign(block=1), two.assign(block=2)], ignore_index=True)
    first = type_belief_from_log(mix, one)
    chained = type_belief_from_log(mix, two, prior=first)
    np.testing.assert_allclose(type_belief_from_log(mix, log, session="block"), chained, atol=1e-12)
    # without sessions the second half continues the first's trust: a different posterior in general
    joined = log.assign(trial=np.arange(1, len(log) + 1))
    assert abs(type_belief_from_log(mix, joined)[0] - chained[0]) > 1e-6


def test_log_problems_are_named():
    mix = paper_conservative_mixture(0.3)
    log = pd.concat([_log_of(mix, 0, 5, 1).assign(participant="a"), _log_of(mix, 0, 5, 2).assign(participant="b")])
    with pytest.raises(TypeBeliefError, match="2 participants"):
        type_belief_from_log(mix, log)
    with pytest.raises(TypeBeliefError, match="participant 'c'"):
        type_belief_from_log(mix, log, participant="c")
    assert type_belief_from_log(mix, log, participant="a").shape == (2,)
    bad = log.assign(complexity="medium")
    with pytest.raises(TypeBeliefError, match="medium"):
        type_belief_from_log(mix, bad, participant="a")
    # an unrecorded human action is not conditioned on
    blank = log.assign(human_action=None)
    post = type_belief_from_log(mix, blank, participant="a")
    assert np.all(np.isfinite(post)) and post.sum() == pytest.approx(1.0)
