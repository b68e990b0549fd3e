"""POMDP tensors against entries computed by hand from the paper's numbers."""

import numpy as np
import pytest

from trustseek.vocab import ASK, AUTONOMOUS, FAULTY, INTERVENE, RELIABLE, RELY

LOW, HIGH = 0, 1


def state_index(pomdp, t: int, e: int, c: int) -> int:
    """The index of state (trust, experience, complexity) in the flat arrays (``pomdp.states``)."""
    return (t * 2 + e) * pomdp.n_complexity + c


def test_expected_reward_by_hand(pomdp):
    R = pomdp.expected_reward  # [c, a, t]
    # eq. (2): P(rely) * (p_suc * 2 + (1 - p_suc) * (-3)) + P(intervene) * 0
    assert R[HIGH, AUTONOMOUS, LOW] == pytest.approx(0.46 * (0.83 * 2 - 0.17 * 3))
    assert R[HIGH, AUTONOMOUS, HIGH] == pytest.approx(0.95 * (0.83 * 2 - 0.17 * 3))
    assert R[LOW, AUTONOMOUS, LOW] == pytest.approx(0.98 * (0.97 * 2 - 0.03 * 3))
    assert R[LOW, AUTONOMOUS, HIGH] == pytest.approx(1.00 * (0.97 * 2 - 0.03 * 3))
    assert np.all(R[:, ASK, :] == 1.0)


def test_experience_table(pomdp):
    ex = pomdp.experience  # [c, a, o, e]
    assert ex[HIGH, AUTONOMOUS, RELY].tolist() == pytest.approx([0.17, 0.83])
    assert ex[LOW, AUTONOMOUS, RELY].tolist() == pytest.approx([0.03, 0.97])
    assert ex[HIGH, AUTONOMOUS, INTERVENE].tolist() == [1.0, 0.0]
    assert ex[LOW, ASK, INTERVENE].tolist() == [1.0, 0.0]  # asking in low complexity: faulty
    assert ex[HIGH, ASK, INTERVENE].tolist() == [0.0, 1.0]  # asking in high complexity: reliable


def test_flat_transition_entries(pomdp):
    T = pomdp.transition_matrix  # [a, s, s2]
    assert T.shape == (2, 8, 8)
    np.testing.assert_allclose(T.sum(axis=2), 1.0, atol=1e-12)
    s = state_index(pomdp, HIGH, RELIABLE, HIGH)
    # high trust, high complexity, autonomous -> low trust, faulty, next complexity low:
    # P(E'=faulty | T=high) = P(intervene) + P(rely) (1 - p_suc) = 0.05 + 0.95 * 0.17; then trust drops w.p. 1
    s2 = state_index(pomdp, LOW, FAULTY, LOW)
    assert T[AUTONOMOUS, s, s2] == pytest.approx((0.05 + 0.95 * 0.17) * 1.0 * 0.5)
    # low trust, high complexity, autonomous -> high trust after success: 0.46 * 0.83 * 1.0 * 0.5
    s = state_index(pomdp, LOW, FAULTY, HIGH)
    assert T[AUTONOMOUS, s, state_index(pomdp, HIGH, RELIABLE, HIGH)] == pytest.approx(0.46 * 0.83 * 0.5)
    # ... and stays low after a failure or intervention w.p. 0.7
    assert T[AUTONOMOUS, s, state_index(pomdp, LOW, FAULTY, LOW)] == pytest.approx((0.54 + 0.46 * 0.17) * 0.7 * 0.5)
    # asking in high complexity from low trust: reliable experience, trust repaired w.p. 0.44
    assert T[ASK, s, state_index(pomdp, HIGH, RELIABLE, LOW)] == pytest.approx(0.44 * 0.5)
    assert T[ASK, s, state_index(pomdp, LOW, FAULTY, LOW)] == 0.0
    # the experience in the state has no influence on where the state goes
    for a in range(2):
        np.testing.assert_array_equal(T[a, state_index(pomdp, LOW, FAULTY, HIGH)], T[a, state_index(pomdp, LOW, RELIABLE, HIGH)])


def test_flat_observation_and_reward(pomdp):
    Z = pomdp.observation_matrix
    R = pomdp.reward_matrix
    s = state_index(pomdp, LOW, FAULTY, HIGH)
    assert Z[AUTONOMOUS, s].tolist() == pytest.approx([0.54, 0.46])
    assert Z[ASK, s].tolist() == [1.0, 0.0]
    assert R[s, AUTONOMOUS] == pytest.approx(0.46 * 1.15)
    assert R[s, ASK] == 1.0
    assert pomdp.states[s] == ("low", "faulty", "high")


def test_kernel_marginals(pomdp):
    k = pomdp.kernel  # [c, a, t, o, e, t2]
    np.testing.assert_allclose(k.sum(axis=(3, 4, 5)), 1.0, atol=1e-12)
    np.testing.assert_allclose(k.sum(axis=(4, 5)), pomdp.emission, atol=1e-12)


def test_named_axes_match_shapes(pomdp):
    sizes = {
        "complexity": 2,
        "robot_action": 2,
        "trust": 2,
        "next_trust": 2,
        "human_action": 2,
        "next_experience": 2,
        "state": 8,
        "next_state": 8,
    }
    for name, axes in pomdp.axes.items():
        assert getattr(pomdp, name).shape == tuple(sizes[a] for a in axes), name
