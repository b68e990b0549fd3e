"""Estimate the supervisor model (a :class:`~trustseek.model.TrustModel`) from logged trials.

* :func:`fit_trust_model` -- restarts, the best fit, diagnostics (expected events behind
  every cell, warnings for cells the data do not identify), bootstrap intervals;
* :func:`decode` -- smoothed P(trust | data) and the Viterbi path per trial.

The structure (the ``paper`` preset and its variants) and the conversion between IOHMM
tables and a TrustModel are in :mod:`.trust_iohmm`; the number of levels is chosen in
:mod:`.selection`.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pandas as pd

from ..model.core import TrustModel
from ..model.iohmm import IOHMMModel
from ..vocab import ACTIONS, EXPERIENCES
from .bootstrap import Intervals
from .bootstrap import bootstrap as _bootstrap
from .iohmm import IOHMMFit, fit_iohmm, loglik, posteriors
from .ratings import RatingStructure
from .sequences import Sequences, encode
from .spec import FitError, IOHMMSpec, Params
from .structure import Structure, describe_combination
from .trust_iohmm import (
    broadcast,
    check_convertible,
    from_trust_model,
    general_spec,
    index_grid,
    model_complexities,
    preset_spec,
    to_iohmm_model,
    to_trust_model,
)

log = logging.getLogger(__name__)

MIN_EVENTS = 5  # fewer expected events than this behind a row: "not identified by this data"


class Fitted:
    """What a fitted model's result derives from its fit: the criteria, the posteriors and the
    fit's record for JSON (shared by :class:`FitResult` and :class:`ModelFitResult`)."""

    fit: IOHMMFit
    seed: int
    warnings: list[str]
    intervals: Intervals | None

    @property
    def loglik(self) -> float:
        return self.fit.loglik

    @property
    def restart_logliks(self) -> list[float]:
        return self.fit.restart_logliks

    @property
    def n_params(self) -> int:
        return self.fit.n_params

    @property
    def aic(self) -> float:
        return self.fit.aic

    @property
    def bic(self) -> float:
        return self.fit.bic

    def posteriors(self) -> pd.DataFrame:
        """Smoothed P(level | all trials of the participant) and the Viterbi level, one row per trial."""
        return posterior_frame(self.fit.seqs, self.fit.spec, self.fit.params)

    def fit_record(self, bootstrap: int) -> dict[str, Any]:
        """The fit's figures, each start's run, the seed, the bootstrap and the spec, for ``to_dict``."""
        runs, iv = self.fit.runs, self.intervals
        return {
            "loglik": self.loglik,
            "n_params": self.n_params,
            "aic": self.aic,
            "bic": self.bic,
            "n_participants": self.fit.seqs.n_participants,
            "n_trials": self.fit.seqs.n_trials,
            "n_observations": self.fit.n_observations,
            "restart_logliks": self.restart_logliks,
            "best_restart": self.fit.best,
            "iterations": [r.iterations for r in runs],
            "subsample_iterations": [r.subsample_iterations for r in runs],
            "converged": [r.converged for r in runs],
            "ended": [r.ended for r in runs],
            "seconds": [r.seconds for r in runs],
            "seed": self.seed,
            "bootstrap": bootstrap,
            "ci_level": None if iv is None else iv.level,
            "ci_method": None if iv is None else iv.method,
            "ci_other_maximum": None if iv is None else iv.other_maximum,
            "spec": self.fit.spec.to_dict(),
        }


@dataclass
class FitResult(Fitted):
    """A fitted trust model with its diagnostics (see :func:`fit_trust_model`)."""

    model: TrustModel
    fit: IOHMMFit
    counts: dict[str, np.ndarray]
    estimated: dict[str, np.ndarray]
    ci: dict[str, tuple[np.ndarray, np.ndarray]] | None = None
    bootstrap: int = 0
    seed: int = 0
    warnings: list[str] = field(default_factory=list)
    intervals: Intervals | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": self.model.to_dict(),
            **self.fit_record(self.bootstrap),
            "counts": {k: v.tolist() for k, v in self.counts.items()},
            "estimated": {k: v.tolist() for k, v in self.estimated.items()},
            "ci": None
            if self.ci is None
            else {k: {"lower": lo.tolist(), "upper": hi.tolist()} for k, (lo, hi) in self.ci.items()},
            "warnings": list(self.warnings),
        }

    def cells(self) -> list[dict[str, Any]]:
        """One record per estimated cell: label, TrustModel index, estimate, CI, events.

        A model whose tables ignore some inputs lists each distinct row once, labelled
        by the inputs it depends on.
        """
        m, spec = self.model, self.fit.spec
        T = m.trust_levels
        short = {"complexity": "C", "robot_action": "a", "experience": "E'"}
        names = {"complexity": m.complexities, "robot_action": ACTIONS, "experience": EXPERIENCES}
        out: list[dict[str, Any]] = []
        seen: set[tuple[Any, ...]] = set()

        def add(table: str, idx: tuple[int, ...], label: str, key: tuple[Any, ...]) -> None:
            if not self.estimated[table][idx] or key in seen:
                return
            seen.add(key)
            rec: dict[str, Any] = {
                "table": table,
                "index": list(idx),
                "cell": label,
                "estimate": float((m.rating.probs if table == "rating" and m.rating is not None else getattr(m, table))[idx]),
                "events": float(self.counts[table][idx]),
            }
            if self.ci is not None:
                rec["lower"], rec["upper"] = float(self.ci[table][0][idx]), float(self.ci[table][1][idx])
            if self.intervals is not None:
                rec["widened"] = bool(self.intervals.widened[table][idx])
            out.append(rec)

        def cond(inputs: Sequence[str], values: dict[str, int]) -> str:
            return "".join(f", {short[c]}={names[c][values[c]]}" for c in inputs)

        for t in range(1, m.n_trust) if m.n_trust == 2 else range(m.n_trust):
            add("initial", (t,), f"P(T1={T[t]})", ("i", t))
        eg = index_grid(spec, spec.emission_inputs, False)
        for c in range(m.n_complexity):
            for a in range(2):
                for t in range(m.n_trust):
                    v = {"complexity": c, "robot_action": a}
                    add("emission", (c, a, t, 1), f"P(rely | T={T[t]}{cond(spec.emission_inputs, v)})", ("e", int(eg[c, a]), t))
        tg = index_grid(spec, spec.transition_inputs, True)
        for c in range(m.n_complexity):
            for a in range(2):
                for e in range(2):
                    for t in range(m.n_trust):
                        for u in range(m.n_trust):
                            if m.n_trust == 2 and u == 0:
                                continue
                            v = {"complexity": c, "robot_action": a, "experience": e}
                            add(
                                "transition",
                                (c, a, e, t, u),
                                f"P(T'={T[u]} | T={T[t]}{cond(spec.transition_inputs, v)})",
                                ("t", int(tg[c, a, e]), t, u),
                            )
        if m.rating is not None and "rating" in self.estimated:
            levels = m.rating.levels
            for t in range(m.n_trust):
                for r in range(len(levels)):
                    add("rating", (t, r), f"P(rating={levels[r]} | T={T[t]})", ("r", t, r))
        return out


def posterior_frame(seqs: Sequences, spec: IOHMMSpec, params: Params) -> pd.DataFrame:
    """Per trial, in the frame's row order: P(level | all trials of the participant) and the Viterbi level."""
    gamma, path, _ = posteriors(seqs, spec, params)
    valid = seqs.rows >= 0
    tt, nn = np.nonzero(valid)
    order = np.argsort(seqs.rows[valid], kind="stable")
    tt, nn = tt[order], nn[order]
    out: dict[str, Any] = {
        "participant": [seqs.participants[i] for i in nn],
        "trial": seqs.trial_numbers(tt, nn),
    }
    for k, name in enumerate(spec.levels):
        out[f"p_trust_{name}"] = gamma[tt, nn, k]
    out["viterbi_trust"] = np.array(spec.levels, dtype=object)[path[tt, nn]]
    return pd.DataFrame(out)


def _estimated_mask(structure: Structure) -> dict[str, np.ndarray]:
    """Row-level: True where a row is estimated (not fixed, not empty)."""
    em = ~np.all(structure.em.fixed, axis=-1)  # (Ue, K)
    tr = ~np.all(structure.tr.fixed, axis=-1)  # (Ut, K)
    return {"initial": np.full(structure.K, structure.K > 1), "emission": em.astype(float), "transition": tr.astype(float)}


def _warnings(fit: IOHMMFit, events: dict[str, np.ndarray]) -> list[str]:
    """One line per estimated row with fewer than :data:`MIN_EVENTS` expected events behind it."""
    s, spec = fit.structure, fit.spec
    out = []
    for name, table, inputs in (("emission", s.em, spec.emission_inputs), ("transition", s.tr, spec.transition_inputs)):
        ev = events[name]
        for g in range(table.G):
            u = int(table.rep[g])
            for k in range(s.K):
                if np.all(table.fixed[u, k]):
                    continue
                n = float(ev[u, k])
                if n < MIN_EVENTS:
                    out.append(
                        f"{name}[{describe_combination(u, inputs, spec.categories)}][T={spec.levels[k]}]: "
                        f"{n:.1f} expected events, not identified by this data"
                    )
    if "rating" in events:
        for k in range(s.K):
            n = float(events["rating"][k].sum())
            if n < MIN_EVENTS:
                out.append(f"rating[T={spec.levels[k]}]: {n:.1f} expected events, not identified by this data")
    else:
        out += _constant_output(fit)
    return out


def _constant_output(fit: IOHMMFit) -> list[str]:
    """A warning when every output the model does not fix is the same category (e.g. every
    participant always relies): no level then explains the data better than another, so the
    initial distribution and the transitions are not identified, whatever their events."""
    seqs, s = fit.seqs, fit.structure
    free = ~np.all(s.em.fixed, axis=(1, 2))  # (Ue,): some level's row is estimated
    ue = np.where(seqs.ue >= 0, seqs.ue, 0)
    seen = (seqs.y >= 0) & (seqs.ue >= 0) & free[ue]
    values = np.unique(seqs.y[seen])
    if fit.spec.n_levels < 2 or len(values) != 1:
        return []
    only = fit.spec.output_categories[int(values[0])]
    return [
        f"every {fit.spec.output} the model does not fix is {only!r}: the data cannot tell the {fit.spec.n_levels} "
        "levels apart, so the initial distribution and the transitions are not identified (any values fit as well)"
    ]


def fit_sequences(
    seqs: Sequences,
    spec: IOHMMSpec,
    restarts: int = 10,
    seed: int = 0,
    bootstrap: int = 0,
    n_jobs: int | None = None,
    tol: float = 1e-8,
    max_iter: int = 1000,
    progress: Callable[[int, int], None] | None = None,
    init: Sequence[Params] = (),
) -> FitResult:
    """:func:`fit_trust_model` on already encoded sequences."""
    check_convertible(spec)
    total = restarts + len(init) + bootstrap
    done = 0

    def tick() -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total)

    fit = fit_iohmm(
        seqs,
        spec,
        restarts=restarts,
        seed=np.random.SeedSequence([seed, 0]),
        tol=tol,
        max_iter=max_iter,
        init=init,
        on_restart=lambda i, r: tick(),
        n_jobs=n_jobs,
    )
    model = to_trust_model(
        spec,
        fit.params,
        notes=f"fitted by trustseek: {seqs.n_participants} participants, {seqs.n_trials} trials, log-likelihood {fit.loglik:.4f}",
    )
    events = fit.expected_events()
    counts = broadcast(spec, events)
    estimated = {k: v.astype(bool) for k, v in broadcast(spec, _estimated_mask(fit.structure)).items()}
    if isinstance(fit.structure, RatingStructure):
        st = fit.workspace().estep(fit.params)
        rc = fit.structure.rating_counts(st.emission)  # (K, R) expected events behind each rating cell
        events["rating"] = rc
        counts["rating"] = np.repeat(rc.sum(-1, keepdims=True), spec.n_ratings, axis=-1)
        estimated["rating"] = np.ones_like(rc, dtype=bool)
    result = FitResult(model, fit, counts, estimated, seed=seed, warnings=_warnings(fit, events))
    for w in result.warnings:
        log.info("%s", w)
    if bootstrap > 0 and spec.rating is not None:
        raise FitError(["bootstrap intervals are not available for a fit with ratings (fit without --bootstrap)"])
    if bootstrap > 0:
        result.intervals = bootstrap_intervals = _bootstrap(
            seqs,
            spec,
            fit.params,
            bootstrap,
            seed=seed,
            restarts=min(restarts, 3),
            n_jobs=n_jobs,
            tol=tol,
            max_iter=max_iter,
            progress=lambda label, d, t: tick(),
            weights=events,  # levels of a replicate are matched on the rows the data determine
        )
        result.ci = bootstrap_intervals.intervals
        result.bootstrap = bootstrap
        result.warnings += bootstrap_intervals.notes()
    return result


def fit_trust_model(
    frame: pd.DataFrame,
    preset: str | IOHMMSpec = "paper",
    restarts: int = 10,
    seed: int = 0,
    bootstrap: int = 0,
    prior: float = 0.0,
    n_jobs: int | None = None,
    tol: float = 1e-8,
    max_iter: int = 1000,
    progress: Callable[[int, int], None] | None = None,
    rating: str | None = None,
    rating_levels: Sequence[str] | None = None,
    actions: bool = True,
    **spec_options: Any,
) -> FitResult:
    """Fit a trust model to a trial table (the canonical columns, e.g. from :func:`read_trials`).

    ``preset`` is ``"paper"`` (optionally adjusted by ``levels``, ``transition_inputs``,
    ``emission_inputs``, ``complexities`` keyword options) or an :class:`IOHMMSpec`.
    ``prior`` adds that Dirichlet pseudo-count to every free cell (MAP).  With
    ``bootstrap`` > 0, participants are resampled that many times and a 95 % interval is
    reported for every cell (:mod:`.bootstrap`: percentile, replicate levels aligned to
    the estimate, widened to contain it; at least 200 resamples are advised, fewer add
    a warning), computed over ``n_jobs`` processes (default: all cores); the fit itself
    shares its E-steps over ``n_jobs`` threads.  Results do not depend on ``n_jobs``.  ``progress(done, total)``
    is called after every restart and bootstrap replicate.

    ``rating`` names a column of self-reported trust ratings, a second emission of the hidden
    trust (P(rating | trust), one free row per level; an empty cell contributes probability
    1): the model is fitted on the human actions and the ratings jointly, and carries the
    rating table.  Its ordinal levels, lowest first, are ``rating_levels``, or the categories
    of the column when it is categorical (as :func:`~trustseek.data.read_trials` returns a
    mapped rating).  ``actions=False`` leaves the human actions out (every one counted
    missing): a fit on the ratings alone, whose emission rows are then never estimated.
    """
    spec = preset_spec(preset, frame, prior=prior, **spec_options)
    if rating is not None:
        spec = replace(spec, rating=rating, rating_levels=rating_levels_of(frame, rating, rating_levels))
    if not actions:
        if rating is None:
            raise FitError(["a fit without the human actions needs a rating column"])
        frame = frame.assign(human_action=pd.Series(pd.NA, index=frame.index, dtype=object))
    result = fit_sequences(encode(frame, spec), spec, restarts, seed, bootstrap, n_jobs, tol, max_iter, progress)
    marked = never_estimated(frame, spec)
    if marked:
        result.model = result.model.replace(not_estimated=marked)
        names = ", ".join(result.model.not_estimated_rows())
        result.warnings.append(f"never estimated (no such trials in the data; marked in the model file): {names}")
    return result


def rating_levels_of(frame: pd.DataFrame, column: str, levels: Sequence[str] | None = None) -> tuple[str, ...]:
    """The declared levels of a rating column: ``levels``, else its categories (a categorical column)."""
    if column not in frame.columns:
        raise FitError([f"rating column {column!r} is not in the log; its columns: {list(map(str, frame.columns))}"])
    if levels is not None:
        return tuple(str(x) for x in levels)
    values = frame[column]
    if isinstance(values.dtype, pd.CategoricalDtype):
        return tuple(str(x) for x in values.cat.categories)
    raise FitError(
        [
            f"rating column {column!r}: declare its levels, lowest first (e.g. --rating-levels 1,2,3,4,5,6,7, "
            "or 'rating' in the mapping file)"
        ]
    )


def trust_loglik(frame: pd.DataFrame, model: TrustModel | IOHMMModel, rating: str | None = None) -> float:
    """Log-likelihood of the log under ``model``: the human actions, and with ``rating`` (a column)
    the ratings too, through the model's rating table (an empty rating contributes probability 1)."""
    spec, params = from_trust_model(model, rating)
    return loglik(encode(frame, spec), spec, params)


def never_estimated(frame: pd.DataFrame, spec: IOHMMSpec) -> tuple[tuple[str, tuple[int, ...]], ...]:
    """TrustModel rows no trial of ``frame`` informs: emission rows (c, a) with no observed human
    action (unless the spec fixes the row, as the paper preset fixes P(intervene | ask) = 1), and
    transition rows (c, a, e) with no trial of a participant followed by another.

    Rows that inputs a table ignores repeat (e.g. the ask rows when transitions do not depend
    on the robot action) are copies of other rows, not estimates: they are listed too."""
    complexities = model_complexities(spec)
    columns = (("complexity", complexities), ("robot_action", ACTIONS), ("experience", EXPERIENCES))
    if any(name not in frame for name, _ in columns):
        return ()  # a log without these columns: nothing to say per row
    c, a, e = (_index_codes(frame[name], names) for name, names in columns)
    if (c < 0).any() or (a < 0).any():
        return ()
    observed = frame["human_action"].notna().to_numpy()
    # a trial has a next one when it is not its participant's last (encode refused repeated indices)
    participant = frame["participant"]
    if isinstance(participant.dtype, pd.CategoricalDtype):
        person, n_people = participant.cat.codes.to_numpy(dtype=np.int64), len(participant.cat.categories)
    else:
        person, people = pd.factorize(participant)
        n_people = len(people)
    trial = frame["trial"].to_numpy(dtype=np.int64)
    last = np.full(n_people, np.iinfo(np.int64).min)
    np.maximum.at(last, person, trial)
    has_next = trial < last[person]
    n = len(complexities)
    row = c * 2 + a  # the emission row (c, a) of each trial; 2 * row + e its transition row (c, a, e)
    em_seen = (np.bincount(row[observed], minlength=n * 2) > 0).reshape(n, 2)
    sel = has_next & (e >= 0)
    tr_seen = (np.bincount(2 * row[sel] + e[sel], minlength=n * 4) > 0).reshape(n, 2, 2)
    fixed_ask = "robot_action" in spec.emission_inputs and any(
        dict(f.where) == {"robot_action": "ask"} for f in spec.fixed_emissions
    )
    out: list[tuple[str, tuple[int, ...]]] = []
    for i in range(len(complexities)):
        for j in range(2):
            if not em_seen[i, j] and not (fixed_ask and j == 1):
                out.append(("emission", (i, j)))
            for k in range(2):
                if not tr_seen[i, j, k]:
                    out.append(("transition", (i, j, k)))
    return tuple(out)


def _index_codes(values: pd.Series, names: Sequence[str]) -> np.ndarray:
    """Each value's index in ``names``, -1 where it is missing or not among them (a categorical
    column through its categories: no value looked up per row)."""
    if isinstance(values.dtype, pd.CategoricalDtype):
        lookup = [names.index(v) if v in names else -1 for v in values.cat.categories]
        return np.array([*lookup, -1], dtype=np.int32)[values.cat.codes.to_numpy()]  # code -1 (missing): the last
    return values.map({v: i for i, v in enumerate(names)}).fillna(-1).to_numpy(dtype=np.int32)


def decode(frame: pd.DataFrame, model: TrustModel | IOHMMModel, rating: str | None = None) -> pd.DataFrame:
    """Per-trial smoothed P(trust = level | all trials of the participant) and the Viterbi level
    (with ``rating``, a column, from the ratings too, through the model's rating table); a
    general model decodes from its own inputs."""
    spec, params = from_trust_model(model, rating)
    seqs = encode(frame, spec)
    try:
        return posterior_frame(seqs, spec, params)
    except FitError:
        bad = [
            seqs.participants[i] for i in range(seqs.n_participants) if not np.isfinite(loglik(seqs.subset([i]), spec, params))
        ]
        raise FitError(
            [f"participant {p!r}: the trials have probability zero under this model" for p in bad]
            or ["the data have probability zero under this model"]
        ) from None


# --------------------------------------------------------------------------- a model with any named inputs


@dataclass
class ModelFitResult(Fitted):
    """A fitted general model (:class:`~trustseek.model.iohmm.IOHMMModel`, any named inputs) with
    its diagnostics: expected events behind every row, warnings for rows the data do not identify."""

    model: IOHMMModel
    fit: IOHMMFit
    events: dict[str, np.ndarray]
    warnings: list[str] = field(default_factory=list)
    seed: int = 0
    intervals: Intervals | None = None  # bootstrap intervals of every table cell (fit_model's ``bootstrap``)

    def cells(self) -> list[dict[str, Any]]:
        """One record per estimated row cell: label, table, input levels, estimate, expected events
        (tied rows once, fixed and never-reached rows left out; of two categories the second only)."""
        m, s = self.model, self.fit.structure
        L = m.levels
        out: list[dict[str, Any]] = []
        iv = self.intervals

        def with_interval(rec: dict[str, Any], table: str, idx: tuple[int, ...]) -> dict[str, Any]:
            if iv is not None:
                rec["lower"], rec["upper"] = float(iv.intervals[table][0][idx]), float(iv.intervals[table][1][idx])
                rec["widened"] = bool(iv.widened[table][idx])
            return rec

        for k in range(1, m.n_levels) if m.n_levels == 2 else range(m.n_levels):
            rec = {
                "table": "initial",
                "where": {},
                "cell": f"P(S1={L[k]})",
                "estimate": float(m.initial[k]),
                "events": float(self.events["initial"][k]),
            }
            out.append(with_interval(rec, "initial", (k,)))
        for name, table, arr, cats in (
            ("emission", s.em, m.emission, m.output_categories),
            ("transition", s.tr, m.transition, L),
        ):
            for g in range(table.G):
                u = int(table.rep[g])
                if table.empty[u]:
                    continue
                where = m.combination(name, u)
                cond = "".join(f", {c}={v}" for c, v in where.items())
                for k in range(m.n_levels):
                    if np.all(table.fixed[u, k]):
                        continue
                    for j in range(1, len(cats)) if len(cats) == 2 else range(len(cats)):
                        head = f"{m.output}={cats[j]}" if name == "emission" else f"S'={cats[j]}"
                        rec = {
                            "table": name,
                            "where": where,
                            "level": L[k],
                            "category": cats[j],
                            "cell": f"P({head} | S={L[k]}{cond})",
                            "estimate": float(arr[u, k, j]),
                            "events": float(self.events[name][u, k]),
                        }
                        out.append(with_interval(rec, name, (u, k, j)))
        if m.rating is not None and "rating" in self.events:
            for k in range(m.n_levels):
                for r, lv in enumerate(m.rating.levels):
                    out.append(
                        {
                            "table": "rating",
                            "where": {},
                            "level": L[k],
                            "category": lv,
                            "cell": f"P(rating={lv} | S={L[k]})",
                            "estimate": float(m.rating.probs[k, r]),
                            "events": float(self.events["rating"][k].sum()),
                        }
                    )
        return out

    def to_dict(self) -> dict[str, Any]:
        bootstrap = 0 if self.intervals is None else self.intervals.replicates
        return {"model": self.model.to_dict(), **self.fit_record(bootstrap), "warnings": list(self.warnings)}


def fit_model(
    frame: pd.DataFrame,
    emission_inputs: Sequence[str],
    transition_inputs: Sequence[str],
    levels: Sequence[str] | int = ("low", "high"),
    restarts: int = 10,
    seed: int = 0,
    prior: float = 0.0,
    n_jobs: int | None = None,
    tol: float = 1e-8,
    max_iter: int = 1000,
    progress: Callable[[int, int], None] | None = None,
    rating: str | None = None,
    rating_levels: Sequence[str] | None = None,
    actions: bool = True,
    spec: IOHMMSpec | None = None,
    bootstrap: int = 0,
) -> ModelFitResult:
    """Fit the human action's IOHMM with any named inputs (columns of ``frame``, e.g. a mapping's
    ``inputs`` and the canonical complexity, robot_action, experience) to a general model.

    Each input's levels keep their declared order (a categorical column's categories: the
    mapping's).  The structure is :func:`~.trust_iohmm.general_spec` (or ``spec``); restarts,
    seeding, tolerance, ratings and ``actions`` are as for :func:`fit_trust_model`, which fits
    the same model with the paper's inputs as a :class:`~trustseek.model.TrustModel`.
    ``bootstrap`` > 0 resamples participants that many times for an interval of every table
    cell (:mod:`.bootstrap`, as for the trust model); ``progress`` then counts its replicates too."""
    if spec is None:
        spec = general_spec(frame, emission_inputs, transition_inputs, levels, prior)
    if rating is not None:
        spec = replace(spec, rating=rating, rating_levels=rating_levels_of(frame, rating, rating_levels))
    if not actions:
        if rating is None:
            raise FitError(["a fit without the human actions needs a rating column"])
        frame = frame.assign(human_action=pd.Series(pd.NA, index=frame.index, dtype=object))
    problems = spec.problems()
    if problems:
        raise FitError(problems)
    seqs = encode(frame, spec)
    if bootstrap > 0 and spec.rating is not None:
        raise FitError(["bootstrap intervals are not available for a fit with ratings (fit without --bootstrap)"])
    done = 0

    def tick(i: int = 0, r: Any = None) -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, restarts + bootstrap)

    fit = fit_iohmm(
        seqs,
        spec,
        restarts=restarts,
        seed=np.random.SeedSequence([seed, 0]),
        tol=tol,
        max_iter=max_iter,
        on_restart=tick,
        n_jobs=n_jobs,
    )
    notes = f"fitted by trustseek: {seqs.n_participants} participants, {seqs.n_trials} trials, log-likelihood {fit.loglik:.4f}"
    model = to_iohmm_model(spec, fit.params, notes)
    events = fit.expected_events()
    if isinstance(fit.structure, RatingStructure):
        st = fit.workspace().estep(fit.params)
        events["rating"] = fit.structure.rating_counts(st.emission)
    warnings = _warnings(fit, events)
    never = [
        f"{name}[{describe_combination(int(u), inputs, spec.categories)}]"
        for name, table, inputs in (
            ("emission", fit.structure.em, spec.emission_inputs),
            ("transition", fit.structure.tr, spec.transition_inputs),
        )
        for u in table.rep[table.empty[table.rep]]
        if not np.all(table.fixed[u])
    ]
    if never:
        warnings.append(f"never estimated (no such trials in the data; the model file holds defaults): {', '.join(never)}")
    for w in warnings:
        log.info("%s", w)
    result = ModelFitResult(model, fit, events, warnings, seed)
    if bootstrap > 0:
        result.intervals = _bootstrap(
            seqs,
            spec,
            fit.params,
            bootstrap,
            seed=seed,
            restarts=min(restarts, 3),
            n_jobs=n_jobs,
            tol=tol,
            max_iter=max_iter,
            progress=lambda label, d, t: tick(),
            weights={k: v for k, v in events.items() if k in ("initial", "emission", "transition")},
        )
        result.warnings += result.intervals.notes()
    return result
