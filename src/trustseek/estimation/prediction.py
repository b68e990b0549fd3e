"""How well a trust model predicts: one-step-ahead P(rely) by filtering, against simple baselines.

For trial t the model predicts sum_k P(T_t = k | trials 1..t-1) P(rely | T_t = k, C_t, a_t), the
belief from the forward filter (never the smoothed posterior); the baselines (:mod:`.baselines`) see
the same past.  Trials whose emission row fixes P(rely) at 0 or 1 for every level, and trials without
a recorded human action, are not scored.  Scores: log-loss (clipped to [:data:`EPS`, 1 - EPS]),
Brier and AUC, with participant-bootstrap percentile intervals and the paired differences model -
baseline; in-sample (:func:`predict_in_sample`) or on held-out folds of participants
(:func:`predict_heldout`).  See docs/validation.md.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any

import numpy as np
import pandas as pd

from ..model.core import TrustModel
from ..parallel import in_processes
from ..statistics import LEVEL, auc, bootstrap_counts, paired, percentile_interval
from ..vocab import HUMAN_ACTIONS
from .baselines import BASELINES, BaselineFit, Features, baseline_predictions, features, fit_baselines
from .iohmm import fit_iohmm
from .options import DEFAULTS, FitOptions
from .sequences import Sequences, deal_folds, encode
from .spec import FitError, IOHMMSpec, Params
from .trust_iohmm import from_model, preset_spec

log = logging.getLogger(__name__)

EPS = 1e-9  # predictions are clipped to [EPS, 1 - EPS] for the log-loss
CONFIDENT = 1e-6  # a scored trial whose action the model gave less than this probability: a confident miss
METRICS = ("log_loss", "brier", "auc")
LOWER_IS_BETTER = {"log_loss": True, "brier": True, "auc": False}
RELY = HUMAN_ACTIONS.index("rely")


# --------------------------------------------------------------------------- the filter


@dataclass
class Filtered:
    """The forward filter of every participant, time-major (T, N) like :class:`Sequences`.

    ``prior[t, n]`` is P(T_t | trials before t), ``posterior[t, n]`` P(T_t | trials up to t);
    ``p_rely[t, n]`` the predicted P(rely) of trial t; ``determined[t, n]`` marks trials whose
    emission row gives every level the same certain P(rely) (no prediction)."""

    prior: np.ndarray
    posterior: np.ndarray
    p_rely: np.ndarray
    determined: np.ndarray


def determined_rows(params: Params) -> np.ndarray:
    """Per emission row: True when every level has the same P(rely), exactly 0 or 1."""
    p = params.emission[:, :, RELY]  # (Ue, K)
    same = np.all(p == p[:, :1], axis=1)
    return same & ((p[:, 0] == 0.0) | (p[:, 0] == 1.0))


def filter_beliefs(seqs: Sequences, params: Params) -> Filtered:
    """Forward-filter every participant under ``params``: the belief before and after each trial
    and the predicted P(rely).  An observed action that has probability zero under the belief
    leaves the belief as it was."""
    T, N = seqs.y.shape
    K = params.initial.shape[-1]
    valid = seqs.rows >= 0
    ue = np.where(valid, seqs.ue, 0).astype(np.int64)
    ut = np.where(valid, seqs.ut, 0).astype(np.int64)
    prior = np.zeros((T, N, K))
    posterior = np.zeros((T, N, K))
    p_rely = np.full((T, N), np.nan)
    b = np.broadcast_to(params.initial, (N, K)).astype(float)
    cols = np.arange(N)
    for t in range(T):
        em = params.emission[ue[t]]  # (N, K, M)
        prior[t] = b
        p_rely[t] = np.einsum("nk,nk->n", b, em[:, :, RELY])
        y = seqs.y[t].astype(np.int64)
        lik = np.where((y >= 0)[:, None], em[cols, :, np.maximum(y, 0)], 1.0)
        post = b * lik
        s = post.sum(-1)
        ok = s > 0
        post = np.where(ok[:, None], post / np.where(ok, s, 1.0)[:, None], b)
        posterior[t] = post
        if t + 1 < T:
            b = np.einsum("nk,nkj->nj", post, params.transition[ut[t]])
    p_rely[~valid] = np.nan
    prior[~valid] = np.nan
    posterior[~valid] = np.nan
    determined = determined_rows(params)[ue] & valid
    return Filtered(prior, posterior, p_rely, determined)


# --------------------------------------------------------------------------- scores


def _losses(p: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    q = np.clip(p, EPS, 1 - EPS)
    return -(y * np.log(q) + (1 - y) * np.log1p(-q)), (p - y) ** 2


CHUNK_CELLS = 4_000_000  # resamples x trials held in memory at once by the bootstrap of AUCs and correlations


def chunks(replicates: int, n: int) -> list[slice]:
    """Slices of the resamples, few enough at a time that a (resamples, n) array stays small."""
    step = max(1, CHUNK_CELLS // max(n, 1))
    return [slice(i, i + step) for i in range(0, replicates, step)]


def score(
    predictions: dict[str, np.ndarray], y: np.ndarray, participant: np.ndarray, n_participants: int, bootstrap: int, seed: int
) -> tuple[dict[str, dict[str, dict[str, float]]], dict[str, dict[str, dict[str, Any]]]]:
    """Metrics of every predictor on scored trials (``y`` 0/1, ``participant`` codes 0..N-1), with
    participant-bootstrap intervals, and the paired differences model - baseline."""
    counts = bootstrap_counts(n_participants, bootstrap, seed)
    total = counts @ np.bincount(participant, minlength=n_participants).astype(float)  # trials per resample
    point: dict[str, dict[str, float]] = {}
    reps: dict[str, dict[str, np.ndarray]] = {}
    for name, p in predictions.items():
        ll, br = _losses(p, y)
        point[name] = {
            "log_loss": float(ll.mean()) if ll.size else float("nan"),
            "brier": float(br.mean()) if br.size else float("nan"),
            "auc": float(auc(p, y)),
        }
        with np.errstate(invalid="ignore", divide="ignore"):
            reps[name] = {
                "log_loss": (counts @ np.bincount(participant, ll, n_participants)) / total,
                "brier": (counts @ np.bincount(participant, br, n_participants)) / total,
                "auc": np.concatenate(
                    [np.zeros(0), *(auc(p, y, counts[c][:, participant].astype(float)) for c in chunks(len(counts), len(p)))]
                ),
            }
    metrics: dict[str, dict[str, dict[str, float]]] = {}
    for name in predictions:
        metrics[name] = {}
        for m in METRICS:
            lo, hi = percentile_interval(reps[name][m])
            metrics[name][m] = {"estimate": point[name][m], "lower": lo, "upper": hi}
    diffs = {
        base: {
            m: paired(point["model"][m] - point[base][m], reps["model"][m] - reps[base][m], LOWER_IS_BETTER[m]) for m in METRICS
        }
        for base in predictions
        if base != "model"
    }
    return metrics, diffs


# --------------------------------------------------------------------------- reports


@dataclass
class PredictionReport:
    """The per-trial predictions, the scores with intervals, and the model-baseline differences."""

    mode: str  # "in-sample" or "held-out"
    trials: pd.DataFrame
    metrics: dict[str, dict[str, dict[str, float]]]
    differences: dict[str, dict[str, dict[str, Any]]]
    n_participants: int
    n_scored: int
    n_determined: int
    determined_matched: int
    n_unrecorded: int
    n_confident_misses: int
    bootstrap: int
    seed: int
    folds: int | None = None
    baselines: list[dict[str, Any]] = field(default_factory=list)

    def statements(self) -> list[str]:
        """One line per baseline and metric where the model does not beat the baseline."""
        if self.bootstrap == 0:
            return ["no bootstrap resamples (--bootstrap 0): no intervals, so no judgement whether the model beats a baseline"]
        out = []
        names = {"log_loss": "log-loss", "brier": "Brier score", "auc": "AUC"}
        for base, per in self.differences.items():
            for m, d in per.items():
                if d["better"] == "model":
                    continue
                if not np.isfinite(d["estimate"]):
                    out.append(
                        f"the model and the {base} baseline are not compared in {names[m]}: the score is undefined "
                        "(e.g. AUC when every scored action is the same)"
                    )
                    continue
                if not np.isfinite(d["lower"]):
                    how, ci = "no bootstrap interval", ""
                else:
                    how = "the baseline is better" if d["better"] == "baseline" else "the interval includes 0"
                    ci = f" [{d['lower']:+.4f}, {d['upper']:+.4f}]"
                out.append(
                    f"the model does not beat the {base} baseline in {names[m]}: difference {d['estimate']:+.4f}{ci} ({how})"
                )
        return out

    def misses_note(self) -> str | None:
        """A line when some scored actions had (nearly) probability zero under the model."""
        if not self.n_confident_misses:
            return None
        return (
            f"{self.n_confident_misses} scored trials had probability below {CONFIDENT:g} under the model "
            f"(each adds up to {-np.log(EPS):.1f} nats to the log-loss): cells estimated at 0 or 1; "
            "a fit with a prior (--prior 0.5) keeps them inside"
        )

    def excluded_note(self) -> str:
        return (
            f"{self.n_determined} trials whose P(rely) the model fixes (e.g. P(intervene | ask) = 1) are not scored: "
            f"they are no prediction ({self.determined_matched} of them went as fixed); "
            f"{self.n_unrecorded} trials without a recorded human action are not scored"
        )

    def to_dict(self) -> dict[str, Any]:
        counts = ("n_participants", "n_scored", "n_determined", "determined_matched", "n_unrecorded", "n_confident_misses")
        return {
            **{k: getattr(self, k) for k in ("mode", "folds", *counts, "bootstrap")},
            "ci_level": LEVEL,
            "seed": self.seed,
            "metrics": self.metrics,
            "differences": self.differences,
            "baselines": self.baselines,
            "statements": self.statements(),
            "excluded": self.excluded_note(),
            "misses": self.misses_note(),
        }


def _report(
    frame: pd.DataFrame,
    seqs: Sequences,
    preds: dict[str, np.ndarray],
    determined: np.ndarray,
    feats: Features,
    bootstrap: int,
    seed: int,
    fold_of: np.ndarray | None,
    baseline_fits: list[BaselineFit],
) -> PredictionReport:
    """The report of the predictions ``preds`` (the model's P(rely) as "model", then the baselines'),
    per trial in the frame's row order and scored; held-out when ``fold_of`` gives the folds."""
    valid = seqs.rows >= 0
    p_model = preds["model"]
    s = feats.scored
    nn = np.nonzero(s)[1]
    y = feats.rely[s]
    metrics, diffs = score({k: v[s] for k, v in preds.items()}, y, nn, seqs.n_participants, bootstrap, seed)
    # per trial, in the frame's row order
    who = seqs.row_participants()
    out: dict[str, Any] = {"participant": np.asarray(seqs.participants, dtype=object)[who]}
    out["trial"] = seqs.per_row(seqs.trial_numbers(*np.indices(valid.shape)), 0, np.int64)
    for c in ("complexity", "robot_action", "human_action"):
        out[c] = frame[c].to_numpy() if c in frame else np.full(len(frame), None)
    out["scored"], out["fixed_by_model"] = seqs.per_row(s, False, bool), seqs.per_row(determined, False, bool)
    if fold_of is not None:
        out["fold"] = fold_of[who] + 1
    out |= {f"p_rely_{k}": seqs.per_row(v) for k, v in preds.items()}
    trials = pd.DataFrame(out)
    pm = p_model[s]
    misses = int((np.where(y == 1, pm, 1 - pm) < CONFIDENT).sum())
    unrecorded = int((valid & ~np.isfinite(feats.rely)).sum())
    det_obs = determined & np.isfinite(feats.rely)
    matched = int((det_obs & (feats.rely == np.where(np.isfinite(p_model), np.round(p_model), -1))).sum())
    return PredictionReport(
        mode="in-sample" if fold_of is None else "held-out",
        trials=trials,
        metrics=metrics,
        differences=diffs,
        n_participants=seqs.n_participants,
        n_scored=int(s.sum()),
        n_determined=int(det_obs.sum()),
        determined_matched=matched,
        n_unrecorded=unrecorded,
        n_confident_misses=misses,
        bootstrap=bootstrap,
        seed=seed,
        folds=None if fold_of is None else int(fold_of.max()) + 1,
        baselines=[b.to_dict() for b in baseline_fits],
    )


def _check_scored(feats: Features) -> None:
    if not feats.scored.any():
        raise FitError(["no trial to score: every recorded human action is fixed by the model (or none is recorded)"])


def predict_in_sample(frame: pd.DataFrame, model: TrustModel, bootstrap: int = 1000, seed: int = 0) -> PredictionReport:
    """One-step-ahead predictions of every trial under ``model`` (in-sample when ``model`` was
    fitted to ``frame``), scored against the baselines estimated on the same trials (the inputs'
    logistic regression with participant intercepts)."""
    spec, params = from_model(model)
    seqs = encode(frame, spec)
    filt = filter_beliefs(seqs, params)
    feats = features(frame, seqs, filt.determined, params.emission.shape[0], params.transition.shape[0])
    _check_scored(feats)
    bfit = fit_baselines(feats, np.arange(seqs.n_participants), intercepts=True)
    preds = {"model": filt.p_rely, **baseline_predictions(feats, bfit)}
    return _report(frame, seqs, preds, filt.determined, feats, bootstrap, seed, None, [bfit])


def fold_assignment(n_participants: int, folds: int, seed: int = 0) -> np.ndarray:
    """The fold (0..folds-1) of every participant: a seeded permutation dealt round-robin, so
    fold sizes differ by at most one."""
    return deal_folds(n_participants, folds, [seed, 6])


def predict_heldout(
    frame: pd.DataFrame,
    folds: int = 5,
    preset: str | IOHMMSpec = "paper",
    options: FitOptions = DEFAULTS,
    bootstrap: int = 1000,
    prior: float = 0.0,
    progress: Callable[[int, int], None] | None = None,
    **spec_options: Any,
) -> PredictionReport:
    """One-step-ahead predictions of held-out participants: ``folds`` folds of participants
    (seeded by ``options.seed``); each is predicted by a model fitted to the others (``options``
    as for :func:`~.fit.fit_trust_model`, the restarts seeded as a fit with that seed would be) and
    scored against baselines estimated on the same training folds.  The folds' fits run side by
    side over ``options.n_jobs`` processes (each on one thread; the same numbers).
    ``progress(done, folds)`` is called after each fold."""
    seed = options.seed_number
    spec = preset_spec(preset, frame, prior=prior, **spec_options)
    seqs = encode(frame, spec)
    fold_of = fold_assignment(seqs.n_participants, folds, seed)
    T, N = seqs.y.shape
    p_model = np.full((T, N), np.nan)
    determined = np.zeros((T, N), dtype=bool)
    calls = [
        # each fold's restarts seeded as a fit with that seed would be
        partial(
            fit_iohmm,
            seqs.subset(np.flatnonzero(fold_of != f)),
            spec,
            replace(options, seed=np.random.SeedSequence([seed, 0]), n_jobs=1),
        )
        for f in range(folds)
    ]
    fits = in_processes(calls, options.n_jobs, lambda _f, done: progress(done, folds) if progress else None)
    for f, fit in enumerate(fits):
        test = np.flatnonzero(fold_of == f)
        held = filter_beliefs(seqs.subset(test), fit.params)
        Tt = held.p_rely.shape[0]
        p_model[:Tt, test] = held.p_rely
        determined[:Tt, test] = held.determined
        log.info("fold %d of %d: %d training participants, log-likelihood %.4f", f + 1, folds, N - len(test), fit.loglik)
    feats = features(
        frame, seqs, determined, spec.n_combinations(spec.emission_inputs), spec.n_combinations(spec.transition_inputs)
    )
    _check_scored(feats)
    base = {k: np.full((T, N), np.nan) for k in BASELINES}
    bfits = []
    for f in range(folds):
        train, test = np.flatnonzero(fold_of != f), np.flatnonzero(fold_of == f)
        bfit = fit_baselines(feats, train)
        bfits.append(bfit)
        for k, v in baseline_predictions(feats, bfit).items():
            base[k][:, test] = v[:, test]
    preds = {"model": p_model, **base}
    return _report(frame, seqs, preds, determined, feats, bootstrap, seed, fold_of, bfits)
