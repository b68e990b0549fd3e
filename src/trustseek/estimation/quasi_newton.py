"""The quasi-Newton finish of an EM run: L-BFGS-B on the free cells, gradient by Fisher's identity.

EM crawls along flat ridges of the likelihood (weakly identified directions) with
tiny steps, and a relative-change test then stops it short of the maximum; a
quasi-Newton method walks such ridges.  The free cells are written as
stick-breaking fractions in [0, 1] (a box, so cells can sit on the boundary
exactly), and the gradient comes free with the E-step's expected counts.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import minimize
from threadpoolctl import ThreadpoolController

from ..compiled import python
from . import kernels
from .em import CAPPED, RunResult
from .estep import EStep, Workspace
from .spec import Params
from .structure import FLOOR, Structure

MEMORY = 20  # L-BFGS-B correction pairs
RECENT = 32  # evaluations remembered to recover the parameters of an accepted iterate


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
    """Free cells as stick-breaking fractions in [0, 1]: a box, for L-BFGS-B.

    A row with free cells c_0..c_{m-1} and free mass s holds p_0 = s v_0,
    p_j = s v_j prod_{i<j} (1 - v_i), p_{m-1} = s prod_{i<m-1} (1 - v_i).  With
    expected counts (plus pseudo-counts) w, the gradient of the objective is, by
    Fisher's identity, w_j / v_j - (sum_{i>j} w_i) / (1 - v_j).
    """

    EPS = 1e-12

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
        out = []
        for part in self.parts:
            flat = np.empty(part.rows * part.m)
            flat[part.src] = getattr(p, part.table).ravel()[part.dst]
            vals = flat.reshape(part.rows, part.m)
            rem = part.mass.copy()
            for j in range(part.m - 1):
                out.append(np.clip(vals[:, j] / np.maximum(rem, FLOOR), self.EPS, 1 - self.EPS))
                rem = rem - vals[:, j]
        return np.concatenate(out) if out else np.zeros(0)

    def _layout(self) -> tuple[np.ndarray, ...]:
        """The parts as per-row arrays for the compiled :func:`~.kernels.stick_values` and
        :func:`~.kernels.stick_gradient` (built on first use; ``parts`` may be set after construction)."""
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
        table, m, mass, tbase, tstride, coff, cptr, cdst = self._layout()
        python(kernels.stick_values)(  # a few cells: not worth loading numba for
            np.ascontiguousarray(theta, dtype=float),
            table,
            m,
            mass,
            tbase,
            tstride,
            coff,
            cptr,
            cdst,
            out.initial.reshape(-1),
            out.emission.reshape(-1),
            out.transition.reshape(-1),
        )
        return out

    def gradient(self, theta: np.ndarray, st: EStep) -> np.ndarray:
        """Gradient of the objective with respect to ``theta`` from the E-step at that point."""
        table, m, _mass, tbase, tstride, coff, cptr, cdst = self._layout()
        out = np.empty(len(theta))
        python(kernels.stick_gradient)(
            np.ascontiguousarray(theta, dtype=float),
            float(self.structure.spec.prior),
            table,
            m,
            tbase,
            tstride,
            coff,
            cptr,
            cdst,
            np.ascontiguousarray(st.initial, dtype=float).reshape(-1),
            np.ascontiguousarray(st.emission, dtype=float).reshape(-1),
            np.ascontiguousarray(st.transition, dtype=float).reshape(-1),
            out,
        )
        return out


_blas: dict[str, Any] = {"controller": None, "depth": 0, "limiter": None}
_blas_lock = threading.Lock()


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """BLAS limited to one thread while inside (reentrant, and shared by threads: the limit is set
    by the first to enter and lifted by the last to leave).  L-BFGS-B makes a few tiny BLAS calls
    per iteration, which a multithreaded BLAS slows by two orders of magnitude on a busy machine."""
    with _blas_lock:
        if _blas["depth"] == 0:
            if _blas["controller"] is None:
                _blas["controller"] = ThreadpoolController()
            _blas["limiter"] = _blas["controller"].limit(limits=1, user_api="blas")
        _blas["depth"] += 1
    try:
        yield
    finally:
        with _blas_lock:
            _blas["depth"] -= 1
            if _blas["depth"] == 0:
                _blas["limiter"].restore_original_limits()
                _blas["limiter"] = None


class _Budget(Exception):
    """The finish ran out of E-steps."""


@dataclass
class _Best:
    """The best point L-BFGS-B has accepted so far, and the recent evaluations to find it among."""

    objective: float
    params: Params
    loglik: float
    history: list[float]
    seen: dict[bytes, tuple[float, Params, float]] = field(default_factory=dict)

    def remember(self, theta: np.ndarray, f: float, p: Params, ll: float) -> None:
        if len(self.seen) > RECENT:
            self.seen.pop(next(iter(self.seen)))
        self.seen[np.asarray(theta, dtype=float).tobytes()] = (f, p, ll)

    def accept(self, theta: np.ndarray) -> None:
        hit = self.seen.get(np.asarray(theta, dtype=float).tobytes())
        if hit is not None and hit[0] >= self.objective:
            if hit[0] > self.objective:
                self.history.append(float(hit[0]))
            self.objective, self.params, self.loglik = hit


def finish(
    structure: Structure, work: Workspace, run: RunResult, tol: float = 1e-8, max_iter: int = 1000, sticks: Sticks | None = None
) -> RunResult:
    """Continue a run with L-BFGS-B on the stick-breaking fractions of the free cells.

    Every iterate of L-BFGS-B decreases the negated objective, and the result is kept
    only if its objective is at least the run's, so the objective history never
    decreases.  It stops when the relative change per iteration falls below ``tol``,
    which on a badly scaled stretch of the likelihood can happen short of a stationary
    point (:mod:`.convergence` checks and goes on); iterations count E-steps, within
    ``max_iter`` in total.  ``sticks``: the free cells' layout, when not the structure's own
    (a mixture's tables).
    """
    t0 = time.perf_counter()
    budget = max_iter - run.iterations
    sticks = Sticks(structure) if sticks is None else sticks
    if budget < 2 or sticks.size == 0 or not math.isfinite(run.objective):
        return run
    base = run.params
    best = _Best(run.objective, run.params, run.loglik, list(run.history))
    calls = 0

    def fun(theta: np.ndarray) -> tuple[float, np.ndarray]:
        nonlocal calls
        if calls >= budget:
            raise _Budget
        calls += 1
        p = sticks.params(theta, base)
        st = work.estep(p)
        f = float(st.loglik + structure.log_prior(p))
        best.remember(theta, f, p, float(st.loglik))
        if not math.isfinite(f):
            return math.inf, np.zeros_like(theta)
        return -f, -sticks.gradient(theta, st)

    try:
        with one_blas_thread():
            res = minimize(
                fun,
                sticks.theta(base),
                jac=True,
                method="L-BFGS-B",
                bounds=[(sticks.EPS, 1 - sticks.EPS)] * sticks.size,
                callback=best.accept,
                options={"ftol": tol, "gtol": 0.0, "maxfun": budget, "maxiter": budget, "maxcor": MEMORY},
            )
        best.accept(res.x)
        success = calls < budget  # stopped by its tolerance (or at the limits of precision), not by the cap
    except _Budget:  # the E-step cap: keep the best accepted point
        success = False
    converged = run.converged and success
    return RunResult(
        best.params,
        best.loglik,
        best.objective,
        best.history,
        run.iterations + calls,
        converged,
        run.seconds + time.perf_counter() - t0,
        run.ended if converged else CAPPED,
        run.finishes + 1,
    )
