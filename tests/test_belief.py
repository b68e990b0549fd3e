"""Belief updates: eq. (3) and the exact Bayes filter."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trustseek import BayesUpdate, PaperUpdate, paper_model
from trustseek.model.core import ASK, AUTONOMOUS, FAULTY, INTERVENE, RELIABLE, RELY

LOW, HIGH = 0, 1


def test_paper_update_is_eq3(model):
    up = PaperUpdate(model)
    b = np.array([0.4, 0.6])
    # eq. (3): b' = P(H | H, E', C, a) b + P(H | L, E', C, a) (1 - b)
    out = up.update(b, HIGH, ASK, INTERVENE, RELIABLE)
    assert out[1] == pytest.approx(0.94 * 0.6 + 0.44 * 0.4)
    # the human action is ignored
    np.testing.assert_array_equal(up.update(b, HIGH, AUTONOMOUS, RELY, FAULTY), up.update(b, HIGH, AUTONOMOUS, INTERVENE, FAULTY))


def test_bayes_update_by_hand(model):
    up = BayesUpdate(model)
    b = np.array([0.4, 0.6])
    # an intervention in high complexity is evidence of low trust: P(int | L) = 0.54, P(int | H) = 0.05
    post_h = 0.6 * 0.05 / (0.6 * 0.05 + 0.4 * 0.54)
    out = up.update(b, HIGH, AUTONOMOUS, INTERVENE, FAULTY)
    # then the faulty-experience transition in high complexity: H -> L w.p. 1, L stays L w.p. 0.7
    assert out[1] == pytest.approx(post_h * 0.0 + (1 - post_h) * 0.3)
    # relying is evidence of high trust
    post_h = 0.6 * 0.95 / (0.6 * 0.95 + 0.4 * 0.46)
    out = up.update(b, HIGH, AUTONOMOUS, RELY, FAULTY)
    assert out[1] == pytest.approx((1 - post_h) * 0.3)
    # when asked the human always teleoperates: no information, same as eq. (3)
    np.testing.assert_allclose(up.update(b, HIGH, ASK, INTERVENE, RELIABLE), PaperUpdate(model).update(b, HIGH, ASK, INTERVENE, RELIABLE))


def test_unobserved_and_impossible_actions(model):
    up = BayesUpdate(model)
    b = np.array([0.4, 0.6])
    paper = PaperUpdate(model).update(b, HIGH, AUTONOMOUS, RELY, RELIABLE)
    np.testing.assert_allclose(up.update(b, HIGH, AUTONOMOUS, -1, RELIABLE), paper)
    # 'rely' when asked has probability 0 under the paper model: the prior is kept
    np.testing.assert_allclose(up.update(b, HIGH, ASK, RELY, RELIABLE), PaperUpdate(model).update(b, HIGH, ASK, RELY, RELIABLE))


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(1, 20),
    seed=st.integers(0, 2**32 - 1),
    which=st.sampled_from(["bayes", "paper"]),
)
def test_vectorized_equals_scalar_and_stays_a_distribution(n, seed, which):
    model = paper_model()
    rng = np.random.default_rng(seed)
    up = BayesUpdate(model) if which == "bayes" else PaperUpdate(model)
    bh = rng.random(n)
    b = np.stack([1 - bh, bh], axis=1)
    c, a, o, e = (rng.integers(0, 2, n) for _ in range(4))
    out = up.update(b, c, a, o, e)
    assert out.shape == (n, 2)
    np.testing.assert_allclose(out.sum(axis=1), 1.0, atol=1e-12)
    assert np.all(out >= 0)
    for i in range(n):
        np.testing.assert_allclose(out[i], up.update(b[i], c[i], a[i], o[i], e[i]), atol=1e-15)
