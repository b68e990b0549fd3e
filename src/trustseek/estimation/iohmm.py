"""A discrete input-output hidden Markov model (IOHMM) and its extended Baum-Welch fit.

The model (Bengio & Frasconi 1996, as used in Section II of the paper) has K hidden
levels, one discrete output column and discrete input columns:

* ``initial[k]``            P(S_1 = k)
* ``emission[u, k, y]``     P(y_t = y | S_t = k, emission inputs of trial t = u)
* ``transition[u, k, j]``   P(S_{t+1} = j | S_t = k, transition inputs of trial t = u)

``u`` is the combination of the named input columns (C-order over the columns as
listed in the spec).  The transition from trial t to t+1 uses the inputs recorded
in row t, so a variable known only after the trial (the paper's experience E_{t+1})
is simply a column of row t.

Structure (:class:`IOHMMSpec`): fixed rows (e.g. P(intervene | ask) = 1), rows tied
across input combinations, Dirichlet pseudo-counts ``prior`` (MAP), and rows that
no data event reaches: transitions default to the identity (the level does not
change), emissions to uniform; such rows are not estimated.

The fit is scaled forward-backward with the expected counts accumulated in the
same pass (compiled, :mod:`trustseek.forward_backward`; the numpy version --
sequences padded into time-major arrays, a Python loop over time only, counts
gathered with ``np.bincount`` -- is the reference and the fallback), an M-step
in closed form, SQUAREM acceleration that falls back to the plain EM step
whenever the extrapolated point does not improve, and a quasi-Newton finish
(:func:`finish`, L-BFGS-B) for the flat ridges where EM crawls.  The objective
(log-likelihood plus log-prior) never decreases.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np
import pandas as pd
from scipy.optimize import minimize

from . import kernels as _fb
from ..errors import TrustseekError

SCAN_RATIO = 20  # sequences at least this many times longer than their number: E-step by prefix products
BATCH_MAX_COLUMNS = 1000  # restarts x participants up to this: restarts run batched in lockstep
MIN_EVENTS = 5  # fewer expected events than this behind a row: "not identified by this data"
_FLOOR = 1e-300
_add = np.add.reduce  # the ufunc method directly: the time loop is call-overhead bound
_FINISH_SWITCH = 1e-5  # EM hands over to the L-BFGS-B finish at this relative change (or the fit's tol if looser)
_FINISH_FTOL = 0.01  # the finish stops at this fraction of the fit's relative tolerance
_SHRINK = 0.05  # SQUAREM: a cell may shrink at most this factor per extrapolation


class FitError(TrustseekError, ValueError):
    """The data and the model structure do not fit together (e.g. an event a fixed cell forbids)."""


# --------------------------------------------------------------------------- specification


@dataclass(frozen=True)
class Fixed:
    """Rows fixed to given values for every hidden level.

    ``where`` selects input combinations by column value (``{}`` = all).  ``probs``
    maps output categories to probabilities (emissions) or is ``"identity"``
    (transitions: the level does not change).
    """

    where: Mapping[str, str]
    probs: Mapping[str, float] | str


@dataclass(frozen=True)
class IOHMMSpec:
    """Structure of a discrete IOHMM: levels, output, inputs and constraints."""

    levels: tuple[str, ...]
    output: str
    output_categories: tuple[str, ...]
    emission_inputs: tuple[str, ...] = ()
    transition_inputs: tuple[str, ...] = ()
    categories: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    fixed_emissions: tuple[Fixed, ...] = ()
    fixed_transitions: tuple[Fixed, ...] = ()
    tied_emissions: tuple[tuple[Mapping[str, str], ...], ...] = ()
    tied_transitions: tuple[tuple[Mapping[str, str], ...], ...] = ()
    order_by: tuple[Mapping[str, str], str] | None = None
    prior: float = 0.0

    @property
    def n_levels(self) -> int:
        return len(self.levels)

    def problems(self) -> list[str]:
        p: list[str] = []
        if len(self.levels) < 1 or len(set(self.levels)) != len(self.levels):
            p.append(f"levels must be distinct names, got {list(self.levels)}")
        if len(self.output_categories) < 2:
            p.append(f"the output {self.output!r} needs at least 2 categories")
        for col in (*self.emission_inputs, *self.transition_inputs):
            if col not in self.categories or len(self.categories[col]) < 1:
                p.append(f"input column {col!r} has no categories")
        for name, cols in (("emission", self.emission_inputs), ("transition", self.transition_inputs)):
            if len(set(cols)) != len(cols):
                p.append(f"{name} inputs repeat a column: {list(cols)}")
            if self.output in cols:
                p.append(f"the output {self.output!r} cannot also be a {name} input")
        if not (math.isfinite(self.prior) and self.prior >= 0):
            p.append(f"prior must be a finite pseudo-count >= 0, got {self.prior!r}")
        return p

    def with_levels(self, levels: Sequence[str]) -> "IOHMMSpec":
        from dataclasses import replace

        return replace(self, levels=tuple(levels))

    def to_dict(self) -> dict[str, Any]:
        return {
            "levels": list(self.levels),
            "output": self.output,
            "output_categories": list(self.output_categories),
            "emission_inputs": list(self.emission_inputs),
            "transition_inputs": list(self.transition_inputs),
            "categories": {k: list(v) for k, v in self.categories.items()},
            "fixed_emissions": [{"where": dict(f.where), "probs": f.probs if isinstance(f.probs, str) else dict(f.probs)} for f in self.fixed_emissions],
            "fixed_transitions": [{"where": dict(f.where), "probs": f.probs if isinstance(f.probs, str) else dict(f.probs)} for f in self.fixed_transitions],
            "tied_emissions": [[dict(w) for w in g] for g in self.tied_emissions],
            "tied_transitions": [[dict(w) for w in g] for g in self.tied_transitions],
            "order_by": None if self.order_by is None else {"where": dict(self.order_by[0]), "category": self.order_by[1]},
            "prior": self.prior,
        }


@dataclass
class Params:
    """IOHMM parameters: ``initial`` (K,), ``emission`` (U_e, K, M), ``transition`` (U_t, K, K)."""

    initial: np.ndarray
    emission: np.ndarray
    transition: np.ndarray

    def copy(self) -> "Params":
        return Params(self.initial.copy(), self.emission.copy(), self.transition.copy())

    def vector(self) -> np.ndarray:
        return np.concatenate([self.initial.ravel(), self.emission.ravel(), self.transition.ravel()])

    def permuted(self, perm: np.ndarray) -> "Params":
        return Params(self.initial[perm], self.emission[:, perm], self.transition[:, perm][:, :, perm])


# --------------------------------------------------------------------------- data


@dataclass
class Sequences:
    """Trials encoded as padded, time-major integer arrays (built by :func:`encode`)."""

    participants: list[str]
    lengths: np.ndarray  # (N,)
    y: np.ndarray  # (T, N) output code, -1 = unobserved or padding
    ue: np.ndarray  # (T, N) emission-input combination, -1 = padding
    ut: np.ndarray  # (T, N) transition-input combination of row t (t -> t+1), -1 = padding
    rows: np.ndarray  # (T, N) index of the source row in the frame, -1 = padding
    n_rows: int

    @property
    def n_participants(self) -> int:
        return len(self.participants)

    @property
    def n_trials(self) -> int:
        return int(self.lengths.sum())

    @property
    def n_observed(self) -> int:
        return int((self.y >= 0).sum())

    def subset(self, idx: np.ndarray) -> "Sequences":
        """Sequences ``idx`` (repeats allowed: the bootstrap resamples participants)."""
        idx = np.asarray(idx)
        T = int(self.lengths[idx].max()) if len(idx) else 1
        return Sequences(
            [self.participants[i] for i in idx],
            self.lengths[idx],
            np.ascontiguousarray(self.y[:T, idx]),
            np.ascontiguousarray(self.ue[:T, idx]),
            np.ascontiguousarray(self.ut[:T, idx]),
            np.ascontiguousarray(self.rows[:T, idx]),
            self.n_rows,
        )


def _combo(codes: list[np.ndarray], sizes: list[int], n: int) -> np.ndarray:
    if not codes:
        return np.zeros(n, dtype=np.int64)
    return np.ravel_multi_index(tuple(codes), tuple(sizes)).astype(np.int64)


def encode(frame: pd.DataFrame, spec: IOHMMSpec, participant: str = "participant", trial: str = "trial") -> Sequences:
    """Encode a validated trial table (one row per trial) for ``spec``.

    Participants keep their order of first appearance; trials are placed by their
    1-based index.  A missing output value is unobserved.
    """
    n = len(frame)
    problems: list[str] = []
    codes: dict[str, np.ndarray] = {}
    for col in dict.fromkeys((*spec.emission_inputs, *spec.transition_inputs, spec.output)):
        if col not in frame.columns:
            problems.append(f"column {col!r} is missing (needed by the model)")
            continue
        cats = list(spec.output_categories if col == spec.output else spec.categories[col])
        values = frame[col]
        missing = values.isna().to_numpy()
        cat = pd.Categorical(values.astype(object).where(~missing, None), categories=cats)
        c = np.asarray(cat.codes, dtype=np.int64)
        bad = np.flatnonzero((c < 0) & ~missing)
        for i in bad[:10]:
            problems.append(f"row {i + 1}, column {col!r}: value {values.iloc[i]!r} is not one of {cats}")
        if col != spec.output:
            for i in np.flatnonzero(missing)[:10]:
                problems.append(f"row {i + 1}, column {col!r}: value is missing")
        codes[col] = c
    if problems:
        raise FitError(problems)
    pid = frame[participant].astype(str).to_numpy()
    uniq, first = np.unique(pid, return_index=True)
    order_p = uniq[np.argsort(first)]
    pcode = pd.Categorical(pid, categories=order_p).codes.astype(np.int64)
    tpos = frame[trial].to_numpy().astype(np.int64) - 1
    lengths = np.bincount(pcode, minlength=len(order_p)).astype(np.int64)
    T, N = int(lengths.max()) if n else 1, len(order_p)
    if n and (tpos.min() < 0 or np.any(tpos >= lengths[pcode])):
        raise FitError(["trial indices must run 1..n within each participant"])
    ue = _combo([codes[c] for c in spec.emission_inputs], [len(spec.categories[c]) for c in spec.emission_inputs], n)
    ut = _combo([codes[c] for c in spec.transition_inputs], [len(spec.categories[c]) for c in spec.transition_inputs], n)
    out = {}
    for name, vals in (("y", codes[spec.output]), ("ue", ue), ("ut", ut), ("rows", np.arange(n))):
        arr = np.full((T, N), -1, dtype=np.int64)
        arr[tpos, pcode] = vals
        out[name] = arr
    return Sequences([str(p) for p in order_p], lengths, out["y"], out["ue"], out["ut"], out["rows"], n)


# --------------------------------------------------------------------------- compiled structure


class _Table:
    """Fixed cells, tie groups and defaults of one parameter table (U combos x K x M)."""

    def __init__(self, U: int, K: int, M: int):
        self.U, self.K, self.M = U, K, M
        self.fixed = np.zeros((U, K, M), dtype=bool)
        self.values = np.zeros((U, K, M))
        self.group = np.arange(U)

    def finish(self, events: np.ndarray, default: np.ndarray) -> None:
        """Renumber tie groups, and fix rows of groups with no data events to ``default`` (K, M)."""
        _, self.group = np.unique(self.group, return_inverse=True)
        self.group = self.group.ravel()
        self.G = int(self.group.max()) + 1 if self.U else 0
        self.rep = np.array([np.flatnonzero(self.group == g)[0] for g in range(self.G)], dtype=np.int64)
        self.group_events = np.bincount(self.group, weights=events, minlength=self.G)
        self.empty = self.group_events[self.group] == 0  # (U,)
        for u in np.flatnonzero(self.empty):
            free = ~self.fixed[u]
            self.values[u][free] = default[free]
            self.fixed[u] = True
        # rows fully fixed (and not empty) need no estimate either
        self.gfixed = self.fixed[self.rep]  # (G, K, M)
        self.gvalues = self.values[self.rep]
        self.mass = 1.0 - np.where(self.gfixed, self.gvalues, 0.0).sum(-1)  # (G, K)
        self.free_cells = (~self.gfixed).sum(-1)  # (G, K)

    def n_free(self) -> int:
        return int(np.maximum(self.free_cells - 1, 0).sum())

    def random(self, rng: np.random.Generator) -> np.ndarray:
        d = rng.dirichlet(np.ones(self.M), size=(self.G, self.K))
        d = 0.8 * d + 0.2 / self.M  # never an exact zero
        d = np.where(self.gfixed, 0.0, d)
        s = d.sum(-1, keepdims=True)
        p = np.where(self.gfixed, self.gvalues, d / np.where(s > 0, s, 1.0) * self.mass[..., None])
        return p[self.group]

    def project(self, p: np.ndarray) -> np.ndarray:
        """Put a (..., U, K, M) table back on the constraint set (after extrapolation)."""
        g = p[..., self.rep, :, :]
        g = np.where(self.gfixed, 0.0, np.clip(g, 1e-12, None))
        s = g.sum(-1, keepdims=True)
        g = np.where(self.gfixed, self.gvalues, g / np.where(s > 0, s, 1.0) * self.mass[..., None])
        return g[..., self.group, :, :]

    def mstep(self, counts: np.ndarray, prior: float, previous: np.ndarray) -> np.ndarray:
        """Closed-form M-step for (..., U, K, M) expected counts (leading axes: independent fits)."""
        if not hasattr(self, "_onehot"):
            self._onehot = (self.group[:, None] == np.arange(self.G)[None, :]).astype(float)  # (U, G)
        cg = np.moveaxis(np.moveaxis(counts, -3, -1) @ self._onehot, -1, -3)  # (..., G, K, M)
        free = np.where(self.gfixed, 0.0, cg + prior)
        tot = free.sum(-1, keepdims=True)
        prev = previous[..., self.rep, :, :]
        est = free / np.where(tot > 0, tot, 1.0) * self.mass[..., None]
        g = np.where(self.gfixed, self.gvalues, np.where(tot > 0, est, prev))
        return g[..., self.group, :, :]

    def log_prior(self, p: np.ndarray, prior: float):
        """Dirichlet log-density (up to a constant) over the leading axes."""
        if prior == 0:
            return 0.0 if p.ndim == 3 else np.zeros(p.shape[:-3])
        g = np.log(np.maximum(p[..., self.rep, :, :], _FLOOR))
        out = prior * np.where(self.gfixed, 0.0, g).sum((-3, -2, -1))
        return float(out) if p.ndim == 3 else out


def _select(where: Mapping[str, str], inputs: Sequence[str], cats: Mapping[str, Sequence[str]], what: str) -> np.ndarray:
    """Boolean mask over the input combinations matching ``where``."""
    sizes = [len(cats[c]) for c in inputs]
    mask = np.ones(sizes or [1], dtype=bool) if sizes else np.ones(1, dtype=bool)
    for col, val in where.items():
        if col not in inputs:
            raise FitError([f"{what}: {col!r} is not one of the inputs {list(inputs)}"])
        if val not in cats[col]:
            raise FitError([f"{what}: {col}={val!r} is not one of {list(cats[col])}"])
        idx = [slice(None)] * len(inputs)
        idx[list(inputs).index(col)] = [i for i, v in enumerate(cats[col]) if v != val]
        mask[tuple(idx)] = False
    return mask.ravel()


class Structure:
    """An :class:`IOHMMSpec` compiled against data (which rows have events)."""

    def __init__(self, spec: IOHMMSpec, seqs: Sequences):
        problems = spec.problems()
        if problems:
            raise FitError(problems)
        self.spec = spec
        K, M = spec.n_levels, len(spec.output_categories)
        cats = spec.categories
        Ue = int(np.prod([len(cats[c]) for c in spec.emission_inputs])) if spec.emission_inputs else 1
        Ut = int(np.prod([len(cats[c]) for c in spec.transition_inputs])) if spec.transition_inputs else 1
        self.K, self.M, self.Ue, self.Ut = K, M, Ue, Ut
        self.em = _Table(Ue, K, M)
        self.tr = _Table(Ut, K, K)
        for f in spec.fixed_emissions:
            mask = _select(f.where, spec.emission_inputs, cats, "fixed emission")
            if isinstance(f.probs, str):
                raise FitError([f"fixed emission rows need probabilities, got {f.probs!r}"])
            for cat, p in f.probs.items():
                if cat not in spec.output_categories:
                    raise FitError([f"fixed emission: {cat!r} is not an output category {list(spec.output_categories)}"])
                j = spec.output_categories.index(cat)
                self.em.fixed[mask, :, j] = True
                self.em.values[mask, :, j] = float(p)
        for f in spec.fixed_transitions:
            mask = _select(f.where, spec.transition_inputs, cats, "fixed transition")
            if f.probs != "identity":
                raise FitError([f"fixed transition rows support 'identity', got {f.probs!r}"])
            self.tr.fixed[mask] = True
            self.tr.values[mask] = np.eye(K)
        for table, ties, inputs, what in (
            (self.em, spec.tied_emissions, spec.emission_inputs, "tied emission"),
            (self.tr, spec.tied_transitions, spec.transition_inputs, "tied transition"),
        ):
            for gi, group in enumerate(ties):
                mask = np.zeros(table.U, dtype=bool)
                for where in group:
                    mask |= _select(where, inputs, cats, what)
                rows = np.flatnonzero(mask)
                if len(rows) and len({(table.fixed[r].tobytes(), table.values[r].tobytes()) for r in rows}) > 1:
                    raise FitError([f"{what} group {gi + 1} ties rows with different fixed cells"])
                table.group[rows] = rows[0] if len(rows) else 0
        # data events behind each combination
        obs = seqs.y >= 0
        self.em_events = np.bincount(seqs.ue[obs], minlength=Ue).astype(float)
        trans = _transition_mask(seqs)
        self.tr_events = np.bincount(seqs.ut[:-1][trans], minlength=Ut).astype(float)
        self.em.finish(self.em_events, np.full((K, M), 1.0 / M))
        self.tr.finish(self.tr_events, np.eye(K))
        self.n_free = (K - 1) + self.em.n_free() + self.tr.n_free()
        # impossible events under fixed cells
        yo, uo = seqs.y[obs], seqs.ue[obs]
        zero_all = np.all(self.em.fixed & (self.em.values == 0), axis=1)  # (Ue, M): impossible at every level
        bad = zero_all[uo, yo]
        if bad.any():
            rows = seqs.rows[obs][bad]
            lines = [
                f"row {r + 1}: {spec.output} = {spec.output_categories[y]!r} is impossible under a fixed cell ({_describe_combo(u, spec.emission_inputs, cats)})"
                for r, y, u in zip(rows[:10], yo[bad][:10], uo[bad][:10])
            ]
            if bad.sum() > 10:
                lines.append(f"... and {int(bad.sum()) - 10} more")
            raise FitError(lines)

    def random(self, rng: np.random.Generator) -> Params:
        K = self.K
        pi = 0.8 * rng.dirichlet(np.ones(K)) + 0.2 / K
        return Params(pi, self.em.random(rng), self.tr.random(rng))

    def project(self, p: Params) -> Params:
        pi = np.clip(p.initial, 1e-12, None)
        return Params(pi / pi.sum(-1, keepdims=True), self.em.project(p.emission), self.tr.project(p.transition))

    def mstep(self, stats: "EStep", previous: Params) -> Params:
        a = self.spec.prior
        c0 = stats.initial + a
        tot = c0.sum(-1, keepdims=True)
        pi = np.where(tot > 0, c0 / np.where(tot > 0, tot, 1.0), previous.initial)
        return Params(pi, self.em.mstep(stats.emission, a, previous.emission), self.tr.mstep(stats.transition, a, previous.transition))

    def log_prior(self, p: Params):
        a = self.spec.prior
        if a == 0:
            return 0.0 if p.initial.ndim == 1 else np.zeros(p.initial.shape[0])
        lp = a * np.log(np.maximum(p.initial, _FLOOR)).sum(-1) + self.em.log_prior(p.emission, a) + self.tr.log_prior(p.transition, a)
        return float(lp) if p.initial.ndim == 1 else lp

    def order(self, p: Params) -> np.ndarray:
        """Permutation putting levels in ascending order of the spec's ``order_by`` emission."""
        spec = self.spec
        if spec.order_by is None or self.K == 1:
            return np.arange(self.K)
        where, cat = spec.order_by
        mask = _select(where, spec.emission_inputs, spec.categories, "order_by") & ~self.em.empty
        if not mask.any():
            mask = _select(where, spec.emission_inputs, spec.categories, "order_by")
        score = p.emission[mask][:, :, spec.output_categories.index(cat)].mean(0)
        return np.argsort(score, kind="stable")


def _describe_combo(u: int, inputs: Sequence[str], cats: Mapping[str, Sequence[str]]) -> str:
    if not inputs:
        return "no inputs"
    idx = np.unravel_index(int(u), [len(cats[c]) for c in inputs])
    return ", ".join(f"{c}={cats[c][i]}" for c, i in zip(inputs, idx))


def _transition_mask(seqs: Sequences) -> np.ndarray:
    """(T-1, N): True where row t has a successor t+1 in the same sequence."""
    T = seqs.y.shape[0]
    return np.arange(T - 1)[:, None] < (seqs.lengths[None, :] - 1)


# --------------------------------------------------------------------------- E-step


@dataclass
class EStep:
    loglik: float
    initial: np.ndarray  # expected counts (K,)
    emission: np.ndarray  # (Ue, K, M)
    transition: np.ndarray  # (Ut, K, K)
    gamma: np.ndarray | None = None  # (T, N, K) posteriors


class Workspace:
    """Per-trial index arrays for one data set and one model size, reused by every E-step.

    Arrays are laid out level-major, ``(K, T, N)``, so that one step of the time
    recursion is a handful of numpy calls on contiguous length-N rows.  The
    transition from t to t+1 and the emission at t+1 are combined into one
    table indexed by ``midx`` (few distinct input combinations), gathered once
    per E-step.
    """

    def __init__(self, seqs: Sequences, K: int, M: int, Ue: int, Ut: int, method: str = "auto"):
        self.seqs, self.K, self.M, self.Ue, self.Ut = seqs, K, M, Ue, Ut
        T, N = seqs.y.shape
        self.T, self.N = T, N
        if method not in ("auto", "numba", "loop", "scan"):
            raise ValueError(f"method must be auto, numba, loop or scan, got {method!r}")
        if method == "numba" and not _fb.AVAILABLE:
            raise ValueError("method 'numba' needs the numba package")
        # compiled loop when numba is there; otherwise the numpy time loop costs ~T numpy
        # calls per pass and the scan ~log2(T) calls on log2(T)-times more work: the scan
        # wins for few, long sequences
        self.compiled = method == "numba" or (method == "auto" and _fb.AVAILABLE)
        # the numpy fallback (and the posteriors, which the compiled loop does not keep)
        self.scan = method == "scan" or (method in ("auto", "numba") and T > 1 and T >= SCAN_RATIO * N)
        obs = seqs.y >= 0
        self.PE = Ue * M + 1  # emission rows + dummy "nothing observed"
        self.eidx = np.where(obs, seqs.ue * M + seqs.y, Ue * M)
        tm = _transition_mask(seqs)
        self.tidx = np.where(tm, seqs.ut[:-1], Ut)  # dummy row Ut = identity, not counted
        self.midx = self.tidx * self.PE + self.eidx[1:]
        self.ebins = (self.eidx[None, :, :] + (np.arange(K) * self.PE)[:, None, None]).ravel()
        self.tbins = (self.tidx[None, :, :] + (np.arange(K * K) * (Ut + 1))[:, None, None]).ravel()
        self.eye = np.eye(K)
        if self.compiled:
            self._kernel = _fb.Kernel(self.eidx, self.tidx, seqs.lengths, K, self.PE, Ut + 1, 1)
        self._buffered = False
        if self.scan:
            self._init_scan()
            return
        if not self.compiled:
            self._buffers()

    def _buffers(self) -> None:
        """Work buffers of the numpy time loop, reused by every E-step (fresh multi-megabyte arrays cost page faults)."""
        if self._buffered:
            return
        self._buffered = True
        K, T, N = self.K, self.T, self.N
        self._Mt = np.empty((K, K, max(T - 1, 0), N))
        self._alpha = np.empty((K, T, N))
        self._beta = np.empty((K, T, N))
        self._gamma = np.empty((K, T, N))
        self._xi = np.empty((K, K, max(T - 1, 0), N))
        self._bs = np.empty((K, max(T - 1, 0), N))
        self._c = np.empty((T, N))

    def _emission_table(self, p: Params) -> np.ndarray:
        Bx = np.ones((self.PE, self.K))
        Bx[:-1] = p.emission.transpose(0, 2, 1).reshape(self.Ue * self.M, self.K)
        return Bx

    def _transition_table(self, p: Params) -> np.ndarray:
        Ax = np.empty((self.Ut + 1, self.K, self.K))
        Ax[:-1] = p.transition
        Ax[-1] = self.eye
        return Ax

    def tables(self, p: Params) -> tuple[np.ndarray, np.ndarray]:
        """Per-trial emission likelihoods (T, N, K) and transition matrices (T-1, N, K, K)."""
        return self._emission_table(p)[self.eidx], self._transition_table(p)[self.tidx]

    def _steps(self, p: Params):
        """B0 (K, N): emission likelihood of trial 1; Mt (K, K, T-1, N): A_t[i, j] * B_{t+1}[j]."""
        K = self.K
        Bx, Ax = self._emission_table(p), self._transition_table(p)
        mtab = (Ax[:, None, :, :] * Bx[None, :, None, :]).reshape(-1, K * K).T  # (K*K, P)
        Mt = self._Mt
        np.take(mtab, self.midx, axis=1, out=Mt.reshape(K * K, self.T - 1, self.N), mode="clip")
        B0 = Bx[self.eidx[0]].T
        return B0, Mt

    def _compiled(self, p: Params) -> EStep:
        K = self.K
        emit = self._emission_table(p)[None]
        trans = self._transition_table(p)[None]
        ll, ci, ce, ct = self._kernel.run(p.initial[None], emit, trans)
        em = ce[0, :-1].reshape(self.Ue, self.M, K).transpose(0, 2, 1)
        return EStep(float(ll[0]), ci[0], np.ascontiguousarray(em), np.ascontiguousarray(ct[0, :-1]))

    def forward(self, p: Params, B0=None, Mt=None):
        if self.compiled and B0 is None:
            return None, None, self._compiled(p).loglik
        if self.scan:
            return None, None, self._scan(p, counts=False).loglik
        self._buffers()
        if B0 is None:
            B0, Mt = self._steps(p)
        T, N, K = self.T, self.N, self.K
        alpha, c = self._alpha, self._c
        a = p.initial[:, None] * B0
        with np.errstate(invalid="ignore", divide="ignore"):
            for t in range(T):
                s = _add(a, 0, out=c[t])
                np.divide(a, s, out=alpha[:, t])
                if t + 1 < T:
                    a = _add(alpha[:, None, t] * Mt[:, :, t], 0)
            loglik = float(np.log(c).sum())
        return alpha, c, loglik

    def estep(self, p: Params, posteriors: bool = False) -> EStep:
        if self.compiled and not posteriors:
            return self._compiled(p)
        if self.scan:
            return self._scan(p, counts=True, posteriors=posteriors)
        self._buffers()
        B0, Mt = self._steps(p)
        T, N, K = self.T, self.N, self.K
        alpha, c, loglik = self.forward(p, B0, Mt)
        if not np.isfinite(loglik):
            return EStep(-math.inf, np.zeros(K), np.zeros_like(p.emission), np.zeros_like(p.transition))
        beta = self._beta  # scaled: beta[:, t] = P(y_{>t} | S_t) / prod_{s>t} c_s
        beta[:, T - 1] = 1.0
        for t in range(T - 1, 0, -1):
            b = beta[:, t] / c[t]
            _add(Mt[:, :, t - 1] * b[None], 1, out=beta[:, t - 1])
        gamma = np.multiply(alpha, beta, out=self._gamma)
        xi = np.multiply(alpha[:, None, :-1], Mt, out=self._xi)
        xi *= np.divide(beta[:, 1:], c[1:], out=self._bs)[None]
        em = np.bincount(self.ebins, weights=gamma.ravel(), minlength=K * self.PE).reshape(K, self.PE)
        em = em[:, :-1].reshape(K, self.Ue, self.M).transpose(1, 0, 2)
        tr = np.bincount(self.tbins, weights=xi.ravel(), minlength=K * K * (self.Ut + 1)).reshape(K, K, self.Ut + 1)
        tr = tr[:, :, :-1].transpose(2, 0, 1)
        return EStep(loglik, gamma[:, 0].sum(1), np.ascontiguousarray(em), np.ascontiguousarray(tr),
                     gamma.transpose(1, 2, 0).copy() if posteriors else None)

    # -- parallel prefix products (few or long sequences) ------------------------
    def _init_scan(self) -> None:
        K, T, N = self.K, self.T, self.N
        self.midx_s = np.ascontiguousarray(self.midx.T)  # (N, T-1)
        self.eidx0 = self.eidx[0]
        self.ebins_s = (np.ascontiguousarray(self.eidx.T)[:, :, None] * K + np.arange(K)).ravel()
        self.tbins_s = (np.ascontiguousarray(self.tidx.T)[:, :, None] * (K * K) + np.arange(K * K)).ravel()

    def _scan(self, p: Params, counts: bool, posteriors: bool = False) -> EStep:
        """E-step by inclusive prefix and suffix products of the per-step matrices.

        M_t = A_t diag(B_{t+1}) (N, T-1, K, K).  F_t = M_0 ... M_t and G_t = M_t ... M_{T-2}
        are built in log2(T) rounds of batched matrix products, each product rescaled to
        sum 1 with its log-scale kept.  alpha_t ∝ alpha_0 F_{t-1}, beta_t ∝ G_t 1.
        """
        K, T, N = self.K, self.T, self.N
        Bx, Ax = self._emission_table(p), self._transition_table(p)
        mtab = Ax[:, None, :, :] * Bx[None, :, None, :]
        mtab = mtab.reshape(-1, K, K)
        Mt = mtab[self.midx_s]  # (N, T-1, K, K)
        a0 = p.initial[None, :] * Bx[self.eidx0]  # (N, K)
        with np.errstate(divide="ignore", invalid="ignore"):
            s0 = a0.sum(1)
            a0 = a0 / s0[:, None]
            F, logF = _prefix_products(Mt)
            last = np.einsum("nk,nkj->n", a0, F[:, -1]) if T > 1 else np.ones(N)
            ll = np.log(s0) + (np.log(last) + logF[:, -1] if T > 1 else 0.0)
            loglik = float(np.sum(ll))
        K0 = np.zeros(K)
        if not np.isfinite(loglik):
            return EStep(-math.inf, K0, np.zeros_like(p.emission), np.zeros_like(p.transition))
        if not counts:
            return EStep(loglik, K0, p.emission * 0, p.transition * 0)
        alpha = np.empty((N, T, K))
        alpha[:, 0] = a0
        alpha[:, 1:] = np.matmul(a0[:, None, None, :], F)[:, :, 0, :]
        alpha[:, 1:] /= alpha[:, 1:].sum(-1, keepdims=True)
        G = _suffix_products(Mt)
        beta = np.ones((N, T, K))
        beta[:, :-1] = G.sum(-1)
        beta[:, :-1] /= beta[:, :-1].sum(-1, keepdims=True)
        gamma = alpha * beta
        gamma /= gamma.sum(-1, keepdims=True)
        xi = alpha[:, :-1, :, None] * Mt * beta[:, 1:, None, :]
        xi /= xi.sum((-2, -1), keepdims=True)
        em = np.bincount(self.ebins_s, weights=gamma.ravel(), minlength=self.PE * K).reshape(self.PE, K)
        em = em[:-1].reshape(self.Ue, self.M, K).transpose(0, 2, 1)
        tr = np.bincount(self.tbins_s, weights=xi.ravel(), minlength=(self.Ut + 1) * K * K).reshape(self.Ut + 1, K, K)[:-1]
        return EStep(loglik, gamma[:, 0].sum(0), np.ascontiguousarray(em), np.ascontiguousarray(tr),
                     gamma.transpose(1, 0, 2).copy() if posteriors else None)

    def viterbi(self, p: Params) -> np.ndarray:
        """Most likely level path, (T, N), -1 on padding."""
        Bt, At = self.tables(p)
        T, N, K = self.T, self.N, self.K
        with np.errstate(divide="ignore"):
            lB, lA = np.log(Bt), np.log(At)
            delta = np.log(p.initial)[None, :] + lB[0]
        back = np.empty((T, N, K), dtype=np.int64)
        for t in range(1, T):
            cand = delta[:, :, None] + lA[t - 1]  # (N, K, K)
            back[t] = cand.argmax(1)
            delta = np.take_along_axis(cand, back[t][:, None, :], 1)[:, 0, :] + lB[t]
        path = np.empty((T, N), dtype=np.int64)
        path[T - 1] = delta.argmax(1)
        for t in range(T - 1, 0, -1):
            path[t - 1] = np.take_along_axis(back[t], path[t][:, None], 1)[:, 0]
        pad = np.arange(T)[:, None] >= self.seqs.lengths[None, :]
        path[pad] = -1
        return path


class BatchWorkspace:
    """E-steps of R parameter sets on the same sequences at once.

    The data are laid side by side R times (column r*N + n is sequence n under
    parameter set r), so one pass of the time loop serves every restart: with few
    participants the cost of a pass is numpy call overhead, shared this way.
    Parameters carry a leading axis R.
    """

    def __init__(self, seqs: Sequences, K: int, M: int, Ue: int, Ut: int, R: int, method: str = "auto"):
        self.seqs, self.K, self.M, self.Ue, self.Ut, self.R = seqs, K, M, Ue, Ut, R
        T, N = seqs.y.shape
        self.T, self.N, self.NR = T, N, N * R
        obs = seqs.y >= 0
        PE = self.PE = Ue * M + 1
        P = self.P = (Ut + 1) * PE
        if method not in ("auto", "numba", "loop"):
            raise ValueError(f"method must be auto, numba or loop, got {method!r}")
        self.compiled = method == "numba" or (method == "auto" and _fb.AVAILABLE)
        if self.compiled:  # one compiled pass per parameter set; no side-by-side copies of the data
            eidx = np.where(obs, seqs.ue * M + seqs.y, Ue * M)
            tidx = np.where(_transition_mask(seqs), seqs.ut[:-1], Ut)
            self._kernel = _fb.Kernel(eidx, tidx, seqs.lengths, K, PE, Ut + 1, R)
            return
        off = np.arange(R)
        eidx = np.where(obs, seqs.ue * M + seqs.y, Ue * M)
        tidx = np.where(_transition_mask(seqs), seqs.ut[:-1], Ut)
        self.eidx = (eidx[:, None, :] + (off * PE)[None, :, None]).reshape(T, R * N)
        self.midx = (tidx[:, None, :] * PE + eidx[1:, None, :] + (off * P)[None, :, None]).reshape(T - 1, R * N)
        tidxR = (tidx[:, None, :] + (off * (Ut + 1))[None, :, None]).reshape(T - 1, R * N)
        self.ebins = (self.eidx[None] + (np.arange(K) * R * PE)[:, None, None]).ravel()
        self.tbins = (tidxR[None] + (np.arange(K * K) * R * (Ut + 1))[:, None, None]).ravel()
        NR = R * N
        self._Mt = np.empty((K, K, max(T - 1, 0), NR))
        self._alpha = np.empty((K, T, NR))
        self._beta = np.empty((K, T, NR))
        self._gamma = np.empty((K, T, NR))
        self._xi = np.empty((K, K, max(T - 1, 0), NR))
        self._bs = np.empty((K, max(T - 1, 0), NR))
        self._c = np.empty((T, NR))
        self.eye = np.eye(K)

    def estep(self, p: Params, active: np.ndarray | None = None) -> EStep:
        """Batched E-step: ``loglik`` (R,), counts with a leading axis R.

        The compiled E-step skips parameter sets where ``active`` is false (their
        log-likelihood and counts are reported as 0); the numpy one computes all.
        """
        K, T, N, R = self.K, self.T, self.N, self.R
        if self.compiled:
            Bx = np.ones((R, self.PE, K))
            Bx[:, :-1] = p.emission.transpose(0, 1, 3, 2).reshape(R, self.Ue * self.M, K)
            Ax = np.empty((R, self.Ut + 1, K, K))
            Ax[:, :-1] = p.transition
            Ax[:, -1] = np.eye(K)
            ll, ci, ce, ct = self._kernel.run(p.initial, Bx, Ax, active)
            em = ce[:, :-1].reshape(R, self.Ue, self.M, K).transpose(0, 1, 3, 2)
            return EStep(ll, ci, np.ascontiguousarray(em), np.ascontiguousarray(ct[:, :-1]))
        Bx = np.ones((R, self.PE, K))
        Bx[:, :-1] = p.emission.transpose(0, 1, 3, 2).reshape(R, self.Ue * self.M, K)
        Ax = np.empty((R, self.Ut + 1, K, K))
        Ax[:, :-1] = p.transition
        Ax[:, -1] = self.eye
        mtab = (Ax[:, :, None, :, :] * Bx[:, None, :, None, :]).reshape(R * self.P, K * K).T
        Mt = self._Mt
        np.take(mtab, self.midx, axis=1, out=Mt.reshape(K * K, T - 1, self.NR), mode="clip")
        B0 = Bx.reshape(R * self.PE, K)[self.eidx[0]].T
        alpha, c, beta = self._alpha, self._c, self._beta
        a = np.repeat(p.initial.T, N, axis=1) * B0
        with np.errstate(invalid="ignore", divide="ignore"):
            for t in range(T):
                sm = _add(a, 0, out=c[t])
                np.divide(a, sm, out=alpha[:, t])
                if t + 1 < T:
                    a = _add(alpha[:, None, t] * Mt[:, :, t], 0)
            ll = np.log(c).sum(0).reshape(R, N).sum(1)
            beta[:, T - 1] = 1.0
            for t in range(T - 1, 0, -1):
                b = beta[:, t] / c[t]
                _add(Mt[:, :, t - 1] * b[None], 1, out=beta[:, t - 1])
            gamma = np.multiply(alpha, beta, out=self._gamma)
            xi = np.multiply(alpha[:, None, :-1], Mt, out=self._xi)
            xi *= np.divide(beta[:, 1:], c[1:], out=self._bs)[None]
        em = np.bincount(self.ebins, weights=gamma.ravel(), minlength=K * R * self.PE).reshape(K, R, self.PE)
        em = em[:, :, :-1].reshape(K, R, self.Ue, self.M).transpose(1, 2, 0, 3)
        tr = np.bincount(self.tbins, weights=xi.ravel(), minlength=K * K * R * (self.Ut + 1)).reshape(K, K, R, self.Ut + 1)
        tr = tr[:, :, :, :-1].transpose(2, 3, 0, 1)
        init = gamma[:, 0].reshape(K, R, N).sum(2).T
        bad = ~np.isfinite(ll)
        if bad.any():
            ll = np.where(bad, -np.inf, ll)
            em[bad], tr[bad], init[bad] = 0.0, 0.0, 0.0
        return EStep(ll, np.ascontiguousarray(init), np.ascontiguousarray(em), np.ascontiguousarray(tr))


def _stack(ps: Sequence[Params]) -> Params:
    return Params(np.stack([p.initial for p in ps]), np.stack([p.emission for p in ps]), np.stack([p.transition for p in ps]))


def _where(mask: np.ndarray, a: Params, b: Params) -> Params:
    m1, m3 = mask[:, None], mask[:, None, None, None]
    return Params(np.where(m1, a.initial, b.initial), np.where(m3, a.emission, b.emission), np.where(m3, a.transition, b.transition))


def _where_stats(mask: np.ndarray, a: EStep, b: EStep) -> EStep:
    m3 = mask[:, None, None, None]
    return EStep(np.where(mask, a.loglik, b.loglik), np.where(mask[:, None], a.initial, b.initial),
                 np.where(m3, a.emission, b.emission), np.where(m3, a.transition, b.transition))


def run_em_batch(
    structure: Structure,
    work: BatchWorkspace,
    starts: Sequence[Params],
    tol: float = 1e-8,
    max_iter: int = 1000,
    accelerate: bool = True,
) -> list[RunResult]:
    """:func:`run_em` for several starts in lockstep on one :class:`BatchWorkspace`.

    Every start follows exactly the decisions :func:`run_em` would take (accept or
    reject the extrapolation, convergence); a converged start is frozen while the
    others go on.  ``seconds`` is the batch's time divided evenly.
    """
    t0 = time.perf_counter()
    R = len(starts)

    def evaluate(p: Params, mask: np.ndarray | None = None):
        st = work.estep(p, mask)
        return st, st.loglik + structure.log_prior(p)

    p0 = _stack(starts)
    st0, f0 = evaluate(p0)
    if not np.all(np.isfinite(f0)):
        raise FitError(["the initial values give the data probability zero"])
    history = [[float(x)] for x in f0]
    n_e = np.ones(R, dtype=np.int64)
    active = np.ones(R, dtype=bool)
    converged = np.zeros(R, dtype=bool)
    final_p, final_st, final_f = p0, st0, f0.copy()

    def freeze(mask, p, st, f, conv):
        nonlocal final_p, final_st, final_f
        if mask.any():
            final_p = _where(mask, p, final_p)
            final_st = _where_stats(mask, st, final_st)
            final_f = np.where(mask, f, final_f)
            converged[mask] = conv
            active[mask] = False

    def small(fa, fb):
        return (fb - fa) <= tol * np.abs(fa)

    while active.any():
        if np.all(n_e[active] >= max_iter):
            freeze(active.copy(), p0, st0, f0, False)
            break
        p1 = structure.mstep(st0, p0)
        st1, f1 = evaluate(p1, active)
        n_e[active] += 1
        down = active & ~(f1 >= f0)
        freeze(down, p0, st0, f0, True)
        for r in np.flatnonzero(active):
            history[r].append(float(f1[r]))
        done = active & small(f0, f1)
        freeze(done, p1, st1, f1, True)
        cap = active & (n_e >= max_iter)
        if not accelerate or cap.any():
            freeze(cap, p1, st1, f1, False)
            p0, st0, f0 = p1, st1, f1
            continue
        p2 = structure.mstep(st1, p1)
        st2, f2 = evaluate(p2, active)
        n_e[active] += 1
        down = active & ~(f2 >= f1)
        freeze(down, p1, st1, f1, True)
        for r in np.flatnonzero(active):
            history[r].append(float(f2[r]))
        done = active & small(f1, f2)
        freeze(done, p2, st2, f2, True)
        v0, v1, v2 = (np.concatenate([q.initial.reshape(R, -1), q.emission.reshape(R, -1), q.transition.reshape(R, -1)], 1) for q in (p0, p1, p2))
        r_, v_ = v1 - v0, v2 - 2 * v1 + v0
        nv = np.sqrt((v_ * v_).sum(1))
        step = np.where(nv > 0, -np.sqrt((r_ * r_).sum(1)) / np.where(nv > 0, nv, 1.0), -1.0)
        p0, st0, f0 = p2, st2, f2
        cap = active & (n_e >= max_iter)
        freeze(cap, p2, st2, f2, False)
        ext = active & (step < -1.0)
        if ext.any():
            st = step[:, None]
            x = np.maximum(v0 - 2 * st * r_ + st * st * v_, _SHRINK * v2)
            a, b = p0.initial[0].size, p0.emission[0].size
            pe = structure.project(Params(x[:, :a].copy(), x[:, a : a + b].reshape(p0.emission.shape).copy(), x[:, a + b :].reshape(p0.transition.shape).copy()))
            pe = _where(ext, pe, p2)
            ste, fe = evaluate(pe, ext)
            n_e[ext] += 1
            ok = ext & (fe >= f2) & np.isfinite(fe)
            for r in np.flatnonzero(ok):
                history[r].append(float(fe[r]))
            p0, st0, f0 = _where(ok, pe, p0), _where_stats(ok, ste, st0), np.where(ok, fe, f0)
    seconds = (time.perf_counter() - t0) / R
    out = []
    for r in range(R):
        pr = Params(final_p.initial[r].copy(), final_p.emission[r].copy(), final_p.transition[r].copy())
        out.append(RunResult(pr, float(final_st.loglik[r]), float(final_f[r]), history[r], int(n_e[r]), bool(converged[r]), seconds))
    return out


def _prefix_products(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inclusive prefix products along axis 1 (Hillis-Steele), rescaled: (F, log scale)."""
    F = M.copy()
    logs = np.zeros(M.shape[:2])
    n, d = M.shape[1], 1
    while d < n:
        prod = np.matmul(F[:, :-d], F[:, d:])
        sc = prod.sum((-2, -1))
        prod /= sc[..., None, None]
        logs[:, d:] = logs[:, :-d] + logs[:, d:] + np.log(sc)
        F[:, d:] = prod
        d *= 2
    return F, logs


def _suffix_products(M: np.ndarray) -> np.ndarray:
    """Inclusive suffix products along axis 1 (G_t = M_t ... M_last), each rescaled to sum 1."""
    G = M / M.sum((-2, -1), keepdims=True)
    n, d = M.shape[1], 1
    while d < n:
        prod = np.matmul(G[:, :-d], G[:, d:])
        prod /= prod.sum((-2, -1), keepdims=True)
        G[:, :-d] = prod
        d *= 2
    return G


# --------------------------------------------------------------------------- EM


@dataclass
class RunResult:
    params: Params
    loglik: float
    objective: float
    history: list[float]
    iterations: int
    converged: bool
    seconds: float


def run_em(
    structure: Structure,
    work: Workspace,
    params: Params,
    tol: float = 1e-8,
    max_iter: int = 1000,
    accelerate: bool = True,
) -> RunResult:
    """EM from ``params`` until the relative change of the objective is below ``tol``.

    ``iterations`` counts E-steps.  ``history`` holds the objective of every accepted
    point in order; it never decreases.  With ``accelerate`` a SQUAREM cycle makes
    two EM steps, extrapolates, and keeps the extrapolated point only if its
    objective is at least that of the second EM step.
    """
    t0 = time.perf_counter()

    def evaluate(p: Params):
        st = work.estep(p)
        return st, st.loglik + structure.log_prior(p)

    p0 = params
    st0, f0 = evaluate(p0)
    if not math.isfinite(f0):
        raise FitError(["the initial values give the data probability zero"])
    history, n_e, converged = [f0], 1, False

    def small(fa: float, fb: float) -> bool:
        return (fb - fa) <= tol * abs(fa)

    while n_e < max_iter:
        p1 = structure.mstep(st0, p0)
        st1, f1 = evaluate(p1)
        n_e += 1
        if not f1 >= f0:  # only rounding can do this at a fixed point: stop at the better point
            converged = True
            break
        history.append(f1)
        if small(f0, f1):
            p0, st0, f0, converged = p1, st1, f1, True
            break
        if not accelerate or n_e >= max_iter:
            p0, st0, f0 = p1, st1, f1
            continue
        p2 = structure.mstep(st1, p1)
        st2, f2 = evaluate(p2)
        n_e += 1
        if not f2 >= f1:
            p0, st0, f0, converged = p1, st1, f1, True
            break
        history.append(f2)
        if small(f1, f2):
            p0, st0, f0, converged = p2, st2, f2, True
            break
        v0, v1, v2 = p0.vector(), p1.vector(), p2.vector()
        r, v = v1 - v0, v2 - 2 * v1 + v0
        nv = float(np.sqrt(v @ v))
        step = -float(np.sqrt(r @ r)) / nv if nv > 0 else -1.0
        p0, st0, f0 = p2, st2, f2
        if step < -1.0 and n_e < max_iter:
            # a cell may shrink at most 20-fold per cycle: clamping cells to the boundary
            # would leave EM crawling there and stop it early at a worse point
            x = np.maximum(v0 - 2 * step * r + step * step * v, _SHRINK * v2)
            pe = structure.project(_unpack(x, p0))
            ste, fe = evaluate(pe)
            n_e += 1
            if fe >= f2 and math.isfinite(fe):
                history.append(fe)
                p0, st0, f0 = pe, ste, fe
    loglik = st0.loglik
    return RunResult(p0, loglik, f0, history, n_e, converged, time.perf_counter() - t0)


def _unpack(x: np.ndarray, like: Params) -> Params:
    a, b = like.initial.size, like.emission.size
    return Params(
        x[:a].copy(),
        x[a : a + b].reshape(like.emission.shape).copy(),
        x[a + b :].reshape(like.transition.shape).copy(),
    )


# --------------------------------------------------------------------------- quasi-Newton finish


class _Budget(Exception):
    """The finish ran out of E-steps."""


class _Sticks:
    """Free cells as stick-breaking fractions in [0, 1]: a box, for L-BFGS-B.

    A row with free cells c_0..c_{m-1} and free mass s holds p_0 = s v_0,
    p_j = s v_j prod_{i<j} (1 - v_i), p_{m-1} = s prod_{i<m-1} (1 - v_i).  With
    expected counts (plus pseudo-counts) w, the gradient of the objective is, by
    Fisher's identity, w_j / v_j - (sum_{i>j} w_i) / (1 - v_j).
    """

    EPS = 1e-12

    def __init__(self, structure: "Structure"):
        self.s = structure
        K = structure.K
        # parts: rows with the same number m of free cells; cell j of row r is value
        # r * m + j, stored at the flat positions dst of the full array (every member of
        # a tie group), taken from the values src
        self.parts = []
        if K >= 2:
            self.parts.append(("initial", 1, K, np.ones(1), np.arange(K), np.arange(K)))
        for name, table in (("emission", structure.em), ("transition", structure.tr)):
            rows: dict[int, list] = {}
            for g in range(table.G):
                for k in range(K):
                    cells = np.flatnonzero(~table.gfixed[g, k])
                    if len(cells) >= 2 and table.mass[g, k] > 0:
                        rows.setdefault(len(cells), []).append((g, k, cells))
            KM = K * table.M
            for m, lst in sorted(rows.items()):
                dst, src = [], []
                for r, (g, k, cells) in enumerate(lst):
                    for u in np.flatnonzero(table.group == g):
                        dst.extend(u * KM + k * table.M + cells)
                        src.extend(r * m + np.arange(m))
                mass = np.array([table.mass[g, k] for g, k, _ in lst])
                self.parts.append((name, len(lst), m, mass, np.array(dst, dtype=np.int64), np.array(src, dtype=np.int64)))
        self.size = sum(R * (m - 1) for _, R, m, _, _, _ in self.parts)

    def theta(self, p: Params) -> np.ndarray:
        out = []
        for name, R, m, mass, dst, src in self.parts:
            vals = np.empty(R * m)
            vals[src] = getattr(p, name).ravel()[dst]
            vals = vals.reshape(R, m)
            rem = mass.copy()
            for j in range(m - 1):
                out.append(np.clip(vals[:, j] / np.maximum(rem, _FLOOR), self.EPS, 1 - self.EPS))
                rem = rem - vals[:, j]
        return np.concatenate(out) if out else np.zeros(0)

    def params(self, theta: np.ndarray, base: Params) -> Params:
        arrays = {"initial": base.initial.copy(), "emission": base.emission.copy(), "transition": base.transition.copy()}
        pos = 0
        for name, R, m, mass, dst, src in self.parts:
            v = theta[pos : pos + R * (m - 1)].reshape(m - 1, R)
            pos += R * (m - 1)
            rem = mass.copy()
            vals = np.empty((R, m))
            for j in range(m - 1):
                vals[:, j] = rem * v[j]
                rem = rem * (1 - v[j])
            vals[:, m - 1] = rem
            arrays[name].ravel()[dst] = vals.ravel()[src]
        return Params(arrays["initial"], arrays["emission"], arrays["transition"])

    def gradient(self, theta: np.ndarray, st: "EStep") -> np.ndarray:
        a = self.s.spec.prior
        out = np.empty_like(theta)
        pos = 0
        for name, R, m, mass, dst, src in self.parts:
            w = np.bincount(src, weights=getattr(st, name).ravel()[dst], minlength=R * m).reshape(R, m) + a
            v = theta[pos : pos + R * (m - 1)].reshape(m - 1, R)
            tail = np.cumsum(w[:, ::-1], axis=1)[:, ::-1]  # tail[:, j] = sum_{i>=j} w_i
            out[pos : pos + R * (m - 1)] = (w[:, : m - 1].T / v - tail[:, 1:].T / (1 - v)).ravel()
            pos += R * (m - 1)
        return out


def finish(structure: "Structure", work: Workspace, run: "RunResult", tol: float = 1e-8, max_iter: int = 1000) -> "RunResult":
    """Continue a run with L-BFGS-B on the stick-breaking fractions of the free cells.

    EM crawls along flat ridges of the likelihood (weakly identified directions) with
    tiny steps, and the relative-change test then stops it short of the maximum; a
    quasi-Newton method walks such ridges.  The gradient is free (Fisher's identity on
    the E-step counts).  Every iterate of L-BFGS-B decreases the negated objective, and
    the result is kept only if its objective is at least the run's, so the objective
    history never decreases.  Iterations count E-steps, within ``max_iter`` in total.
    """
    t0 = time.perf_counter()
    budget = max_iter - run.iterations
    sticks = _Sticks(structure)
    if budget < 2 or sticks.size == 0 or not math.isfinite(run.objective):
        return run
    base = run.params
    seen: dict[bytes, tuple[float, Params, float]] = {}  # recent evaluations: theta -> (objective, params, loglik)
    history = list(run.history)

    calls = [0]

    def fun(theta):
        if calls[0] >= budget:
            raise _Budget
        calls[0] += 1
        p = sticks.params(theta, base)
        st = work.estep(p)
        f = st.loglik + structure.log_prior(p)
        if len(seen) > 32:
            seen.pop(next(iter(seen)))
        seen[np.asarray(theta, dtype=float).tobytes()] = (f, p, st.loglik)
        if not math.isfinite(f):
            return math.inf, np.zeros_like(theta)
        return -f, -sticks.gradient(theta, st)

    best = {"f": run.objective, "p": run.params, "ll": run.loglik}

    def accepted(xk):
        hit = seen.get(np.asarray(xk, dtype=float).tobytes())
        if hit is not None and hit[0] >= best["f"]:
            if hit[0] > best["f"]:
                history.append(float(hit[0]))
            best.update(f=hit[0], p=hit[1], ll=hit[2])

    try:
        res = minimize(fun, sticks.theta(base), jac=True, method="L-BFGS-B", bounds=[(sticks.EPS, 1 - sticks.EPS)] * sticks.size,
                       callback=accepted, options={"ftol": tol, "gtol": 0.0, "maxfun": budget, "maxiter": budget, "maxcor": 20})
        accepted(res.x)
        success = calls[0] < budget  # stopped by its tolerance (or at the limits of precision), not by the cap
    except _Budget:  # the E-step cap: keep the best accepted point
        success = False
    n_e = run.iterations + calls[0]
    converged = run.converged and success
    return RunResult(best["p"], float(best["ll"]), float(best["f"]), history, n_e, converged, run.seconds + time.perf_counter() - t0)


@dataclass
class IOHMMFit:
    """Result of :func:`fit_iohmm`; levels are ordered by the spec's ``order_by`` rule."""

    spec: IOHMMSpec
    structure: Structure
    seqs: Sequences
    params: Params
    loglik: float
    objective: float
    runs: list[RunResult]
    best: int

    @property
    def n_params(self) -> int:
        return self.structure.n_free

    @property
    def n_observations(self) -> int:
        return self.seqs.n_observed

    @property
    def aic(self) -> float:
        return 2 * self.n_params - 2 * self.loglik

    @property
    def bic(self) -> float:
        return self.n_params * math.log(max(self.n_observations, 1)) - 2 * self.loglik

    @property
    def restart_logliks(self) -> list[float]:
        return [r.loglik for r in self.runs]

    def workspace(self) -> Workspace:
        s = self.structure
        return Workspace(self.seqs, s.K, s.M, s.Ue, s.Ut)

    def expected_events(self) -> dict[str, np.ndarray]:
        """Posterior-expected number of data events behind each row (tied rows: the group's)."""
        st = self.workspace().estep(self.params)
        s = self.structure
        out = {"initial": np.full(s.K, float(self.seqs.n_participants))}
        for name, table, counts in (("emission", s.em, st.emission), ("transition", s.tr, st.transition)):
            g = np.zeros((table.G, s.K))
            np.add.at(g, table.group, counts.sum(-1))
            out[name] = g[table.group]  # (U, K)
        return out


def fit_iohmm(
    seqs: Sequences,
    spec: IOHMMSpec,
    restarts: int = 10,
    seed: int | np.random.SeedSequence = 0,
    tol: float = 1e-8,
    max_iter: int = 1000,
    accelerate: bool = True,
    init: Sequence[Params] = (),
    on_restart: Callable[[int, RunResult], None] | None = None,
    quasi_newton: bool = True,
) -> IOHMMFit:
    """Fit ``spec`` to ``seqs``: the runs from ``init`` and ``restarts`` random starts; the best is kept.

    Each run is EM with SQUAREM (all runs in lockstep) and, with ``quasi_newton``, EM
    only to the relative tolerance ``max(tol, 1e-5)`` followed by :func:`finish`
    (L-BFGS-B) to ``tol / 100``: on flat ridges of the likelihood EM's small steps
    would meet ``tol`` short of the maximum.  ``max_iter`` caps the E-steps of a run.
    """
    structure = Structure(spec, seqs)
    work = Workspace(seqs, structure.K, structure.M, structure.Ue, structure.Ut)
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    starts = [structure.project(p) for p in init]
    starts += [structure.random(np.random.default_rng(s)) for s in ss.spawn(restarts)]
    if not starts:
        raise FitError(["at least one restart is needed"])
    em_tol = max(tol, _FINISH_SWITCH) if quasi_newton else tol
    if len(starts) > 1 and (work.compiled or (not work.scan and seqs.n_participants * len(starts) <= BATCH_MAX_COLUMNS)):
        # run every start in lockstep on one batched workspace
        bw = BatchWorkspace(seqs, structure.K, structure.M, structure.Ue, structure.Ut, len(starts))
        em_runs = run_em_batch(structure, bw, starts, tol=em_tol, max_iter=max_iter, accelerate=accelerate)
    else:
        em_runs = [run_em(structure, work, p, tol=em_tol, max_iter=max_iter, accelerate=accelerate) for p in starts]
    runs = []
    for i, r in enumerate(em_runs):
        if quasi_newton:
            r = finish(structure, work, r, tol=tol * _FINISH_FTOL, max_iter=max_iter)
        runs.append(r)
        if on_restart is not None:
            on_restart(i, r)
    best = int(np.argmax([r.objective for r in runs]))
    p = runs[best].params
    perm = structure.order(p)
    return IOHMMFit(spec, structure, seqs, p.permuted(perm), runs[best].loglik, runs[best].objective, runs, best)


def loglik(seqs: Sequences, spec: IOHMMSpec, params: Params) -> float:
    """Log-likelihood of ``seqs`` under ``params`` (forward pass only)."""
    K, M = spec.n_levels, len(spec.output_categories)
    Ue, Ut = params.emission.shape[0], params.transition.shape[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        return Workspace(seqs, K, M, Ue, Ut).forward(params)[2]


def posteriors(seqs: Sequences, spec: IOHMMSpec, params: Params) -> tuple[np.ndarray, np.ndarray, float]:
    """Smoothed P(level | all data of the participant) per trial, (T, N, K); Viterbi path (T, N); log-likelihood."""
    K, M = spec.n_levels, len(spec.output_categories)
    work = Workspace(seqs, K, M, params.emission.shape[0], params.transition.shape[0])
    st = work.estep(params, posteriors=True)
    if st.gamma is None:
        raise FitError(["the data has probability zero under this model"])
    return st.gamma, work.viterbi(params), st.loglik
