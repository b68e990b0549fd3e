"""Estimation: the discrete IOHMM, its extended Baum-Welch fit, and the trust-model fit built on it.

* :mod:`.spec` -- what an IOHMM is made of (:class:`IOHMMSpec`, :class:`Params`);
* :mod:`.sequences` -- trial tables encoded as integer arrays (:func:`encode`);
* :mod:`.structure` -- a spec compiled against data: free, tied and fixed cells, M-step;
* :mod:`.ratings` -- a self-reported rating as a second emission of the level (joint output);
* :mod:`.estep` / :mod:`.kernels` -- the E-step (compiled, with the numpy reference);
* :mod:`.em` / :mod:`.quasi_newton` -- EM for R starts with SQUAREM, and the L-BFGS-B finish;
* :mod:`.convergence` -- a run has converged at a stationary point, checked by one more EM step;
* :mod:`.iohmm` -- :func:`fit_iohmm`, log-likelihood, posteriors, Viterbi;
* :mod:`.trust_iohmm` -- the paper's structure, tables to and from a TrustModel;
* :mod:`.fit`, :mod:`.bootstrap`, :mod:`.selection` -- the trust-model fit, its intervals,
  and the choice of the number of levels; :func:`fit_model`, the same fit with any named
  inputs (a general model, :class:`~trustseek.model.IOHMMModel`).
"""

from .fit import MIN_EVENTS, FitResult, ModelFitResult, decode, fit_model, fit_trust_model, trust_loglik
from .iohmm import IOHMMFit, fit_iohmm, loglik, posteriors
from .selection import select_levels, selection_warnings
from .sequences import Sequences, encode
from .spec import FitError, Fixed, IOHMMSpec, Params
from .trust_iohmm import (
    MODEL_INPUTS,
    PAPER_EMISSION_INPUTS,
    PAPER_TRANSITION_INPUTS,
    from_trust_model,
    general_spec,
    paper_spec,
    to_trust_model,
)

__all__ = [
    "MIN_EVENTS",
    "MODEL_INPUTS",
    "PAPER_EMISSION_INPUTS",
    "PAPER_TRANSITION_INPUTS",
    "FitError",
    "FitResult",
    "Fixed",
    "IOHMMFit",
    "IOHMMSpec",
    "ModelFitResult",
    "Params",
    "Sequences",
    "decode",
    "encode",
    "fit_iohmm",
    "fit_model",
    "fit_trust_model",
    "from_trust_model",
    "general_spec",
    "loglik",
    "paper_spec",
    "posteriors",
    "select_levels",
    "selection_warnings",
    "to_trust_model",
    "trust_loglik",
]
