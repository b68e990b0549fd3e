"""Choosing the number of supervisor types: BIC on all data and participant-held-out log-likelihood.

Each M-type fit (:func:`~.mixture.fit_mixture`) starts from random points, from the pooled
fit with every row perturbed, and from the fit with one type fewer with each type split in
two (:func:`~.mixture.split_type_starts`: as likely as that fit, so EM only climbs from it).
Folds are over participants; a held-out participant's likelihood is the mixture's,
sum_m w_m P(trials | type m), under the training fit as fitted, except the rows that hold a
free cell at 0, smoothed by :data:`~.selection.HELDOUT_PSEUDOCOUNT` per free cell (as for the
number of levels: :func:`~.selection.heldout_loglik`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import pandas as pd

from .mixture import MixtureFit, check_types, fit_mixture, split_type_starts
from .mixture_em import MixtureParams, MixtureWorkspace
from .options import FitOptions
from .selection import BEST_TOLERANCE, HELDOUT_PSEUDOCOUNT, HeldOutComparison, comparison_warnings, smooth_zero_rows
from .sequences import Sequences, encode
from .spec import FitError
from .trust_iohmm import inputs_spec

log = logging.getLogger(__name__)

#: the fits of a selection of types: 10 starts each, to a relative tolerance of 1e-6, on one thread
TYPE_SELECTION = FitOptions(tol=1e-6, n_jobs=1)


def heldout_mixture_loglik(test: Sequences, fit: MixtureFit) -> float:
    """sum over the held-out participants of log sum_m w_m P(trials | type m), under
    :func:`heldout_mixture_params` of the training fit."""
    return float(MixtureWorkspace(test, fit.structure).loglik(heldout_mixture_params(fit)))


def heldout_mixture_params(fit: MixtureFit, pseudocount: float = HELDOUT_PSEUDOCOUNT) -> MixtureParams:
    """The tables the held-out score uses: ``fit``'s as fitted, except a row holding a free cell
    at 0 (at most :data:`~.selection.ZERO_CELL`), replaced by the smoothed row (one M-step from the
    training fit's expected counts plus ``pseudocount`` per free cell), so that an event no
    training participant showed does not make a held-out participant's score -inf.  The
    initial table is one distribution over (type, first trust), smoothed as a whole.  Smoothing
    every row would pull rarely visited rows towards uniform, more so the more types there are."""
    p = fit.params
    st = fit.workspace().estep(p)
    smooth = fit.structure.mstep(st, p, prior=fit.spec.prior + pseudocount)
    return MixtureParams(
        smooth_zero_rows(p.initial, smooth.initial, (-2, -1)),
        smooth_zero_rows(p.emission, smooth.emission),
        smooth_zero_rows(p.transition, smooth.transition),
    )


def select_types(
    frame: pd.DataFrame,
    types: Sequence[int] = (1, 2, 3, 4),
    folds: int = 5,
    options: FitOptions = TYPE_SELECTION,
    differ: str | Sequence[str] = "all",
    prior: float = 0.0,
    progress: Callable[[str, int, int], None] | None = None,
    widen: bool = False,
    **spec_options: Any,
) -> list[dict[str, Any]]:
    """Compare numbers of supervisor types (``types``, e.g. 1..4): per M the log-likelihood, how
    many starts reached it (within :data:`~.selection.BEST_TOLERANCE`), free parameters, AIC, BIC,
    the k-fold participant-held-out log-likelihood and the empty types; ``best_bic`` and
    ``best_heldout`` mark the choices.  :func:`type_selection_warnings` says when a choice is the
    largest M compared; with ``widen`` one more M is compared while it is (up to :data:`MAX_TYPES`;
    such rows carry ``widened``)."""
    types = sorted({int(m) for m in types})
    if not types or types[0] < 1:
        raise FitError([f"the numbers of types must be positive integers, got {list(types)}"])
    spec = inputs_spec(frame, "paper", prior, **spec_options)
    seqs = encode(frame, spec)
    check_types(types[-1], seqs)
    previous: dict[int, MixtureFit] = {}  # per slot (-1: all participants, f: fold f's training participants)
    pooled: dict[int, MixtureFit] = {}  # the one-type fit of each slot

    def one_fit(data: Sequences, M: int, slot: int, key: list[int]) -> MixtureFit:
        ss = np.random.SeedSequence(key)
        before = previous.get(slot)
        init = []
        if before is not None and before.n_types == M - 1:
            init = split_type_starts(before.params, np.random.default_rng(ss.generate_state(4)), before.structure)
            # the split starts live in the previous fit's structure: re-projected by the new one in fit_mixture
        fit = fit_mixture(
            data,
            spec,
            M,
            replace(options, seed=ss),
            differ=differ,
            pooled=pooled[slot].params.type_params(0) if slot in pooled else None,
            init=init,
        )
        previous[slot] = fit
        if M == 1:
            pooled[slot] = fit
        return fit

    def extra(full: MixtureFit) -> dict[str, Any]:
        return {"weights": full.weights.tolist(), "empty_types": full.empty_types}

    cap = min(MAX_TYPES, seqs.n_participants) if widen else 0
    comparison = HeldOutComparison("types", folds, options.seed_number, cap, progress)
    rows = comparison.run(seqs, types, one_fit, heldout_mixture_loglik, extra)
    for w in type_selection_warnings(rows):
        log.warning("%s", w)
    return rows


MAX_TYPES = 12  # the most supervisor types select-types compares (the command's --types bound)


def type_selection_warnings(rows: Sequence[dict[str, Any]]) -> list[str]:
    """A best number of types at the largest compared, fits whose best only one start reached,
    and fits with empty types."""

    def empty(r: dict[str, Any]) -> list[str]:
        if not r.get("empty_types"):
            return []
        return [f"{r['types']} types: empty type(s) {', '.join(r['empty_types'])}: fewer types fit as well"]

    return comparison_warnings(rows, "types", MAX_TYPES, "--types {low}..{next}", f" (within {BEST_TOLERANCE})", empty)
