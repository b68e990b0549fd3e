"""Estimate the supervisor model (a :class:`~trustseek.model.TrustModel`) from logged trials:
:func:`fit_trust_model` and :func:`fit_model` (the best of the restarts, the expected events behind
every row, warnings for rows the data do not identify, bootstrap intervals); :func:`decode`.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import pandas as pd

from ..model.core import TrustModel
from .bootstrap import bootstrap as _bootstrap
from .iohmm import EMFit, fit_iohmm, loglik, posterior_frame
from .options import DEFAULTS, FitOptions, counting
from .ratings import RatingStructure
from .result import FitResult
from .sequences import Sequences, encode, participant_codes
from .spec import TABLES, FitError, IOHMMSpec, Params
from .structure import Structure, describe_combination
from .trust_iohmm import (
    broadcast,
    check_convertible,
    from_model,
    general_spec,
    model_categories,
    model_complexities,
    preset_spec,
    to_model,
)

log = logging.getLogger(__name__)

MIN_EVENTS = 5  # fewer expected events than this behind a row: "not identified by this data"


def _estimated_mask(structure: Structure) -> dict[str, np.ndarray]:
    """Row-level: True where a row is estimated (not fixed, not empty)."""
    s = structure
    return {"initial": np.full(s.K, s.K > 1), "emission": s.em.estimated(), "transition": s.tr.estimated()}


def _warnings(fit: EMFit, events: dict[str, np.ndarray]) -> list[str]:
    """A line when the best start stopped at the cap on E-steps, not converged; and one per
    estimated row with fewer than :data:`MIN_EVENTS` expected events behind it."""
    s, spec = fit.structure, fit.spec
    out = fit.cap_warnings()
    for name, table, inputs in (("emission", s.em, spec.emission_inputs), ("transition", s.tr, spec.transition_inputs)):
        for u, k in table.estimated_rows():
            n = float(events[name][u, k])
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


def _constant_output(fit: EMFit) -> list[str]:
    """A warning when every output the model does not fix is the same category (e.g. everyone always
    relies): the initial distribution and the transitions are then not identified."""
    seqs, s = fit.seqs, fit.structure
    # (Ue + 1,): some level's row is estimated; the last entry for no combination (code -1)
    free = np.append(s.em.estimated().any(-1), False)
    values = seqs.y[(seqs.y >= 0) & free[seqs.ue]]
    if fit.spec.n_levels < 2 or values.size == 0 or values.min() != values.max():
        return []
    only = fit.spec.output_categories[int(values[0])]
    return [
        f"every {fit.spec.output} the model does not fix is {only!r}: the data cannot tell the {fit.spec.n_levels} "
        "levels apart, so the initial distribution and the transitions are not identified (any values fit as well)"
    ]


def fit_sequences(
    seqs: Sequences,
    spec: IOHMMSpec,
    options: FitOptions = DEFAULTS,
    bootstrap: int = 0,
    progress: Callable[[int, int], None] | None = None,
    init: Sequence[Params] = (),
) -> FitResult:
    """:func:`fit_trust_model` on already encoded sequences."""
    check_convertible(spec)
    result, tick = _fitted(seqs, spec, options, bootstrap, progress, init)
    events = result.events
    counts = broadcast(spec, events)
    estimated = {k: v.astype(bool) for k, v in broadcast(spec, _estimated_mask(result.structure)).items()}
    if "rating" in events:
        counts["rating"] = np.repeat(events["rating"].sum(-1, keepdims=True), spec.n_ratings, axis=-1)
        estimated["rating"] = np.ones_like(events["rating"], dtype=bool)
    result.counts, result.estimated, result.warnings = counts, estimated, _warnings(result, events)
    return _with_intervals(result, bootstrap, options, tick)


def _fitted(
    seqs: Sequences,
    spec: IOHMMSpec,
    options: FitOptions,
    bootstrap: int,
    progress: Callable[[int, int], None] | None,
    init: Sequence[Params] = (),
    general: bool = False,
) -> tuple[FitResult, Callable[..., None]]:
    """The EM fit of ``spec`` (:func:`~.iohmm.fit_iohmm`) with its model (with ``general``, a general
    model) and the expected events behind its rows (a rating's too); and the tick that reports
    ``progress`` after each start and each of the ``bootstrap`` replicates to come."""
    if bootstrap > 0 and spec.rating is not None:
        raise FitError(["bootstrap intervals are not available for a fit with ratings (fit without --bootstrap)"])
    tick = counting(progress, options.starts + len(init) + bootstrap)
    seed = options.seed_number
    fit = fit_iohmm(seqs, spec, replace(options, seed=np.random.SeedSequence([seed, 0])), init=init, on_restart=tick)
    notes = f"fitted by trustseek: {seqs.n_participants} participants, {seqs.n_trials} trials, log-likelihood {fit.loglik:.4f}"
    return FitResult.of(fit, to_model(spec, fit.params, notes, general=general), _expected_events(fit), seed), tick


def _expected_events(fit: EMFit) -> dict[str, np.ndarray]:
    """Posterior-expected number of data events behind each row (tied rows: the group's), and with a
    rating, behind each rating cell (K, R)."""
    st = fit.workspace().estep(fit.params)
    s = fit.structure
    out = {"initial": np.full(s.K, float(fit.seqs.n_participants))}
    for name, table, counts in (("emission", s.em, s.action_counts(st.emission)), ("transition", s.tr, st.transition)):
        out[name] = table.grouped(counts.sum(-1))[table.group]  # (U, K)
    if isinstance(s, RatingStructure):
        out["rating"] = s.rating_counts(st.emission)
    return out


def _with_intervals(result: FitResult, bootstrap: int, options: FitOptions, tick: Callable[[], None]) -> FitResult:
    """``result`` with its warnings logged and, with ``bootstrap`` > 0, its intervals over that many
    resamples (each refit from at most 3 random starts; ``tick`` after each), their notes added."""
    for w in result.warnings:
        log.info("%s", w)
    if bootstrap > 0:
        result.intervals = _bootstrap(
            result.seqs,
            result.spec,
            result.params,
            bootstrap,
            replace(options, restarts=min(options.starts, 3)),
            progress=lambda label, d, t: tick(),
            weights={k: v for k, v in result.events.items() if k in TABLES},
        )
        result.warnings += result.intervals.notes()
    return result


def fit_trust_model(
    frame: pd.DataFrame,
    preset: str | IOHMMSpec = "paper",
    options: FitOptions = DEFAULTS,
    bootstrap: int = 0,
    prior: float = 0.0,
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
    a warning), computed over ``options.n_jobs`` processes (default: all cores); the fit itself
    shares its E-steps over as many threads.  ``options`` (:class:`~.options.FitOptions`) are
    the search's: restarts, seed, tolerance, iteration cap, workers; results do not depend on
    the workers.  ``progress(done, total)`` is called after every restart and bootstrap replicate.

    ``rating`` names a column of self-reported trust ratings, a second emission of the hidden
    trust (P(rating | trust), one free row per level; an empty cell contributes probability
    1): the model is fitted on the human actions and the ratings jointly, and carries the
    rating table.  Its ordinal levels, lowest first, are ``rating_levels``, or the categories
    of the column when it is categorical (as :func:`~trustseek.data.read_trials` returns a
    mapped rating).  ``actions=False`` leaves the human actions out (every one counted
    missing): a fit on the ratings alone, whose emission rows are then never estimated.
    """
    spec = preset_spec(preset, frame, prior=prior, **spec_options)
    frame, spec = _with_rating(frame, spec, rating, rating_levels, actions)
    result = fit_sequences(encode(frame, spec), spec, options, bootstrap, progress)
    marked = never_estimated(frame, spec)
    if marked:
        result.model = result.model.replace(not_estimated=marked)
        names = ", ".join(result.model.not_estimated_rows())
        result.warnings.append(f"never estimated (no such trials in the data; marked in the model file): {names}")
    return result


def _with_rating(
    frame: pd.DataFrame, spec: IOHMMSpec, rating: str | None, levels: Sequence[str] | None, actions: bool
) -> tuple[pd.DataFrame, IOHMMSpec]:
    """The spec with the rating column (its levels: :func:`rating_levels_of`), and without the human
    actions (every one counted missing) unless ``actions``."""
    if rating is not None:
        spec = replace(spec, rating=rating, rating_levels=rating_levels_of(frame, rating, levels))
    if not actions:
        if rating is None:
            raise FitError(["a fit without the human actions needs a rating column"])
        frame = frame.assign(human_action=pd.Series(pd.NA, index=frame.index, dtype=object))
    return frame, spec


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


def trust_loglik(frame: pd.DataFrame, model: TrustModel, rating: str | None = None) -> float:
    """Log-likelihood of the log under ``model``: the human actions, and with ``rating`` (a column)
    the ratings too, through the model's rating table (an empty rating contributes probability 1)."""
    spec, params = from_model(model, rating)
    return loglik(encode(frame, spec), spec, params)


def never_estimated(frame: pd.DataFrame, spec: IOHMMSpec) -> tuple[tuple[str, tuple[int, ...]], ...]:
    """TrustModel rows no trial of ``frame`` informs: emission rows (c, a) with no observed human
    action (unless the spec fixes the row, as the paper preset fixes P(intervene | ask) = 1), and
    transition rows (c, a, e) with no trial of a participant followed by another.

    Rows that inputs a table ignores repeat (e.g. the ask rows when transitions do not depend
    on the robot action) are copies of other rows, not estimates: they are listed too."""
    complexities = model_complexities(spec)
    columns = model_categories(complexities)
    if any(name not in frame for name in columns):
        return ()  # a log without these columns: nothing to say per row
    c, a, e = (_index_codes(frame[name], names) for name, names in columns.items())
    if (c < 0).any() or (a < 0).any():
        return ()
    # a trial has a next one when it is not its participant's last (encode refused repeated indices)
    person, people = participant_codes(frame["participant"])
    trial = frame["trial"].to_numpy(dtype=np.int64)
    last = np.full(len(people), np.iinfo(np.int64).min)
    np.maximum.at(last, person, trial)
    # one count per (what the trial informs, c, a, e + 1): 1 an observed human action (its
    # emission row), 2 a next trial (its transition row, when e is known), 3 both
    informs = frame["human_action"].notna().to_numpy().view(np.int8) + 2 * (trial < last[person]).view(np.int8)
    n = len(complexities)
    key = ((informs.astype(np.int16) * n + c) * 2 + a) * 3 + (e + 1)
    counts = np.bincount(key, minlength=4 * n * 6).reshape(4, n, 2, 3)
    em_seen = counts[[1, 3]].sum((0, 3)) > 0
    tr_seen = counts[2:, :, :, 1:].sum(0) > 0
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
    """Each value's index in ``names``, -1 where it is missing or not among them."""
    if isinstance(values.dtype, pd.CategoricalDtype):
        lookup = [names.index(v) if v in names else -1 for v in values.cat.categories]
        return np.array([*lookup, -1], dtype=np.int16)[values.cat.codes.to_numpy()]  # code -1 (missing): the last
    return values.map({v: i for i, v in enumerate(names)}).fillna(-1).to_numpy(dtype=np.int16)


def decode(frame: pd.DataFrame, model: TrustModel, rating: str | None = None) -> pd.DataFrame:
    """Per-trial smoothed P(trust = level | all trials of the participant) and the Viterbi level
    (with ``rating``, a column, from the ratings too, through the model's rating table); a
    general model decodes from its own inputs."""
    spec, params = from_model(model, rating)
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


def fit_model(
    frame: pd.DataFrame,
    emission_inputs: Sequence[str],
    transition_inputs: Sequence[str],
    levels: Sequence[str] | int = ("low", "high"),
    options: FitOptions = DEFAULTS,
    prior: float = 0.0,
    progress: Callable[[int, int], None] | None = None,
    rating: str | None = None,
    actions: bool = True,
    bootstrap: int = 0,
) -> FitResult:
    """Fit the human action's IOHMM with any named inputs (columns of ``frame``, e.g. a mapping's
    ``inputs`` and the canonical complexity, robot_action, experience) to a general model.

    Each input's levels keep their declared order (a categorical column's categories: the
    mapping's).  The structure is :func:`~.trust_iohmm.general_spec`; ``options``
    (:class:`~.options.FitOptions`), ratings and ``actions`` are as for :func:`fit_trust_model`, which fits
    the same model with the paper's inputs as a :class:`~trustseek.model.TrustModel` (a rating
    column's levels are its categories, as :func:`~trustseek.data.read_trials` reads a mapped rating).
    ``bootstrap`` > 0 resamples participants that many times for an interval of every table
    cell (:mod:`.bootstrap`, as for the trust model); ``progress`` then counts its replicates too."""
    spec = general_spec(frame, emission_inputs, transition_inputs, levels, prior)
    frame, spec = _with_rating(frame, spec, rating, None, actions)
    problems = spec.problems()
    if problems:
        raise FitError(problems)
    result, tick = _fitted(encode(frame, spec), spec, options, bootstrap, progress, general=True)
    warnings = result.warnings = _warnings(result, result.events)
    never = [
        f"{name}[{describe_combination(int(u), inputs, spec.categories)}]"
        for name, table, inputs in (
            ("emission", result.structure.em, spec.emission_inputs),
            ("transition", result.structure.tr, spec.transition_inputs),
        )
        for u in table.rep[table.defaulted[table.rep]]
    ]
    if never:
        warnings.append(f"never estimated (no such trials in the data; the model file holds defaults): {', '.join(never)}")
    return _with_intervals(result, bootstrap, options, tick)
