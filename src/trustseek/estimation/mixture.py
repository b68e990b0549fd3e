"""Supervisor types: a mixture of M trust IOHMMs, each participant one latent type (Remark 1).

Every type has the pooled model's structure (trust models for the paper's inputs, general models
for a study's named inputs, :func:`~.trust_iohmm.inputs_spec`); a participant's whole sequence comes
from one type.  The M IOHMMs' initial rows hold the joint P(type, S_1), so the pooled fit's EM
applies unchanged (:mod:`.mixture_em`); with M = 1 it is the pooled fit, operation for operation.
Within each type the levels are named by the spec's rule; the types are ordered by their mean
P(rely), lowest first (:meth:`~.mixture_em.MixtureStructure.type_order`).  A type of fewer than
:data:`~.mixture_em.EMPTY` expected participants is *empty*: kept, reported, its initial row uniform.
See docs/types.md.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any

import numpy as np
import pandas as pd

from ..model.core import TrustModel
from ..model.mixture import TypeMixture
from ..statistics import LEVEL, percentile_bounds
from .bootstrap import (
    TABLE_NAMES,
    bound_zero_cells,
    boundary_note,
    cell_tables,
    few_resamples,
    flat_cells,
    replicate,
    split_cells,
)
from .em import RunResult, converge_runs, run_em
from .estep import EStep
from .fit import never_estimated
from .iohmm import EMFit, describe_run, fit_iohmm, posteriors, trial_columns
from .mixture_em import EMPTY, FINISH_MARGIN, PERTURB, MixtureParams, MixtureStructure, MixtureWorkspace
from .options import DEFAULTS, SERIAL, FitOptions, counting
from .sequences import Sequences, encode
from .spec import TABLES, FitError, IOHMMSpec, Params
from .trust_iohmm import (
    from_model,
    inputs_spec,
    is_trust_structure,
    to_model,
)

log = logging.getLogger(__name__)


@dataclass
class MixtureFit(EMFit):
    """Result of :func:`fit_mixture`: the EM run, ``params`` with the types in the stated order
    (``type1`` first), and the types' names."""

    structure: MixtureStructure
    params: MixtureParams
    names: tuple[str, ...]
    warnings: list[str] = field(default_factory=list)
    not_estimated: tuple[tuple[str, tuple[int, ...]], ...] = ()  # TrustModel rows no trial informs (as the pooled fit)

    @property
    def n_types(self) -> int:
        return self.structure.n_types

    @property
    def differ(self) -> tuple[str, ...]:
        return self.structure.differ

    @property
    def weights(self) -> np.ndarray:
        return self.params.weights

    @property
    def empty_types(self) -> list[str]:
        n = self.seqs.n_participants
        return [name for name, w in zip(self.names, self.weights, strict=True) if w * n < EMPTY]

    def workspace(self, seqs: Sequences | None = None) -> MixtureWorkspace:
        return MixtureWorkspace(self.seqs if seqs is None else seqs, self.structure)

    def type_posteriors(self) -> np.ndarray:
        """(N, M): P(type | all trials of the participant)."""
        return type_posteriors(self.workspace(), self.params)

    def posterior_frame(self) -> pd.DataFrame:
        """One row per participant: ``participant`` (the study's value), ``trials``, ``type`` (the most
        probable) and ``p_type_<name>`` per type."""
        post = self.type_posteriors()
        out: dict[str, Any] = {"participant": list(self.seqs.participants), "trials": self.seqs.lengths.astype(np.int64)}
        out["type"] = np.array(self.names, dtype=object)[post.argmax(1)]
        return pd.DataFrame(out | {f"p_type_{name}": post[:, m] for m, name in enumerate(self.names)})

    def models(self) -> list[TrustModel]:
        """The types as trust models, or as general models for a study's named inputs."""
        general = general_types(self.spec)
        models = [to_model(self.spec, self.params.type_params(m), general=general) for m in range(self.n_types)]
        return [m.replace(not_estimated=self.not_estimated) for m in models] if self.not_estimated else models

    def mixture(self, notes: str = "") -> TypeMixture:
        """The types as a :class:`~trustseek.model.mixture.TypeMixture` (JSON ``trustseek.mixture/1``)."""
        w = np.clip(self.weights, 0.0, None)
        note = notes or (
            f"fitted by trustseek: {self.n_types} types ({', '.join(self.differ)} differ), {self.seqs.n_participants} "
            f"participants, {self.seqs.n_trials} trials, log-likelihood {self.loglik:.4f}"
        )
        return TypeMixture(self.names, w / w.sum(), tuple(self.models()), note)

    def to_dict(self) -> dict[str, Any]:
        return {
            "types": self.n_types,
            "names": list(self.names),
            "weights": self.weights.tolist(),
            "differ": list(self.differ),
            **self.figures(),
            "restart_logliks": self.restart_logliks,
            "best_restart": self.best,
            "iterations": [r.iterations for r in self.runs],
            "ended": [r.ended for r in self.runs],
            "empty_types": self.empty_types,
            "warnings": list(self.warnings),
        }


def type_posteriors(work: MixtureWorkspace, params: MixtureParams) -> np.ndarray:
    """(N, M): P(type | all trials of the participant) from log P(trials, type)."""
    st = work.estep(params)
    assert st.sequence is not None
    s = st.sequence.T  # (N, M)
    top = s.max(1, keepdims=True)
    if not np.all(np.isfinite(top)):
        raise FitError(["some participant's trials have probability zero under every type"])
    e = np.exp(s - top)
    return e / e.sum(1, keepdims=True)


def split_type_starts(previous: MixtureParams, rng: np.random.Generator, structure: MixtureStructure) -> list[MixtureParams]:
    """Starts with one type more than ``previous``: each type copied, the two copies' rows pushed
    apart (log-odds +/- a normal draw) and its weight shared at random."""
    M0 = previous.initial.shape[0]
    out = []
    for j in range(M0):
        f = rng.uniform(0.3, 0.7)
        ini = np.concatenate([previous.initial, previous.initial[j : j + 1] * (1 - f)])
        ini[j] *= f

        def push(a: np.ndarray, j: int = j) -> np.ndarray:
            x = np.maximum(a[j], 1e-6) * np.exp(rng.normal(0.0, PERTURB / 2, size=a[j].shape))
            y = np.maximum(a[j], 1e-6) ** 2 / x
            return np.concatenate([a[:j], (x / x.sum(-1, keepdims=True))[None], a[j + 1 :], (y / y.sum(-1, keepdims=True))[None]])

        out.append(structure.project(MixtureParams(ini, push(previous.emission), push(previous.transition))))
    return out


def fit_mixture(
    seqs: Sequences,
    spec: IOHMMSpec,
    types: int,
    options: FitOptions = SERIAL,
    differ: str | Sequence[str] = "all",
    pooled: Params | None = None,
    init: Sequence[MixtureParams] = (),
    on_restart: Callable[[int, RunResult], None] | None = None,
) -> MixtureFit:
    """Fit M = ``types`` supervisor types to ``seqs``; the best of the runs is kept.  Starts: ``init``, then
    ``options.restarts`` seeded ones: with M >= 2 the first half the pooled fit (``pooled``, or one of 3
    restarts made here) perturbed (:meth:`MixtureStructure.perturbed`), the rest random.  With M = 1 each
    run is exactly :func:`~.iohmm.fit_iohmm`'s; with M >= 2 EM with SQUAREM to ``tol`` and the stationarity
    check, then the L-BFGS-B finish only for the runs ending within :data:`FINISH_MARGIN` nats of the best
    (a type the data do not need lies on a flat ridge where finishing every run costs more: docs/types.md)."""
    structure = MixtureStructure(spec, seqs, types, differ)
    restarts, tol, max_iter = options.starts, options.tol, options.max_iter
    sticks = structure.sticks()
    settings = options.run(sticks is not None and structure.n_types == 1)  # with M >= 2 EM runs to tol, the finish later
    work = MixtureWorkspace(seqs, structure, threads=settings.threads)
    ss = options.seed_sequence
    M = structure.n_types
    starts: list[MixtureParams] = [structure.project(p) for p in init]
    children = ss.spawn(restarts)
    n_perturbed = (restarts + 1) // 2 if M > 1 else 0
    if n_perturbed and pooled is None:
        pooled = fit_iohmm(
            seqs, spec, FitOptions(restarts=3, seed=ss.spawn(1)[0], tol=max(tol, 1e-6), max_iter=max_iter, n_jobs=1)
        ).params
    for i, s in enumerate(children):
        rng = np.random.default_rng(s)
        starts.append(structure.perturbed(pooled, rng) if i < n_perturbed and pooled is not None else structure.random(rng))
    if not starts:
        raise FitError(["at least one start is needed"])
    log.debug("fitting %d types to %d sequences from %d starts", M, seqs.n_participants, len(starts))
    runs: list[RunResult] = []
    if M == 1:  # the pooled fit's procedure, step for step
        runs += converge_runs(structure, work, run_em(structure, work, starts, settings.em_tol, max_iter), settings, sticks)
    else:
        # every start: EM with SQUAREM to tol and the stationarity check; then the L-BFGS-B finish
        # (and the check again) only for the starts ending within FINISH_MARGIN of the best
        runs += converge_runs(structure, work, run_em(structure, work, starts, tol, max_iter), settings)
        if sticks is not None:
            top = max(r.objective for r in runs)
            near = [i for i, r in enumerate(runs) if r.objective >= top - FINISH_MARGIN and r.iterations < max_iter]
            done = converge_runs(structure, work, [runs[i] for i in near], replace(settings, quasi_newton=True), sticks)
            for i, r in zip(near, done, strict=True):
                runs[i] = r
    for i, r in enumerate(runs):
        log.debug("%s", describe_run(i, r))
        if on_restart is not None:
            on_restart(i, r)
    best = int(np.argmax([r.objective for r in runs]))
    p = structure.relabel(work.as_own(runs[best].params))
    names = tuple(f"type{m + 1}" for m in range(M))
    fit = MixtureFit(spec, structure, seqs, p, runs[best].loglik, runs[best].objective, runs, best, names)
    fit.warnings = mixture_warnings(fit)
    for w in fit.warnings:
        log.info("%s", w)
    return fit


def mixture_warnings(fit: MixtureFit) -> list[str]:
    out = []
    n = fit.seqs.n_participants
    for name, w in zip(fit.names, fit.weights, strict=True):
        if w * n < EMPTY:
            out.append(f"{name} is empty ({w * n:.2g} expected participants): fewer types fit these data as well")
    return out + fit.cap_warnings()


def general_types(spec: IOHMMSpec) -> bool:
    """True when ``spec``'s types are general models (an input a trust model does not have)."""
    return not is_trust_structure(spec.transition_inputs, spec.emission_inputs)


def fit_types(
    frame: pd.DataFrame,
    types: int,
    preset: str | IOHMMSpec = "paper",
    options: FitOptions = DEFAULTS,
    differ: str | Sequence[str] = "all",
    prior: float = 0.0,
    progress: Callable[[int, int], None] | None = None,
    **spec_options: Any,
) -> MixtureFit:
    """Fit ``types`` supervisor types to a trial table (the structure as the pooled fit's, :func:`~.trust_iohmm.inputs_spec`),
    searched as ``options`` say (:class:`~.options.FitOptions`)."""
    restarts, seed = options.starts, options.seed_number
    spec = inputs_spec(frame, preset, prior, **spec_options)
    seqs = encode(frame, spec)
    check_types(types, seqs)
    pooled = None
    if types > 1:
        pooled = fit_iohmm(seqs, spec, replace(options, restarts=min(restarts, 3), seed=np.random.SeedSequence([seed, 5]))).params
    options = replace(options, seed=np.random.SeedSequence([seed, 0]))
    fit = fit_mixture(seqs, spec, types, options, differ=differ, pooled=pooled, on_restart=counting(progress, restarts))
    fit.not_estimated = () if general_types(spec) else never_estimated(frame, spec)
    return fit


def check_types(types: int, seqs: Sequences) -> None:
    """Refuse more types than participants: each participant is one type, so the rest would be empty."""
    if types > seqs.n_participants:
        raise FitError(
            [f"types (--types) must be at most the log's {seqs.n_participants} participants (each participant is one type), "
             f"got {types}"]
        )  # fmt: skip


def mixture_params(mixture: TypeMixture) -> tuple[IOHMMSpec, MixtureParams]:
    """The types' spec (the paper's structure, or the general models' own) and the mixture's tables
    (for decoding and scoring)."""
    specs = [from_model(m) for m in mixture.models]
    spec = specs[0][0]
    return spec, MixtureParams.from_types(mixture.weights, [p for _, p in specs])


def mixture_loglik(seqs: Sequences, mixture: TypeMixture) -> float:
    """The mixture log-likelihood sum_n log sum_m w_m P(trials of n | type m)."""
    spec, params = mixture_params(mixture)
    structure = MixtureStructure(spec, seqs, mixture.n_types)
    with np.errstate(divide="ignore"):
        return float(MixtureWorkspace(seqs, structure).loglik(params))


def decode_types(frame: pd.DataFrame, mixture: TypeMixture) -> pd.DataFrame:
    """Per trial: P(type | the participant's trials) as ``p_type_<name>``, the most probable ``type``, and
    P(trust | trials) = sum_m P(type m | trials) P(trust | trials, type m), with the Viterbi path of the
    most probable type."""
    spec, params = mixture_params(mixture)
    seqs = encode(frame, spec)
    structure = MixtureStructure(spec, seqs, mixture.n_types)
    post = type_posteriors(MixtureWorkspace(seqs, structure), params)  # (N, M)
    gamma = np.zeros((*seqs.rows.shape, spec.n_levels))
    best = post.argmax(1)
    path = np.full(seqs.rows.shape, -1, dtype=np.int64)
    for m in range(mixture.n_types):
        if not (post[:, m] > 0).any():
            continue
        keep = np.flatnonzero(post[:, m] > 0)
        sub = seqs.subset(keep)
        g, vpath, _ = posteriors(sub, spec, params.type_params(m))
        T = g.shape[0]
        gamma[:T, keep] += post[keep, m][None, :, None] * g
        mine = best[keep] == m
        path[:T, keep[mine]] = vpath[:, mine]
    out, nn = trial_columns(seqs, spec.levels, gamma, path)
    out["type"] = np.array(mixture.names, dtype=object)[best[nn]]
    for m, name in enumerate(mixture.names):
        out[f"p_type_{name}"] = post[nn, m]
    return pd.DataFrame(out)


#: a types' bootstrap replicate's refit: from the estimate and 2 random starts, to a relative tolerance of 1e-6
TYPE_REFITS = FitOptions(restarts=2, tol=1e-6)


def _refit_types(
    spec: IOHMMSpec, types: int, differ: tuple[str, ...], params: MixtureParams, sample: Sequences, options: FitOptions
) -> np.ndarray:
    """The refitted types' cells and weights, types matched to the estimate's (Hungarian assignment
    on the squared distance of their cells)."""
    from scipy.optimize import linear_sum_assignment

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
    types are matched to the estimate's, widened to contain the estimate (as :class:`~.bootstrap.Intervals`)."""

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
    level: float = LEVEL,
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
    lo, hi, at_boundary = _type_boundary_bounds(fit, lo, hi, per)
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
    """A mixture's structure whose EM keeps rows ``rows``, level ``k`` of ``table`` (``em`` or ``tr``) of
    type ``m`` (every type for a part they share: ``m`` a slice) at ``row``."""

    def __init__(self, base: MixtureStructure, table: str, m: int | slice, rows: np.ndarray, k: int, row: np.ndarray):
        self.__dict__.update(base.__dict__)
        self.held = (TABLE_NAMES[table], m, rows, k, row)

    def _hold(self, p: MixtureParams) -> MixtureParams:
        name, m, rows, k, row = self.held
        getattr(p, name)[..., m, rows, k, :] = row
        return p

    def mstep(self, stats: EStep, previous: Params, prior: float | None = None) -> MixtureParams:
        return self._hold(super().mstep(stats, previous, prior))

    def project(self, p: Params) -> MixtureParams:
        return self._hold(super().project(p))


def _type_boundary_bounds(fit: MixtureFit, lo: np.ndarray, hi: np.ndarray, per: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Likelihood-ratio intervals (:func:`~.bootstrap.bound_zero_cells`, the mixture refitted by EM) for
    the types' cells (``per`` each in ``lo``, ``hi``, as :func:`_type_vectors` lays them out, the
    weights after them).  The new bounds, and how many cells got one."""
    types = [fit.params.type_params(m) for m in range(fit.n_types)]
    n = fit.n_types * per
    hold = partial(_HeldType, fit.structure)
    lo_c, hi_c, bounded, _ = bound_zero_cells(fit.structure, fit.workspace(), fit.spec, fit.params, types, lo[:n], hi[:n], hold)
    return np.concatenate([lo_c, lo[n:]]), np.concatenate([hi_c, hi[n:]]), int(bounded.sum())
