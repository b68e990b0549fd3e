"""The free cells of a fit as stick-breaking fractions in [0, 1]: a box, for the quasi-Newton finish.

A row with free cells c_0..c_{m-1} and free mass s holds p_0 = s v_0,
p_j = s v_j prod_{i<j} (1 - v_i), p_{m-1} = s prod_{i<m-1} (1 - v_i); the gradient of the
objective comes from the E-step's expected counts by Fisher's identity.  :class:`Sticks` is
the layout (numpy); its maps, compiled, are those of :mod:`.stick_maps`, which the compiled run's
finish (:mod:`.compiled_em`) calls too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .estep import EStep
from .spec import Params
from .stick_maps import EPS as EPS  # the fractions' box: [EPS, 1 - EPS]
from .stick_maps import stick_gradient, stick_theta, stick_values
from .structure import Structure


@dataclass
class _Part:
    """Rows with the same number m of free cells in one table: cell j of row r is value r * m + j,
    stored at the flat positions ``dst`` of the full array (every member of a tie group), taken
    from the values ``src``."""

    table: str
    rows: int
    m: int
    mass: np.ndarray  # (rows,) probability the free cells share
    dst: np.ndarray
    src: np.ndarray


class Sticks:
    """The layout of a structure's free cells as stick-breaking fractions (see the module)."""

    def __init__(self, structure: Structure):
        self.structure = structure
        K = structure.K
        self.parts: list[_Part] = []
        if K >= 2:
            self.parts.append(_Part("initial", 1, K, np.ones(1), np.arange(K), np.arange(K)))
        for name, table in (("emission", structure.em), ("transition", structure.tr)):
            rows: dict[int, list[tuple[int, int, np.ndarray]]] = {}
            for g in range(table.G):
                for k in range(K):
                    cells = np.flatnonzero(~table.gfixed[g, k])
                    if len(cells) >= 2 and table.mass[g, k] > 0:
                        rows.setdefault(len(cells), []).append((g, k, cells))
            KM = K * table.M
            for m, lst in sorted(rows.items()):
                dst: list[np.ndarray] = []
                src: list[np.ndarray] = []
                for r, (g, k, cells) in enumerate(lst):
                    for u in np.flatnonzero(table.group == g):
                        dst.append(u * KM + k * table.M + cells)
                        src.append(r * m + np.arange(m))
                mass = np.array([table.mass[g, k] for g, k, _ in lst])
                self.parts.append(
                    _Part(name, len(lst), m, mass, np.concatenate(dst).astype(np.int64), np.concatenate(src).astype(np.int64))
                )
        self.size = sum(p.rows * (p.m - 1) for p in self.parts)
        self._built: tuple[list[_Part], tuple[np.ndarray, ...]] | None = None

    def theta(self, p: Params) -> np.ndarray:
        """The fractions of the free cells of ``p``."""
        out = np.empty(self.size)
        cells = tuple(np.ascontiguousarray(a, dtype=float).reshape(-1) for a in (p.initial, p.emission, p.transition))
        stick_theta(cells, self._layout(), out)
        return out

    def _layout(self) -> tuple[np.ndarray, ...]:
        """The parts as per-row arrays for the compiled :func:`stick_values` and
        :func:`stick_gradient` (built on first use; ``parts`` may be set after construction)."""
        if self._built is not None and self._built[0] is self.parts:
            return self._built[1]
        codes = {"initial": 0, "emission": 1, "transition": 2}
        table, m, mass, tbase, tstride, coff = [], [], [], [], [], []
        counts: list[int] = []
        dsts: list[np.ndarray] = []
        pos = cells = 0
        for part in self.parts:
            order = np.argsort(part.src, kind="stable")  # each value's positions, in their order in dst
            counts.extend(np.bincount(part.src, minlength=part.rows * part.m).tolist())
            dsts.append(part.dst[order])
            for r in range(part.rows):
                table.append(codes[part.table])
                m.append(part.m)
                mass.append(part.mass[r])
                tbase.append(pos + r)
                tstride.append(part.rows)
                coff.append(cells)
                cells += part.m
            pos += part.rows * (part.m - 1)
        i64 = np.int64
        layout = (
            np.array(table, dtype=i64),
            np.array(m, dtype=i64),
            np.array(mass, dtype=float),
            np.array(tbase, dtype=i64),
            np.array(tstride, dtype=i64),
            np.array(coff, dtype=i64),
            np.concatenate([[0], np.cumsum(counts)]).astype(i64),
            np.concatenate(dsts).astype(i64) if dsts else np.zeros(0, dtype=i64),
        )
        self._built = (self.parts, layout)
        return layout

    def params(self, theta: np.ndarray, base: Params) -> Params:
        """``base`` with its free cells set from the fractions ``theta``."""
        out = Params(base.initial.copy(), base.emission.copy(), base.transition.copy())
        stick_values(
            np.ascontiguousarray(theta, dtype=float),
            self._layout(),
            (out.initial.reshape(-1), out.emission.reshape(-1), out.transition.reshape(-1)),
        )
        return out

    def gradient(self, theta: np.ndarray, st: EStep) -> np.ndarray:
        """Gradient of the objective with respect to ``theta`` from the E-step at that point."""
        out = np.empty(len(theta))
        counts = (st.initial, st.emission, st.transition)
        stick_gradient(
            np.ascontiguousarray(theta, dtype=float),
            float(self.structure.spec.prior),
            self._layout(),
            tuple(np.ascontiguousarray(c, dtype=float).reshape(-1) for c in counts),
            out,
        )
        return out
