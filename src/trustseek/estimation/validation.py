"""Does the hidden trust track self-reports?  Correlations of decoded trust with trust ratings.

On the rated trials (:func:`parse_ratings`: numbers, or ordinal labels lowest first),
:func:`validate_ratings` correlates the ratings (Spearman and Pearson) with the decoded trust
(``smoothed`` and ``filtered``: the expected level on [0, 1]) and with baselines
(:data:`RATING_BASELINES`), ``pooled``, ``within`` participants (centred on their means) and
``between`` them (their means), with participant-bootstrap intervals and differences trust -
baseline on the same resamples.  See docs/validation.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from ..data.cells import NAN_WORDS, DataError
from ..model.core import TrustModel
from ..statistics import LEVEL, bootstrap_counts, correlations, paired, percentile_interval
from .baselines import indicators, running_rate
from .iohmm import posteriors
from .prediction import chunks, filter_beliefs
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
    rely, reliable = indicators(frame)
    values = {name: seqs.per_row((arr * scale).sum(-1)) for name, arr in (("smoothed", gamma), ("filtered", filt.posterior))}
    values["reliable_fraction"] = seqs.per_row(running_rate(seqs.spread(reliable), inclusive=True))
    if not np.isfinite(reliable).any():
        values["reliable_fraction"] = np.full(len(frame), np.nan)
    values["reliance"] = rely
    values["reliance_rate"] = seqs.per_row(running_rate(seqs.spread(rely), inclusive=True))
    return values, seqs.row_participants(), seqs.n_participants


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

    def diff(m: str, base: str, scope: str, method: str) -> dict[str, Any]:
        est = corr[m][scope][method]["estimate"] - corr[base][scope][method]["estimate"]
        return paired(est, reps[m][scope][method] - reps[base][scope][method], ours="trust")

    return {m: {b: {s: {k: diff(m, b, s, k) for k in METHODS} for s in SCOPES} for b in RATING_BASELINES} for m in TRUST_MEASURES}
