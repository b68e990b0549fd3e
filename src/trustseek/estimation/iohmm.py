"""Fitting a discrete IOHMM (extended Baum-Welch, :mod:`.em` or :mod:`.compiled_run`) and inference.

:func:`fit_iohmm` runs every start, keeps the best and names its levels by the spec's rule: an
:class:`EMFit` (extended by the model fits' :class:`~.result.FitResult` and a mixture's).
:func:`loglik`, :func:`posteriors` and :func:`viterbi` are the inference the package needs.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from ..solvers.base import one_blas_thread
from . import compiled_run
from .em import STATIONARY, RunResult, converge_runs, run_em
from .estep import Workspace
from .options import SERIAL, FitOptions
from .ratings import make_structure
from .sequences import Sequences
from .spec import FitError, IOHMMSpec, Params
from .structure import Structure

log = logging.getLogger(__name__)


@dataclass
class EMFit:
    """What an EM fit leaves (:func:`~.iohmm.fit_iohmm`, and a mixture's): the spec and structure
    fitted, the data, the best start's tables (``params``; levels ordered by the spec's
    ``order_by`` rule), log-likelihood and objective, every start's run and which was best; and
    the criteria derived from them: free parameters, observations, AIC, BIC."""

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

    def cap_warnings(self) -> list[str]:
        """A line when the best start stopped at the cap on E-steps before it converged (another
        start's cap leaves the estimates as they are)."""
        best = self.runs[self.best]
        if best.converged:
            return []
        return [
            f"the best restart stopped at the cap on E-steps ({best.iterations}) before it converged: its "
            "estimates may still move (raise --max-iter, or loosen --tol)"
        ]

    @property
    def restart_logliks(self) -> list[float]:
        return [r.loglik for r in self.runs]

    def workspace(self, seqs: Sequences | None = None) -> Workspace:
        """The E-step of the fitted structure on its data (or on ``seqs``)."""
        return Workspace(self.seqs if seqs is None else seqs, *self.structure.dims)

    def criteria(self) -> dict[str, Any]:
        """The log-likelihood, free parameters, AIC and BIC."""
        return {"loglik": self.loglik, "n_params": self.n_params, "aic": self.aic, "bic": self.bic}

    def figures(self) -> dict[str, Any]:
        """The criteria and the data's size, for JSON."""
        return {**self.criteria(), "n_participants": self.seqs.n_participants, "n_trials": self.seqs.n_trials}


def describe_run(i: int, r: RunResult) -> str:
    """Start ``i``'s run ``r`` in one line of the log."""
    state = "converged: stationary" if r.ended == STATIONARY else f"not converged: {r.ended}"
    sub = f" (after {r.subsample_iterations} on a subsample)" if r.subsample_iterations else ""
    return (
        f"start {i}: log-likelihood {r.loglik:.6f} after {r.iterations} E-steps{sub} and {r.finishes} finishes "
        f"({state}, {r.seconds:.3f} s)"
    )


def fit_iohmm(
    seqs: Sequences,
    spec: IOHMMSpec,
    options: FitOptions = SERIAL,
    init: Sequence[Params] = (),
    on_restart: Callable[[int, RunResult], None] | None = None,
    accelerate: bool = True,
    quasi_newton: bool = True,
    compiled: bool = True,
) -> EMFit:
    """Fit ``spec`` to ``seqs``: the runs from ``init`` and ``options.restarts`` random starts (from
    ``options.seed``); the best is kept.

    Each run is EM with SQUAREM (``accelerate``) and, with ``quasi_newton``, EM only to
    ``max(tol, 1e-5)`` then the quasi-Newton finish; it has converged only at a stationary point,
    where one more EM step gains at most ``tol`` (relative) (:func:`~.em.converge`), else at
    ``max_iter`` E-steps.  Each run's outcome is logged (debug) and passed to ``on_restart``; the
    ``n_jobs`` threads change no number.  A spec with a rating is fitted by EM alone.  With
    ``compiled`` (no rating, E-steps compiled) each start runs compiled (:mod:`.compiled_run`), else
    the starts run in lockstep and scipy's L-BFGS-B finishes them (:func:`~.em.converge_runs`).
    """
    structure = make_structure(spec, seqs)
    settings = options.run(quasi_newton and not structure.joint, accelerate)
    work = Workspace(seqs, *structure.dims, threads=settings.threads)
    ss = options.seed_sequence
    starts = [structure.project(p) for p in init]
    starts += [structure.random(np.random.default_rng(s)) for s in ss.spawn(options.starts)]
    if not starts:
        raise FitError(["at least one restart is needed"])
    log.debug(
        "fitting %d levels to %d sequences (%d trials) from %d starts",
        structure.K,
        seqs.n_participants,
        seqs.n_trials,
        len(starts),
    )
    group = work.lockstep(len(starts))
    runs: list[RunResult] = []

    def record(r: RunResult) -> None:
        log.debug("%s", describe_run(len(runs), r))
        if on_restart is not None:
            on_restart(len(runs), r)
        runs.append(r)

    if compiled and compiled_run.applies(structure, work):  # (a spec with a rating goes the lockstep way below)
        for r in compiled_run.run_starts(structure, work, starts, settings):
            record(r)
    with one_blas_thread():
        for g in range(len(runs), len(starts), group):
            ems = run_em(structure, work, starts[g : g + group], settings.em_tol, settings.max_iter, settings.accelerate)
            for r in converge_runs(structure, work, ems, settings):
                record(r)
    best = int(np.argmax([r.objective for r in runs]))
    p = runs[best].params
    log.info("best of %d starts: %s", len(runs), describe_run(best, runs[best]))
    return EMFit(spec, structure, seqs, p.permuted(structure.order(p)), runs[best].loglik, runs[best].objective, runs, best)


def _workspace(seqs: Sequences, spec: IOHMMSpec, params: Params) -> Workspace:
    return Workspace(seqs, spec.n_levels, spec.n_emitted, params.emission.shape[0], params.transition.shape[0])


def loglik(seqs: Sequences, spec: IOHMMSpec, params: Params) -> float:
    """Log-likelihood of ``seqs`` under ``params`` (forward pass only)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return float(_workspace(seqs, spec, params).loglik(params))


def posteriors(seqs: Sequences, spec: IOHMMSpec, params: Params) -> tuple[np.ndarray, np.ndarray, float]:
    """Smoothed P(level | all data of the participant) per trial, (T, N, K); Viterbi path (T, N); log-likelihood."""
    work = _workspace(seqs, spec, params)
    st = work.estep(params, posteriors=True)
    if st.gamma is None:
        raise FitError(["the data has probability zero under this model"])
    return st.gamma, viterbi(work, params), float(st.loglik)


def viterbi(work: Workspace, p: Params) -> np.ndarray:
    """Most likely level path of each sequence of the workspace, (T, N), -1 on padding."""
    Bx, Ax = work.tables(p.as_batch())
    T, N = work.T, work.N
    with np.errstate(divide="ignore"):
        lB, lA = np.log(Bx[0][work.eidx]), np.log(Ax[0][work.tidx])  # (T, N, K), (T-1, N, K, K)
        delta = np.log(p.initial)[None, :] + lB[0]
    back = np.empty((T, N, work.K), dtype=np.int64)
    for t in range(1, T):
        cand = delta[:, :, None] + lA[t - 1]  # (N, K, K)
        back[t] = cand.argmax(1)
        delta = np.take_along_axis(cand, back[t][:, None, :], 1)[:, 0, :] + lB[t]
    path = np.empty((T, N), dtype=np.int64)
    path[T - 1] = delta.argmax(1)
    for t in range(T - 1, 0, -1):
        path[t - 1] = np.take_along_axis(back[t], path[t][:, None], 1)[:, 0]
    path[np.arange(T)[:, None] >= work.seqs.lengths[None, :]] = -1
    return path


def posterior_frame(seqs: Sequences, spec: IOHMMSpec, params: Params) -> pd.DataFrame:
    """Per trial, in the frame's row order: P(level | all trials of the participant) and the Viterbi level."""
    gamma, path, _ = posteriors(seqs, spec, params)
    return pd.DataFrame(trial_columns(seqs, spec.levels, gamma, path)[0])


def trial_columns(
    seqs: Sequences, levels: Sequence[str], gamma: np.ndarray, path: np.ndarray
) -> tuple[dict[str, Any], np.ndarray]:
    """Per trial, in the frame's row order: the participant, the trial, ``p_trust_<level>`` from
    ``gamma`` (T, N, K) and ``viterbi_trust`` from ``path`` (T, N); and each trial's sequence."""
    valid = seqs.rows >= 0
    tt, nn = np.nonzero(valid)
    order = np.argsort(seqs.rows[valid], kind="stable")
    tt, nn = tt[order], nn[order]
    out: dict[str, Any] = {"participant": [seqs.participants[i] for i in nn], "trial": seqs.trial_numbers(tt, nn)}
    for k, name in enumerate(levels):
        out[f"p_trust_{name}"] = gamma[tt, nn, k]
    out["viterbi_trust"] = np.array(levels, dtype=object)[path[tt, nn]]
    return out, nn
