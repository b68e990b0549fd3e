"""Choosing the number of trust levels (:func:`select_levels`) or of supervisor types
(:func:`select_types`): BIC on all data and participant-held-out log-likelihood.

Each K-level fit starts from random points (by its free parameters, :func:`default_restarts`), from
the (K-1)-level fit with one level split in two (:func:`split_starts`: as likely, EM only climbs),
then from the best local maxima with two levels merged and one split (:func:`split_merge_starts`);
each M-type fit from random points, the perturbed pooled fit and the (M-1)-type fit with each type
split (:func:`~.mixture.split_type_starts`).  Every row reports how many starts reached the best
log-likelihood (within :data:`BEST_TOLERANCE`).  See docs/fitting.md and docs/types.md.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from functools import partial
from typing import Any

import numpy as np
import pandas as pd

from ..parallel import in_processes
from .iohmm import EMFit, fit_iohmm
from .mixture import MixtureFit, check_types, fit_mixture, split_type_starts
from .options import FitOptions
from .sequences import Sequences, deal_folds, encode
from .spec import FitError, IOHMMSpec, Params
from .structure import Structure, mixed
from .trust_iohmm import inputs_spec, level_names

log = logging.getLogger(__name__)

#: a fit's random starts by its free parameters (:func:`default_restarts`), on one thread
BY_PARAMETERS = FitOptions(restarts=None, n_jobs=1)
#: the fits of a selection: starts by free parameters, each to a relative tolerance of 1e-6
SELECTION = FitOptions(restarts=None, tol=1e-6, n_jobs=1)
#: the fits of a selection of types: 10 starts each, to a relative tolerance of 1e-6, on one thread
TYPE_SELECTION = FitOptions(tol=1e-6, n_jobs=1)

HELDOUT_PSEUDOCOUNT = 0.5  # per free cell of a row smoothed for held-out scoring (training counts + this)
ZERO_CELL = 1e-9  # a fitted probability at most this is a zero (the fit clips such cells to 1e-12)
BEST_TOLERANCE = 0.01  # nats: a start within this of the best log-likelihood "reached the best"
SPLITS_PER_LEVEL = 2  # split starts per level of the (K-1)-level fit (different perturbations)
MIN_RESTARTS = 10  # random starts per fit at least ...
RESTARTS_PER_PARAMETER = 0.25  # ... and this many per free parameter
SPLIT_MIX = 0.05  # a split start mixes this much of a random row into every row (no exact zero)
MOVE_ROUNDS = 3  # at most this many rounds of merge-and-split starts ...
MOVE_SOURCES = 3  # ... each from this many of the best distinct local maxima not moved from before
FOLD_MOVE_SOURCES = 1  # ... in select's training folds (the held-out score needs no last nat)


def default_restarts(n_free: int) -> int:
    """Random starts for a fit with ``n_free`` free parameters: ``max(10, n_free / 4)``."""
    return max(MIN_RESTARTS, math.ceil(RESTARTS_PER_PARAMETER * n_free))


def reached_best(logliks: Sequence[float], tol: float = BEST_TOLERANCE) -> int:
    """How many of ``logliks`` lie within ``tol`` nats of their maximum."""
    ll = np.asarray(logliks, dtype=float)
    ll = ll[np.isfinite(ll)]
    return int((ll >= ll.max() - tol).sum()) if ll.size else 0


def split_starts(previous: Params, rng: np.random.Generator, per_level: int = SPLITS_PER_LEVEL) -> list[Params]:
    """Starts with one more level: each level j of ``previous`` split in two, ``per_level`` times: the
    copy takes a random share of j's initial probability and incoming transitions and j's rows out, the
    halves' emission rows pushed apart, every row mixed with :data:`SPLIT_MIX` of a random row (the
    structure's projection restores fixed and tied cells when the fit starts)."""
    K0 = previous.initial.shape[-1]
    out = []
    for j in range(K0):
        for _ in range(per_level):
            f = rng.uniform(0.3, 0.7)
            pi = np.append(previous.initial, previous.initial[j] * (1 - f))
            pi[j] *= f
            em = np.concatenate([previous.emission, previous.emission[:, j : j + 1]], axis=1)  # (U, K, M)
            push = np.exp(rng.normal(0.0, 1.0, size=em[:, j].shape))
            em[:, j] = em[:, j] * push
            em[:, K0] = em[:, K0] / push
            tr = previous.transition
            tr = np.concatenate([tr, tr[:, :, j : j + 1] * (1 - f)], axis=2)  # (U, K0, K): column j split
            tr[:, :, j] *= f
            tr = np.concatenate([tr, tr[:, j : j + 1]], axis=1)  # (U, K, K): the copy's row is j's
            out.append(Params(mixed(pi, rng, SPLIT_MIX), mixed(em, rng, SPLIT_MIX), mixed(tr, rng, SPLIT_MIX)))
    return out


def merge_levels(params: Params, i: int, j: int) -> Params:
    """``params`` with level ``j`` merged into level ``i`` (one level fewer): initial and incoming
    transition probabilities add up; ``i`` keeps its own rows out."""
    keep = [k for k in range(params.initial.shape[-1]) if k != j]
    pi = params.initial.copy()
    pi[i] += pi[j]
    tr = params.transition.copy()
    tr[:, :, i] += tr[:, :, j]
    return Params(pi[keep], params.emission[:, keep].copy(), tr[:, keep][:, :, keep])


def split_merge_starts(params: Params, rng: np.random.Generator) -> list[Params]:
    """Starts with as many levels as ``params``: every pair of levels merged, then every level of the
    result split in two (:func:`merge_levels`, :func:`split_starts`): moves that EM itself cannot make."""
    K = params.initial.shape[-1]
    out: list[Params] = []
    for i in range(K):
        for j in range(i + 1, K):
            out += split_starts(merge_levels(params, i, j), rng, per_level=1)
    return out


def fit_with_moves(
    seqs: Sequences,
    spec: IOHMMSpec,
    previous: Params | None = None,
    options: FitOptions = BY_PARAMETERS,
    splits: int = SPLITS_PER_LEVEL,
    rounds: int = MOVE_ROUNDS,
    sources_per_round: int = MOVE_SOURCES,
) -> EMFit:
    """:func:`~.iohmm.fit_iohmm` from ``options.restarts`` random starts (default :func:`default_restarts`)
    and ``previous`` (one level fewer) split; then up to ``rounds`` times, while that gains more than
    :data:`BEST_TOLERANCE`, from the ``sources_per_round`` best distinct maxima not moved from before
    (:func:`move_sources`) with two levels merged and one split.  Every run is kept in ``runs``."""
    ss = options.seed_sequence
    # the random starts are those fit_iohmm draws from ``seed`` (the first n of n + m are the
    # same): more restarts only add starts; the split and merge moves draw from the seed's own state
    rng = np.random.default_rng(ss.generate_state(4))
    restarts = options.restarts
    n_random = restarts if restarts is not None else default_restarts(Structure(spec, seqs).n_free)
    init: list[Params] = []
    K = spec.n_levels
    if previous is not None and previous.initial.shape[-1] == K - 1 and splits > 0:
        init = split_starts(previous, rng, splits)
    fit = fit_iohmm(seqs, spec, replace(options, restarts=n_random, seed=ss), init=init)
    used: list[float] = []  # objectives of the fits already moved from
    for _ in range(rounds if K > 2 else 0):
        sources = move_sources(fit, used, sources_per_round)
        if not sources:
            break
        used += [fit.runs[i].objective for i in sources]
        starts = [p for i in sources for p in split_merge_starts(fit.runs[i].params, rng)]
        more = fit_iohmm(seqs, spec, replace(options, restarts=0, seed=0), init=starts)
        gain = more.objective - fit.objective
        runs = fit.runs + more.runs
        fit = replace(more, runs=runs, best=len(fit.runs) + more.best) if gain > 0 else replace(fit, runs=runs)
        if gain <= BEST_TOLERANCE:
            break
    return fit


def move_sources(fit: EMFit, used: Sequence[float], n: int) -> list[int]:
    """Indices of the ``n`` best distinct local maxima among ``fit``'s runs not moved from yet.

    Runs within :data:`BEST_TOLERANCE` of each other (or of an objective in ``used``) count
    as one maximum."""
    out: list[int] = []
    seen = [float(u) for u in used]
    for i in sorted(range(len(fit.runs)), key=lambda i: -fit.runs[i].objective):
        r = fit.runs[i]
        if len(out) >= n:
            break
        if not np.isfinite(r.objective) or any(abs(r.objective - u) <= BEST_TOLERANCE for u in seen):
            continue
        out.append(i)
        seen.append(r.objective)
    return out


def select_levels(
    frame: pd.DataFrame,
    levels: Sequence[int] = (1, 2, 3, 4),
    folds: int = 5,
    options: FitOptions = SELECTION,
    prior: float = 0.0,
    progress: Callable[[str, int, int], None] | None = None,
    splits: int = SPLITS_PER_LEVEL,
    widen: bool = False,
    jobs: int | None = 1,
    **spec_options: Any,
) -> list[dict[str, Any]]:
    """Compare numbers of trust levels: BIC on all data and k-fold participant-held-out log-likelihood
    (:class:`HeldOutComparison`, over ``jobs`` processes; with ``widen`` one more level while a best
    is the largest compared, up to :data:`MAX_LEVELS`).  ``spec_options`` adjust the ``paper``
    preset, or name inputs of a general model (:func:`~.trust_iohmm.inputs_spec`).  Each fit is
    :func:`fit_with_moves` with ``splits`` split starts per level, merge-and-split moves from the
    :data:`MOVE_SOURCES` best maxima on all participants, :data:`FOLD_MOVE_SOURCES` in the training
    folds."""
    base = inputs_spec(frame, "paper", prior, **spec_options)
    seqs = encode(frame, base)
    cap = MAX_LEVELS if widen else 0
    comparison = HeldOutComparison("levels", folds, options.seed_number, cap, progress, jobs)
    rows = comparison.run(seqs, levels, _LevelFit(base, replace(options, n_jobs=1), splits))
    for w in selection_warnings(rows):
        log.warning("%s", w)
    return rows


@dataclass(frozen=True)
class _LevelFit:
    """A slot's fit with ``K`` levels (:func:`fit_with_moves`), split from its fit with one level
    fewer (``before``: its tables); the next number's ``before`` is this fit's."""

    base: IOHMMSpec
    options: FitOptions
    splits: int

    def __call__(self, data: Sequences, K: int, slot: int, key: list[int], before: Params | None) -> tuple[EMFit, Params]:
        fit = fit_with_moves(
            data,
            self.base.with_levels(level_names(K)),
            before,
            replace(self.options, seed=np.random.SeedSequence(key)),
            splits=self.splits,
            sources_per_round=MOVE_SOURCES if slot < 0 else FOLD_MOVE_SOURCES,
        )
        return fit, fit.params


@dataclass(frozen=True)
class HeldOutComparison:
    """Numbers of levels or types (``key``) compared by BIC on all participants and by the
    log-likelihood of ``folds`` held-out folds of participants (seeded by ``seed``); with
    ``cap`` > 0 widened while a best is the largest compared (:func:`widening`).
    ``progress(label, done, total)`` is called after every fit.  The fits of a number run over
    ``jobs`` processes (None: all cores), with the same results."""

    key: str
    folds: int
    seed: int
    cap: int = 0
    progress: Callable[[str, int, int], None] | None = None
    jobs: int | None = 1

    def run(
        self,
        seqs: Sequences,
        values: Sequence[int],
        fit: Callable[[Sequences, int, int, list[int], Any], tuple[Any, Any]],
        extra: Callable[[Any], dict[str, Any]] | None = None,
    ) -> list[dict[str, Any]]:
        """One row per number compared: ``fit(data, n, slot, seed key, before)`` on all participants
        (slot -1) and on each fold's training participants (slot f, scored by :func:`heldout_loglik`)
        returns the fit and the slot's ``before`` for the next number (None at first): the fits of
        a number are independent of each other.  ``extra(full fit)`` adds entries to the row.  The
        rows' choices are marked."""
        N = seqs.n_participants
        folds = self.folds
        fold_of = deal_folds(N, folds, [self.seed, 2])  # refuses more folds than participants
        data = [seqs] + [seqs.subset(np.flatnonzero(fold_of != f)) for f in range(folds)]
        tests = [seqs.subset(np.flatnonzero(fold_of == f)) for f in range(folds)]
        asked = list(values)
        total, done = len(asked) * (folds + 1), 0
        rows: list[dict[str, Any]] = []
        before: list[Any] = [None] * (folds + 1)
        for n in widening(asked, rows, self.key, self.cap):
            total += 0 if n in asked else folds + 1
            label = f"{n} {self.key}"
            keys = [[self.seed, 3, n]] + [[self.seed, 4, n, f] for f in range(folds)]
            calls = [partial(fit, data[i], n, i - 1, keys[i], before[i]) for i in range(folds + 1)]

            def finished(_i: int, count: int, label: str = label, start: int = done, total: int = total) -> None:
                if self.progress:
                    self.progress(label, start + count, total)

            fits, before = map(list, zip(*in_processes(calls, self.jobs, finished), strict=True))
            done += folds + 1
            per_fold = [heldout_loglik(tests[f], fits[f + 1]) for f in range(folds)]
            rows.append(self._row(n, fits[0], per_fold, extra, n not in asked))
        mark_choices(rows, self.key)
        return rows

    def _row(self, n: int, full: Any, per_fold: list[float], extra: Any, widened: bool) -> dict[str, Any]:
        held = float(sum(per_fold))
        hits = reached_best(full.restart_logliks)
        log.info(
            "%d %s: log-likelihood %.4f (reached by %d of %d starts), BIC %.2f, held-out log-likelihood %.4f",
            n,
            self.key,
            full.loglik,
            hits,
            len(full.runs),
            full.bic,
            held,
        )
        return {
            self.key: n,
            **full.criteria(),
            "heldout_loglik": held,
            "heldout_per_fold": per_fold,
            **(extra(full) if extra else {}),
            "restart_logliks": full.restart_logliks,
            "starts": len(full.runs),
            "reached_best": hits,
            "widened": widened,
        }


def widening(values: Sequence[int], rows: list[dict[str, Any]], key: str, cap: int) -> Iterator[int]:
    """The numbers to compare: ``values``, then (``cap`` > 0) one more at a time while the best of
    either criterion over ``rows`` (filled by the caller as each number is compared) is the largest
    compared, up to ``cap``."""
    yield from values
    top = max(values)
    while cap and top < cap and rows:
        mark_choices(rows, key)
        if not any((r["best_bic"] or r["best_heldout"]) and r[key] == top for r in rows):
            return
        top += 1
        yield top


def mark_choices(rows: Sequence[dict[str, Any]], key: str) -> None:
    """Mark in a selection table (one row per value of ``key``) the row of lowest BIC
    (``best_bic``) and of highest held-out log-likelihood (``best_heldout``)."""
    best_bic = min(rows, key=lambda r: float(r["bic"]))[key]
    best_cv = max(rows, key=lambda r: float(r["heldout_loglik"]))[key]
    for r in rows:
        r["best_bic"] = r[key] == best_bic
        r["best_heldout"] = r[key] == best_cv


MAX_LEVELS = 8  # the most trust levels select compares (the command's --max-levels bound)


def selection_warnings(rows: Sequence[dict[str, Any]]) -> list[str]:
    """Warnings on a :func:`select_levels` table: a best number of levels at the largest compared,
    and fits whose best log-likelihood only one start reached."""
    return comparison_warnings(rows, "levels", MAX_LEVELS, "--max-levels {next}")


def comparison_warnings(
    rows: Sequence[dict[str, Any]],
    key: str,
    cap: int,
    more: str,
    within: str = "",
    of_row: Callable[[dict[str, Any]], list[str]] | None = None,
) -> list[str]:
    """Warnings on a comparison of numbers of ``key`` (levels or types): a best number at the
    largest compared (``more``, the option to compare more, formatted with ``low`` and ``next``;
    ``cap`` the most comparable), fits whose best log-likelihood only one start reached, and
    ``of_row(row)`` after each row's."""
    out = []
    if len(rows) > 1:
        top = max(int(r[key]) for r in rows)
        low = min(int(r[key]) for r in rows)
        for best, what in (("best_heldout", "held-out log-likelihood"), ("best_bic", "BIC")):
            if any(r[best] and r[key] == top for r in rows):
                hint = (
                    f"compare more with {more.format(low=low, next=top + 1)}"
                    if top < cap
                    else f"{cap} is the most compared: read the choice as 'at least {top}'"
                )
                out.append(f"the best {what} is at {top} {key}, the largest compared: more {key} may fit better ({hint})")
    for r in rows:
        if r[key] > 1 and r.get("reached_best", 2) < 2:
            out.append(
                f"{r[key]} {key}: only 1 of {r['starts']} starts reached the best log-likelihood{within}; "
                "the maximum may not have been found (more --restarts)"
            )
        out += of_row(r) if of_row else []
    return out


def heldout_loglik(test: Sequences, fit: EMFit) -> float:
    """Held-out log-likelihood of ``test`` under the training fit (of a mixture: sum over participants of
    log sum_m w_m P(trials | type m)), its tables as fitted but where a free cell at 0 would make it
    -inf (:func:`heldout_params`): smoothing every row would pull the many sparsely visited rows of a
    larger model towards uniform (docs/fitting.md, "Choosing the number of levels")."""
    return float(fit.workspace(test).loglik(heldout_params(fit)))


def heldout_params(fit: EMFit, pseudocount: float = HELDOUT_PSEUDOCOUNT) -> Params:
    """``fit``'s tables with every row holding a free cell at 0 (at most :data:`ZERO_CELL`) replaced by the
    smoothed row: one M-step from the fit's expected counts plus ``pseudocount`` per free cell (on top of
    the spec's prior); a mixture's initial table, one distribution over (type, first level), as a whole."""
    p = fit.params
    smooth = fit.structure.mstep(fit.workspace().estep(p), p, prior=fit.spec.prior + pseudocount)
    axes = (-2, -1) if isinstance(fit, MixtureFit) else (-1,)
    return type(p)(
        smooth_zero_rows(p.initial, smooth.initial, axes),
        smooth_zero_rows(p.emission, smooth.emission),
        smooth_zero_rows(p.transition, smooth.transition),
    )


def smooth_zero_rows(fitted: np.ndarray, smoothed: np.ndarray, axes: tuple[int, ...] = (-1,)) -> np.ndarray:
    """``fitted`` with every row (over ``axes``) that holds a free cell at 0 (at most
    :data:`ZERO_CELL`, where ``smoothed`` is above it: fixed zeros stay) taken from ``smoothed``."""
    zero = ((fitted <= ZERO_CELL) & (smoothed > fitted)).any(axis=axes, keepdims=True)
    return np.where(zero, smoothed, fitted)


def select_types(
    frame: pd.DataFrame,
    types: Sequence[int] = (1, 2, 3, 4),
    folds: int = 5,
    options: FitOptions = TYPE_SELECTION,
    differ: str | Sequence[str] = "all",
    prior: float = 0.0,
    progress: Callable[[str, int, int], None] | None = None,
    widen: bool = False,
    jobs: int | None = 1,
    **spec_options: Any,
) -> list[dict[str, Any]]:
    """Compare numbers of supervisor types (``types``, e.g. 1..4) as :func:`select_levels` compares levels
    (up to :data:`MAX_TYPES`); each row also holds the types' weights and the empty types."""
    types = sorted({int(m) for m in types})
    if not types or types[0] < 1:
        raise FitError([f"the numbers of types must be positive integers, got {list(types)}"])
    spec = inputs_spec(frame, "paper", prior, **spec_options)
    seqs = encode(frame, spec)
    check_types(types[-1], seqs)

    def extra(full: MixtureFit) -> dict[str, Any]:
        return {"weights": full.weights.tolist(), "empty_types": full.empty_types}

    cap = min(MAX_TYPES, seqs.n_participants) if widen else 0
    comparison = HeldOutComparison("types", folds, options.seed_number, cap, progress, jobs)
    rows = comparison.run(seqs, types, _TypeFit(spec, replace(options, n_jobs=1), differ), extra)
    for w in type_selection_warnings(rows):
        log.warning("%s", w)
    return rows


MAX_TYPES = 12  # the most supervisor types select-types compares (the command's --types bound)


@dataclass(frozen=True)
class _TypeFit:
    """A slot's fit of ``M`` types (:func:`~.mixture.fit_mixture`), from its fit with one type fewer,
    each type split, and its one-type fit perturbed; ``before``: (the fit with one type fewer, the
    one-type fit)."""

    spec: IOHMMSpec
    options: FitOptions
    differ: str | Sequence[str]

    def __call__(
        self, data: Sequences, M: int, slot: int, key: list[int], before: tuple[MixtureFit, MixtureFit | None] | None
    ) -> tuple[MixtureFit, tuple[MixtureFit, MixtureFit | None]]:
        ss = np.random.SeedSequence(key)
        previous, pooled = before if before is not None else (None, None)
        init = []
        if previous is not None and previous.n_types == M - 1:
            init = split_type_starts(previous.params, np.random.default_rng(ss.generate_state(4)), previous.structure)
            # the split starts live in the previous fit's structure: re-projected by the new one in fit_mixture
        fit = fit_mixture(
            data,
            self.spec,
            M,
            replace(self.options, seed=ss),
            differ=self.differ,
            pooled=pooled.params.type_params(0) if pooled is not None else None,
            init=init,
        )
        return fit, (fit, fit if M == 1 else pooled)


def type_selection_warnings(rows: Sequence[dict[str, Any]]) -> list[str]:
    """A best number of types at the largest compared, fits whose best only one start reached,
    and fits with empty types."""

    def empty(r: dict[str, Any]) -> list[str]:
        if not r.get("empty_types"):
            return []
        return [f"{r['types']} types: empty type(s) {', '.join(r['empty_types'])}: fewer types fit as well"]

    return comparison_warnings(rows, "types", MAX_TYPES, "--types {low}..{next}", f" (within {BEST_TOLERANCE})", empty)
