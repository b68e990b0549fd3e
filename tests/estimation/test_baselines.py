"""predict's baselines see the model's named inputs: a one-level model and a logistic regression
on the same inputs (participant intercepts in-sample), so that an input, not trust, is credited
to the input."""

from __future__ import annotations

import numpy as np
import pandas as pd

from trustseek.estimation.baselines import INTERCEPT_RIDGE, RIDGE, logistic
from trustseek.estimation.prediction import predict_in_sample
from trustseek.model.core import TrustModel


def test_the_group_intercepts_are_the_dense_ridge_solution():
    rng = np.random.default_rng(0)
    n, groups = 300, 7
    X = np.column_stack([np.ones(n), rng.normal(size=(n, 2))])
    g = rng.integers(0, groups, n)
    y = (rng.random(n) < 1 / (1 + np.exp(-(X @ [0.3, 1.0, -0.5] + np.linspace(-1, 1, groups)[g])))).astype(float)
    beta, alpha = logistic(X, y, g, groups)
    # the same penalised likelihood, maximised over the dense design [X, one-hot(g)]
    Z = np.column_stack([X, np.eye(groups)[g]])
    ridge = np.r_[np.full(3, RIDGE), np.full(groups, INTERCEPT_RIDGE)]
    w = np.zeros(3 + groups)
    for _ in range(50):
        p = 1 / (1 + np.exp(-(Z @ w)))
        w += np.linalg.solve((Z * (p * (1 - p))[:, None]).T @ Z + np.diag(ridge), Z.T @ (y - p) - ridge * w)
    np.testing.assert_allclose(np.r_[beta, alpha], w, atol=1e-8)


def _advice_log(rng, people=12, trials=30, spread=0.0):
    rows = []
    for p in range(people):
        shift = spread * (p / (people - 1) - 0.5)
        for t in range(1, trials + 1):
            advice = rng.choice(["agree", "disagree"])
            rate = (0.8 if advice == "agree" else 0.4) + shift
            rows.append({"participant": f"p{p}", "trial": t, "human_action": "rely" if rng.random() < rate else "intervene",
                         "advice": advice})  # fmt: skip
    frame = pd.DataFrame(rows)
    frame["advice"] = pd.Categorical(frame["advice"], ["agree", "disagree"])
    return frame


def _model(p_agree, p_disagree):
    """A model of the advice alone: both levels rely alike (no trust to track)."""
    emission = np.array([[[1 - p_agree, p_agree]] * 2, [[1 - p_disagree, p_disagree]] * 2])
    return TrustModel(("low", "high"), "human_action", ("intervene", "rely"), {"advice": ("agree", "disagree")},
                      ("advice",), (), np.array([0.5, 0.5]), emission, np.array([[0.9, 0.1], [0.1, 0.9]]))  # fmt: skip


def test_a_model_of_an_input_does_not_beat_baselines_that_see_the_input():
    frame = _advice_log(np.random.default_rng(1))
    report = predict_in_sample(frame, _model(0.8, 0.4), bootstrap=50, seed=0)
    d = {(base, m): x for base, by in report.differences.items() for m, x in by.items()}
    assert d[("constant", "log_loss")]["better"] == "model"  # the input alone beats a constant
    for base in ("one_level", "inputs_logistic"):
        assert d[(base, "log_loss")]["better"] != "model", d[(base, "log_loss")]
        assert d[(base, "log_loss")]["estimate"] > -0.01  # the model gains nothing over them
    assert any("does not beat the one_level baseline" in s for s in report.statements())


def test_participant_intercepts_take_up_who_relies_more():
    frame = _advice_log(np.random.default_rng(2), spread=0.3)
    report = predict_in_sample(frame, _model(0.8, 0.4), bootstrap=0)
    m = report.metrics
    assert m["inputs_logistic"]["log_loss"]["estimate"] < m["one_level"]["log_loss"]["estimate"] - 0.005
