"""A replicate's shorter paths give the numbers of the general ones: the fitted model of
fit_trust_model, the paired t-test of scipy."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import ttest_rel

from trustseek.design.replicate import FitSettings, fit_encoded
from trustseek.estimation.fit import fit_trust_model
from trustseek.estimation.options import FitOptions
from trustseek.estimation.sequences import encode
from trustseek.estimation.trust_iohmm import preset_spec
from trustseek.model.presets import paper_model
from trustseek.simulation.designs import simulate_design
from trustseek.statistics import paired_tests


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-50, 50, allow_nan=False), min_size=2, max_size=40), st.integers(0, 2**31 - 1))
def test_paired_t_is_scipys(values, seed):
    a = np.asarray(values)
    b = a + np.random.default_rng(seed).normal(0.3, 2.0, len(a))
    d = a - b
    if np.all(d == d[0]):
        return
    expected = float(ttest_rel(a, b).pvalue)
    assert paired_tests(a, b)["t"] == pytest.approx(expected, rel=1e-9, abs=1e-300)


def test_the_replicate_fit_is_fit_trust_models_model():
    frame = simulate_design(paper_model(), 9, seed=3)
    fs = FitSettings(restarts=2)
    spec = preset_spec("paper", frame)
    got = fit_encoded(encode(frame, spec), spec, fs, 17)
    ref = fit_trust_model(frame, options=FitOptions(restarts=2, seed=17, tol=fs.tol, max_iter=fs.max_iter, n_jobs=1)).model
    for name in ("initial", "emission", "transition"):
        assert np.array_equal(getattr(got, name), getattr(ref, name))


@pytest.mark.parametrize("p_ask", [(0.0, 1.0), (0.1, 0.4), (1.0, 1.0)])
def test_a_belief_free_policy_has_the_value_of_the_grid_chain(p_ask):
    from trustseek.design import evaluation
    from trustseek.model.presets import paper_task
    from trustseek.policies import randomized

    task = paper_task()
    policy = randomized(dict(zip(task.complexities, p_ask, strict=True)))
    got = evaluation.evaluate_policy(policy, paper_model(), task, grid=101)
    # the grid chain, as for a policy that reads the belief: P(ask | x, C) at every grid point
    probs = np.asarray(p_ask, dtype=float)
    hidden = type("Hidden", (), {"belief_update": None, "model": None})()
    hidden.actions = lambda beliefs, c, rng: probs[c]
    ref = evaluation.evaluate_policy(hidden, paper_model(), task, grid=101)
    assert got.value == pytest.approx(ref.value, rel=1e-9)
    assert got.by_trust == pytest.approx(ref.by_trust, rel=1e-9)


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 500), st.integers(1, 16))
def test_even_parts_give_every_worker_as_many_tasks_of_about_one_length(n, workers):
    from trustseek.design.sweep import _even_parts

    items = list(range(n))
    parts = _even_parts(items, workers)
    assert [x for p in parts for x in p] == items
    sizes = [len(p) for p in parts]
    assert max(sizes) <= 8 and max(sizes) - min(sizes) <= 1 and min(sizes) >= 1
    if n >= workers:
        assert len(parts) % workers == 0
