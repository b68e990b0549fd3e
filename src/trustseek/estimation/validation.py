"""Does the hidden trust track self-reports?  Correlations of decoded trust with trust ratings.

A log may carry a self-reported trust rating on some trials (every trial, or the last trial of
each block, empty elsewhere): numbers, or ordinal labels declared lowest first
(:func:`parse_ratings`).  On the rated trials, :func:`validate_ratings` correlates the ratings
with

* the decoded trust: ``smoothed`` (P(trust = high | all the participant's trials); for K > 2
  levels the expected level, scaled to 0 = lowest, 1 = highest) and ``filtered`` (the same
  from the trials up to and including the rated one only);
* baselines (:data:`RATING_BASELINES`): the fraction of trials so far (the rated one included)
  whose automation was reliable, the trial's own reliance (1 rely, 0 intervene; trials without
  a recorded action are skipped), and the participant's reliance rate so far (Laplace-smoothed).

Each correlation (Spearman and Pearson) is given in three scopes:

* ``pooled`` -- every rated trial;
* ``within`` -- values and ratings centred on the participant's means, then pooled (participants
  with fewer than two rated trials left out): does trust move with the ratings over time?
* ``between`` -- one point per participant, the means of values and ratings: do participants
  who report more trust get more decoded trust?

Intervals are participant-bootstrap percentiles (participants drawn with replacement; a
participant drawn twice counts twice); differences trust - baseline are on the same resamples.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from ..data.cells import NAN_WORDS, DataError
from ..model.core import TrustModel
from ..vocab import EXPERIENCES
from .iohmm import posteriors
from .prediction import LEVEL, bootstrap_counts, chunks, filter_beliefs, percentile_interval
from .sequences import encode
from .spec import FitError
from .trust_iohmm import from_model

TRUST_MEASURES = ("smoothed", "filtered")
RATING_BASELINES = ("reliable_fraction", "reliance", "reliance_rate")
SCOPES = ("pooled", "within", "between")
METHODS = ("spearman", "pearson")
SHOWN = 5
MIN_BETWEEN = 3  # participants needed for a between-participant correlation


# --------------------------------------------------------------------------- ratings


def parse_ratings(
    frame: pd.DataFrame, column: str, labels: Sequence[str] | None = None, missing: Sequence[str] = ()
) -> np.ndarray:
    """Per row of ``frame`` the rating in ``column`` as a number (NaN where there is none).

    Without ``labels`` every rating must be a number; with ``labels`` (ordinal, lowest first)
    every rating must be one of them and becomes its position 1, 2, ...  Empty cells, NaN words
    and the ``missing`` texts are no rating; anything else that does not parse is an error
    naming the participants and trials."""
    if column not in frame.columns:
        raise DataError([f"rating column {column!r} is not in the log; its columns: {list(map(str, frame.columns))}"])
    if labels is not None:
        labels = [str(x).strip() for x in labels]
        dupes = sorted({x for x in labels if labels.count(x) > 1})
        if len(labels) < 2 or dupes or not all(labels):
            raise DataError([f"rating labels: expected at least 2 distinct labels, lowest first, got {labels}"])
    markers = {m.strip().lower() for m in missing} | set(NAN_WORDS)
    values = frame[column].astype(object).to_numpy()
    inverse, uniques = pd.factorize(pd.Series(values, dtype=object), use_na_sentinel=True)
    parsed = np.full(len(uniques) + 1, np.nan)  # the last entry: an empty cell
    bad = np.zeros(len(uniques) + 1, dtype=bool)
    for j, v in enumerate(np.asarray(uniques, dtype=object)):
        if isinstance(v, float) and np.isnan(v):
            continue
        text = str(v).strip()
        if text == "" or text.lower() in markers:
            continue
        if labels is not None:
            if text in labels:
                parsed[j] = labels.index(text) + 1
            else:
                bad[j] = True
            continue
        try:
            f = float(text)
        except ValueError:
            f = np.nan
        if np.isfinite(f):
            parsed[j] = f
        else:
            bad[j] = True
    inverse = np.where(inverse < 0, len(uniques), inverse)
    rows = np.flatnonzero(bad[inverse])
    if len(rows):
        where = "; ".join(
            f"participant {frame['participant'].iloc[r]} trial {frame['trial'].iloc[r]}: {values[r]!r}" for r in rows[:SHOWN]
        )
        more = f"; ... ({len(rows) - SHOWN} more)" if len(rows) > SHOWN else ""
        if labels is None:
            what = "not numbers (declare ordinal labels, lowest first, with --rating-labels, e.g. low,medium,high)"
        else:
            what = f"not among the declared labels {labels}"
        raise DataError([f"rating column {column!r}: {len(rows)} ratings are {what}: {where}{more}"])
    out = parsed[inverse]
    if not np.isfinite(out).any():
        raise DataError([f"rating column {column!r}: no trial has a rating (every cell is empty)"])
    return out


# --------------------------------------------------------------------------- weighted correlations


def _weighted_ranks(x: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Mid-ranks of ``x`` in the data where element i appears ``w[b, i]`` times, (B, n)."""
    order = np.argsort(x, kind="stable")
    xs = x[order]
    starts = np.flatnonzero(np.r_[True, xs[1:] != xs[:-1]])
    group = np.cumsum(np.r_[True, xs[1:] != xs[:-1]]) - 1
    g = np.add.reduceat(w[:, order], starts, axis=1)  # (B, G)
    mid = np.cumsum(g, axis=1) - g + (g + 1) / 2
    ranks = np.empty_like(w, dtype=float)
    ranks[:, order] = mid[:, group]
    return ranks


def _weighted_pearson(x: np.ndarray, y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Pearson correlation for every row of weights; x, y are (n,) or (B, n)."""
    W = w.sum(-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mx = (w * x).sum(-1) / W
        my = (w * y).sum(-1) / W
        dx = x - mx[:, None]
        dy = y - my[:, None]
        sxy = (w * dx * dy).sum(-1)
        sxx = (w * dx * dx).sum(-1)
        syy = (w * dy * dy).sum(-1)
        # a constant variable (up to rounding) has no correlation
        ok = (sxx > 1e-12 * (w * x * x).sum(-1) + 1e-300) & (syy > 1e-12 * (w * y * y).sum(-1) + 1e-300) & (W >= 3)
        return np.where(ok, sxy / np.sqrt(np.where(ok, sxx * syy, 1.0)), np.nan)


def correlations(x: np.ndarray, y: np.ndarray, w: np.ndarray) -> dict[str, np.ndarray]:
    """Spearman and Pearson correlations of ``x`` and ``y`` (n,) for every row of weights (B, n)."""
    if x.size == 0:
        nan = np.full(w.shape[0], np.nan)
        return {"spearman": nan, "pearson": nan}
    return {
        "spearman": _weighted_pearson(_weighted_ranks(x, w), _weighted_ranks(y, w), w),
        "pearson": _weighted_pearson(x, y, w),
    }


# --------------------------------------------------------------------------- the report


@dataclass
class ValidationReport:
    """Correlations of the decoded trust and of the baselines with the ratings, with intervals."""

    column: str
    labels: list[str] | None
    n_rated: int
    n_participants: int
    n_participants_rated: int
    correlations: dict[str, dict[str, dict[str, dict[str, float]]]]  # measure -> scope -> method -> value
    differences: dict[str, dict[str, dict[str, dict[str, dict[str, Any]]]]]  # trust -> baseline -> scope -> method
    trials: pd.DataFrame
    bootstrap: int
    seed: int

    def statements(self) -> list[str]:
        """One line per trust measure and baseline the trust does not beat (Spearman) in some scope."""
        if self.bootstrap == 0:
            return ["no bootstrap resamples (--bootstrap 0): no intervals, so no judgement whether the trust beats a baseline"]
        out = []
        for m, per in self.differences.items():
            for base, scopes in per.items():
                lost = []
                undefined = [scope for scope, d in scopes.items() if not np.isfinite(d["spearman"]["estimate"])]
                if undefined:
                    out.append(
                        f"the {m} trust and the {base} baseline are not compared ({', '.join(undefined)}): a correlation "
                        "is undefined there (a constant value or too few rated trials)"
                    )
                for scope, d in scopes.items():
                    s = d["spearman"]
                    if s["better"] != "trust" and scope not in undefined:
                        lo, hi = s["lower"], s["upper"]
                        ci = f"[{lo:+.3f}, {hi:+.3f}]" if np.isfinite(lo) else "(no interval)"
                        lost.append(f"{scope} {s['estimate']:+.3f} {ci}")
                if lost:
                    out.append(
                        f"the {m} trust does not beat the {base} baseline (Spearman, difference trust - baseline): "
                        + "; ".join(lost)
                    )
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "rating_column": self.column,
            "rating_labels": self.labels,
            "n_rated": self.n_rated,
            "n_participants": self.n_participants,
            "n_participants_rated": self.n_participants_rated,
            "bootstrap": self.bootstrap,
            "ci_level": LEVEL,
            "seed": self.seed,
            "within": "values and ratings centred on each participant's means, then pooled",
            "between": "participant means",
            "correlations": self.correlations,
            "differences": self.differences,
            "statements": self.statements(),
        }


def _running_rate(hits: np.ndarray, known: np.ndarray, participant: np.ndarray, order: np.ndarray) -> np.ndarray:
    """Per row: (hits + 1) / (known + 2) over the participant's trials up to and including this one."""
    h = np.where(known, hits, 0.0)[order]
    k = known.astype(float)[order]
    p = participant[order]
    ch, ck = np.cumsum(h), np.cumsum(k)
    first = np.flatnonzero(np.r_[True, p[1:] != p[:-1]])
    size = np.diff(np.r_[first, len(p)])
    base_h = np.repeat(ch[first] - h[first], size)
    base_k = np.repeat(ck[first] - k[first], size)
    out = np.empty(len(p))
    out[order] = (ch - base_h + 1.0) / (ck - base_k + 2.0)
    return out


def validate_ratings(
    frame: pd.DataFrame,
    model: TrustModel,
    ratings: np.ndarray,
    column: str = "rating",
    labels: Sequence[str] | None = None,
    bootstrap: int = 1000,
    seed: int = 0,
) -> ValidationReport:
    """Correlations of the decoded trust under ``model`` with ``ratings`` (one number per row of
    ``frame``, NaN = no rating), and of the baselines, with participant-bootstrap intervals."""
    ratings = np.asarray(ratings, dtype=float)
    values, pcode, N = _decoded_values(frame, model)
    rated = np.isfinite(ratings)
    corr, reps = _correlations(values, ratings, pcode, N, bootstrap_counts(N, bootstrap, seed).astype(float))
    diffs = _differences(corr, reps)
    trials = pd.DataFrame(
        {
            "participant": frame["participant"].to_numpy(),
            "trial": frame["trial"].to_numpy(),
            "rating": ratings,
            **{f"trust_{k}" if k in TRUST_MEASURES else k: v for k, v in values.items()},
        }
    )
    return ValidationReport(
        column=column,
        labels=None if labels is None else [str(x) for x in labels],
        n_rated=int(rated.sum()),
        n_participants=N,
        n_participants_rated=len(np.unique(pcode[rated])),
        correlations=corr,
        differences=diffs,
        trials=trials,
        bootstrap=bootstrap,
        seed=seed,
    )


def _decoded_values(frame: pd.DataFrame, model: TrustModel) -> tuple[dict[str, np.ndarray], np.ndarray, int]:
    """Per row of ``frame``: the smoothed and filtered trust (the levels' mean on [0, 1]) and the
    baselines; each row's participant code; the number of participants."""
    spec, params = from_model(model)
    seqs = encode(frame, spec)
    K = spec.n_levels
    scale = np.arange(K) / (K - 1)
    try:
        gamma, _, _ = posteriors(seqs, spec, params)
    except FitError:
        raise FitError(["the trials have probability zero under this model: nothing to decode"]) from None
    filt = filter_beliefs(seqs, params)
    valid = seqs.rows >= 0
    rows = seqs.rows[valid]
    n = len(frame)
    pcode = np.empty(n, dtype=np.int64)
    pcode[rows] = np.nonzero(valid)[1]
    trial_no = np.empty(n, dtype=np.int64)
    vt, vn = np.nonzero(valid)
    trial_no[rows] = seqs.trial_numbers(vt, vn)
    values: dict[str, np.ndarray] = {}
    for name, arr in (("smoothed", gamma), ("filtered", filt.posterior)):
        v = np.full(n, np.nan)
        v[rows] = (arr[valid] * scale).sum(-1)
        values[name] = v
    order = np.lexsort((trial_no, pcode))
    ha = frame["human_action"]
    recorded = ha.notna().to_numpy()
    rely = np.where(recorded, (ha.astype(object) == "rely").to_numpy(dtype=float), np.nan)
    if "experience" in frame and frame["experience"].notna().any():
        ex = frame["experience"]
        exp_known = ex.notna().to_numpy()
        reliable = (ex.astype(object) == EXPERIENCES[1]).to_numpy(dtype=float)
        values["reliable_fraction"] = _running_rate(reliable, exp_known, pcode, order)
    else:
        values["reliable_fraction"] = np.full(n, np.nan)
    values["reliance"] = rely
    values["reliance_rate"] = _running_rate(np.nan_to_num(rely), recorded, pcode, order)
    return values, pcode, seqs.n_participants


def _correlations(values: dict[str, np.ndarray], ratings: np.ndarray, pcode: np.ndarray, N: int, counts: np.ndarray):
    """Each value's correlations with the ratings per scope and method (estimate and interval), and
    their bootstrap replicates (``counts``: the participants' multiplicities per replicate)."""
    rated = np.isfinite(ratings)
    ones = np.ones((1, N))
    corr: dict[str, dict[str, dict[str, dict[str, float]]]] = {}
    reps: dict[str, dict[str, dict[str, np.ndarray]]] = {}
    for name, v in values.items():
        use = rated & np.isfinite(v)
        x, y, p = v[use], ratings[use], pcode[use]
        per_n = np.bincount(p, minlength=N).astype(float)
        with np.errstate(invalid="ignore", divide="ignore"):
            mx = np.bincount(p, x, N) / per_n
            my = np.bincount(p, y, N) / per_n
        multi = per_n[p] >= 2
        xw, yw, pw = (x - mx[p])[multi], (y - my[p])[multi], p[multi]
        has = per_n > 0
        data = {"pooled": (x, y, p), "within": (xw, yw, pw), "between": (mx[has], my[has], np.flatnonzero(has))}
        corr[name], reps[name] = {}, {}
        for scope, (a, b, who) in data.items():
            point = correlations(a, b, ones[:, who])
            parts = [correlations(a, b, counts[c][:, who]) for c in chunks(len(counts), len(a))]
            boot = {k: np.concatenate([np.zeros(0), *(q[k] for q in parts)]) for k in METHODS}
            if scope == "between":
                few = (counts[:, who] > 0).sum(1) < MIN_BETWEEN
                boot = {k: np.where(few, np.nan, r) for k, r in boot.items()}
                if len(who) < MIN_BETWEEN:
                    point = {k: np.full(1, np.nan) for k in point}
            reps[name][scope] = boot
            corr[name][scope] = {}
            for method in METHODS:
                lo, hi = percentile_interval(boot[method])
                corr[name][scope][method] = {"estimate": float(point[method][0]), "lower": lo, "upper": hi, "n": len(a)}
    return corr, reps


def _differences(corr, reps) -> dict[str, dict[str, dict[str, dict[str, dict[str, Any]]]]]:
    """Trust measure minus baseline, per scope and method, with the bootstrap's interval and which is better."""
    diffs: dict[str, dict[str, dict[str, dict[str, dict[str, Any]]]]] = {}
    for m in TRUST_MEASURES:
        diffs[m] = {}
        for base in RATING_BASELINES:
            diffs[m][base] = {}
            for scope in SCOPES:
                diffs[m][base][scope] = {}
                for method in METHODS:
                    lo, hi = percentile_interval(reps[m][scope][method] - reps[base][scope][method])
                    est = corr[m][scope][method]["estimate"] - corr[base][scope][method]["estimate"]
                    better = "neither"
                    if np.isfinite(lo) and np.isfinite(hi):
                        better = "trust" if lo > 0 else "baseline" if hi < 0 else "neither"
                    diffs[m][base][scope][method] = {"estimate": est, "lower": lo, "upper": hi, "better": better}
    return diffs
