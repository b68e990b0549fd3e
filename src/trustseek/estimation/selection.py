"""Choosing the number of trust levels: BIC on all data and participant-held-out log-likelihood."""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import pandas as pd

from .estep import Workspace
from .iohmm import IOHMMFit, fit_iohmm
from .sequences import Sequences, encode
from .spec import Params
from .trust_iohmm import level_names, preset_spec

log = logging.getLogger(__name__)

HELDOUT_PSEUDOCOUNT = 0.5  # added to every free cell's training counts before held-out scoring


def select_levels(
    frame: pd.DataFrame,
    levels: Sequence[int] = (1, 2, 3, 4),
    folds: int = 5,
    restarts: int = 10,
    seed: int = 0,
    prior: float = 0.0,
    tol: float = 1e-6,
    max_iter: int = 1000,
    progress: Callable[[str, int, int], None] | None = None,
    **spec_options: Any,
) -> list[dict[str, Any]]:
    """Compare numbers of trust levels: BIC on all data and k-fold participant-held-out log-likelihood.

    ``spec_options`` adjust the ``paper`` preset (as for :func:`~.fit.fit_trust_model`);
    ``progress(label, done, total)`` is called after every fit (``label`` names the number
    of levels being compared).
    """
    base = preset_spec("paper", frame, prior=prior, **spec_options)
    seqs = encode(frame, base)
    N = seqs.n_participants
    folds = max(2, min(folds, N))
    perm = np.random.default_rng(np.random.SeedSequence([seed, 2])).permutation(N)
    fold_of = np.empty(N, dtype=np.int64)
    fold_of[perm] = np.arange(N) % folds
    total = len(levels) * (folds + 1)
    done = 0

    def tick(label: str) -> None:
        nonlocal done
        done += 1
        if progress:
            progress(label, done, total)

    rows: list[dict[str, Any]] = []
    for K in levels:
        spec = base.with_levels(level_names(K))
        full = fit_iohmm(seqs, spec, restarts=restarts, seed=np.random.SeedSequence([seed, 3, K]), tol=tol, max_iter=max_iter)
        tick(f"{K} levels")
        per_fold = []
        for f in range(folds):
            train, test = np.flatnonzero(fold_of != f), np.flatnonzero(fold_of == f)
            fit = fit_iohmm(
                seqs.subset(train),
                spec,
                restarts=restarts,
                seed=np.random.SeedSequence([seed, 4, K, f]),
                tol=tol,
                max_iter=max_iter,
            )
            per_fold.append(heldout_loglik(seqs.subset(test), fit))
            tick(f"{K} levels")
        held = float(sum(per_fold))
        log.info("%d levels: log-likelihood %.4f, BIC %.2f, held-out log-likelihood %.4f", K, full.loglik, full.bic, held)
        rows.append(
            {
                "levels": K,
                "loglik": full.loglik,
                "n_params": full.n_params,
                "aic": full.aic,
                "bic": full.bic,
                "heldout_loglik": held,
                "heldout_per_fold": per_fold,
                "restart_logliks": full.restart_logliks,
            }
        )
    best_bic = min(rows, key=lambda r: float(r["bic"]))["levels"]
    best_cv = max(rows, key=lambda r: float(r["heldout_loglik"]))["levels"]
    for r in rows:
        r["best_bic"] = r["levels"] == best_bic
        r["best_heldout"] = r["levels"] == best_cv
    return rows


def heldout_loglik(test: Sequences, fit: IOHMMFit) -> float:
    """Held-out log-likelihood under the training fit, smoothed so that it stays finite.

    A training fold can drive a cell to exactly 0 (no training participant ever did
    that) while a held-out participant does it: the held-out log-likelihood would be
    -inf, and every number of levels would tie at -inf.  The model is therefore scored
    with the training fit's expected counts plus :data:`HELDOUT_PSEUDOCOUNT` per free
    cell (one smoothed M-step from the maximum-likelihood point).  Input rows unseen in
    training keep their defaults.
    """
    s = fit.structure
    st = fit.workspace().estep(fit.params)
    a = fit.spec.prior + HELDOUT_PSEUDOCOUNT
    c0 = st.initial + a
    params = Params(
        c0 / c0.sum(), s.em.mstep(st.emission, a, fit.params.emission), s.tr.mstep(st.transition, a, fit.params.transition)
    )
    return float(Workspace(test, *s.dims).loglik(params))
