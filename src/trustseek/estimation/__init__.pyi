"""The public names of :mod:`trustseek.estimation`: read by type checkers, and by ``__init__.py`` to load each on first use."""

# every submodule, as the package attribute of that name
from . import (
    baselines,
    blas,
    bootstrap,
    compiled_em,
    compiled_run,
    compiled_steps,
    em,
    estep,
    fit,
    forward_backward,
    iohmm,
    kernels,
    mixture,
    mixture_em,
    options,
    personal,
    prediction,
    ratings,
    result,
    selection,
    sequences,
    spec,
    stick_maps,
    sticks,
    structure,
    trust_iohmm,
    validation,
)
from .fit import MIN_EVENTS, decode, fit_model, fit_trust_model, trust_loglik
from .iohmm import EMFit, fit_iohmm, loglik, posteriors
from .options import FitOptions
from .result import FitResult
from .selection import select_levels, selection_warnings
from .sequences import Sequences, encode
from .spec import FitError, Fixed, IOHMMSpec, Params
from .trust_iohmm import (
    MODEL_INPUTS,
    PAPER_EMISSION_INPUTS,
    PAPER_TRANSITION_INPUTS,
    from_model,
    general_spec,
    paper_spec,
    to_model,
)

__all__ = [
    "MIN_EVENTS",
    "MODEL_INPUTS",
    "PAPER_EMISSION_INPUTS",
    "PAPER_TRANSITION_INPUTS",
    "EMFit",
    "FitError",
    "FitOptions",
    "FitResult",
    "Fixed",
    "IOHMMSpec",
    "Params",
    "Sequences",
    "decode",
    "encode",
    "fit_iohmm",
    "fit_model",
    "fit_trust_model",
    "from_model",
    "general_spec",
    "loglik",
    "paper_spec",
    "posteriors",
    "select_levels",
    "selection_warnings",
    "to_model",
    "trust_loglik",
]
