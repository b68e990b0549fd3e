"""Participant-bootstrap intervals of supervisor types (:func:`bootstrap_types`): each replicate
refits the mixture to resampled participants, its types matched to the estimate's."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from .bootstrap import (
    BOUNDARY,
    TABLE_NAMES,
    boundary_note,
    cell_positions,
    cell_tables,
    cells_at_zero,
    few_resamples,
    profile_bound,
    replicate,
    resample,
)
from .em import run_em
from .estep import EStep, Workspace
from .mixture import MixtureFit, fit_mixture, general_types
from .mixture_em import PARTS, MixtureParams, MixtureStructure
from .options import FitOptions
from .sequences import Sequences
from .spec import FitError, IOHMMSpec, Params
from .trust_iohmm import to_model

#: a types' bootstrap replicate's refit: from the estimate and 2 random starts, to a relative tolerance of 1e-6
TYPE_REFITS = FitOptions(restarts=2, tol=1e-6)


@dataclass(frozen=True)
class _TypeReplicate:
    """One bootstrap replicate of a mixture fit, sent whole to a worker process."""

    seqs: Sequences
    spec: IOHMMSpec
    types: int
    differ: tuple[str, ...]
    params: MixtureParams
    seed: np.random.SeedSequence
    options: FitOptions  # the refit's search (its seed: the replicate's)

    def run(self) -> np.ndarray:
        """The refitted types' TrustModel cells and weights, types matched to the estimate's."""
        sample, options = resample(self.seqs, self.seed, self.options)
        fit = fit_mixture(
            sample,
            self.spec,
            self.types,
            options,
            differ=self.differ,
            init=[self.params],
            pooled=self.params.type_params(0),
        )
        ref = _type_vectors(self.spec, self.params)
        rep = _type_vectors(self.spec, fit.params)
        cost = ((ref[:, None, :] - rep[None, :, :]) ** 2).sum(-1)
        _, cols = linear_sum_assignment(cost)
        return np.concatenate([rep[cols].ravel(), fit.weights[cols]])


def _type_vectors(spec: IOHMMSpec, params: MixtureParams) -> np.ndarray:
    """(M, cells): every type's model cells (a TrustModel's, or a general model's), table after table."""
    out = []
    for m in range(params.initial.shape[0]):
        tm = to_model(spec, params.type_params(m), general=general_types(spec))
        out.append(np.concatenate([np.asarray(getattr(tm, t), dtype=float).ravel() for t in PARTS]))
    return np.array(out)


@dataclass
class TypeIntervals:
    """Participant-bootstrap intervals of every type's TrustModel cells and weight: ``cells[name][table]
    = (lower, upper)`` and ``weights[name] = (lower, upper)``; percentile intervals of replicates whose
    types are matched to the estimate's (Hungarian assignment on the squared distance of their
    cells), widened to contain the estimate (as :mod:`.bootstrap`)."""

    cells: dict[str, dict[str, tuple[np.ndarray, np.ndarray]]]
    weights: dict[str, tuple[float, float]]
    replicates: int
    level: float
    boundary: int = 0  # cells with the likelihood-ratio interval at a boundary

    def notes(self) -> list[str]:
        """Plain-language warnings about these intervals (empty when there is nothing to say)."""
        out = few_resamples(self.replicates, self.level)
        if self.boundary:
            out.append(boundary_note(self.boundary, "cells of the types", "profile log-likelihood, the mixture refitted,"))
        return out


def bootstrap_types(
    fit: MixtureFit,
    replicates: int,
    options: FitOptions = TYPE_REFITS,
    level: float = 0.95,
    progress: Callable[[int, int], None] | None = None,
) -> TypeIntervals:
    """Intervals at ``level`` for the types of ``fit`` over ``replicates`` resamples of the participants;
    each replicate refits from the estimate and ``options.restarts`` seeded starts (:class:`~.options.FitOptions`).
    Replicate b uses the b-th child of ``options.seed``, whatever the number of processes
    (``options.n_jobs``, default all cores)."""
    if replicates < 1:
        raise FitError([f"the bootstrap needs at least one replicate, got {replicates}"])

    def done(_i: int, finished: int) -> None:
        if progress is not None:
            progress(finished, replicates)

    def job(seed: np.random.SeedSequence) -> _TypeReplicate:
        return _TypeReplicate(fit.seqs, fit.spec, fit.n_types, fit.differ, fit.params, seed, options)

    flat = np.vstack(replicate(job, replicates, options, done))
    est = np.concatenate([_type_vectors(fit.spec, fit.params).ravel(), fit.weights])
    a = (1 - level) / 2
    lo, hi = np.quantile(flat, [a, 1 - a], axis=0)
    lo, hi = np.minimum(lo, est), np.maximum(hi, est)
    M = fit.n_types
    per = (len(est) - M) // M
    lo, hi, at_boundary = _boundary_bounds(fit, lo, hi, per)
    ref = fit.models()[0]
    cells: dict[str, dict[str, tuple[np.ndarray, np.ndarray]]] = {}
    weights: dict[str, tuple[float, float]] = {}
    for m, name in enumerate(fit.names):
        pos = m * per
        cells[name] = {}
        for t in PARTS:
            shape = np.asarray(getattr(ref, t)).shape
            size = int(np.prod(shape))
            cells[name][t] = (lo[pos : pos + size].reshape(shape), hi[pos : pos + size].reshape(shape))
            pos += size
        weights[name] = (float(lo[M * per + m]), float(hi[M * per + m]))
    return TypeIntervals(cells, weights, replicates, level, at_boundary)


class _HeldType(MixtureStructure):
    """A mixture's structure whose EM keeps rows ``rows``, level ``k`` of table ``name`` of type ``m``
    (every type for a part they share: ``m`` a slice) at ``row``."""

    def __init__(self, base: MixtureStructure, name: str, m: int | slice, rows: np.ndarray, k: int, row: np.ndarray):
        self.__dict__.update(base.__dict__)
        self.held = (name, m, rows, k, row)

    def _hold(self, p: MixtureParams) -> MixtureParams:
        name, m, rows, k, row = self.held
        getattr(p, name)[..., m, rows, k, :] = row
        return p

    def mstep(self, stats: EStep, previous: Params, prior: float | None = None) -> MixtureParams:
        return self._hold(super().mstep(stats, previous, prior))

    def project(self, p: Params) -> MixtureParams:
        return self._hold(super().project(p))


def _refit(
    fit: MixtureFit, work: Workspace, name: str, which: int | slice, rows: np.ndarray, k: int
) -> Callable[[np.ndarray], float]:
    """The mixture's largest log-likelihood with rows ``rows``, level ``k`` of table ``name`` of type(s)
    ``which`` held at a row (EM from the estimate; ``-inf`` where the data are impossible)."""

    def refit(row: np.ndarray) -> float:
        held = _HeldType(fit.structure, name, which, rows, k, row)
        start = MixtureParams(fit.params.initial.copy(), fit.params.emission.copy(), fit.params.transition.copy())
        getattr(start, name)[which, rows, k] = row
        try:
            (r,) = run_em(held, work, [held.project(start)], tol=1e-5, max_iter=200)
        except FitError:  # the data impossible at this value
            return -np.inf
        return float(r.loglik)

    return refit


def _boundary_bounds(fit: MixtureFit, lo: np.ndarray, hi: np.ndarray, per: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Likelihood-ratio intervals (:func:`~.bootstrap.profile_bound`, the mixture refitted by EM) for
    the free cells of the types estimated at 0 whose bootstrap interval is [0, 0] (``lo``, ``hi``:
    every type's cells, ``per`` each, as :func:`_type_vectors` lays them out); a row's other cell, if it
    has just one, gets the mirror bound.  The new bounds, and how many cells got one."""
    structure, work = fit.structure, fit.workspace()
    top = float(np.sum(work.estep(fit.params).loglik))
    lo, hi, moved = lo.copy(), hi.copy(), 0
    for m in range(fit.n_types):
        ref = cell_tables(fit.spec, fit.params.type_params(m))
        for table, t, u, k, c, pos in cells_at_zero(structure, fit.spec, fit.params.type_params(m)):
            name = TABLE_NAMES[table]
            shared = structure.shared(name)
            if (shared and m > 0) or np.any(hi[m * per + pos] >= BOUNDARY):
                continue  # a shared cell is bounded once, with type 0's
            which: int | slice = slice(None) if shared else m
            rows = np.flatnonzero(t.group == t.group[u])

            refit = _refit(fit, work, name, which, rows, k)
            bound = profile_bound(getattr(fit.params, name)[m, u, k], c, top, refit)
            types = range(fit.n_types) if shared else (m,)
            mirror = cell_positions(fit.spec, ref, name, u, k, 1 - c)
            for mm in types:
                hi[mm * per + pos] = bound
                if t.M == 2:
                    lo[mm * per + mirror] = np.minimum(lo[mm * per + mirror], 1.0 - bound)
                moved += len(pos)
    return lo, hi, moved
