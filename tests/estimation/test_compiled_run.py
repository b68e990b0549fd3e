"""The compiled whole run (estimation/compiled_run.py, compiled_em.pyx) and its steps (estimation/compiled_steps.pyx) against the numpy pieces and the lockstep path."""

import numpy as np
import pytest

from trustseek.estimation import FitError, Params, encode, fit_iohmm, paper_spec
from trustseek.estimation import compiled_run as cr
from trustseek.estimation import compiled_steps as steps
from trustseek.estimation.em import em_step, run_em
from trustseek.estimation.estep import Workspace
from trustseek.estimation.options import FitOptions, RunSettings
from trustseek.estimation.structure import Structure
from trustseek.model.presets import paper_model
from trustseek.simulation.designs import simulate_design


def problem(n: int, seed: int, **spec_options):
    spec = paper_spec(**spec_options)
    seqs = encode(simulate_design(paper_model(), n, seed=seed), spec)
    s = Structure(spec, seqs)
    return spec, seqs, s, Workspace(seqs, *s.dims)


def pieces(s: Structure, w: Workspace):
    K, M, Ue, Ut = s.dims
    kern = w._kernel
    bufs = steps.estep_buffers(K, w.PE, Ut + 1, kern.C, True)
    return (K, Ue, M, Ut), (kern.eidx, kern.tidx, kern.code, kern.lengths), bufs, cr._table(s.em), cr._table(s.tr)


@pytest.mark.parametrize("levels, prior", [(2, 0.0), (3, 0.3)])
def test_estep_and_mstep_are_those_of_the_workspace_and_structure(levels, prior):
    _spec, _seqs, s, w = problem(300, 2, levels=levels, prior=prior)  # more than one item of sequences
    (K, Ue, M, Ut), data, bufs, emt, trt = pieces(s, w)
    p = s.random(np.random.default_rng(levels))
    flat = p.vector().copy()
    counts = np.empty_like(flat)
    model = (K, Ue, M, Ut, prior, emt, trt)
    ll, f = steps.evaluate(flat, model, (data, bufs), counts)
    st = w.estep(p)
    assert ll == st.loglik  # the same items summed in the same order
    assert f == pytest.approx(float(st.loglik + s.log_prior(p)), rel=1e-14)
    assert np.array_equal(counts, np.concatenate([st.initial, st.emission.ravel(), st.transition.ravel()]))
    q = np.empty_like(flat)
    steps.em_step(flat, counts, model, q)
    np.testing.assert_allclose(q, s.mstep(st, p).vector(), rtol=1e-13, atol=1e-15)


def test_em_decides_as_run_em():
    """Without the finish and with the check's tolerance equal to EM's, the compiled run's first
    accepted objectives are those of the lockstep EM, step for step (to rounding: the M-step's
    sums over tied rows go in another order)."""
    _spec, _seqs, s, w = problem(40, 3)
    for r in range(3):
        start = s.random(np.random.default_rng(r))
        (ref,) = run_em(s, w, [start], tol=1e-6)
        (got,) = cr.run_starts(s, w, [start], RunSettings(1e-6, 1000, 1e-6, quasi_newton=False))
        np.testing.assert_allclose(got.history[: len(ref.history)], ref.history, rtol=1e-8)
        assert got.iterations >= ref.iterations


@pytest.mark.parametrize("n, seed", [(9, 1), (9, 2), (60, 4)])
def test_every_start_ends_stationary_at_least_as_high_as_the_lockstep_path(n, seed):
    spec, seqs, s, w = problem(n, seed)
    fast = fit_iohmm(seqs, spec, options=FitOptions(restarts=6, seed=seed, n_jobs=1))
    slow = fit_iohmm(seqs, spec, options=FitOptions(restarts=6, seed=seed, n_jobs=1), compiled=False)
    for a, b in zip(fast.runs, slow.runs, strict=True):
        assert a.converged and a.ended == "stationary" and a.finishes >= 1
        f, _, fq = em_step(s, w, a.params)
        assert fq - f <= 1e-8 * abs(f)
        assert a.objective == pytest.approx(f, rel=1e-12)
        assert np.all(np.diff(a.history) >= 0) and a.history[-1] == a.objective
        assert a.loglik >= b.loglik - 1e-9 * abs(b.loglik)  # the same maximum, not left short
    assert fast.loglik == pytest.approx(slow.loglik, rel=1e-9)


def test_the_cap_on_esteps_is_kept():
    spec, seqs, _s, _w = problem(9, 1)
    for cap in (1, 5, 30, 60):
        fit = fit_iohmm(seqs, spec, options=FitOptions(restarts=3, seed=0, max_iter=cap, n_jobs=1))
        for r in fit.runs:
            assert r.iterations <= cap
            assert r.ended == "E-step cap" and not r.converged
            assert np.all(np.diff(r.history) >= 0)


def test_threads_do_not_change_the_runs():
    spec, seqs, _s, _w = problem(30, 4)
    fits = [fit_iohmm(seqs, spec, options=FitOptions(restarts=5, seed=2, n_jobs=j)) for j in (1, 2)]
    for a, b in zip(fits[0].runs, fits[1].runs, strict=True):
        assert np.array_equal(a.params.vector(), b.params.vector())
        assert (a.iterations, a.finishes, a.ended, a.history) == (b.iterations, b.finishes, b.ended, b.history)


def test_a_start_giving_the_data_probability_zero_is_refused():
    _spec, _seqs, s, w = problem(9, 1)
    p = s.random(np.random.default_rng(0))
    em = p.emission.copy()
    em[:, :, 0], em[:, :, 1] = 0.0, 1.0  # every first-category output impossible
    with pytest.raises(FitError, match="probability zero"):
        cr.run_starts(s, w, [p, Params(p.initial, em, p.transition)], RunSettings(1e-8, 1000, 1e-5))


def test_the_estep_on_threads_is_the_kernels_to_the_last_bit():
    """With fewer starts than threads, from steps.PARALLEL_ITEMS items, the compiled run's E-steps
    run their items on the E-step threads: the numbers of the kernel's E-step, and the run of one
    thread, on one thread or two."""
    _spec, _seqs, s, w = problem(steps.PARALLEL_ITEMS * cr.CHUNK + 5, 4)
    (K, Ue, M, Ut), data, _bufs, emt, trt = pieces(s, w)
    assert w._kernel.C > steps.PARALLEL_ITEMS
    p = s.random(np.random.default_rng(1))
    st = w.estep(p)
    for threads in (1, 2):
        bufs = steps.estep_buffers(K, w.PE, Ut + 1, w._kernel.C, threads)
        flat, counts = p.vector().copy(), np.empty(len(p.vector()))
        ll, _f = steps.evaluate(flat, (K, Ue, M, Ut, 0.0, emt, trt), (data, bufs), counts)
        assert ll == st.loglik
        assert np.array_equal(counts, np.concatenate([st.initial, st.emission.ravel(), st.transition.ravel()]))
    one, two = (cr.run_starts(s, w, [p], RunSettings(1e-8, 40, 1e-5, threads=t))[0] for t in (1, 2))  # 40 E-steps: cheap
    assert (one.loglik, one.iterations, one.history) == (two.loglik, two.iterations, two.history)
    assert np.array_equal(one.params.vector(), two.params.vector())
