"""The compiled E-step: extreme parameters against the numpy reference, and the same result
to the last bit whatever the number of threads."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trustseek.estimation import Params, encode, fit_iohmm, kernels, paper_spec
from trustseek.estimation.estep import Workspace
from trustseek.estimation.options import FitOptions
from trustseek.estimation.structure import Structure
from trustseek.model.presets import paper_model
from trustseek.simulation.designs import simulate_design


def data(n, seed, K=2, trials=(41, 30)):
    df = simulate_design(paper_model(), n, seed=seed, n_trials=trials)
    spec = paper_spec(levels=K)
    seqs = encode(df, spec)
    return spec, seqs, Structure(spec, seqs)


def extreme(s: Structure, rng: np.random.Generator, floor_exp: int) -> Params:
    """Random parameters whose cells span 1 down to 10**-floor_exp (rows renormalised)."""
    p = s.random(rng)

    def squash(a: np.ndarray) -> np.ndarray:
        a = a * 10.0 ** -rng.integers(0, floor_exp + 1, size=a.shape)
        return a / a.sum(-1, keepdims=True)

    return Params(squash(p.initial), squash(p.emission), squash(p.transition))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**31 - 1), K=st.sampled_from([2, 3]), floor_exp=st.sampled_from([3, 12, 60]))
def test_compiled_estep_equals_numpy_on_extreme_parameters(seed, K, floor_exp):
    """Cells as small as 1e-60 (one trial's probability can then be 1e-180; the two-level
    pass rescales its vectors instead of normalising them at each trial): the same
    log-likelihood and counts as the numpy time loop."""
    _spec, seqs, s = data(6, seed % 1000, K)
    p = extreme(s, np.random.default_rng(seed), floor_exp)
    ref = Workspace(seqs, K, 2, s.Ue, s.Ut, method="loop").estep(p)
    got = Workspace(seqs, K, 2, s.Ue, s.Ut, method="compiled").estep(p)
    if not np.isfinite(ref.loglik):
        assert got.loglik == ref.loglik
        return
    # rounding differs between the two recursions; with cells of 1e-60 it reaches ~1e-10 relative
    assert got.loglik == pytest.approx(ref.loglik, rel=1e-9, abs=1e-9)
    for name in ("initial", "emission", "transition"):
        np.testing.assert_allclose(getattr(got, name), getattr(ref, name), rtol=1e-6, atol=1e-8)


def test_long_sequence_with_tiny_cells_matches_reference():
    """One 20,000-trial sequence whose data probability is far below the smallest double:
    the rescaled recursions stay finite and agree with the normalised numpy reference."""
    df = simulate_design(paper_model(), 200, seed=3, n_trials=(58, 42))
    df["participant"] = "long"
    df["trial"] = np.arange(1, len(df) + 1)
    spec = paper_spec()
    seqs = encode(df, spec)
    s = Structure(spec, seqs)
    p = extreme(s, np.random.default_rng(5), 6)
    ref = Workspace(seqs, 2, 2, s.Ue, s.Ut, method="loop").estep(p)
    got = Workspace(seqs, 2, 2, s.Ue, s.Ut, method="compiled").estep(p)
    assert np.isfinite(got.loglik) and got.loglik < -2000
    assert got.loglik == pytest.approx(ref.loglik, rel=1e-9)
    for name in ("initial", "emission", "transition"):
        np.testing.assert_allclose(getattr(got, name), getattr(ref, name), rtol=1e-7, atol=1e-7)


@pytest.mark.parametrize("K", [2, 3])
def test_threads_do_not_change_the_estep(monkeypatch, K):
    """The work split over 1, 2 or 3 threads gives the same numbers to the last bit."""
    monkeypatch.setattr(kernels, "PARALLEL_MIN", 0)
    _spec, seqs, s = data(300, 4, K)  # three chunks of sequences per parameter set
    starts = Params.stack([s.random(np.random.default_rng(r)) for r in range(3)])
    active = np.array([True, False, True])
    results = [Workspace(seqs, K, 2, s.Ue, s.Ut, threads=j).estep(starts, active) for j in (1, 2, 3)]
    for other in results[1:]:
        for name in ("loglik", "initial", "emission", "transition"):
            assert np.array_equal(getattr(other, name), getattr(results[0], name))
    assert results[0].loglik[1] == 0.0 and np.all(results[0].emission[1] == 0)


def test_fit_is_the_same_with_one_and_two_threads(monkeypatch):
    monkeypatch.setattr(kernels, "PARALLEL_MIN", 0)
    spec, seqs, _s = data(260, 7)
    one = fit_iohmm(seqs, spec, options=FitOptions(restarts=3, seed=1, n_jobs=1))
    two = fit_iohmm(seqs, spec, options=FitOptions(restarts=3, seed=1, n_jobs=2))
    assert one.loglik == two.loglik
    assert np.array_equal(one.params.vector(), two.params.vector())
    assert [r.iterations for r in one.runs] == [r.iterations for r in two.runs]


def _pool_answers() -> None:
    import os

    os._exit(0 if kernels._pool(2).submit(pow, 2, 3).result() == 8 else 1)


def test_a_forked_child_gets_e_step_threads_of_its_own():
    """A process forked after a threaded E-step inherited the parent's thread pool without its
    threads: its first threaded E-step waited forever (the reproduction's steps run beside the fit)."""
    import multiprocessing

    assert kernels._pool(2).submit(pow, 2, 3).result() == 8  # the pool exists in this process
    child = multiprocessing.get_context("fork").Process(target=_pool_answers)
    child.start()
    child.join(timeout=60)
    if child.is_alive():
        child.kill()
        child.join()
        pytest.fail("the forked child's E-step threads never ran")
    assert child.exitcode == 0
