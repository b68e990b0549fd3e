"""Conformance of every way a fit runs (in the spirit of the solvers' tests/solvers/test_conformance.py
and scikit-learn's check_estimator).

A fit of the IOHMM runs one of three ways: EM in lockstep with scipy's L-BFGS-B finish on the
numpy E-step (the reference, ``Workspace(method="loop")``), the same on the compiled E-step
(``fit_iohmm(..., compiled=False)``: a fit with a rating, the supervisor types), and the whole run
compiled per start (``compiled_run``, the default where it applies).  Each must: give the E-step's numbers of the
numpy reference at its end point (numpy and compiled E-steps agree); never let a run's objective
decrease; end every start stationary; and recover the model that generated the data (its
log-likelihood at least that of the truth, its identified cells near the truth's).
"""

from functools import partial
from unittest import mock

import numpy as np
import pytest

from trustseek.estimation import encode, fit_iohmm, from_model, iohmm, loglik, paper_spec
from trustseek.estimation.estep import Workspace
from trustseek.estimation.options import FitOptions
from trustseek.model.presets import paper_model
from trustseek.simulation.designs import simulate_design

#: how a fit runs: (compiled whole run, the E-step's method)
WAYS = {"lockstep-numpy": (False, "loop"), "lockstep-compiled-estep": (False, "auto"), "compiled-run": (True, "auto")}


@pytest.fixture(scope="module")
def data():
    spec = paper_spec()
    seqs = encode(simulate_design(paper_model(), 40, seed=7), spec)
    fits = {}
    for way, (compiled, method) in WAYS.items():
        with mock.patch.object(iohmm, "Workspace", partial(Workspace, method=method)):
            fits[way] = fit_iohmm(seqs, spec, options=FitOptions(restarts=2, seed=0, n_jobs=1), compiled=compiled)
    return spec, seqs, fits


@pytest.mark.parametrize("way", list(WAYS))
def test_every_way_a_fit_runs_conforms(data, way):
    _spec, seqs, fits = data
    fit = fits[way]
    # numpy and compiled E-steps agree at the end point
    K, M, Ue, Ut = fit.structure.dims
    ref = Workspace(seqs, K, M, Ue, Ut, method="loop").estep(fit.params)
    got = Workspace(seqs, K, M, Ue, Ut, method="compiled").estep(fit.params)
    np.testing.assert_allclose(got.loglik, ref.loglik, rtol=1e-12)
    for a, b in ((got.initial, ref.initial), (got.emission, ref.emission), (got.transition, ref.transition)):
        np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-10)
    # the objective never decreases along a run, and every start ends stationary
    for r in fit.runs:
        assert np.all(np.diff(r.history) >= 0)
        assert r.ended == "stationary" and r.converged
        assert r.history[-1] == r.objective
    # it recovers the generating model: at least the truth's log-likelihood, its free cells near the truth's
    truth_spec, truth = from_model(paper_model())
    assert fit.loglik >= loglik(seqs, truth_spec, truth) - 1e-9
    free = ~fit.structure.em.fixed
    assert np.max(np.abs(fit.params.emission - truth.emission)[free]) < 0.15
    # the three ways reach the same maximum
    best = max(f.loglik for f in fits.values())
    assert fit.loglik == pytest.approx(best, rel=1e-8)
