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
needed to contain the point estimate (see :class:`Intervals`).  Replicate b always
uses the b-th child of the seed, so the intervals do not depend on how many processes
compute them.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Mapping
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field

import numpy as np

from ..compiled import load as load_compiled
from . import kernels
from .iohmm import fit_iohmm
from .sequences import Sequences
from .spec import FitError, IOHMMSpec, Params
from .trust_iohmm import check_convertible, to_trust_model

log = logging.getLogger(__name__)

TABLES = ("initial", "emission", "transition")
LEVEL = 0.95
OUTSIDE = 1e-9  # an estimate this close to its percentile interval is not outside it
MIN_REPLICATES = 200  # fewest resamples for a 95 % interval: each 2.5 % tail then rests on 5 replicates
OTHER_MAXIMUM = 1e-4  # a random start beats the refit continued from the estimate by more than this (log-likelihood)


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
    m = to_trust_model(spec, params)
    return {name: getattr(m, name) for name in TABLES}


@dataclass(frozen=True)
class _Replicate:
    """One bootstrap replicate, sent whole to a worker process."""

    seqs: Sequences
    spec: IOHMMSpec
    params: Params
    weights: Mapping[str, np.ndarray]
    seed: np.random.SeedSequence
    restarts: int
    tol: float
    max_iter: int
    compiled: bool = False  # every replicate compiled (the bootstrap as a whole pays for it)

    def run(self) -> tuple[np.ndarray, bool]:
        """The refitted model's cells (:func:`cell_tables`), flattened table after table, levels aligned to the estimate;
        and whether a random start found a higher maximum than the refit continued from the estimate."""
        if self.compiled:
            with kernels.many_fits():
                return self._run()
        return self._run()

    def _run(self) -> tuple[np.ndarray, bool]:
        rng = np.random.default_rng(self.seed)
        n = self.seqs.n_participants
        sample = self.seqs.subset(rng.integers(0, n, n))
        fit = fit_iohmm(
            sample,
            self.spec,
            restarts=self.restarts,
            seed=self.seed.spawn(1)[0],
            tol=self.tol,
            max_iter=self.max_iter,
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

    @property
    def method(self) -> str:
        return "percentile, levels aligned to the estimate, widened to contain it"

    def notes(self) -> list[str]:
        """Plain-language warnings about these intervals (empty when there is nothing to say)."""
        out = []
        if self.replicates < MIN_REPLICATES and self.level >= LEVEL:
            out.append(
                f"bootstrap: {self.replicates} resamples are too few for {self.level:.0%} intervals "
                f"(at least {MIN_REPLICATES}: --bootstrap {MIN_REPLICATES}); the bounds are rough"
            )
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
    seed: int = 0,
    restarts: int = 3,
    n_jobs: int | None = None,
    tol: float = 1e-8,
    max_iter: int = 1000,
    level: float = LEVEL,
    progress: Callable[[str, int, int], None] | None = None,
    weights: Mapping[str, np.ndarray] | None = None,
) -> Intervals:
    """Intervals at ``level`` for every cell (:func:`cell_tables`) of the fit ``params``, over ``replicates`` resamples.

    ``weights`` are passed to :func:`align` (the fit's expected events behind each row
    are a good choice).  Replicates run over ``n_jobs`` processes (default: all cores);
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
    children = np.random.SeedSequence([seed, 1]).spawn(replicates)
    w = {k: np.asarray(v, dtype=float) for k, v in (weights or {}).items()}
    jobs = [_Replicate(seqs, spec, params, w, ch, restarts, tol, max_iter, compiled) for ch in children]
    n_jobs = n_jobs or os.cpu_count() or 1
    results: dict[int, tuple[np.ndarray, bool]] = {}

    def done(i: int, res: tuple[np.ndarray, bool]) -> None:
        results[i] = res
        log.debug("bootstrap replicate %d done (%d of %d)", i, len(results), replicates)
        if progress is not None:
            progress("bootstrap", len(results), replicates)

    log.info(
        "bootstrap: %d replicates of %d participants over %d processes", replicates, seqs.n_participants, min(n_jobs, replicates)
    )
    if n_jobs <= 1 or replicates == 1:
        for i, job in enumerate(jobs):
            done(i, job.run())
    else:
        with ProcessPoolExecutor(max_workers=min(n_jobs, replicates)) as ex:
            futures = {ex.submit(job.run): i for i, job in enumerate(jobs)}
            for f in as_completed(futures):
                done(futures[f], f.result())
    flat = np.vstack([results[i][0] for i in range(replicates)])
    other = sum(results[i][1] for i in range(replicates))
    alpha = (1 - level) / 2
    lo, hi = np.quantile(flat, [alpha, 1 - alpha], axis=0)
    ref = cell_tables(spec, params)
    est = np.concatenate([ref[name].ravel() for name in TABLES])
    # outside by more than rounding: a cell on the stick-breaking boundary sits at 1e-12 times the
    # row's free mass, which differs between the estimate and a replicate in the 17th decimal
    widened = (est < lo - OUTSIDE) | (est > hi + OUTSIDE)
    lo, hi = np.minimum(lo, est), np.maximum(hi, est)
    intervals, wide, draws = {}, {}, {}
    pos = 0
    for name in TABLES:
        shape = ref[name].shape
        size = int(np.prod(shape))
        cut = slice(pos, pos + size)
        intervals[name] = (lo[cut].reshape(shape), hi[cut].reshape(shape))
        wide[name] = widened[cut].reshape(shape)
        draws[name] = flat[:, cut].reshape((replicates, *shape))
        pos += size
    if widened.any():
        log.info("bootstrap: %d cell interval(s) widened to contain the estimate", int(widened.sum()))
    return Intervals(intervals, replicates, level, wide, int(other), draws)
