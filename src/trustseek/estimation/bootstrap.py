"""Participant-level bootstrap of a fit: an interval for every cell of the model's tables.

The cells are a TrustModel's (a fit with the paper's inputs) or, for a model of other named
inputs, the IOHMM's own tables (:func:`cell_tables`).

Each replicate resamples participants with replacement and refits from the point
estimate and a few random starts (the estimator of the point estimate: the best of
several maxima).  Its levels are then matched to the point estimate's by the
permutation that best reproduces it (:func:`align`), not named by the ordering rule
alone: a replicate whose levels are close on the ordering cell would otherwise swap
them and mix two levels' values in one interval.

The interval of a cell is the percentile interval of the replicates, widened where
needed to contain the point estimate (see :class:`Intervals`).  At a boundary the percentile
interval cannot move: where the estimate of a free cell is 0 and every resample's own maximum
is 0 too (the percentile interval is [0, 0]), the interval is the likelihood-ratio one instead
(:func:`boundary_bounds`): every value whose profile log-likelihood (the rest refitted) is within
:data:`BOUNDARY_DROP` of the maximum, the 95 % point of the chi-bar-square at a boundary.  Replicate b always
uses the b-th child of the seed, so the intervals do not depend on how many processes
compute them.
"""

from __future__ import annotations

import copy
import logging
import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..compiled import load as load_compiled
from . import kernels
from .em import run_em
from .estep import Workspace
from .iohmm import fit_iohmm
from .options import FitOptions, check_jobs
from .ratings import make_structure
from .sequences import Sequences
from .spec import FitError, IOHMMSpec, Params
from .structure import Structure, Table
from .trust_iohmm import check_convertible, index_grid, to_model

#: a bootstrap replicate's refit: from the estimate and 3 random starts, over all cores
REFITS = FitOptions(restarts=3)

log = logging.getLogger(__name__)

TABLES = ("initial", "emission", "transition")
LEVEL = 0.95
OUTSIDE = 1e-9  # an estimate this close to its percentile interval is not outside it
MIN_REPLICATES = 200  # fewest resamples for a 95 % interval: each 2.5 % tail then rests on 5 replicates
OTHER_MAXIMUM = 1e-4  # a random start beats the refit continued from the estimate by more than this (log-likelihood)
BOUNDARY = 1e-6  # a free cell estimated below this is at the boundary
TABLE_NAMES = {"em": "emission", "tr": "transition"}  # a structure's tables and the Params arrays they fill
BOUNDARY_DROP = 2.706 / 2  # log-likelihood drop of a 95 % bound at a boundary: chi-bar-square(0.5, 0.5), 2.706 / 2
PROFILE_STEPS = 6  # bisection steps of a likelihood-ratio bound: to 1/64, the wider end kept


def align(reference: Params, params: Params, weights: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
    """The permutation of ``params``' levels that best matches ``reference``'s (for :meth:`Params.permuted`).

    Level j of ``params`` is assigned to level i of ``reference`` so as to minimise the
    sum over levels of a weighted squared distance between their rows: the initial
    probability, every emission row, and the probability of staying at the level in
    every transition row.  ``weights`` (``initial`` (K,), ``emission`` (Ue, K),
    ``transition`` (Ut, K), e.g. the expected events behind each row) weigh the rows of
    reference level i; by default every row counts once.  The assignment is exact
    (Hungarian algorithm), whatever the number of levels.
    """
    K = reference.initial.shape[-1]
    w = dict(weights or {})
    wi = np.asarray(w.get("initial", np.ones(K)), dtype=float)
    we = np.asarray(w.get("emission", np.ones(reference.emission.shape[:2])), dtype=float)
    wt = np.asarray(w.get("transition", np.ones(reference.transition.shape[:2])), dtype=float)
    cost = wi[:, None] * (reference.initial[:, None] - params.initial[None, :]) ** 2
    de = ((reference.emission[:, :, None, :] - params.emission[:, None, :, :]) ** 2).sum(-1)  # (Ue, K ref, K rep)
    cost = cost + (we[:, :, None] * de).sum(0)
    stay_ref = np.diagonal(reference.transition, axis1=-2, axis2=-1)  # (Ut, K)
    stay = np.diagonal(params.transition, axis1=-2, axis2=-1)
    cost = cost + (wt[:, :, None] * (stay_ref[:, :, None] - stay[:, None, :]) ** 2).sum(0)
    from scipy.optimize import linear_sum_assignment  # scipy.optimize takes 0.7 s to import; a fit needs it only here

    rows, cols = linear_sum_assignment(cost)
    perm = np.empty(K, dtype=np.int64)
    perm[rows] = cols
    return perm


def cell_tables(spec: IOHMMSpec, params: Params) -> dict[str, np.ndarray]:
    """The tables whose cells get intervals: a trust model's TrustModel arrays, or for a model of
    other named inputs its own ``initial`` (K,), ``emission`` (Ue, K, Y), ``transition`` (Ut, K, K)."""
    try:
        check_convertible(spec)
    except FitError:
        return {"initial": params.initial, "emission": params.emission, "transition": params.transition}
    m = to_model(spec, params)
    return {name: getattr(m, name) for name in TABLES}


def _held(structure: Structure, table: str, u: int, k: int, row: np.ndarray) -> Structure:
    """``structure`` with row (u, k) of ``table`` (``em`` or ``tr``; its tie group with it) fixed to ``row``."""
    held = copy.deepcopy(structure)
    t: Table = getattr(held, table)
    rows = np.flatnonzero(t.group == t.group[u])
    t.fixed[rows, k, :] = True
    t.values[rows, k, :] = row
    t.gfixed, t.gvalues = t.fixed[t.rep], t.values[t.rep]
    t.mass = 1.0 - np.where(t.gfixed, t.gvalues, 0.0).sum(-1)
    t.free_cells = (~t.gfixed).sum(-1)
    return held


def cell_positions(spec: IOHMMSpec, ref: Mapping[str, np.ndarray], table: str, u: int, k: int, m: int) -> np.ndarray:
    """Where Params cell (u, k, m) of ``table`` lies in the flattened :func:`cell_tables` (all its copies)."""
    offset = {"initial": 0, "emission": ref["initial"].size, "transition": ref["initial"].size + ref["emission"].size}[table]
    shape = ref[table].shape
    try:
        check_convertible(spec)
    except FitError:
        return np.array([offset + np.ravel_multi_index((u, k, m), shape)])
    inputs = spec.emission_inputs if table == "emission" else spec.transition_inputs
    grid = index_grid(spec, inputs, table == "transition")  # TrustModel cell -> combination
    cells = np.argwhere(grid == u)
    return np.array([offset + np.ravel_multi_index((*c, k, m), shape) for c in cells], dtype=np.int64)


def profile_bound(est: np.ndarray, m: int, top: float, refit: Callable[[np.ndarray], float]) -> float:
    """The largest value of cell ``m`` of a row estimated at ``est`` (cell ``m`` at 0) whose profile
    log-likelihood is within :data:`BOUNDARY_DROP` of ``top``, the maximum: ``refit(row)`` is the
    largest log-likelihood with the row held at ``row`` (the other cells keep their shares of the
    rest), ``-inf`` where the data are impossible.  Bisection to 1/64, the wider end kept."""
    others = np.arange(est.size) != m
    share = est[others] / est[others].sum() if est[others].sum() > 0 else np.full(others.sum(), 1.0 / others.sum())

    def drop(v: float) -> float:
        row = np.zeros(est.size)
        row[m], row[others] = v, (1 - v) * share
        return top - refit(row)

    if drop(1.0) <= BOUNDARY_DROP:
        return 1.0
    a, b = 0.0, 1.0
    for _ in range(PROFILE_STEPS):
        mid = (a + b) / 2
        a, b = (mid, b) if drop(mid) <= BOUNDARY_DROP else (a, mid)
    return b


def _profile_bound(work: Workspace, structure: Structure, params: Params, table: str, u: int, k: int, m: int) -> float:
    """:func:`profile_bound` of free cell (u, k, m) of a single model, the other cells refitted by EM."""
    name = TABLE_NAMES[table]

    def refit(row: np.ndarray) -> float:
        held = _held(structure, table, u, k, row)
        start = Params(params.initial.copy(), params.emission.copy(), params.transition.copy())
        getattr(start, name)[getattr(held, table).group == getattr(held, table).group[u], k] = row
        try:
            (r,) = run_em(held, work, [held.project(start)], tol=1e-5, max_iter=200)
        except FitError:  # the data impossible at this value
            return -np.inf
        return float(r.loglik)

    return profile_bound(getattr(params, name)[u, k], m, float(np.sum(work.estep(params).loglik)), refit)


def few_resamples(replicates: int, level: float) -> list[str]:
    """The note of intervals at ``level`` on fewer than :data:`MIN_REPLICATES` resamples (or none)."""
    if replicates >= MIN_REPLICATES or level < LEVEL:
        return []
    return [
        f"bootstrap: {replicates} resamples are too few for {level:.0%} intervals "
        f"(at least {MIN_REPLICATES}: --bootstrap {MIN_REPLICATES}); the bounds are rough"
    ]


def boundary_note(count: int, cells: str = "cells", profile: str = "profile log-likelihood") -> str:
    """The note of ``count`` intervals that are likelihood-ratio ones (:func:`profile_bound`)."""
    return (
        f"bootstrap: {count} {cells} estimated at 0 (or 1) stayed there in every resample; their intervals are "
        f"likelihood-ratio ones (the values whose {profile} is within {BOUNDARY_DROP:.2f} of the maximum)"
    )


def cells_at_zero(
    structure: Structure, spec: IOHMMSpec, params: Params
) -> Iterator[tuple[str, Table, int, int, int, np.ndarray]]:
    """The free emission and transition cells of ``params`` estimated at 0, in rows whose cells are
    all free: (``em`` or ``tr``, its table, u, k, m, where the cell lies in the flattened
    :func:`cell_tables`)."""
    ref = cell_tables(spec, params)
    for table, name in TABLE_NAMES.items():
        t: Table = getattr(structure, table)
        values = getattr(params, name)
        for u in t.rep:
            for k in range(t.K):
                free = np.flatnonzero(~t.fixed[u, k])
                if len(free) < t.M:
                    continue  # a row with fixed cells (or no events) is not estimated
                for m in free[values[u, k, free] < BOUNDARY]:
                    pos = cell_positions(spec, ref, name, int(u), k, int(m))
                    if len(pos):
                        yield table, t, int(u), k, int(m), pos


def boundary_bounds(
    seqs: Sequences, spec: IOHMMSpec, params: Params, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Likelihood-ratio intervals for the free emission and transition cells estimated at 0 whose
    bootstrap interval is [0, 0] (flattened :func:`cell_tables`); a row's other free cell, if it has
    just one, gets the mirror bound.  The new lower and upper bounds, and the cells they changed."""
    structure = make_structure(spec, seqs)
    work = Workspace(seqs, *structure.dims, threads=1)
    ref = cell_tables(spec, params)
    lo, hi, moved = lo.copy(), hi.copy(), np.zeros(lo.shape, dtype=bool)
    for table, t, u, k, m, pos in cells_at_zero(structure, spec, params):
        if np.any(hi[pos] >= BOUNDARY):
            continue
        bound = _profile_bound(work, structure, params, table, u, k, m)
        hi[pos], moved[pos] = bound, True
        if t.M == 2:
            name = TABLE_NAMES[table]
            mirror = cell_positions(spec, ref, name, u, k, 1 - m)
            lo[mirror], moved[mirror] = np.minimum(lo[mirror], 1.0 - bound), True
    return lo, hi, moved


def resample(seqs: Sequences, seed: np.random.SeedSequence, options: FitOptions) -> tuple[Sequences, FitOptions]:
    """A bootstrap replicate's participants (drawn with replacement, seeded by ``seed``) and the
    options of its refit (seeded by the seed's first child, on one thread)."""
    rng = np.random.default_rng(seed)
    n = seqs.n_participants
    return seqs.subset(rng.integers(0, n, n)), replace(options, seed=seed.spawn(1)[0], n_jobs=1)


@dataclass(frozen=True)
class _Replicate:
    """One bootstrap replicate, sent whole to a worker process."""

    seqs: Sequences
    spec: IOHMMSpec
    params: Params
    weights: Mapping[str, np.ndarray]
    seed: np.random.SeedSequence
    options: FitOptions  # the refit's search (its seed: the replicate's)
    compiled: bool = False  # every replicate compiled (the bootstrap as a whole pays for it)

    def run(self) -> tuple[np.ndarray, bool]:
        """The refitted model's cells (:func:`cell_tables`), flattened table after table, levels aligned to the estimate;
        and whether a random start found a higher maximum than the refit continued from the estimate."""
        if self.compiled:
            with kernels.many_fits():
                return self._run()
        return self._run()

    def _run(self) -> tuple[np.ndarray, bool]:
        sample, options = resample(self.seqs, self.seed, self.options)
        fit = fit_iohmm(
            sample,
            self.spec,
            options,
            init=[self.params],
        )
        p = fit.params.permuted(align(self.params, fit.params, self.weights))
        tables = cell_tables(self.spec, p)
        other = fit.runs[fit.best].objective - fit.runs[0].objective > OTHER_MAXIMUM
        return np.concatenate([tables[name].ravel() for name in TABLES]), bool(other)


@dataclass
class Intervals:
    """Bootstrap intervals for every cell of the model's tables, and what they rest on.

    ``intervals[table] = (lower, upper)``: the percentile interval at ``level`` of the
    ``replicates`` refits, widened to contain the point estimate where it did not
    (``widened[table]``, True for those cells).  A percentile interval that leaves out
    the estimate means the replicates' distribution is not centred on it; on these
    data that happens when the likelihood has another maximum almost as high, which
    many resamples prefer (``other_maximum`` counts the replicates in which a random
    start beat the refit continued from the estimate).  The estimate maximises the
    likelihood, so no likelihood-based test rejects it; the widened interval contains
    the percentile interval, so its coverage is at least that interval's.
    """

    intervals: dict[str, tuple[np.ndarray, np.ndarray]]
    replicates: int
    level: float
    widened: dict[str, np.ndarray]
    other_maximum: int
    draws: dict[str, np.ndarray] = field(repr=False)
    likelihood: dict[str, np.ndarray] = field(default_factory=dict)  # cells with the likelihood-ratio interval at a boundary

    @property
    def boundary(self) -> int:
        """How many cells have the likelihood-ratio interval at a boundary (:func:`boundary_bounds`)."""
        return int(sum(m.sum() for m in self.likelihood.values()))

    @property
    def method(self) -> str:
        return "percentile, levels aligned to the estimate, widened to contain it"

    def notes(self) -> list[str]:
        """Plain-language warnings about these intervals (empty when there is nothing to say)."""
        out = few_resamples(self.replicates, self.level)
        if self.boundary:
            out.append(boundary_note(self.boundary))
        if any(w.any() for w in self.widened.values()):
            out.append(
                "bootstrap: some intervals were widened to contain their estimate (the replicates lay on one side "
                f"of it); in {self.other_maximum} of {self.replicates} resamples the refit found another maximum "
                "of the likelihood, so those cells are not well determined by the data"
            )
        return out


def bootstrap(
    seqs: Sequences,
    spec: IOHMMSpec,
    params: Params,
    replicates: int,
    options: FitOptions = REFITS,
    level: float = LEVEL,
    progress: Callable[[str, int, int], None] | None = None,
    weights: Mapping[str, np.ndarray] | None = None,
) -> Intervals:
    """Intervals at ``level`` for every cell (:func:`cell_tables`) of the fit ``params``, over ``replicates`` resamples.

    ``weights`` are passed to :func:`align` (the fit's expected events behind each row
    are a good choice).  Each replicate refits from the estimate and ``options.restarts`` random
    starts (:class:`~.options.FitOptions`, seeded from ``options.seed``) over ``options.n_jobs``
    processes (default: all cores);
    ``progress("bootstrap", done, replicates)`` is called as each one finishes.  Fewer than :data:`MIN_REPLICATES`
    resamples for a 95 % interval are allowed (tests, quick looks) but logged
    and named in :meth:`Intervals.notes`.
    """
    if replicates < 1:
        raise ValueError(f"the bootstrap needs at least one replicate, got {replicates}")
    if replicates < MIN_REPLICATES and level >= LEVEL:
        log.info(
            "bootstrap: %d resamples are too few for %.0f%% intervals (at least %d)", replicates, 100 * level, MIN_REPLICATES
        )
    compiled = kernels.worth_compiling(replicates * seqs.n_trials)
    if compiled:
        load_compiled()  # many fits: the compiled E-step in every one (worker processes start from here)
    w = {k: np.asarray(v, dtype=float) for k, v in (weights or {}).items()}

    def done(i: int, finished: int) -> None:
        log.debug("bootstrap replicate %d done (%d of %d)", i, finished, replicates)
        if progress is not None:
            progress("bootstrap", finished, replicates)

    log.info(
        "bootstrap: %d replicates of %d participants over %d processes",
        replicates,
        seqs.n_participants,
        min(processes(options), replicates),
    )
    results = replicate(lambda ch: _Replicate(seqs, spec, params, w, ch, options, compiled), replicates, options, done)
    flat = np.vstack([r[0] for r in results])
    other = sum(r[1] for r in results)
    alpha = (1 - level) / 2
    lo, hi = np.quantile(flat, [alpha, 1 - alpha], axis=0)
    ref = cell_tables(spec, params)
    est = np.concatenate([ref[name].ravel() for name in TABLES])
    # outside by more than rounding: a cell on the stick-breaking boundary sits at 1e-12 times the
    # row's free mass, which differs between the estimate and a replicate in the 17th decimal
    widened = (est < lo - OUTSIDE) | (est > hi + OUTSIDE)
    lo, hi = np.minimum(lo, est), np.maximum(hi, est)
    lo, hi, at_boundary = boundary_bounds(seqs, spec, params, lo, hi)
    intervals, wide, draws, likelihood = {}, {}, {}, {}
    pos = 0
    for name in TABLES:
        shape = ref[name].shape
        size = int(np.prod(shape))
        cut = slice(pos, pos + size)
        intervals[name] = (lo[cut].reshape(shape), hi[cut].reshape(shape))
        wide[name] = widened[cut].reshape(shape)
        likelihood[name] = at_boundary[cut].reshape(shape)
        draws[name] = flat[:, cut].reshape((replicates, *shape))
        pos += size
    if widened.any():
        log.info("bootstrap: %d cell interval(s) widened to contain the estimate", int(widened.sum()))
    return Intervals(intervals, replicates, level, wide, int(other), draws, likelihood)


def processes(options: FitOptions) -> int:
    """The processes a bootstrap runs on: ``options.n_jobs``, or all cores."""
    return options.n_jobs or os.cpu_count() or 1


def replicate(
    job: Callable[[np.random.SeedSequence], Any], replicates: int, options: FitOptions, done: Callable[[int, int], None]
) -> list[Any]:
    """Every replicate's result, in order: replicate b runs ``job(seed)`` with the b-th child of
    ``options.seed`` (whatever the number of processes), over :func:`processes`; ``done(b, finished)``
    is called as each finishes."""
    children = np.random.SeedSequence([options.seed_number, 1]).spawn(replicates)
    results: dict[int, Any] = {}

    def finished(i: int, res: Any) -> None:
        results[i] = res
        done(i, len(results))

    run_replicates([job(ch) for ch in children], processes(options), finished)
    return [results[i] for i in range(replicates)]


def run_replicates(jobs: Sequence[Any], n_jobs: int, done: Callable[[int, Any], None]) -> None:
    """Each job's ``run()``, in this process or over ``n_jobs`` processes (never more than there
    are jobs); ``done(i, result)`` is called as job ``i`` finishes (in order in this process)."""
    if n_jobs <= 1 or len(jobs) == 1:
        for i, job in enumerate(jobs):
            done(i, job.run())
        return
    check_jobs(n_jobs)
    with ProcessPoolExecutor(max_workers=min(n_jobs, len(jobs))) as ex:
        futures = {ex.submit(job.run): i for i, job in enumerate(jobs)}
        for f in as_completed(futures):
            done(futures[f], f.result())
