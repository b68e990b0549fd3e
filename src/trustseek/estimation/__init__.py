"""Estimation: the discrete IOHMM, its extended Baum-Welch fit, and the trust-model fit built on it.

* :mod:`.spec` -- what an IOHMM is made of (:class:`IOHMMSpec`, :class:`Params`);
* :mod:`.sequences` -- trial tables encoded as integer arrays (:func:`encode`);
* :mod:`.structure` -- a spec compiled against data: free, tied and fixed cells, M-step;
* :mod:`.ratings` -- a self-reported rating as a second emission of the level (joint output);
* :mod:`.estep` / :mod:`.kernels` / :mod:`.forward_backward` -- the E-step (compiled, with the numpy reference);
* :mod:`.em` / :mod:`.sticks` -- the EM driver: R starts with SQUAREM, the L-BFGS-B finish on the free
  cells' stick-breaking fractions, the stationarity check; :mod:`.compiled_run`, the same run compiled;
* :mod:`.options` -- how a fit searches (:class:`FitOptions`: restarts, seed, tolerance, iteration
  cap, workers), one set taken by every fit, selection and bootstrap;
* :mod:`.iohmm` -- :func:`fit_iohmm`, log-likelihood, posteriors, Viterbi;
* :mod:`.trust_iohmm` -- the paper's structure, tables to and from a TrustModel;
* :mod:`.fit`, :mod:`.bootstrap`, :mod:`.selection` -- the trust-model fit, its intervals,
  and the choice of the number of levels; :func:`fit_model`, the same fit with any named
  inputs (a general model: a :class:`~trustseek.model.TrustModel` with those inputs).

Each name is loaded on first use (the names are in ``__init__.pyi``).
"""

import lazy_loader as _lazy

__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
