"""Supervisor types: a mixture of M trust IOHMMs, each participant one latent type (Remark 1).

Every type has the structure of the pooled model (the same inputs, fixed cells, ties and
rows no event reaches): trust models for the paper's inputs, general models
(``trustseek.iohmm/1``) for a study's named inputs, as the pooled fit (:func:`types_spec`);
a participant's whole sequence comes from one type.  The mixture
is written as M IOHMMs whose initial rows hold the joint P(type, S_1): type m's row sums to
its weight w_m.  The EM of the pooled fit then applies unchanged (:func:`~.em.run_em` with
SQUAREM, the L-BFGS-B finish and the stationarity check of :mod:`.convergence`): per
participant the forward pass of every type gives log P(sequence, type) and the type
responsibilities (log-sum-exp), and each type's backward pass adds its expected counts
weighted by the responsibility (one compiled pass, :meth:`~.kernels.Kernel.run_mixture`).
The M-step normalises the joint initial table over (type, level), so a type's weight is its
mean responsibility, and the other tables per type.  Parts named shared (``differ`` leaves
them out) pool their counts over the types and are one table for all.

With M = 1 every step is the pooled fit's, operation for operation: the same starts, the
same E-step sums, the same M-step; the result equals :func:`~.iohmm.fit_iohmm`'s.

**Naming the types.**  Within each type the levels are named by the spec's rule (one
order for all types when a part is shared, from the weight-averaged tables).  Types are
then ordered by their mean P(rely) (the spec's ``order_by`` category) over the free
emission rows the data reach and over the levels, lowest first: ``type1`` relies least
(the most conservative).  Ties (to 1e-9: e.g. shared emissions) are broken by P(T1 =
highest level), then by the mean probability of moving to or staying at the highest level
over the free transition rows the data reach, then by weight (largest first).

A type whose weight falls to zero (fewer than :data:`EMPTY` expected participants) is
*empty*: it is kept, reported in :attr:`MixtureFit.empty_types` and the warnings, and its
initial row (undefined at weight zero) is written uniform.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from ..model.core import TrustModel
from ..model.iohmm import IOHMMModel
from ..model.mixture import TypeMixture
from . import kernels
from .convergence import converge
from .em import STATIONARY, RunResult, run_em
from .estep import EStep, Workspace
from .fit import never_estimated
from .iohmm import FINISH_FTOL, FINISH_SWITCH, FitCriteria, fit_iohmm
from .sequences import Sequences, encode
from .spec import FitError, IOHMMSpec, Params
from .sticks import Sticks, _Part
from .structure import FLOOR, PROJECT_FLOOR, START_MIX, Structure
from .trust_iohmm import (
    PAPER_EMISSION_INPUTS,
    PAPER_TRANSITION_INPUTS,
    from_trust_model,
    general_spec,
    is_trust_structure,
    preset_spec,
    to_iohmm_model,
    to_trust_model,
)

log = logging.getLogger(__name__)

PARTS = ("initial", "emission", "transition")
EMPTY = 1e-3  # a type with fewer expected participants than this is empty
FINISH_MARGIN = 1.0  # with M >= 2, the starts ending this close to the best (nats) get the L-BFGS-B finish
PERTURB = 1.0  # perturbed pooled starts: every row's log-odds moved by a normal draw of this scale
TIE = 1e-9


def parse_differ(differ: str | Sequence[str]) -> tuple[str, ...]:
    """The parts that differ between types: ``"all"``, or a comma-separated list / sequence of
    ``initial``, ``emission``, ``transition`` (the others are shared)."""
    items = [s.strip() for s in differ.split(",")] if isinstance(differ, str) else [str(s).strip() for s in differ]
    items = [s for s in items if s]
    if items == ["all"]:
        return PARTS
    bad = [s for s in items if s not in PARTS]
    if bad or not items:
        raise FitError([f"differ: expected 'all' or some of {list(PARTS)}, got {differ!r}"])
    return tuple(p for p in PARTS if p in items)


class MixtureParams(Params):
    """The tables of M types: ``initial`` (M, K) the joint P(type, S_1), ``emission`` (M, Ue, K, X),
    ``transition`` (M, Ut, K, K); a batch of R mixtures carries a leading axis R on each."""

    @property
    def batched(self) -> bool:
        return self.initial.ndim == 3

    @property
    def weights(self) -> np.ndarray:
        """The types' weights, (M,) or (R, M)."""
        return self.initial.sum(-1)

    @classmethod
    def stack(cls, sets: Sequence[Params]) -> MixtureParams:
        return cls(
            np.stack([p.initial for p in sets]), np.stack([p.emission for p in sets]), np.stack([p.transition for p in sets])
        )

    def as_batch(self) -> MixtureParams:
        return MixtureParams(self.initial[None], self.emission[None], self.transition[None])

    def take(self, r: int) -> MixtureParams:
        return MixtureParams(self.initial[r].copy(), self.emission[r].copy(), self.transition[r].copy())

    def where(self, mask: np.ndarray, other: Params) -> MixtureParams:
        m2, m4 = mask[:, None, None], mask[:, None, None, None, None]
        return MixtureParams(
            np.where(m2, self.initial, other.initial),
            np.where(m4, self.emission, other.emission),
            np.where(m4, self.transition, other.transition),
        )

    def copy(self) -> MixtureParams:
        return MixtureParams(self.initial.copy(), self.emission.copy(), self.transition.copy())

    def vector(self) -> np.ndarray:
        lead = self.initial.shape[:-2]
        return np.concatenate([a.reshape(*lead, -1) for a in (self.initial, self.emission, self.transition)], axis=-1)

    def from_vector(self, x: np.ndarray) -> MixtureParams:
        p = super().from_vector(x)
        return MixtureParams(p.initial, p.emission, p.transition)

    def type_params(self, m: int) -> Params:
        """Type ``m`` as an ordinary IOHMM (its initial row normalised; uniform for an empty type)."""
        pi = self.initial[m]
        s = pi.sum()
        pi = pi / s if s > 0 else np.full(pi.shape, 1.0 / len(pi))
        return Params(pi, self.emission[m].copy(), self.transition[m].copy())

    def relabelled(self, types: np.ndarray, levels: Sequence[np.ndarray]) -> MixtureParams:
        """New type i is old type ``types[i]``, its levels permuted by ``levels[types[i]]``."""
        ini, em, tr = [], [], []
        for m in types:
            p = Params(self.initial[m], self.emission[m], self.transition[m]).permuted(levels[m])
            ini.append(p.initial)
            em.append(p.emission)
            tr.append(p.transition)
        return MixtureParams(np.stack(ini), np.stack(em), np.stack(tr))

    @classmethod
    def from_types(cls, weights: Sequence[float] | np.ndarray, types: Sequence[Params]) -> MixtureParams:
        w = np.asarray(weights, dtype=float)
        return cls(
            np.stack([wi * p.initial for wi, p in zip(w, types, strict=True)]),
            np.stack([p.emission for p in types]),
            np.stack([p.transition for p in types]),
        )


@dataclass
class MixtureEStep(EStep):
    """A mixture E-step: the mixture log-likelihood, per-type counts weighted by the type
    responsibilities (a type axis after the batch axis), and ``sequence`` (R, M, N):
    log P(participant n's trials, type m)."""

    sequence: np.ndarray | None = None

    def take(self, r: int) -> MixtureEStep:
        return MixtureEStep(self.loglik[r], self.initial[r], self.emission[r], self.transition[r], None, self._seq(r))

    def _seq(self, r: int) -> np.ndarray | None:
        return None if self.sequence is None else self.sequence[r]

    def where(self, mask: np.ndarray, other: EStep) -> MixtureEStep:
        m2, m4 = mask[:, None, None], mask[:, None, None, None, None]
        seq = None
        if self.sequence is not None and isinstance(other, MixtureEStep) and other.sequence is not None:
            seq = np.where(m2, self.sequence, other.sequence)
        return MixtureEStep(
            np.where(mask, self.loglik, other.loglik),
            np.where(m2, self.initial, other.initial),
            np.where(m4, self.emission, other.emission),
            np.where(m4, self.transition, other.transition),
            None,
            seq,
        )


class MixtureStructure(Structure):
    """The pooled structure compiled against the data, for M types of which ``differ`` parts differ."""

    def __init__(self, spec: IOHMMSpec, seqs: Sequences, M: int, differ: str | Sequence[str] = "all"):
        super().__init__(spec, seqs)
        if int(M) != M or M < 1:
            raise FitError([f"the number of types must be a positive integer, got {M!r}"])
        self.n_types = int(M)
        self.differ = parse_differ(differ)
        if self.n_types > 1 and not self.differ:
            raise FitError(["the types must differ in some part"])
        K = self.K
        self.base_free = self.n_free
        init = (self.n_types * K - 1) if "initial" in self.differ else (self.n_types - 1) + (K - 1)
        em = self.em.n_free() * (self.n_types if "emission" in self.differ else 1)
        tr = self.tr.n_free() * (self.n_types if "transition" in self.differ else 1)
        self.n_free = init + em + tr

    def shared(self, part: str) -> bool:
        return part not in self.differ

    def _share(self, p: MixtureParams) -> MixtureParams:
        """Shared parts set to type 0's (and a shared initial row to the weight-averaged one)."""
        ini, em, tr = p.initial, p.emission, p.transition
        if self.shared("initial") and self.n_types > 1:
            w = ini.sum(-1, keepdims=True)
            pi = ini.sum(-2, keepdims=True)
            ini = w * (pi / pi.sum(-1, keepdims=True))
        if self.shared("emission") and self.n_types > 1:
            em = np.broadcast_to(em[..., :1, :, :, :], em.shape).copy()
        if self.shared("transition") and self.n_types > 1:
            tr = np.broadcast_to(tr[..., :1, :, :, :], tr.shape).copy()
        return MixtureParams(ini, em, tr)

    def random(self, rng: np.random.Generator) -> MixtureParams:
        """Random types inside the constraints (M = 1: the pooled structure's random start, draw for draw)."""
        types = [super(MixtureStructure, self).random(rng) for _ in range(self.n_types)]
        w = np.ones(1) if self.n_types == 1 else (1 - START_MIX) * rng.dirichlet(np.ones(self.n_types)) + START_MIX / self.n_types
        return self._share(MixtureParams.from_types(w, types))

    def perturbed(self, pooled: Params, rng: np.random.Generator) -> MixtureParams:
        """M copies of ``pooled``, every row's log-odds moved by normal draws, random weights."""

        def jiggle(rows: np.ndarray) -> np.ndarray:
            x = np.maximum(rows, 1e-6) * np.exp(rng.normal(0.0, PERTURB, size=rows.shape))
            x = x / x.sum(-1, keepdims=True)
            return (1 - START_MIX) * x + START_MIX * rng.dirichlet(np.ones(rows.shape[-1]), size=rows.shape[:-1])

        types = [Params(jiggle(pooled.initial), jiggle(pooled.emission), jiggle(pooled.transition)) for _ in range(self.n_types)]
        w = (1 - START_MIX) * rng.dirichlet(np.ones(self.n_types)) + START_MIX / self.n_types
        return self.project(MixtureParams.from_types(w, types))

    def project(self, p: Params) -> MixtureParams:
        ini = np.clip(p.initial, PROJECT_FLOOR, None)
        ini = ini / ini.sum((-2, -1), keepdims=True)
        return self._share(MixtureParams(ini, self.em.project(p.emission), self.tr.project(p.transition)))

    def mstep(self, stats: EStep, previous: Params, prior: float | None = None) -> MixtureParams:
        """The maximising tables for the mixture's expected counts (``prior``: the spec's by default)."""
        a = self.spec.prior if prior is None else prior
        if self.shared("initial") and self.n_types > 1:
            c = stats.initial
            wc = c.sum(-1, keepdims=True) + a
            pc = c.sum(-2, keepdims=True) + a
            wt, pt = wc.sum(-2, keepdims=True), pc.sum(-1, keepdims=True)
            ok = (wt > 0) & (pt > 0)
            ini = np.where(ok, (wc / np.where(wt > 0, wt, 1.0)) * (pc / np.where(pt > 0, pt, 1.0)), previous.initial)
        else:
            c0 = stats.initial + a
            tot = c0.sum((-2, -1), keepdims=True)
            ini = np.where(tot > 0, c0 / np.where(tot > 0, tot, 1.0), previous.initial)
        em = self._table_mstep(self.em, stats.emission, a, previous.emission, self.shared("emission"))
        tr = self._table_mstep(self.tr, stats.transition, a, previous.transition, self.shared("transition"))
        return MixtureParams(ini, em, tr)

    def _table_mstep(self, table: Any, counts: np.ndarray, a: float, previous: np.ndarray, shared: bool) -> np.ndarray:
        if not shared or self.n_types == 1:
            return table.mstep(counts, a, previous)
        pooled = table.mstep(counts.sum(-4, keepdims=True), a, previous[..., :1, :, :, :])
        return np.broadcast_to(pooled, counts.shape).copy()

    def log_prior(self, p: Params) -> np.ndarray:
        a = self.spec.prior
        lead = p.initial.shape[:-2]
        if a == 0:
            return np.zeros(lead)
        out = a * np.log(np.maximum(p.initial, FLOOR)).sum((-2, -1))
        for table, arr, part in ((self.em, p.emission, "emission"), (self.tr, p.transition, "transition")):
            lp = table.log_prior(arr, a)  # (..., M)
            out = out + (lp[..., 0] if self.shared(part) else lp.sum(-1))
        return out

    def sticks(self) -> Sticks | None:
        """The free cells as stick-breaking fractions for the L-BFGS-B finish (None when the
        initial row is shared: the joint table is then a product, not one simplex)."""
        if self.shared("initial") and self.n_types > 1:
            return None
        base = Sticks(self)
        K, M = self.K, self.n_types
        parts: list[_Part] = []
        if M * K >= 2:
            idx = np.arange(M * K)
            parts.append(_Part("initial", 1, M * K, np.ones(1), idx, idx.copy()))
        for part in base.parts:
            if part.table == "initial":
                continue
            size = getattr(self, "em" if part.table == "emission" else "tr")
            cells = size.U * size.K * size.M
            if self.shared(part.table) and M > 1:
                dst = np.concatenate([part.dst + m * cells for m in range(M)])
                parts.append(_Part(part.table, part.rows, part.m, part.mass, dst, np.tile(part.src, M)))
            else:
                for m in range(M):
                    parts.append(_Part(part.table, part.rows, part.m, part.mass, part.dst + m * cells, part.src))
        base.parts = parts
        base.size = sum(q.rows * (q.m - 1) for q in parts)
        return base

    def relabel(self, p: MixtureParams) -> MixtureParams:
        """Levels named by the spec's rule, types ordered by the module's rule (see the module docstring)."""
        M = self.n_types
        if self.differ == PARTS or M == 1:
            levels = [Structure.order(self, p.type_params(m)) for m in range(M)]
        else:
            w = p.weights
            w = w / w.sum()
            avg = Params(
                (p.initial.sum(0) / p.initial.sum()),
                np.tensordot(w, p.emission, axes=(0, 0)),
                np.tensordot(w, p.transition, axes=(0, 0)),
            )
            levels = [Structure.order(self, avg)] * M
        q = p.relabelled(np.arange(M), levels)
        return q.relabelled(self.type_order(q), [np.arange(self.K)] * M)

    def type_order(self, p: MixtureParams) -> np.ndarray:
        """Types by mean P(order_by category) over the free reached emission rows, lowest first; ties
        by P(T1 = highest), mean P(T' = highest) over free reached transition rows, weight (largest first)."""
        M, K = self.n_types, self.K
        cat = 0
        if self.spec.order_by is not None:
            cat = self.spec.output_categories.index(self.spec.order_by[1])
        em_free = ~self.em.empty & ~np.all(self.em.fixed, axis=(-2, -1))
        tr_free = ~self.tr.empty & ~np.all(self.tr.fixed, axis=(-2, -1))
        rely = np.array([p.emission[m][em_free][:, :, cat].mean() if em_free.any() else 0.0 for m in range(M)])
        top = np.array([p.type_params(m).initial[-1] for m in range(M)])
        up = np.array([p.transition[m][tr_free][:, :, K - 1].mean() if tr_free.any() else 0.0 for m in range(M)])
        keys = (np.arange(M), -np.round(p.weights, 9), np.round(up, 9), np.round(top, 9), np.round(rely, 9))
        return np.lexsort(keys)


class MixtureWorkspace(Workspace):
    """The data's index arrays for the compiled mixture E-step (M types, any number of mixtures)."""

    def __init__(self, seqs: Sequences, structure: MixtureStructure, threads: int = 1):
        if not kernels.AVAILABLE:
            raise FitError(["the mixture fit needs the numba package"])
        super().__init__(seqs, *structure.dims, method="numba", threads=threads)
        self.n_types = structure.n_types

    def estep(self, p: Params, active: np.ndarray | None = None, posteriors: bool = False) -> MixtureEStep:
        if not isinstance(p, MixtureParams):  # the finish's points come as plain tables
            p = MixtureParams(p.initial, p.emission, p.transition)
        batch = p if p.batched else p.as_batch()
        R, M, K = batch.initial.shape
        flat = Params(
            batch.initial.reshape(R * M, K),
            batch.emission.reshape(R * M, *batch.emission.shape[2:]),
            batch.transition.reshape(R * M, *batch.transition.shape[2:]),
        )
        Bx, Ax = self.tables(flat)
        assert self._kernel is not None
        ll, ci, ce, ct, seq = self._kernel.run_mixture(flat.initial, Bx, Ax, M, active)
        em = ce[:, :, :-1].reshape(R, M, self.Ue, self.M, K).transpose(0, 1, 2, 4, 3)
        st = MixtureEStep(ll, ci, np.ascontiguousarray(em), np.ascontiguousarray(ct[:, :, :-1]), None, seq)
        return st if p.batched else st.take(0)

    def loglik(self, p: Params) -> np.ndarray:
        return self.estep(p).loglik

    def lockstep(self, n: int) -> int:
        return max(n, 1)


@dataclass
class MixtureFit(FitCriteria):
    """Result of :func:`fit_mixture`: ``params`` with the types in the stated order (``type1`` first)."""

    spec: IOHMMSpec
    structure: MixtureStructure
    seqs: Sequences
    params: MixtureParams
    loglik: float
    objective: float
    runs: list[RunResult]
    best: int
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

    def workspace(self) -> MixtureWorkspace:
        return MixtureWorkspace(self.seqs, self.structure)

    def type_posteriors(self) -> np.ndarray:
        """(N, M): P(type | all trials of the participant)."""
        return type_posteriors(self.workspace(), self.params)

    def posterior_frame(self) -> pd.DataFrame:
        """One row per participant: ``participant`` (the study's value), ``trials``, ``type`` (the most
        probable) and ``p_type_<name>`` per type."""
        return posterior_table(self.seqs, self.names, self.type_posteriors())

    def models(self) -> list[TrustModel] | list[IOHMMModel]:
        """The types as trust models, or as general models for a study's named inputs."""
        if general_types(self.spec):
            return [to_iohmm_model(self.spec, self.params.type_params(m)) for m in range(self.n_types)]
        models = [to_trust_model(self.spec, self.params.type_params(m)) for m in range(self.n_types)]
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
            "loglik": self.loglik,
            "n_params": self.n_params,
            "aic": self.aic,
            "bic": self.bic,
            "n_participants": self.seqs.n_participants,
            "n_trials": self.seqs.n_trials,
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


def posterior_table(seqs: Sequences, names: Sequence[str], post: np.ndarray) -> pd.DataFrame:
    out: dict[str, Any] = {"participant": list(seqs.participants), "trials": seqs.lengths.astype(np.int64)}
    out["type"] = np.array(names, dtype=object)[post.argmax(1)]
    for m, name in enumerate(names):
        out[f"p_type_{name}"] = post[:, m]
    return pd.DataFrame(out)


def _describe(i: int, r: RunResult) -> str:
    state = "converged: stationary" if r.ended == STATIONARY else f"not converged: {r.ended}"
    return f"start {i}: log-likelihood {r.loglik:.6f} after {r.iterations} E-steps ({state}, {r.seconds:.3f} s)"


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
    restarts: int = 10,
    seed: int | np.random.SeedSequence = 0,
    differ: str | Sequence[str] = "all",
    tol: float = 1e-8,
    max_iter: int = 1000,
    pooled: Params | None = None,
    init: Sequence[MixtureParams] = (),
    accelerate: bool = True,
    quasi_newton: bool = True,
    n_jobs: int | None = 1,
    on_restart: Callable[[int, RunResult], None] | None = None,
) -> MixtureFit:
    """Fit M = ``types`` supervisor types to ``seqs``; the best of the runs is kept.

    Starts: ``init``, then ``restarts`` seeded ones: with M >= 2 the first half are the
    pooled fit (``pooled``, or a pooled fit of 3 restarts made here) with every row
    perturbed (:meth:`MixtureStructure.perturbed`), the rest random (with M = 1 all random,
    the pooled fit's own draws).  With M = 1 each run is exactly the pooled fit's
    (:func:`~.iohmm.fit_iohmm`).  With M >= 2 every run is EM with SQUAREM to ``tol`` and the
    stationarity check (one more EM step gains at most ``tol``, relative); the runs that end
    within :data:`FINISH_MARGIN` nats of the best then get the L-BFGS-B finish and the check
    again (not when the initial row is shared): a type the data do not need lies on a flat
    ridge, where the finish of every run cost more E-steps than EM itself (measured in
    docs/types.md).  The objective never decreases along a run.
    """
    structure = MixtureStructure(spec, seqs, types, differ)
    work = MixtureWorkspace(seqs, structure, threads=n_jobs or os.cpu_count() or 1)
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    M = structure.n_types
    starts: list[MixtureParams] = [structure.project(p) for p in init]
    children = ss.spawn(restarts)
    n_perturbed = (restarts + 1) // 2 if M > 1 else 0
    if n_perturbed and pooled is None:
        pooled = fit_iohmm(seqs, spec, restarts=3, seed=ss.spawn(1)[0], tol=max(tol, 1e-6), max_iter=max_iter).params
    for i, s in enumerate(children):
        rng = np.random.default_rng(s)
        starts.append(structure.perturbed(pooled, rng) if i < n_perturbed and pooled is not None else structure.random(rng))
    if not starts:
        raise FitError(["at least one start is needed"])
    log.debug("fitting %d types to %d sequences from %d starts", M, seqs.n_participants, len(starts))
    sticks = structure.sticks() if quasi_newton else None
    qn = quasi_newton and sticks is not None
    runs: list[RunResult] = []
    if M == 1:  # the pooled fit's procedure, step for step
        em_tol = max(tol, FINISH_SWITCH) if qn else tol
        for r in run_em(structure, work, starts, tol=em_tol, max_iter=max_iter, accelerate=accelerate):
            runs.append(converge(structure, work, r, tol, max_iter, em_tol, tol * FINISH_FTOL, qn, accelerate, sticks))
    else:
        # every start: EM with SQUAREM to tol and the stationarity check; then the L-BFGS-B finish
        # (and the check again) only for the starts ending within FINISH_MARGIN of the best
        for r in run_em(structure, work, starts, tol=tol, max_iter=max_iter, accelerate=accelerate):
            runs.append(converge(structure, work, r, tol, max_iter, tol, tol * FINISH_FTOL, False, accelerate))
        if qn:
            top = max(r.objective for r in runs)
            for i, r in enumerate(runs):
                if r.objective >= top - FINISH_MARGIN and r.iterations < max_iter:
                    runs[i] = converge(structure, work, r, tol, max_iter, tol, tol * FINISH_FTOL, True, accelerate, sticks)
    for i, r in enumerate(runs):
        log.debug("%s", _describe(i, r))
        if on_restart is not None:
            on_restart(i, r)
    best = int(np.argmax([r.objective for r in runs]))
    p = structure.relabel(MixtureParams(runs[best].params.initial, runs[best].params.emission, runs[best].params.transition))
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
    capped = [i for i, r in enumerate(fit.runs) if r.ended != STATIONARY]
    if capped:
        out.append(f"{len(capped)} of {len(fit.runs)} starts stopped at the E-step cap before a stationary point")
    return out


def general_types(spec: IOHMMSpec) -> bool:
    """True when ``spec``'s types are general models (an input a trust model does not have)."""
    return not is_trust_structure(spec.transition_inputs, spec.emission_inputs)


def types_spec(
    frame: pd.DataFrame,
    preset: str | IOHMMSpec = "paper",
    prior: float = 0.0,
    transition_inputs: Sequence[str] = PAPER_TRANSITION_INPUTS,
    emission_inputs: Sequence[str] = PAPER_EMISSION_INPUTS,
    **spec_options: Any,
) -> IOHMMSpec:
    """The structure of every type, as the pooled fit's: the ``preset`` (a trust model) for the
    canonical inputs, :func:`~.trust_iohmm.general_spec` when an input is a study's own."""
    if isinstance(preset, IOHMMSpec) or is_trust_structure(transition_inputs, emission_inputs):
        return preset_spec(
            preset, frame, prior=prior, transition_inputs=transition_inputs, emission_inputs=emission_inputs, **spec_options
        )
    return general_spec(frame, emission_inputs, transition_inputs, spec_options.get("levels", ("low", "high")), prior)


def fit_types(
    frame: pd.DataFrame,
    types: int,
    preset: str | IOHMMSpec = "paper",
    restarts: int = 10,
    seed: int = 0,
    differ: str | Sequence[str] = "all",
    prior: float = 0.0,
    tol: float = 1e-8,
    max_iter: int = 1000,
    n_jobs: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    **spec_options: Any,
) -> MixtureFit:
    """Fit ``types`` supervisor types to a trial table (the structure as the pooled fit's, :func:`types_spec`)."""
    spec = types_spec(frame, preset, prior, **spec_options)
    seqs = encode(frame, spec)
    pooled = None
    if types > 1:
        first = fit_iohmm(
            seqs,
            spec,
            restarts=min(restarts, 3),
            seed=np.random.SeedSequence([seed, 5]),
            tol=tol,
            max_iter=max_iter,
            n_jobs=n_jobs,
        )
        pooled = first.params
    done = 0

    def tick(i: int, r: RunResult) -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, restarts)

    fit = fit_mixture(
        seqs,
        spec,
        types,
        restarts=restarts,
        seed=np.random.SeedSequence([seed, 0]),
        differ=differ,
        tol=tol,
        max_iter=max_iter,
        pooled=pooled,
        n_jobs=n_jobs,
        on_restart=tick,
    )
    fit.not_estimated = () if general_types(spec) else never_estimated(frame, spec)
    return fit


def mixture_params(mixture: TypeMixture) -> tuple[IOHMMSpec, MixtureParams]:
    """The types' spec (the paper's structure, or the general models' own) and the mixture's tables
    (for decoding and scoring)."""
    specs = [from_trust_model(m) for m in mixture.models]
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
    from .iohmm import posteriors

    spec, params = mixture_params(mixture)
    seqs = encode(frame, spec)
    structure = MixtureStructure(spec, seqs, mixture.n_types)
    post = type_posteriors(MixtureWorkspace(seqs, structure), params)  # (N, M)
    valid = seqs.rows >= 0
    tt, nn = np.nonzero(valid)
    order = np.argsort(seqs.rows[valid], kind="stable")
    tt, nn = tt[order], nn[order]
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
    out: dict[str, Any] = {"participant": [seqs.participants[i] for i in nn], "trial": seqs.trial_numbers(tt, nn)}
    for k, name in enumerate(spec.levels):
        out[f"p_trust_{name}"] = gamma[tt, nn, k]
    out["viterbi_trust"] = np.array(spec.levels, dtype=object)[path[tt, nn]]
    out["type"] = np.array(mixture.names, dtype=object)[best[nn]]
    for m, name in enumerate(mixture.names):
        out[f"p_type_{name}"] = post[nn, m]
    return pd.DataFrame(out)
