"""The free cells of a fit as stick-breaking fractions in [0, 1]: a box, for the quasi-Newton finish.

A row with free cells c_0..c_{m-1} and free mass s holds p_0 = s v_0,
p_j = s v_j prod_{i<j} (1 - v_i), p_{m-1} = s prod_{i<m-1} (1 - v_i); the gradient of the
objective comes from the E-step's expected counts by Fisher's identity.  :class:`Sticks` is
the layout (numpy); :func:`stick_theta`, :func:`stick_values` and :func:`stick_gradient` are its
maps, run in plain Python by :class:`Sticks` (a few cells) and compiled inside :mod:`.compiled_run`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..compiled import njit, python
from .estep import EStep
from .spec import Params
from .structure import FLOOR, Structure

EPS = 1e-12  # the fractions' box: [EPS, 1 - EPS]


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
        python(stick_theta)(cells, self._layout(), out)  # a few cells: not worth loading numba for
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
        python(stick_values)(  # a few cells: not worth loading numba for
            np.ascontiguousarray(theta, dtype=float),
            self._layout(),
            (out.initial.reshape(-1), out.emission.reshape(-1), out.transition.reshape(-1)),
        )
        return out

    def gradient(self, theta: np.ndarray, st: EStep) -> np.ndarray:
        """Gradient of the objective with respect to ``theta`` from the E-step at that point."""
        out = np.empty(len(theta))
        counts = (st.initial, st.emission, st.transition)
        python(stick_gradient)(
            np.ascontiguousarray(theta, dtype=float),
            float(self.structure.spec.prior),
            self._layout(),
            tuple(np.ascontiguousarray(c, dtype=float).reshape(-1) for c in counts),
            out,
        )
        return out


@njit(cache=True, nogil=True, inline="always")
def stick_theta(cells, layout, out):
    """The fractions of the flat ``cells`` (initial, emission, transition) in the ``layout`` of
    :func:`stick_values` into ``out``, each in [EPS, 1 - EPS]."""
    table, m, mass, tbase, tstride, coff, cptr, cdst = layout
    f0, f1, f2 = cells
    for i in range(len(m)):
        rem = mass[i]
        for j in range(m[i] - 1):
            q = cdst[cptr[coff[i] + j]]
            val = f0[q] if table[i] == 0 else (f1[q] if table[i] == 1 else f2[q])
            out[tbase[i] + j * tstride[i]] = min(max(val / max(rem, FLOOR), EPS), 1 - EPS)
            rem = rem - val


@njit(cache=True, nogil=True)
def stick_values(theta, layout, out):
    """The cells of stick-breaking rows from their fractions ``theta``, in the ``layout`` (table, m,
    mass, tbase, tstride, coff, cptr, cdst) of :meth:`Sticks._layout`: row i (``m[i]`` cells of
    total ``mass[i]`` in table ``table[i]``: 0 initial, 1 emission, 2 transition) has fraction j
    at ``theta[tbase[i] + j * tstride[i]]``; its cell j goes to the flat positions
    ``cdst[cptr[c]:cptr[c + 1]]`` of that table's ``out`` (initial, emission, transition; flat),
    c = ``coff[i] + j``."""
    table, m, mass, tbase, tstride, coff, cptr, cdst = layout
    out0, out1, out2 = out
    for i in range(len(m)):
        rem = mass[i]
        for j in range(m[i]):
            if j < m[i] - 1:
                v = theta[tbase[i] + j * tstride[i]]
                val = rem * v
                rem = rem * (1 - v)
            else:
                val = rem
            c = coff[i] + j
            for q in range(cptr[c], cptr[c + 1]):
                if table[i] == 0:
                    out0[cdst[q]] = val
                elif table[i] == 1:
                    out1[cdst[q]] = val
                else:
                    out2[cdst[q]] = val


@njit(cache=True, nogil=True)
def stick_gradient(theta, prior, layout, counts, out):
    """The gradient of the objective in the fractions of :func:`stick_values`' ``layout`` into ``out``,
    from the expected ``counts`` of the three tables (initial, emission, transition; flat):
    w_j / v_j - (sum_{i>j} w_i) / (1 - v_j) with w the row's counts plus ``prior``."""
    table, m, _mass, tbase, tstride, coff, cptr, cdst = layout
    w0, w1, w2 = counts
    w = np.empty(int(m.max()) if len(m) else 0)
    for i in range(len(m)):
        for j in range(m[i]):
            c = coff[i] + j
            acc = 0.0
            for q in range(cptr[c], cptr[c + 1]):
                if table[i] == 0:
                    acc += w0[cdst[q]]
                elif table[i] == 1:
                    acc += w1[cdst[q]]
                else:
                    acc += w2[cdst[q]]
            w[j] = acc + prior
        tail = w[m[i] - 1]
        for j in range(m[i] - 2, -1, -1):
            k = tbase[i] + j * tstride[i]
            v = theta[k]
            out[k] = w[j] / v - tail / (1 - v)
            tail = tail + w[j]
