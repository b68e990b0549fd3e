"""The held-out score of select and select-types: the training fit (a model, or a mixture of types) as
fitted, smoothed only in rows that would give -inf."""

from dataclasses import replace

import numpy as np
import pytest

from trustseek import paper_model
from trustseek.estimation import paper_spec, selection
from trustseek.estimation.estep import Workspace
from trustseek.estimation.iohmm import fit_iohmm
from trustseek.estimation.mixture import fit_mixture
from trustseek.estimation.mixture_em import MixtureParams, MixtureWorkspace
from trustseek.estimation.options import FitOptions
from trustseek.estimation.selection import heldout_loglik, heldout_params
from trustseek.estimation.sequences import encode
from trustseek.estimation.spec import Params
from trustseek.estimation.trust_iohmm import level_names, preset_spec
from trustseek.model.presets import paper_conservative_mixture
from trustseek.simulation.designs import simulate_design
from trustseek.simulation.populations import Supervisors


@pytest.fixture(scope="module")
def train_test():
    df = simulate_design(paper_model(), 30, seed=5, n_trials=(10, 10))
    spec = preset_spec("paper", df).with_levels(level_names(2))
    seqs = encode(df, spec)
    fit = fit_iohmm(seqs, spec, options=FitOptions(restarts=2, seed=0, tol=1e-5, n_jobs=1))
    return fit, seqs.subset(np.arange(20, 30))


@pytest.fixture(scope="module")
def types_train_test():
    sup = Supervisors.from_mixture(paper_conservative_mixture(0.5), 30, rng=3)
    seqs = encode(simulate_design(sup, 30, seed=4, n_trials=(10, 10)), paper_spec())
    fit = fit_mixture(seqs.subset(np.arange(20)), paper_spec(), 2, options=FitOptions(restarts=2, seed=0, tol=1e-5, n_jobs=1))
    return fit, seqs.subset(np.arange(20, 30))


def _interior(fit):
    """``fit`` (a model's or a mixture's) moved into the interior: the initial table and every row
    without a fixed cell mixed with 10 % uniform."""
    s, p = fit.structure, fit.params

    def mix(a, fixed):
        free_row = ~np.broadcast_to(fixed, a.shape).any(-1, keepdims=True)
        return np.where(free_row, 0.9 * a + 0.1 / a.shape[-1], a)

    ini = 0.9 * p.initial + 0.1 / p.initial.size
    return replace(fit, params=type(p)(ini, mix(p.emission, s.em.fixed), mix(p.transition, s.tr.fixed)))


@pytest.mark.parametrize(
    ("data", "workspace"),
    [
        pytest.param("train_test", lambda test, s: Workspace(test, *s.dims), id="model"),
        pytest.param("types_train_test", lambda test, s: MixtureWorkspace(test, s), id="types"),
    ],
)
def test_a_fit_without_zero_cells_is_scored_as_fitted(request, data, workspace):
    """Before, every free cell (of every type) got 0.5 more counts: the score differed from the fitted model's."""
    fit, test = request.getfixturevalue(data)
    inner = _interior(fit)
    out = heldout_params(inner)
    for name in ("initial", "emission", "transition"):
        np.testing.assert_array_equal(getattr(out, name), getattr(inner.params, name))
    direct = float(workspace(test, fit.structure).loglik(inner.params))
    assert heldout_loglik(test, inner) == pytest.approx(direct, abs=1e-9)


def test_only_a_row_with_a_zero_free_cell_is_smoothed(train_test):
    fit, _ = train_test
    inner = _interior(fit)
    p = inner.params
    tr = p.transition.copy()
    u, k = int(np.flatnonzero(~fit.structure.tr.fixed.any((-2, -1)))[0]), 1
    tr[u, k] = [1 - 1e-12, 1e-12]  # a free transition row that never leaves level k (as a fit leaves it)
    zeroed = replace(fit, params=Params(p.initial, p.emission, tr))
    out = heldout_params(zeroed)
    assert np.all(out.transition[u, k] > 0)  # smoothed: finite for any held-out participant
    others = np.ones(tr.shape[:2], dtype=bool)
    others[u, k] = False
    np.testing.assert_array_equal(out.transition[others], tr[others])  # every other row as fitted
    np.testing.assert_array_equal(out.emission, p.emission)
    np.testing.assert_array_equal(out.initial, p.initial)
    # the smoothed row is the one-step estimate from the expected counts plus the pseudo-count
    bigger = heldout_params(zeroed, pseudocount=5.0)
    assert abs(bigger.transition[u, k, 1] - 0.5) < abs(out.transition[u, k, 1] - 0.5)


def test_a_held_out_event_the_training_fit_forbids_scores_finite(train_test):
    fit, test = train_test
    p = fit.params
    # the first level never relies where the emission is free: probability exactly 0 ...
    em = p.emission.copy()
    free = ~np.broadcast_to(fit.structure.em.fixed, em.shape)
    rows = np.flatnonzero(free[:, 0, 1])
    em[rows, 0] = [1.0, 0.0]
    zeroed = replace(fit, params=Params(p.initial, em, p.transition))
    with np.errstate(divide="ignore"):
        raw = float(Workspace(test, *fit.structure.dims).loglik(zeroed.params))  # ... held-out participants rely there
    score = heldout_loglik(test, zeroed)
    assert np.isfinite(score) and score < heldout_loglik(test, fit)
    assert raw < score - 100  # as fitted, the held-out participants who rely there cost log(0) (floored)


def test_the_pseudocount_is_the_module_default(train_test):
    fit, _ = train_test
    p = fit.params
    tr = p.transition.copy()
    tr[0, 0] = [0.0, 1.0]
    zeroed = replace(fit, params=Params(p.initial, p.emission, tr))
    np.testing.assert_array_equal(
        heldout_params(zeroed).transition, heldout_params(zeroed, pseudocount=selection.HELDOUT_PSEUDOCOUNT).transition
    )


def test_only_a_mixture_row_with_a_zero_free_cell_is_smoothed(types_train_test):
    fit, test = types_train_test
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


def test_a_zero_in_the_initial_table_smooths_the_whole_joint_table(types_train_test):
    fit, _ = types_train_test
    inner = _interior(fit)
    p = inner.params
    ini = p.initial.copy()
    ini[0, 0] = 0.0
    ini /= ini.sum()
    out = heldout_params(replace(inner, params=MixtureParams(ini, p.emission, p.transition)))
    assert out.initial[0, 0] > 0
    assert out.initial.sum() == pytest.approx(1.0)
    np.testing.assert_array_equal(out.transition, p.transition)
