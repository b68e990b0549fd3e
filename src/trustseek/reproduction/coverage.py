"""How often the fit's bootstrap intervals cover the truth, on simulated data sets."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..estimation.bootstrap import BOUNDARY
from ..estimation.fit import fit_trust_model
from ..estimation.options import FitOptions
from ..model.core import TrustModel
from ..simulation.designs import simulate_design
from .config import seed_int


def coverage_study(
    model: TrustModel,
    n_participants: int = 9,
    datasets: int = 20,
    bootstrap: int = 100,
    seed: int = 0,
    restarts: int = 5,
    n_jobs: int | None = None,
    tol: float = 1e-6,
    truth: TrustModel | None = None,
) -> list[dict[str, Any]]:
    """How often the 95 % bootstrap intervals cover the truth, cell by cell, over ``datasets``
    logs simulated from ``model`` (paper design) and fitted with a ``bootstrap``-replicate
    participant bootstrap.  One record per cell: truth, coverage, mean width and estimate, and of
    the data sets whose estimate lies at 0 or 1 their number (``at_boundary``), coverage
    (``boundary_coverage``, NaN without any) and likelihood-ratio intervals (``likelihood``).
    ``truth`` scores the intervals against another model (a negative control).
    """
    target = model if truth is None else truth
    hits: dict[str, list[float]] = {}
    widths: dict[str, list[float]] = {}
    ests: dict[str, list[float]] = {}
    truths: dict[str, float] = {}
    edge: dict[str, list[float]] = {}
    lr: dict[str, int] = {}
    for d in range(datasets):
        df = simulate_design(model, n_participants, seed=seed_int(np.random.SeedSequence([seed, 5, d])))
        res = fit_trust_model(
            df, options=FitOptions(restarts=restarts, seed=seed + d, tol=tol, n_jobs=n_jobs), bootstrap=bootstrap
        )
        for c in res.cells():
            key = c["cell"]
            t = float(getattr(target, c["table"])[tuple(c["index"])])
            truths[key] = t
            hits.setdefault(key, []).append(float(c["lower"] - 1e-9 <= t <= c["upper"] + 1e-9))
            widths.setdefault(key, []).append(c["upper"] - c["lower"])
            ests.setdefault(key, []).append(c["estimate"])
            if min(c["estimate"], 1 - c["estimate"]) < BOUNDARY:
                edge.setdefault(key, []).append(hits[key][-1])
                mark = res.intervals.likelihood.get(c["table"]) if res.intervals is not None else None
                lr[key] = lr.get(key, 0) + int(mark is not None and bool(mark[tuple(c["index"])]))
    return [
        {
            "cell": k,
            "truth": truths[k],
            "coverage": float(np.mean(v)),
            "datasets": len(v),
            "mean_width": float(np.mean(widths[k])),
            "mean_estimate": float(np.mean(ests[k])),
            "at_boundary": len(edge.get(k, [])),
            "boundary_coverage": float(np.mean(edge[k])) if edge.get(k) else float("nan"),
            "likelihood": lr.get(k, 0),
        }
        for k, v in hits.items()
    ]
