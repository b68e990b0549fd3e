"""Participant-level bootstrap of a fit: an interval for every cell of the model's tables
(:func:`cell_tables`: a TrustModel's, or a general model's own tables).

Each replicate refits resampled participants from the estimate and a few random starts; its levels
are matched to the estimate's (:func:`align`).  A cell's interval is the replicates' percentile
interval widened to contain the estimate (:class:`Intervals`); a free cell at 0 that every resample
leaves at 0 gets the likelihood-ratio interval instead (:func:`bound_zero_cells`, the drop
:data:`BOUNDARY_DROP`).  Replicate b always uses the b-th child of the seed, whatever the number of
processes.  See docs/fitting.md.
"""

from __future__ import annotations

import copy
import logging
import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any

import numpy as np

from ..parallel import in_processes
from ..statistics import LEVEL, percentile_bounds
from .em import run_em
from .estep import Workspace
from .iohmm import fit_iohmm
from .mixture_em import MixtureStructure
from .options import FitOptions
from .ratings import make_structure
from .sequences import Sequences
from .spec import TABLES, FitError, IOHMMSpec, Params
from .structure import Structure, Table
from .trust_iohmm import check_convertible, index_grid, to_model

#: a bootstrap replicate's refit: from the estimate and 3 random starts, over all cores
REFITS = FitOptions(restarts=3)

log = logging.getLogger(__name__)

MIN_REPLICATES = 200  # fewest resamples for a 95 % interval: each 2.5 % tail then rests on 5 replicates
OTHER_MAXIMUM = 1e-4  # a random start beats the refit continued from the estimate by more than this (log-likelihood)
BOUNDARY = 1e-6  # a free cell estimated below this is at the boundary
TABLE_NAMES = {"em": "emission", "tr": "transition"}  # a structure's tables and the Params arrays they fill
BOUNDARY_DROP = 2.706 / 2  # log-likelihood drop of a 95 % bound at a boundary: chi-bar-square(0.5, 0.5), 2.706 / 2
PROFILE_STEPS = 6  # bisection steps of a likelihood-ratio bound: to 1/64, the wider end kept


def align(reference: Params, params: Params, weights: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
    """The permutation of ``params``' levels that best matches ``reference``'s (for :meth:`Params.permuted`):
    the exact assignment (Hungarian algorithm) minimising the weighted squared distance of the levels'
    initial probabilities, emission rows and probabilities of staying in every transition row;
    ``weights`` (``initial`` (K,), ``emission`` (Ue, K), ``transition`` (Ut, K), e.g. the expected
    events behind each row) weigh reference level i's rows, by default once each."""
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


def _trust_cells(spec: IOHMMSpec) -> bool:
    """Whether ``spec``'s cells are a TrustModel's (else the IOHMM's own tables)."""
    try:
        check_convertible(spec)
    except FitError:
        return False
    return True


def cell_tables(spec: IOHMMSpec, params: Params) -> dict[str, np.ndarray]:
    """The tables whose cells get intervals: a trust model's TrustModel arrays, or for a model of
    other named inputs its own ``initial`` (K,), ``emission`` (Ue, K, Y), ``transition`` (Ut, K, K)."""
    m = to_model(spec, params) if _trust_cells(spec) else params
    return {name: getattr(m, name) for name in TABLES}


def cell_positions(spec: IOHMMSpec, ref: Mapping[str, np.ndarray], table: str, u: int, k: int, m: int) -> np.ndarray:
    """Where Params cell (u, k, m) of ``table`` lies in the flattened :func:`cell_tables` (all its copies)."""
    offset = {"initial": 0, "emission": ref["initial"].size, "transition": ref["initial"].size + ref["emission"].size}[table]
    shape = ref[table].shape
    if not _trust_cells(spec):
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


def _held_loglik(
    hold: Callable[[np.ndarray], Structure], work: Workspace, params: Params, name: str, index: tuple, row: np.ndarray
) -> float:
    """The largest log-likelihood with a row of table ``name`` held at ``row`` (``hold(row)``: the structure
    keeping it, ``index``: where it lies in ``params``): EM from ``params``; ``-inf`` where the data are impossible."""
    held = hold(row)
    start = params.copy()
    getattr(start, name)[index] = row
    try:
        (r,) = run_em(held, work, [held.project(start)], tol=1e-5, max_iter=200)
    except FitError:  # the data impossible at this value
        return -np.inf
    return float(r.loglik)


def bound_zero_cells(
    structure: Structure,
    work: Workspace,
    spec: IOHMMSpec,
    params: Params,
    types: Sequence[Params],
    lo: np.ndarray,
    hi: np.ndarray,
    hold: Callable[..., Structure],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Likelihood-ratio intervals (:func:`profile_bound`, the rest refitted by EM from ``params``) for the
    free cells of each of ``types`` (a single model's, or a mixture's types: ``lo``, ``hi`` hold each one's
    flattened :func:`cell_tables` in turn) estimated at 0 whose bootstrap interval is [0, 0]; a row's other
    free cell, if it has just one, gets the mirror bound.  A part the types share is bounded once, with
    type 0's.  ``hold(table, which, rows, k, row)`` is the structure keeping those rows at ``row`` (``which``:
    the type, a slice for a shared part, None for a single model).  The new bounds, the cells bounded and
    their mirrors."""
    top = float(np.sum(work.estep(params).loglik))
    mixture = isinstance(structure, MixtureStructure)
    per = len(lo) // len(types)
    lo, hi = lo.copy(), hi.copy()
    bounded, mirrored = np.zeros(lo.shape, dtype=bool), np.zeros(lo.shape, dtype=bool)
    for m, p in enumerate(types):
        ref = cell_tables(spec, p)
        for table, t, u, k, c, pos in cells_at_zero(structure, spec, p):
            name = TABLE_NAMES[table]
            shared = isinstance(structure, MixtureStructure) and structure.shared(name)
            if (shared and m > 0) or np.any(hi[m * per + pos] >= BOUNDARY):
                continue  # a shared cell is bounded once, with type 0's
            rows = np.flatnonzero(t.group == t.group[u])
            which = (slice(None) if shared else m) if mixture else None
            index = (rows, k) if which is None else (which, rows, k)
            refit = partial(_held_loglik, partial(hold, table, which, rows, k), work, params, name, index)
            bound = profile_bound(getattr(p, name)[u, k], c, top, refit)
            mirror = cell_positions(spec, ref, name, u, k, 1 - c) if t.M == 2 else pos[:0]  # a row of two cells
            for at in (mm * per for mm in (range(len(types)) if shared else (m,))):
                hi[at + pos], bounded[at + pos] = bound, True
                lo[at + mirror], mirrored[at + mirror] = np.minimum(lo[at + mirror], 1.0 - bound), True
    return lo, hi, bounded, mirrored


def _hold_row(structure: Structure, table: str, _which: None, rows: np.ndarray, k: int, row: np.ndarray) -> Structure:
    """``structure`` with rows ``rows`` (a tie group), level ``k`` of ``table`` (``em`` or ``tr``) fixed to ``row``."""
    held = copy.deepcopy(structure)
    t: Table = getattr(held, table)
    t.fixed[rows, k, :] = True
    t.values[rows, k, :] = row
    t.refresh()
    return held


def boundary_bounds(
    seqs: Sequences, spec: IOHMMSpec, params: Params, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`bound_zero_cells` of a single model: the new lower and upper bounds, and the cells they changed."""
    structure = make_structure(spec, seqs)
    work = Workspace(seqs, *structure.dims, threads=1)
    lo, hi, bounded, mirrored = bound_zero_cells(structure, work, spec, params, [params], lo, hi, partial(_hold_row, structure))
    return lo, hi, bounded | mirrored


@dataclass(frozen=True)
class _Replicate:
    """One bootstrap replicate, sent whole to a worker process: ``refit(sample, options)`` (picklable)
    on the participants drawn with replacement (seeded by ``seed``), the refit seeded by the seed's
    first child, on one thread."""

    seqs: Sequences
    seed: np.random.SeedSequence
    options: FitOptions  # the refit's search (its seed: the replicate's)
    refit: Callable[[Sequences, FitOptions], Any]

    def run(self) -> Any:
        n = self.seqs.n_participants
        sample = self.seqs.subset(np.random.default_rng(self.seed).integers(0, n, n))
        return self.refit(sample, replace(self.options, seed=self.seed.spawn(1)[0], n_jobs=1))


def _refit(spec: IOHMMSpec, params: Params, weights: Mapping[str, np.ndarray], sample: Sequences, options: FitOptions):
    """The refitted model's cells (:func:`flat_cells`), levels aligned to the estimate; and whether a
    random start found a higher maximum than the refit continued from the estimate."""
    fit = fit_iohmm(sample, spec, options, init=[params])
    p = fit.params.permuted(align(params, fit.params, weights))
    other = fit.runs[fit.best].objective - fit.runs[0].objective > OTHER_MAXIMUM
    return flat_cells(cell_tables(spec, p)), bool(other)


def flat_cells(tables: Mapping[str, Any]) -> np.ndarray:
    """The cells of ``tables`` (:data:`TABLES`), flattened table after table."""
    return np.concatenate([np.asarray(tables[name], dtype=float).ravel() for name in TABLES])


def split_cells(flat: np.ndarray, shapes: Mapping[str, tuple[int, ...]]) -> dict[str, np.ndarray]:
    """``flat`` (..., cells) cut back into tables of ``shapes``, table after table."""
    out, pos = {}, 0
    for name in TABLES:
        size = int(np.prod(shapes[name]))
        out[name] = flat[..., pos : pos + size].reshape(*flat.shape[:-1], *shapes[name])
        pos += size
    return out


@dataclass
class Intervals:
    """Bootstrap intervals for every cell of the model's tables, and what they rest on:
    ``intervals[table] = (lower, upper)``, the percentile interval at ``level`` of the ``replicates``
    refits, widened to contain the estimate where it did not (``widened[table]``; ``other_maximum``:
    the replicates in which a random start beat the refit continued from the estimate)."""

    intervals: dict[str, tuple[np.ndarray, np.ndarray]]
    replicates: int
    level: float
    widened: dict[str, np.ndarray]
    other_maximum: int
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
    """Intervals at ``level`` for every cell (:func:`cell_tables`) of the fit ``params``, over ``replicates``
    resamples, each refitted from the estimate and ``options.restarts`` random starts over ``options.n_jobs``
    processes (default: all cores); ``weights`` go to :func:`align`; ``progress("bootstrap", done,
    replicates)`` is called as each finishes.  Fewer than :data:`MIN_REPLICATES` resamples are named
    in :meth:`Intervals.notes`."""
    if replicates < 1:
        raise ValueError(f"the bootstrap needs at least one replicate, got {replicates}")
    if replicates < MIN_REPLICATES and level >= LEVEL:
        log.info(
            "bootstrap: %d resamples are too few for %.0f%% intervals (at least %d)", replicates, 100 * level, MIN_REPLICATES
        )
    w = {k: np.asarray(v, dtype=float) for k, v in (weights or {}).items()}

    def done(i: int, finished: int) -> None:
        log.debug("bootstrap replicate %d done (%d of %d)", i, finished, replicates)
        if progress is not None:
            progress("bootstrap", finished, replicates)

    log.info(
        "bootstrap: %d replicates of %d participants over %d processes",
        replicates,
        seqs.n_participants,
        min(options.n_jobs or os.cpu_count() or 1, replicates),
    )
    results = replicate(partial(_refit, spec, params, w), seqs, replicates, options, done)
    flat = np.vstack([r[0] for r in results])
    ref = cell_tables(spec, params)
    shapes = {name: ref[name].shape for name in TABLES}
    lo, hi, widened = percentile_bounds(flat, flat_cells(ref), level)
    lo, hi, at_boundary = boundary_bounds(seqs, spec, params, lo, hi)
    los, his = split_cells(lo, shapes), split_cells(hi, shapes)
    if widened.any():
        log.info("bootstrap: %d cell interval(s) widened to contain the estimate", int(widened.sum()))
    return Intervals(
        {name: (los[name], his[name]) for name in TABLES},
        replicates,
        level,
        split_cells(widened, shapes),
        int(sum(r[1] for r in results)),
        split_cells(at_boundary, shapes),
    )


def replicate(
    refit: Callable[[Sequences, FitOptions], Any],
    seqs: Sequences,
    replicates: int,
    options: FitOptions,
    done: Callable[[int, int], None],
) -> list[Any]:
    """Every replicate's ``refit`` (:class:`_Replicate`), in order: replicate b resamples with the b-th
    child of ``options.seed`` (whatever the number of processes), over ``options.n_jobs`` processes
    (all cores by default; in this process for one); ``done(b, finished)`` is called as each finishes."""
    jobs = [_Replicate(seqs, ch, options, refit).run for ch in np.random.SeedSequence([options.seed_number, 1]).spawn(replicates)]
    return in_processes(jobs, options.n_jobs, done)
