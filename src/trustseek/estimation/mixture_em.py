"""The EM components of supervisor types (:mod:`.mixture`): the types' tables (:class:`MixtureParams`),
the E-step over types (:class:`MixtureEStep`), the structure that normalises the joint initial table
over (type, level) and pools the shared parts (:class:`MixtureStructure`), and the compiled
workspace (:class:`MixtureWorkspace`).  With M = 1 each is the pooled fit's, operation for operation."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from .estep import EStep, Workspace
from .sequences import Sequences
from .spec import TABLES, FitError, IOHMMSpec, Params
from .sticks import Sticks, _Part
from .structure import FLOOR, PROJECT_FLOOR, START_MIX, Structure, mixed, normalised, random_rows

EMPTY = 1e-3  # a type with fewer expected participants than this is empty
FINISH_MARGIN = 1.0  # with M >= 2, the starts ending this close to the best (nats) get the L-BFGS-B finish
PERTURB = 1.0  # perturbed pooled starts: every row's log-odds moved by a normal draw of this scale


def parse_differ(differ: str | Sequence[str]) -> tuple[str, ...]:
    """The parts that differ between types: ``"all"``, or a comma-separated list / sequence of
    ``initial``, ``emission``, ``transition`` (the others are shared)."""
    items = [s.strip() for s in differ.split(",")] if isinstance(differ, str) else [str(s).strip() for s in differ]
    items = [s for s in items if s]
    if items == ["all"]:
        return TABLES
    bad = [s for s in items if s not in TABLES]
    if bad or not items:
        raise FitError([f"differ: expected 'all' or some of {list(TABLES)}, got {differ!r}"])
    return tuple(p for p in TABLES if p in items)


class MixtureParams(Params):
    """The tables of M types: ``initial`` (M, K) the joint P(type, S_1), ``emission`` (M, Ue, K, X),
    ``transition`` (M, Ut, K, K); a batch of R mixtures carries a leading axis R on each."""

    OWN: ClassVar[int] = 2

    @property
    def weights(self) -> np.ndarray:
        """The types' weights, (M,) or (R, M)."""
        return self.initial.sum(-1)

    def type_params(self, m: int) -> Params:
        """Type ``m`` as an ordinary IOHMM (its initial row normalised; uniform for an empty type)."""
        pi = self.initial[m]
        s = pi.sum()
        pi = pi / s if s > 0 else np.full(pi.shape, 1.0 / len(pi))
        return Params(pi, self.emission[m].copy(), self.transition[m].copy())

    def relabelled(self, types: np.ndarray, levels: Sequence[np.ndarray]) -> MixtureParams:
        """New type i is old type ``types[i]``, its levels permuted by ``levels[types[i]]``."""
        return MixtureParams.stack(
            [Params(self.initial[m], self.emission[m], self.transition[m]).permuted(levels[m]) for m in types]
        )

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

    def take(self, r: int | slice) -> MixtureEStep:
        seq = None if self.sequence is None else self.sequence[r]
        return MixtureEStep(self.loglik[r], self.initial[r], self.emission[r], self.transition[r], None, seq)

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
        w = np.ones(1) if self.n_types == 1 else random_rows(rng, self.n_types)
        return self._share(MixtureParams.from_types(w, types))

    def perturbed(self, pooled: Params, rng: np.random.Generator) -> MixtureParams:
        """M copies of ``pooled``, every row's log-odds moved by normal draws, random weights."""

        def jiggle(rows: np.ndarray) -> np.ndarray:
            return mixed(np.maximum(rows, 1e-6) * np.exp(rng.normal(0.0, PERTURB, size=rows.shape)), rng, START_MIX)

        types = [Params(jiggle(pooled.initial), jiggle(pooled.emission), jiggle(pooled.transition)) for _ in range(self.n_types)]
        w = random_rows(rng, self.n_types)
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
            ini = normalised(stats.initial + a, previous.initial, (-2, -1))
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
        if self.differ == TABLES or M == 1:
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
        em_free, tr_free = self.em.estimated().any(-1), self.tr.estimated().any(-1)
        rely = np.array([p.emission[m][em_free][:, :, cat].mean() if em_free.any() else 0.0 for m in range(M)])
        top = np.array([p.type_params(m).initial[-1] for m in range(M)])
        up = np.array([p.transition[m][tr_free][:, :, K - 1].mean() if tr_free.any() else 0.0 for m in range(M)])
        keys = (np.arange(M), -np.round(p.weights, 9), np.round(up, 9), np.round(top, 9), np.round(rely, 9))
        return np.lexsort(keys)


class MixtureWorkspace(Workspace):
    """The data's index arrays for the compiled mixture E-step (M types, any number of mixtures)."""

    def __init__(self, seqs: Sequences, structure: MixtureStructure, threads: int = 1):
        super().__init__(seqs, *structure.dims, method="compiled", threads=threads)
        self.n_types = structure.n_types

    def as_own(self, p: Params) -> MixtureParams:
        """The finish's points come as plain tables."""
        return p if isinstance(p, MixtureParams) else MixtureParams(p.initial, p.emission, p.transition)

    def estep(self, p: Params, active: np.ndarray | None = None, posteriors: bool = False) -> MixtureEStep:
        p = self.as_own(p)
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
