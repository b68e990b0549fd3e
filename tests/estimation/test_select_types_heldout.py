"""The held-out score of select-types: the training mixture as fitted, smoothed only in rows that would give -inf."""

from dataclasses import replace

import numpy as np
import pytest

from trustseek.estimation import encode, kernels, paper_spec
from trustseek.estimation.mixture import fit_mixture
from trustseek.estimation.mixture_em import MixtureParams, MixtureWorkspace
from trustseek.estimation.options import FitOptions
from trustseek.estimation.selection import heldout_loglik, heldout_params
from trustseek.model.presets import paper_conservative_mixture
from trustseek.simulation.designs import simulate_design
from trustseek.simulation.populations import Supervisors

pytestmark = pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not installed")


@pytest.fixture(scope="module")
def train_test():
    mix = paper_conservative_mixture(0.5)
    sup = Supervisors.from_mixture(mix, 30, rng=3)
    seqs = encode(simulate_design(sup, 30, seed=4, n_trials=(10, 10)), paper_spec())
    fit = fit_mixture(seqs.subset(np.arange(20)), paper_spec(), 2, options=FitOptions(restarts=2, seed=0, tol=1e-5, n_jobs=1))
    return fit, seqs.subset(np.arange(20, 30))


def _interior(fit):
    """``fit`` moved into the interior: every row without a fixed cell mixed with 10 % uniform."""
    s, p = fit.structure, fit.params

    def mix(a, fixed):
        free_row = ~np.broadcast_to(fixed, a.shape).any(-1, keepdims=True)
        return np.where(free_row, 0.9 * a + 0.1 / a.shape[-1], a)

    ini = 0.9 * p.initial + 0.1 / p.initial.size
    return replace(fit, params=MixtureParams(ini, mix(p.emission, s.em.fixed), mix(p.transition, s.tr.fixed)))


def test_a_mixture_without_zero_cells_is_scored_as_fitted(train_test):
    """Before, every free cell of every type got 0.5 more counts: the score was not the fitted mixture's."""
    fit, test = train_test
    inner = _interior(fit)
    out = heldout_params(inner)
    for name in ("initial", "emission", "transition"):
        np.testing.assert_array_equal(getattr(out, name), getattr(inner.params, name))
    direct = float(MixtureWorkspace(test, fit.structure).loglik(inner.params))
    assert heldout_loglik(test, inner) == pytest.approx(direct, abs=1e-9)


def test_only_a_row_with_a_zero_free_cell_is_smoothed(train_test):
    fit, test = train_test
    inner = _interior(fit)
    p = inner.params
    tr = p.transition.copy()
    u = int(np.flatnonzero(~fit.structure.tr.fixed.any((-2, -1)))[0])
    tr[1, u, 0] = [1.0, 0.0]  # type 2 never leaves low trust from input row u
    zeroed = replace(inner, params=MixtureParams(p.initial, p.emission, tr))
    out = heldout_params(zeroed)
    assert np.all(out.transition[1, u, 0] > 0)
    others = np.ones(tr.shape[:3], dtype=bool)
    others[1, u, 0] = False
    np.testing.assert_array_equal(out.transition[others], tr[others])
    np.testing.assert_array_equal(out.emission, p.emission)
    np.testing.assert_array_equal(out.initial, p.initial)
    assert np.isfinite(heldout_loglik(test, zeroed))


def test_a_zero_in_the_initial_table_smooths_the_whole_joint_table(train_test):
    fit, _ = train_test
    inner = _interior(fit)
    p = inner.params
    ini = p.initial.copy()
    ini[0, 0] = 0.0
    ini /= ini.sum()
    out = heldout_params(replace(inner, params=MixtureParams(ini, p.emission, p.transition)))
    assert out.initial[0, 0] > 0
    assert out.initial.sum() == pytest.approx(1.0)
    np.testing.assert_array_equal(out.transition, p.transition)
