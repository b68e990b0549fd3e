"""The baselines a model's one-step-ahead P(rely) is compared with (:mod:`.prediction`), each seeing
what the model sees of the participant's past and estimated on the training trials only:
``constant`` (the training rate), ``participant_rate`` (the participant's rate so far, a prior of
:data:`PRIOR_WEIGHT` trials at the training rate), ``last_action`` (P(rely | the previous action)),
``reliable_fraction`` (a logistic regression on the smoothed fraction of reliable automation so far),
``one_level`` (the one-level model: each emission-input combination's rate) and ``inputs_logistic``
(a logistic regression on the model's inputs, with participant intercepts of ridge
:data:`INTERCEPT_RIDGE` in-sample).  See docs/validation.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from ..vocab import EXPERIENCES
from .sequences import Sequences

PRIOR_WEIGHT = 2.0  # pseudo-trials at the training rate behind a participant's running rate
BASELINES = ("constant", "participant_rate", "last_action", "reliable_fraction", "one_level", "inputs_logistic")
RIDGE = 1e-3  # ridge of the logistic regressions' shared coefficients
INTERCEPT_RIDGE = 1.0  # ridge of the participant intercepts: shrunk toward the shared intercept


def _exclusive_cumsum(a: np.ndarray) -> np.ndarray:
    """Along trials: the sum over earlier trials (0 at the first)."""
    c = np.cumsum(a, axis=0)
    return c - a


def indicators(frame: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """Per row of ``frame``: 1 rely, 0 intervene (NaN unrecorded); 1 reliable, 0 faulty automation (NaN
    unknown, every row without a recorded experience)."""
    ha = frame["human_action"]
    rely = np.where(ha.isna().to_numpy(), np.nan, (ha.astype(object) == "rely").to_numpy(dtype=float))
    if "experience" not in frame or not frame["experience"].notna().any():
        return rely, np.full(len(frame), np.nan)
    ex = frame["experience"]
    return rely, np.where(ex.isna().to_numpy(), np.nan, (ex.astype(object) == EXPERIENCES[1]).to_numpy(dtype=float))


def running_rate(x: np.ndarray, inclusive: bool = False) -> np.ndarray:
    """(T, N): the Laplace-smoothed rate (ones + 1) / (known + 2) of the finite 0/1 values of ``x``
    over each participant's earlier trials (and the trial itself with ``inclusive``)."""
    known = np.isfinite(x)
    k, n = np.where(known, x, 0.0), known.astype(float)
    k, n = (np.cumsum(k, axis=0), np.cumsum(n, axis=0)) if inclusive else (_exclusive_cumsum(k), _exclusive_cumsum(n))
    return (k + 1.0) / (n + 2.0)


def logistic(
    X: np.ndarray, y: np.ndarray, groups: np.ndarray | None = None, n_groups: int = 0, iterations: int = 50
) -> tuple[np.ndarray, np.ndarray]:
    """A ridge logistic regression of ``y`` on ``X`` (its first column the intercept), by Newton's
    method; with ``groups`` (a code per row, < ``n_groups``) an intercept per group besides, of
    ridge :data:`INTERCEPT_RIDGE` (the group block of the Hessian is diagonal: solved through its
    Schur complement).  The shared coefficients and the group intercepts (zeros without groups)."""
    p_dim = X.shape[1]
    beta, alpha = np.zeros(p_dim), np.zeros(n_groups)
    g = groups if groups is not None else np.zeros(len(y), dtype=np.int64)
    for _ in range(iterations):
        eta = X @ beta + (alpha[g] if n_groups else 0.0)
        p = 1.0 / (1.0 + np.exp(-eta))
        w, r = p * (1 - p), y - p
        grad_b = X.T @ r - RIDGE * beta
        A = (X * w[:, None]).T @ X + RIDGE * np.eye(p_dim)
        if n_groups:
            grad_a = np.bincount(g, r, n_groups) - INTERCEPT_RIDGE * alpha
            D = np.bincount(g, w, n_groups) + INTERCEPT_RIDGE
            B = np.stack([np.bincount(g, w * X[:, j], n_groups) for j in range(p_dim)])  # (p, groups)
            step_b = np.linalg.solve(A - (B / D) @ B.T, grad_b - B @ (grad_a / D))
            step_a = (grad_a - B.T @ step_b) / D
            alpha += step_a
        else:
            step_b, step_a = np.linalg.solve(A, grad_b), np.zeros(0)
        beta += step_b
        if max(np.max(np.abs(step_b)), np.max(np.abs(step_a), initial=0.0)) < 1e-10:
            break
    return beta, alpha


@dataclass
class Features:
    """Per trial, (T, N): what the baselines use, from the participant's earlier trials."""

    rely: np.ndarray  # 1 rely, 0 intervene, NaN unrecorded or padding
    scored: np.ndarray  # recorded and not determined
    rate_n: np.ndarray  # scored trials before t
    rate_k: np.ndarray  # of which relied
    last: np.ndarray  # previous scored action (1 rely, 0 intervene, NaN none)
    reliable_logit: np.ndarray  # logit of the Laplace-smoothed fraction of reliable automation before t
    ue: np.ndarray  # the trial's emission-input combination (0 at padding)
    ut_prev: np.ndarray  # the previous trial's transition-input combination; n_ut at a first trial
    n_ue: int
    n_ut: int

    def design(self, columns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The inputs' design matrix (intercept, one-hot emission and previous transition inputs) of the
        scored trials of participants ``columns``, and each row's participant (index into ``columns``)."""
        s = self.scored[:, columns]
        ue, ut = self.ue[:, columns][s], self.ut_prev[:, columns][s]
        X = np.zeros((len(ue), 1 + self.n_ue + self.n_ut + 1))
        X[:, 0] = 1.0
        X[np.arange(len(ue)), 1 + ue] = 1.0
        X[np.arange(len(ue)), 1 + self.n_ue + ut] = 1.0
        return X, np.nonzero(s)[1]


def features(frame: pd.DataFrame, seqs: Sequences, determined: np.ndarray, n_ue: int, n_ut: int) -> Features:
    """The baselines' inputs of every trial of ``seqs`` (the model's ``n_ue`` emission and ``n_ut``
    transition input combinations; ``determined`` trials are not scored)."""
    rely_row, rel_row = indicators(frame)
    rely = seqs.spread(rely_row)
    scored = np.isfinite(rely) & ~determined
    r = np.where(scored, rely, 0.0)
    rate_n = _exclusive_cumsum(scored.astype(float))
    rate_k = _exclusive_cumsum(r)
    # previous scored action: forward fill along trials
    T, N = rely.shape
    last = np.full((T, N), np.nan)
    cur = np.full(N, np.nan)
    for t in range(T):
        last[t] = cur
        cur = np.where(scored[t], rely[t], cur)
    f = running_rate(seqs.spread(rel_row))
    valid = seqs.rows >= 0
    ue = np.where(valid, seqs.ue, 0).astype(np.int64)
    ut_prev = np.full((T, N), n_ut, dtype=np.int64)
    ut_prev[1:] = np.where(valid[:-1], seqs.ut[:-1], n_ut)
    return Features(rely, scored, rate_n, rate_k, last, np.log(f) - np.log1p(-f), ue, ut_prev, n_ue, n_ut)


@dataclass
class BaselineFit:
    """The baselines' parameters, estimated on training trials (``participants``: the columns of
    the participant intercepts, -1 for a participant without one)."""

    rate: float
    after_rely: float
    after_intervene: float
    reliable_coef: tuple[float, float]
    one_level: np.ndarray  # P(rely | emission-input combination)
    inputs_coef: np.ndarray
    intercepts: np.ndarray  # (N,) each participant's intercept (0 without one)

    def to_dict(self) -> dict[str, Any]:
        return {
            "rate": self.rate,
            "after_rely": self.after_rely,
            "after_intervene": self.after_intervene,
            "reliable_fraction_logistic": list(self.reliable_coef),
            "one_level": self.one_level.tolist(),
            "inputs_logistic": self.inputs_coef.tolist(),
            "participant_intercepts": int(np.count_nonzero(self.intercepts)),
        }


def fit_baselines(f: Features, columns: np.ndarray, intercepts: bool = False) -> BaselineFit:
    """The baselines' parameters from the scored trials of participants ``columns`` (with
    ``intercepts``, each of them gets its own intercept in ``inputs_logistic``)."""
    s = f.scored[:, columns]
    y = f.rely[:, columns][s]
    rate = (y.sum() + 1.0) / (y.size + 2.0)
    last = f.last[:, columns][s]
    q1 = (y[last == 1].sum() + 1.0) / ((last == 1).sum() + 2.0)
    q0 = (y[last == 0].sum() + 1.0) / ((last == 0).sum() + 2.0)
    x = f.reliable_logit[:, columns][s]
    beta = logistic(np.column_stack([np.ones_like(x), x]), y)[0] if y.size else np.zeros(2)
    ue = f.ue[:, columns][s]
    one = (np.bincount(ue, y, f.n_ue) + 1.0) / (np.bincount(ue, None, f.n_ue) + 2.0)
    X, who = f.design(columns)
    coef, alpha = logistic(X, y, who if intercepts else None, len(columns) if intercepts else 0)
    each = np.zeros(f.rely.shape[1])
    if intercepts:
        each[columns] = alpha
    return BaselineFit(float(rate), float(q1), float(q0), (float(beta[0]), float(beta[1])), one, coef, each)


def baseline_predictions(f: Features, fit: BaselineFit) -> dict[str, np.ndarray]:
    """Every baseline's P(rely), (T, N)."""
    c = fit.rate
    part = (f.rate_k + PRIOR_WEIGHT * c) / (f.rate_n + PRIOR_WEIGHT)
    last = np.where(f.last == 1, fit.after_rely, np.where(f.last == 0, fit.after_intervene, c))
    a, b = fit.reliable_coef
    rel = 1.0 / (1.0 + np.exp(-(a + b * f.reliable_logit)))
    w = fit.inputs_coef
    eta = w[0] + w[1 + f.ue] + w[1 + f.n_ue + f.ut_prev] + fit.intercepts[None, :]
    return {
        "constant": np.full(f.rely.shape, c),
        "participant_rate": part,
        "last_action": last,
        "reliable_fraction": rel,
        "one_level": fit.one_level[f.ue],
        "inputs_logistic": 1.0 / (1.0 + np.exp(-eta)),
    }
