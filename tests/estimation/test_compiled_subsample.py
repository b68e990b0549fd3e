"""The compiled run's subsample phase (large data): each start first on every k-th sequence,
then on the whole data from there, to a stationary point of the whole data."""

import numpy as np
import pytest

from trustseek.estimation import compiled_run as cr
from trustseek.estimation import encode, fit_iohmm, paper_spec
from trustseek.estimation.em import em_step
from trustseek.estimation.estep import Workspace
from trustseek.estimation.options import FitOptions
from trustseek.estimation.structure import Structure
from trustseek.model.presets import paper_model
from trustseek.simulation.designs import simulate_design


def problem(n: int, seed: int):
    spec = paper_spec()
    seqs = encode(simulate_design(paper_model(), n, seed=seed), spec)
    return spec, seqs, Structure(spec, seqs)


def test_small_data_has_no_subsample():
    _spec, seqs, s = problem(9, 1)
    assert cr.subsample(Workspace(seqs, *s.dims)._kernel) is None  # 639 trials: the whole data from the start
    fit = fit_iohmm(seqs, paper_spec(), options=FitOptions(restarts=2, seed=0, n_jobs=1))
    assert [r.subsample_iterations for r in fit.runs] == [0, 0]


@pytest.mark.parametrize("table", ["emission", "transition"])
def test_a_subsample_lacking_a_row_of_the_data_is_not_used(monkeypatch, table):
    monkeypatch.setattr(cr, "SUBSAMPLE_MIN", 0)
    _spec, seqs, s = problem(30, 2)
    kern = Workspace(seqs, *s.dims)._kernel
    assert kern is not None
    idx = cr.subsample(kern, 3)
    assert idx is not None and idx.tolist() == list(range(0, 30, 3))
    assert cr.subsample(kern, 1) is None  # every sequence: the data again
    # a row seen only outside every third sequence: the subsample would estimate it impossible
    a = kern.eidx if table == "emission" else kern.tidx[:, : kern.eidx.shape[1] - 1]
    row, pad = a[1, 0], (kern.PE - 1 if table == "emission" else kern.P - 1)
    sub = a[idx]
    sub[sub == row] = pad  # unobserved output, or no successor: rows without parameters
    a[idx] = sub
    assert cr.subsample(kern, 3) is None


@pytest.mark.parametrize("seed", [1, 2])
def test_every_start_ends_stationary_on_the_whole_data_at_the_whole_data_maximum(monkeypatch, seed):
    spec, seqs, s = problem(240, seed)
    whole = fit_iohmm(seqs, spec, options=FitOptions(restarts=4, seed=seed, n_jobs=1))
    monkeypatch.setattr(cr, "SUBSAMPLE_MIN", 0)
    monkeypatch.setattr(cr, "SUBSAMPLE_EVERY", 4)
    fast = fit_iohmm(seqs, spec, options=FitOptions(restarts=4, seed=seed, n_jobs=1))
    w = Workspace(seqs, *s.dims)
    for r in fast.runs:
        assert r.subsample_iterations > 0 and r.converged and r.ended == "stationary"
        f, _, fq = em_step(s, w, r.params)  # the check on the whole data
        assert fq - f <= 1e-8 * abs(f)
        assert r.objective == pytest.approx(f, rel=1e-12)
        assert np.all(np.diff(r.history) >= 0) and r.history[-1] == r.objective
    assert sum(r.iterations for r in fast.runs) < sum(r.iterations for r in whole.runs)
    assert fast.loglik == pytest.approx(whole.loglik, rel=1e-9)
    two = fit_iohmm(seqs, spec, options=FitOptions(restarts=4, seed=seed, n_jobs=2))  # the same numbers on two threads
    for a, b in zip(fast.runs, two.runs, strict=True):
        assert np.array_equal(a.params.vector(), b.params.vector())
        assert (a.iterations, a.subsample_iterations, a.history) == (b.iterations, b.subsample_iterations, b.history)


def test_the_fit_record_and_the_log_say_how_many_e_steps_ran_on_the_subsample(monkeypatch, caplog):
    import logging

    from trustseek.estimation.fit import fit_trust_model
    from trustseek.model.presets import paper_model
    from trustseek.simulation.designs import simulate_design

    monkeypatch.setattr(cr, "SUBSAMPLE_MIN", 0)
    monkeypatch.setattr(cr, "SUBSAMPLE_EVERY", 4)
    frame = simulate_design(paper_model(), 40, seed=3)
    with caplog.at_level(logging.INFO, logger="trustseek"):
        res = fit_trust_model(frame, options=FitOptions(restarts=2, seed=0, n_jobs=1))
    record = res.fit_record()
    assert record["subsample_iterations"] == [r.subsample_iterations for r in res.runs]
    assert all(n > 0 for n in record["subsample_iterations"])
    assert "on a subsample" in caplog.text
