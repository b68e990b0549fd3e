"""Participant-level bootstrap of a trust-model fit: percentile intervals for every TrustModel cell.

Each replicate resamples participants with replacement and refits from the point
estimate and a few random starts.  Replicate b always uses the b-th child of the seed,
so the intervals do not depend on how many processes compute them.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass

import numpy as np

from .iohmm import fit_iohmm
from .sequences import Sequences
from .spec import IOHMMSpec, Params
from .trust_iohmm import to_trust_model

log = logging.getLogger(__name__)

TABLES = ("initial", "emission", "transition")


@dataclass(frozen=True)
class _Replicate:
    """One bootstrap replicate, sent whole to a worker process."""

    seqs: Sequences
    spec: IOHMMSpec
    params: Params
    seed: np.random.SeedSequence
    restarts: int
    tol: float
    max_iter: int

    def run(self) -> np.ndarray:
        """The refitted TrustModel's cells, flattened table after table."""
        rng = np.random.default_rng(self.seed)
        n = self.seqs.n_participants
        sample = self.seqs.subset(rng.integers(0, n, n))
        fit = fit_iohmm(
            sample,
            self.spec,
            restarts=self.restarts,
            seed=self.seed.spawn(1)[0],
            tol=self.tol,
            max_iter=self.max_iter,
            init=[self.params],
        )
        m = to_trust_model(self.spec, fit.params)
        return np.concatenate([getattr(m, name).ravel() for name in TABLES])


def bootstrap_ci(
    seqs: Sequences,
    spec: IOHMMSpec,
    params: Params,
    replicates: int,
    seed: int = 0,
    restarts: int = 3,
    n_jobs: int | None = None,
    tol: float = 1e-8,
    max_iter: int = 1000,
    level: float = 0.95,
    progress: Callable[[], None] | None = None,
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Percentile intervals at ``level`` for every TrustModel cell, over ``replicates`` resamples.

    Replicates run over ``n_jobs`` processes (default: all cores); ``progress()`` is
    called as each one finishes.
    """
    children = np.random.SeedSequence([seed, 1]).spawn(replicates)
    jobs = [_Replicate(seqs, spec, params, ch, restarts, tol, max_iter) for ch in children]
    n_jobs = n_jobs or os.cpu_count() or 1
    results: dict[int, np.ndarray] = {}

    def done(i: int, cells: np.ndarray) -> None:
        results[i] = cells
        log.debug("bootstrap replicate %d done (%d of %d)", i, len(results), replicates)
        if progress is not None:
            progress()

    log.info(
        "bootstrap: %d replicates of %d participants over %d processes", replicates, seqs.n_participants, min(n_jobs, replicates)
    )
    if n_jobs <= 1 or replicates == 1:
        for i, job in enumerate(jobs):
            done(i, job.run())
    else:
        with ProcessPoolExecutor(max_workers=min(n_jobs, replicates)) as ex:
            futures = {ex.submit(job.run): i for i, job in enumerate(jobs)}
            for f in as_completed(futures):
                done(futures[f], f.result())
    draws = np.vstack([results[i] for i in range(replicates)])
    alpha = (1 - level) / 2
    lo, hi = np.quantile(draws, [alpha, 1 - alpha], axis=0)
    ref = to_trust_model(spec, params)
    out = {}
    pos = 0
    for name in TABLES:
        shape = getattr(ref, name).shape
        size = int(np.prod(shape))
        out[name] = (lo[pos : pos + size].reshape(shape), hi[pos : pos + size].reshape(shape))
        pos += size
    return out
