"""Participant-bootstrap intervals of supervisor types (:func:`bootstrap_types`): each replicate
refits the mixture to resampled participants, its types matched to the estimate's."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from .bootstrap import BOUNDARY, cells_at_zero, few_resamples, replicate, resample
from .mixture import MixtureFit, fit_mixture, general_types
from .mixture_em import PARTS, MixtureParams
from .options import FitOptions
from .ratings import make_structure
from .sequences import Sequences
from .spec import FitError, IOHMMSpec
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
    at_zero: int = 0  # free cells estimated at 0 that stayed there in every resample

    def notes(self) -> list[str]:
        """Plain-language warnings about these intervals (empty when there is nothing to say)."""
        out = few_resamples(self.replicates, self.level)
        if self.at_zero:
            out.append(
                f"bootstrap: {self.at_zero} cells of the types estimated at 0 stayed there in every resample: their "
                "interval [0, 0] says only that no resample moved them, not that the value is known (a single "
                "model's fit, 'trustseek fit --bootstrap', bounds such cells by likelihood ratio)"
            )
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
    return TypeIntervals(cells, weights, replicates, level, _at_zero(fit, hi, per))


def _at_zero(fit: MixtureFit, hi: np.ndarray, per: int) -> int:
    """How many free cells of the types, estimated at 0, have the upper bound 0 (``hi``: every type's
    cells, ``per`` each, as :func:`_type_vectors` lays them out)."""
    structure = make_structure(fit.spec, fit.seqs)
    return sum(
        bool(np.all(hi[m * per + pos] < BOUNDARY))
        for m in range(fit.n_types)
        for *_, pos in cells_at_zero(structure, fit.spec, fit.params.type_params(m))
    )
