"""Participant-bootstrap intervals of supervisor types (:func:`bootstrap_types`): each replicate
refits the mixture to resampled participants, its types matched to the estimate's."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np
from scipy.optimize import linear_sum_assignment

from .bootstrap import (
    TABLES,
    bound_zero_cells,
    boundary_note,
    cell_tables,
    few_resamples,
    flat_cells,
    percentile_bounds,
    replicate,
    split_cells,
)
from .estep import EStep
from .mixture import MixtureFit, fit_mixture
from .mixture_em import MixtureParams, MixtureStructure
from .options import FitOptions
from .sequences import Sequences
from .spec import FitError, IOHMMSpec, Params

#: a types' bootstrap replicate's refit: from the estimate and 2 random starts, to a relative tolerance of 1e-6
TYPE_REFITS = FitOptions(restarts=2, tol=1e-6)


def _refit_types(
    spec: IOHMMSpec, types: int, differ: tuple[str, ...], params: MixtureParams, sample: Sequences, options: FitOptions
) -> np.ndarray:
    """The refitted types' cells and weights, types matched to the estimate's (Hungarian assignment
    on the squared distance of their cells)."""
    fit = fit_mixture(sample, spec, types, options, differ=differ, init=[params], pooled=params.type_params(0))
    ref, rep = _type_vectors(spec, params), _type_vectors(spec, fit.params)
    _, cols = linear_sum_assignment(((ref[:, None, :] - rep[None, :, :]) ** 2).sum(-1))
    return np.concatenate([rep[cols].ravel(), fit.weights[cols]])


def _type_vectors(spec: IOHMMSpec, params: MixtureParams) -> np.ndarray:
    """(M, cells): every type's model cells (:func:`~.bootstrap.cell_tables`), table after table."""
    return np.array([flat_cells(cell_tables(spec, params.type_params(m))) for m in range(params.initial.shape[0])])


@dataclass
class TypeIntervals:
    """Participant-bootstrap intervals of every type's model cells and weight: ``cells[name][table]
    = (lower, upper)`` and ``weights[name] = (lower, upper)``; percentile intervals of replicates whose
    types are matched to the estimate's, widened to contain the estimate (as :mod:`.bootstrap`)."""

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

    refit = partial(_refit_types, fit.spec, fit.n_types, fit.differ, fit.params)
    flat = np.vstack(replicate(refit, fit.seqs, replicates, options, done))
    est = np.concatenate([_type_vectors(fit.spec, fit.params).ravel(), fit.weights])
    lo, hi, _ = percentile_bounds(flat, est, level)
    M = fit.n_types
    per = (len(est) - M) // M
    lo, hi, at_boundary = _boundary_bounds(fit, lo, hi, per)
    ref = fit.models()[0]
    shapes = {t: np.shape(getattr(ref, t)) for t in TABLES}
    cells: dict[str, dict[str, tuple[np.ndarray, np.ndarray]]] = {}
    weights: dict[str, tuple[float, float]] = {}
    for m, name in enumerate(fit.names):
        los, his = split_cells(lo[m * per : (m + 1) * per], shapes), split_cells(hi[m * per : (m + 1) * per], shapes)
        cells[name] = {t: (los[t], his[t]) for t in TABLES}
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


def _hold_type(structure: MixtureStructure, table: str, which: int | slice, rows: np.ndarray, k: int, row: np.ndarray):
    return _HeldType(structure, "emission" if table == "em" else "transition", which, rows, k, row)


def _boundary_bounds(fit: MixtureFit, lo: np.ndarray, hi: np.ndarray, per: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Likelihood-ratio intervals (:func:`~.bootstrap.bound_zero_cells`, the mixture refitted by EM) for
    the types' cells (``per`` each in ``lo``, ``hi``, as :func:`_type_vectors` lays them out, the
    weights after them).  The new bounds, and how many cells got one."""
    types = [fit.params.type_params(m) for m in range(fit.n_types)]
    n = fit.n_types * per
    hold = partial(_hold_type, fit.structure)
    lo_c, hi_c, bounded, _ = bound_zero_cells(fit.structure, fit.workspace(), fit.spec, fit.params, types, lo[:n], hi[:n], hold)
    return np.concatenate([lo_c, lo[n:]]), np.concatenate([hi_c, hi[n:]]), int(bounded.sum())
