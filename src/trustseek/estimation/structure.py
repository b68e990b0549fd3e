"""An :class:`IOHMMSpec` compiled against data: which cells are free, tied, fixed or never reached.

:class:`Structure` turns the spec's fixed rows, tie groups and prior into per-table masks, fixes
the rows no data event reaches (transitions to the identity, emissions to uniform), reports events
a fixed cell forbids, and gives EM random starts, the M-step, the projection onto the constraints,
the log-prior and the permutation that names the levels, all over leading axes (runs side by side).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence

import numpy as np

from .estep import EStep
from .sequences import Sequences
from .spec import FitError, IOHMMSpec, Params

FLOOR = 1e-300  # probabilities are floored here before their log is taken
PROJECT_FLOOR = 1e-12  # an extrapolated cell is clipped to at least this before renormalising
START_MIX = 0.2  # random starts mix this much of the uniform row into a Dirichlet draw: never an exact zero


def random_rows(rng: np.random.Generator, M: int, size: int | tuple[int, ...] | None = None) -> np.ndarray:
    """Random rows of ``M`` cells: a Dirichlet(1) draw with :data:`START_MIX` of the uniform row mixed in."""
    return (1 - START_MIX) * rng.dirichlet(np.ones(M), size=size) + START_MIX / M


def mixed(rows: np.ndarray, rng: np.random.Generator, share: float) -> np.ndarray:
    """``rows`` normalised, with ``share`` of a random (Dirichlet(1)) row mixed into each: no exact zero."""
    rows = rows / rows.sum(-1, keepdims=True)
    return (1 - share) * rows + share * rng.dirichlet(np.ones(rows.shape[-1]), size=rows.shape[:-1])


def normalised(counts: np.ndarray, previous: np.ndarray, axis: int | tuple[int, ...] = -1) -> np.ndarray:
    """Counts scaled to sum to 1 over ``axis``; ``previous`` where they sum to 0 (the M-step of a free row)."""
    tot = counts.sum(axis, keepdims=True)
    return np.where(tot > 0, counts / np.where(tot > 0, tot, 1.0), previous)


class Table:
    """Fixed cells, tie groups and defaults of one table (U input combinations x K levels x M): the spec
    sets ``fixed``, ``values`` and ``group``, then :meth:`finish` adds what the data decide."""

    def __init__(self, U: int, K: int, M: int):
        self.U, self.K, self.M = U, K, M
        self.fixed = np.zeros((U, K, M), dtype=bool)
        self.values = np.zeros((U, K, M))
        self.group = np.arange(U)
        self.G = U
        self.rep = np.arange(U)  # (G,) a representative combination per tie group
        self.onehot = np.eye(U)  # (U, G) combination -> its group
        self.empty = np.zeros(U, dtype=bool)  # (U,) rows no data event reaches
        self.defaulted = np.zeros(U, dtype=bool)  # (U,) of those, the rows with a free cell, set to the default
        self.gfixed = self.fixed
        self.gvalues = self.values
        self.mass = np.ones((U, K))  # (G, K) probability left to the free cells
        self.free_cells = np.full((U, K), M)  # (G, K)

    def finish(self, events: np.ndarray, default: np.ndarray) -> None:
        """Renumber tie groups, and fix rows of groups with no data events to ``default`` (K, M)
        (``defaulted``: those with a cell the structure left free)."""
        _, inverse = np.unique(self.group, return_inverse=True)
        self.group = inverse.ravel()
        self.G = int(self.group.max()) + 1 if self.U else 0
        self.onehot = (self.group[:, None] == np.arange(self.G)[None, :]).astype(float)
        self.rep = np.array([np.flatnonzero(self.group == g)[0] for g in range(self.G)], dtype=np.int64)
        self.empty = self.grouped(events)[self.group] == 0
        for u in np.flatnonzero(self.empty):
            free = ~self.fixed[u]
            self.defaulted[u] = free.any()
            self.values[u][free] = default[free]
            self.fixed[u] = True
        self.refresh()

    def refresh(self) -> None:
        """The per-group views of ``fixed`` and ``values`` (after they changed): fixed cells, their
        values, the mass left to the free cells and how many there are."""
        self.gfixed = self.fixed[self.rep]  # (G, K, M)
        self.gvalues = self.values[self.rep]
        self.mass = 1.0 - np.where(self.gfixed, self.gvalues, 0.0).sum(-1)
        self.free_cells = (~self.gfixed).sum(-1)

    def estimated(self) -> np.ndarray:
        """(U, K): True where a row is estimated (its cells not all fixed; a row the data never reach is)."""
        return ~np.all(self.fixed, axis=-1)

    def estimated_rows(self) -> Iterator[tuple[int, int]]:
        """(u, k) of every estimated row, each tie group's representative once, in order."""
        estimated = self.estimated()
        for u in self.rep:
            for k in range(self.K):
                if estimated[u, k]:
                    yield int(u), k

    def grouped(self, x: np.ndarray) -> np.ndarray:
        """Sums over the combinations of each tie group: (U, ...) -> (G, ...)."""
        return np.tensordot(self.onehot, x, axes=(0, 0))

    def n_free(self) -> int:
        return int(np.maximum(self.free_cells - 1, 0).sum())

    def _normalised(self, g: np.ndarray) -> np.ndarray:
        """Per-group rows (..., G, K, M) with the fixed cells set and the free ones scaled to the free mass."""
        g = np.where(self.gfixed, 0.0, g)
        s = g.sum(-1, keepdims=True)
        g = np.where(self.gfixed, self.gvalues, g / np.where(s > 0, s, 1.0) * self.mass[..., None])
        return g[..., self.group, :, :]

    def random(self, rng: np.random.Generator) -> np.ndarray:
        return self._normalised(random_rows(rng, self.M, (self.G, self.K)))

    def project(self, p: np.ndarray) -> np.ndarray:
        """Put a (..., U, K, M) table back on the constraint set (after extrapolation)."""
        return self._normalised(np.clip(p[..., self.rep, :, :], PROJECT_FLOOR, None))

    def mstep(self, counts: np.ndarray, prior: float, previous: np.ndarray) -> np.ndarray:
        """Closed-form M-step for (..., U, K, M) expected counts (leading axes: independent fits)."""
        cg = np.moveaxis(np.moveaxis(counts, -3, -1) @ self.onehot, -1, -3)  # (..., G, K, M)
        free = np.where(self.gfixed, 0.0, cg + prior)
        tot = free.sum(-1, keepdims=True)
        prev = previous[..., self.rep, :, :]
        est = free / np.where(tot > 0, tot, 1.0) * self.mass[..., None]
        g = np.where(self.gfixed, self.gvalues, np.where(tot > 0, est, prev))
        return g[..., self.group, :, :]

    def log_prior(self, p: np.ndarray, prior: float) -> np.ndarray:
        """Dirichlet log-density (up to a constant) over the leading axes."""
        if prior == 0:
            return np.zeros(p.shape[:-3])
        g = np.log(np.maximum(p[..., self.rep, :, :], FLOOR))
        return prior * np.where(self.gfixed, 0.0, g).sum((-3, -2, -1))


def select_rows(where: Mapping[str, str], inputs: Sequence[str], cats: Mapping[str, Sequence[str]], what: str) -> np.ndarray:
    """Boolean mask over the input combinations matching ``where``."""
    sizes = [len(cats[c]) for c in inputs]
    mask = np.ones(sizes or [1], dtype=bool)
    for col, val in where.items():
        if col not in inputs:
            raise FitError([f"{what}: {col!r} is not one of the inputs {list(inputs)}"])
        if val not in cats[col]:
            raise FitError([f"{what}: {col}={val!r} is not one of {list(cats[col])}"])
        idx: list[slice | list[int]] = [slice(None)] * len(inputs)
        idx[list(inputs).index(col)] = [i for i, v in enumerate(cats[col]) if v != val]
        mask[tuple(idx)] = False
    return mask.ravel()


def describe_combination(u: int, inputs: Sequence[str], cats: Mapping[str, Sequence[str]]) -> str:
    """``complexity=high, robot_action=ask`` for input combination ``u``."""
    if not inputs:
        return "no inputs"
    idx = np.unravel_index(int(u), [len(cats[c]) for c in inputs])
    return ", ".join(f"{c}={cats[c][int(i)]}" for c, i in zip(inputs, idx, strict=True))


class Structure:
    """An :class:`IOHMMSpec` compiled against data (which rows have events)."""

    joint = False  # True for a spec with a rating: parameters carry the joint emission (:mod:`.ratings`)

    def __init__(self, spec: IOHMMSpec, seqs: Sequences):
        problems = spec.problems()
        if problems:
            raise FitError(problems)
        self.spec = spec
        K, M = spec.n_levels, spec.n_outputs
        Ue, Ut = spec.n_combinations(spec.emission_inputs), spec.n_combinations(spec.transition_inputs)
        self.K, self.M, self.Ue, self.Ut = K, M, Ue, Ut
        self.em = Table(Ue, K, M)
        self.tr = Table(Ut, K, K)
        self._fix_rows()
        self._tie_rows()
        # data events behind each combination
        obs = seqs.y >= 0
        self.em_events = np.bincount(seqs.ue[obs], minlength=Ue).astype(float)
        self.tr_events = np.bincount(seqs.ut[:-1][seqs.has_successor()], minlength=Ut).astype(float)
        self.em.finish(self.em_events, np.full((K, M), 1.0 / M))
        self.tr.finish(self.tr_events, np.eye(K))
        self.n_free = (K - 1) + self.em.n_free() + self.tr.n_free()
        self._check_possible(seqs)

    @property
    def dims(self) -> tuple[int, int, int, int]:
        """(K levels, M outputs, Ue emission-input and Ut transition-input combinations)."""
        return self.K, self.M, self.Ue, self.Ut

    def _fix_rows(self) -> None:
        spec, cats = self.spec, self.spec.categories
        for f in spec.fixed_emissions:
            mask = select_rows(f.where, spec.emission_inputs, cats, "fixed emission")
            if isinstance(f.probs, str):
                raise FitError([f"fixed emission rows need probabilities, got {f.probs!r}"])
            for cat, p in f.probs.items():
                if cat not in spec.output_categories:
                    raise FitError([f"fixed emission: {cat!r} is not an output category {list(spec.output_categories)}"])
                j = spec.output_categories.index(cat)
                self.em.fixed[mask, :, j] = True
                self.em.values[mask, :, j] = float(p)
        for f in spec.fixed_transitions:
            mask = select_rows(f.where, spec.transition_inputs, cats, "fixed transition")
            if f.probs != "identity":
                raise FitError([f"fixed transition rows support 'identity', got {f.probs!r}"])
            self.tr.fixed[mask] = True
            self.tr.values[mask] = np.eye(self.K)

    def _tie_rows(self) -> None:
        spec = self.spec
        for table, ties, inputs, what in (
            (self.em, spec.tied_emissions, spec.emission_inputs, "tied emission"),
            (self.tr, spec.tied_transitions, spec.transition_inputs, "tied transition"),
        ):
            for gi, group in enumerate(ties):
                mask = np.zeros(table.U, dtype=bool)
                for where in group:
                    mask |= select_rows(where, inputs, spec.categories, what)
                rows = np.flatnonzero(mask)
                if len(rows) and len({(table.fixed[r].tobytes(), table.values[r].tobytes()) for r in rows}) > 1:
                    raise FitError([f"{what} group {gi + 1} ties rows with different fixed cells"])
                table.group[rows] = rows[0] if len(rows) else 0

    def _check_possible(self, seqs: Sequences) -> None:
        """Report every observed output that a fixed cell rules out at all levels."""
        spec = self.spec
        zero_all = np.all(self.em.fixed & (self.em.values == 0), axis=1)  # (Ue, M): impossible at every level
        # (the rows of an output no fixed cell rules out need not be looked at)
        ruled_out = np.append(zero_all.any(0), False)  # (M + 1,): the last entry for an unobserved output (-1)
        if not ruled_out[seqs.y].any():
            return
        obs = seqs.y >= 0
        yo, uo = seqs.y[obs], seqs.ue[obs]
        bad = zero_all[uo, yo]
        if not bad.any():
            return
        rows = seqs.rows[obs][bad]
        lines = [
            f"row {r + 1}: {spec.output} = {spec.output_categories[y]!r} is impossible under a fixed cell "
            f"({describe_combination(u, spec.emission_inputs, spec.categories)})"
            for r, y, u in zip(rows[:10], yo[bad][:10], uo[bad][:10], strict=True)
        ]
        if bad.sum() > 10:
            lines.append(f"... and {int(bad.sum()) - 10} more")
        raise FitError(lines)

    def action_counts(self, counts: np.ndarray) -> np.ndarray:
        """Expected counts of the output's emission table from the E-step's emission counts."""
        return counts

    def random(self, rng: np.random.Generator) -> Params:
        """A random start inside the constraints, with no exact zero (EM could not leave it)."""
        return Params(random_rows(rng, self.K), self.em.random(rng), self.tr.random(rng))

    def project(self, p: Params) -> Params:
        pi = np.clip(p.initial, PROJECT_FLOOR, None)
        return Params(pi / pi.sum(-1, keepdims=True), self.em.project(p.emission), self.tr.project(p.transition))

    def mstep(self, stats: EStep, previous: Params, prior: float | None = None) -> Params:
        """The maximising parameters for the expected counts ``stats`` plus ``prior`` pseudo-counts
        per free cell (the spec's by default)."""
        a = self.spec.prior if prior is None else prior
        return Params(
            normalised(stats.initial + a, previous.initial),
            self.em.mstep(stats.emission, a, previous.emission),
            self.tr.mstep(stats.transition, a, previous.transition),
        )

    def log_prior(self, p: Params) -> np.ndarray:
        """Dirichlet log-prior of the free cells, up to a constant (a 0-d array for one parameter set)."""
        a = self.spec.prior
        if a == 0:
            return np.zeros(p.initial.shape[:-1])
        return (
            a * np.log(np.maximum(p.initial, FLOOR)).sum(-1)
            + self.em.log_prior(p.emission, a)
            + self.tr.log_prior(p.transition, a)
        )

    def order(self, p: Params) -> np.ndarray:
        """Permutation putting levels in ascending order of P(category) averaged over the ``order_by``
        rows the data reach (all of them if none); ties (to 1e-9) by the same over every reached row
        not fixed, then by the initial probability, then by index."""
        spec = self.spec
        if spec.order_by is None or self.K == 1:
            return np.arange(self.K)
        where, cat = spec.order_by
        o = spec.output_categories.index(cat)
        rows = select_rows(where, spec.emission_inputs, spec.categories, "order_by")
        mask = rows & ~self.em.empty
        if not mask.any():
            mask = rows
        score = p.emission[mask][:, :, o].mean(0)
        free = self.em.estimated().any(-1)
        overall = p.emission[free][:, :, o].mean(0) if free.any() else np.zeros(self.K)
        keys = (np.arange(self.K), np.round(p.initial, 9), np.round(overall, 9), np.round(score, 9))
        return np.lexsort(keys)
