"""The result of the model fits (:func:`.fit.fit_trust_model`, :func:`.fit.fit_model`): :class:`FitResult`,
the EM fit (:class:`~.iohmm.EMFit`, which a mixture's fit extends too) with its model and diagnostics.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from ..model.core import TrustModel
from .iohmm import EMFit, posterior_frame
from .trust_iohmm import index_grid, model_categories

if TYPE_CHECKING:
    from .bootstrap import Intervals


def _listed(n: int) -> range:
    """The categories of a distribution over ``n`` whose cells are listed: of two, the second only."""
    return range(1, n) if n == 2 else range(n)


@dataclass
class FitResult(EMFit):
    """A fitted model (a trust model or a general one) with its EM fit and diagnostics: the
    expected events behind every row (``events``), warnings for rows the data do not identify,
    the seed, and bootstrap intervals (``intervals``) when asked for.  A trust model's result also
    has the events and the estimated cells in the trust model's index (``counts``,
    ``estimated``), the intervals as (lower, upper) tables (``ci``) and the number of replicates
    (``bootstrap``)."""

    model: TrustModel
    events: dict[str, np.ndarray]
    counts: dict[str, np.ndarray] = field(default_factory=dict)
    estimated: dict[str, np.ndarray] = field(default_factory=dict)
    seed: int = 0
    warnings: list[str] = field(default_factory=list)
    intervals: Intervals | None = None

    @property
    def ci(self) -> dict[str, tuple[np.ndarray, np.ndarray]] | None:
        """The bootstrap intervals as (lower, upper) tables, by table (None without a bootstrap)."""
        return None if self.intervals is None else self.intervals.intervals

    @property
    def bootstrap(self) -> int:
        """The number of bootstrap replicates (0: none)."""
        return 0 if self.intervals is None else self.intervals.replicates

    @classmethod
    def of(cls, fit: EMFit, model: TrustModel, events: dict[str, np.ndarray], seed: int) -> FitResult:
        """``fit`` with its model, the expected events behind its rows and the seed."""
        return cls(**{f.name: getattr(fit, f.name) for f in fields(EMFit)}, model=model, events=events, seed=seed)

    def posteriors(self) -> pd.DataFrame:
        """Smoothed P(level | all trials of the participant) and the Viterbi level, one row per trial."""
        return posterior_frame(self.seqs, self.spec, self.params)

    def fit_record(self) -> dict[str, Any]:
        """The fit's figures, each start's run, the seed, the bootstrap and the spec, for ``to_dict``."""
        runs, iv = self.runs, self.intervals
        return {
            **self.figures(),
            "n_observations": self.n_observations,
            "restart_logliks": self.restart_logliks,
            "best_restart": self.best,
            "iterations": [r.iterations for r in runs],
            "subsample_iterations": [r.subsample_iterations for r in runs],
            "converged": [r.converged for r in runs],
            "ended": [r.ended for r in runs],
            "seconds": [r.seconds for r in runs],
            "seed": self.seed,
            "bootstrap": self.bootstrap,
            "ci_level": None if iv is None else iv.level,
            "ci_method": None if iv is None else iv.method,
            "ci_other_maximum": None if iv is None else iv.other_maximum,
            "spec": self.spec.to_dict(),
        }

    def to_dict(self) -> dict[str, Any]:
        """The model, the fit's figures and runs, the seed, the bootstrap, the spec and the warnings
        (a trust model's also its counts, estimated cells and intervals), for JSON."""
        out = {"model": self.model.to_dict(), **self.fit_record()}
        if not self.model.general:
            out["counts"] = {k: v.tolist() for k, v in self.counts.items()}
            out["estimated"] = {k: v.tolist() for k, v in self.estimated.items()}
            out["ci"] = (
                None if self.ci is None else {k: {"lower": lo.tolist(), "upper": hi.tolist()} for k, (lo, hi) in self.ci.items()}
            )
        return out | {"warnings": list(self.warnings)}

    def cells(self) -> list[dict[str, Any]]:
        """One record per estimated cell: label, index (a trust model's) or table, input levels and
        category (a general model's), estimate, interval, expected events.  A model whose tables
        ignore some inputs lists each distinct row once, labelled by the inputs it depends on;
        fixed and never-reached rows are left out."""
        if self.model.general:
            return self._model_cells(self.model)
        return self._trust_cells(self.model)

    def _with_interval(self, rec: dict[str, Any], table: str, idx: tuple[int, ...]) -> dict[str, Any]:
        """``rec`` with the bootstrap interval of cell ``idx`` of ``table``, when there is one."""
        if self.intervals is not None:
            lo, hi = self.intervals.intervals[table]
            rec["lower"], rec["upper"] = float(lo[idx]), float(hi[idx])
            rec["widened"] = bool(self.intervals.widened[table][idx])
        return rec

    def _trust_cells(self, m: TrustModel) -> list[dict[str, Any]]:
        """A trust model's cells: label, TrustModel index, estimate, CI, events (see :meth:`cells`)."""
        spec = self.spec
        T = m.trust_levels
        short = {"complexity": "C", "robot_action": "a", "experience": "E'"}
        names = model_categories(m.complexities)
        out: list[dict[str, Any]] = []
        seen: set[tuple[Any, ...]] = set()

        def add(table: str, idx: tuple[int, ...], label: str, key: tuple[Any, ...]) -> None:
            if not self.estimated[table][idx] or key in seen:
                return
            seen.add(key)
            rec: dict[str, Any] = {
                "table": table,
                "index": list(idx),
                "cell": label,
                "estimate": float((m.rating.probs if table == "rating" and m.rating is not None else getattr(m, table))[idx]),
                "events": float(self.counts[table][idx]),
            }
            out.append(self._with_interval(rec, table, idx))

        def cond(inputs: Sequence[str], values: dict[str, int]) -> str:
            return "".join(f", {short[c]}={names[c][values[c]]}" for c in inputs)

        for t in _listed(m.n_trust):
            add("initial", (t,), f"P(T1={T[t]})", ("i", t))
        eg = index_grid(spec, spec.emission_inputs, False)
        for c, a, t in np.ndindex(m.n_complexity, 2, m.n_trust):
            v = {"complexity": c, "robot_action": a}
            add("emission", (c, a, t, 1), f"P(rely | T={T[t]}{cond(spec.emission_inputs, v)})", ("e", int(eg[c, a]), t))
        tg = index_grid(spec, spec.transition_inputs, True)
        for c, a, e, t in np.ndindex(m.n_complexity, 2, 2, m.n_trust):
            v = {"complexity": c, "robot_action": a, "experience": e}
            for u in _listed(m.n_trust):
                label = f"P(T'={T[u]} | T={T[t]}{cond(spec.transition_inputs, v)})"
                add("transition", (c, a, e, t, u), label, ("t", int(tg[c, a, e]), t, u))
        if m.rating is not None and "rating" in self.estimated:
            levels = m.rating.levels
            for t, r in np.ndindex(m.n_trust, len(levels)):
                add("rating", (t, r), f"P(rating={levels[r]} | T={T[t]})", ("r", t, r))
        return out

    def _model_cells(self, m: TrustModel) -> list[dict[str, Any]]:
        """A general model's row cells: label, table, input levels, estimate, expected events
        (tied rows once, fixed and never-reached rows left out; of two categories the second only)."""
        s = self.structure
        L = m.levels
        out: list[dict[str, Any]] = []

        for k in _listed(m.n_levels):
            rec = {
                "table": "initial",
                "where": {},
                "cell": f"P(S1={L[k]})",
                "estimate": float(m.initial[k]),
                "events": float(self.events["initial"][k]),
            }
            out.append(self._with_interval(rec, "initial", (k,)))
        for name, table, arr, cats in (
            ("emission", s.em, m.emission_rows, m.output_categories),
            ("transition", s.tr, m.transition_rows, L),
        ):
            for u, k in table.estimated_rows():
                where = m.combination(name, u)
                cond = "".join(f", {c}={v}" for c, v in where.items())
                for j in _listed(len(cats)):
                    head = f"{m.output}={cats[j]}" if name == "emission" else f"S'={cats[j]}"
                    rec = {
                        "table": name,
                        "where": where,
                        "level": L[k],
                        "category": cats[j],
                        "cell": f"P({head} | S={L[k]}{cond})",
                        "estimate": float(arr[u, k, j]),
                        "events": float(self.events[name][u, k]),
                    }
                    out.append(self._with_interval(rec, name, (u, k, j)))
        if m.rating is not None and "rating" in self.events:
            for k in range(m.n_levels):
                for r, lv in enumerate(m.rating.levels):
                    out.append(
                        {
                            "table": "rating",
                            "where": {},
                            "level": L[k],
                            "category": lv,
                            "cell": f"P(rating={lv} | S={L[k]})",
                            "estimate": float(m.rating.probs[k, r]),
                            "events": float(self.events["rating"][k].sum()),
                        }
                    )
        return out
