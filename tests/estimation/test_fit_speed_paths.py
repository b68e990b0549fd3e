"""The fit's faster paths give the numbers of the plain ones: sequences two at a time in the
compiled E-step, the starts' finishes side by side on threads, BLAS held to one thread."""

import functools
import os
import subprocess
import sys
import threading

import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from trustseek.estimation import Params, em, encode, fit_iohmm, iohmm, paper_spec
from trustseek.estimation.em import run_em
from trustseek.estimation.estep import Workspace
from trustseek.estimation.options import FitOptions
from trustseek.estimation.spec import FitError
from trustseek.estimation.structure import Structure
from trustseek.model.presets import paper_model
from trustseek.simulation.designs import simulate_design
from trustseek.solvers.base import one_blas_thread


def ragged(n: int, seed: int):
    """``n`` participants with trials cut off at random, so equal and unequal neighbours alternate
    (and one participant keeps a single trial)."""
    df = simulate_design(paper_model(), n, seed=seed, n_trials=(20, 15))
    rng = np.random.default_rng(seed)
    keep = {p: int(rng.choice([35, 35, 20, 7])) for p in df["participant"].unique()}
    keep[df["participant"].iloc[0]] = 1
    df = df[df["trial"] <= df["participant"].map(keep)]
    spec = paper_spec()
    seqs = encode(df, spec)
    return spec, seqs, Structure(spec, seqs)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sequences_two_at_a_time_match_the_numpy_estep(seed):
    _spec, seqs, s = ragged(300, seed)  # more than one chunk of sequences
    assert len(set(seqs.lengths.tolist())) > 2
    p = Params.stack([s.random(np.random.default_rng(seed + r)) for r in range(2)])
    ref = Workspace(seqs, *s.dims, method="loop").estep(p)
    got = Workspace(seqs, *s.dims, method="compiled").estep(p)
    np.testing.assert_allclose(got.loglik, ref.loglik, rtol=1e-12)
    for name in ("initial", "emission", "transition"):
        np.testing.assert_allclose(getattr(got, name), getattr(ref, name), rtol=1e-10, atol=1e-10)


def test_a_pair_with_zero_probability_makes_the_set_impossible():
    _spec, seqs, s = ragged(20, 3)
    p = s.random(np.random.default_rng(0))
    emission = p.emission.copy()
    emission[:, :, 0] = 0.0  # no output can be the first category
    emission[:, :, 1] = 1.0
    st = Workspace(seqs, *s.dims, method="compiled").estep(Params(p.initial, emission, p.transition))
    assert st.loglik == -np.inf and not st.emission.any() and not st.transition.any()


@pytest.mark.parametrize("method", ["loop", "compiled"])
def test_pooled_finishes_give_the_numbers_of_one_at_a_time(monkeypatch, method):
    """The starts' finishes on threads of their own, their E-steps pooled into batches, give each
    start's numbers alone, and are reported in order whatever finished first."""
    spec = paper_spec()
    seqs = encode(simulate_design(paper_model(), 12, seed=4), spec)
    monkeypatch.setattr(iohmm, "Workspace", functools.partial(Workspace, method=method))
    seen: list[int] = []
    batches: list[int] = []
    serve = em._Pool._serve

    def counted(pool):
        if pool.asked and len(pool.asked) >= pool.live:
            batches.append(len(pool.asked))
        serve(pool)

    monkeypatch.setattr(em._Pool, "_serve", counted)
    fits = []
    for pooled in (1, em.POOLED):
        monkeypatch.setattr(em, "POOLED", pooled)
        fits.append(fit_iohmm(seqs, spec, FitOptions(restarts=5, seed=2), on_restart=lambda i, r: seen.append(i), compiled=False))
    assert seen == list(range(5)) * 2
    assert max(batches) == 5  # the second fit pooled its E-steps
    a_fit, b_fit = fits
    assert b_fit.best == a_fit.best and b_fit.loglik == a_fit.loglik
    for a, b in zip(a_fit.runs, b_fit.runs, strict=True):
        assert np.array_equal(a.params.vector(), b.params.vector())
        assert (a.iterations, a.finishes, a.ended, a.history) == (b.iterations, b.finishes, b.ended, b.history)
    assert all(r.ended == "stationary" for r in b_fit.runs)


class _Failing:
    """A workspace whose ``fail_at``-th E-step raises."""

    def __init__(self, work, fail_at):
        self.work, self.calls, self.fail_at = work, 0, fail_at

    def __getattr__(self, name):
        return getattr(self.work, name)

    def estep(self, p, active=None, posteriors=False):
        self.calls += 1
        if self.calls == self.fail_at:
            raise FitError(["the data went away"])
        return self.work.estep(p, active, posteriors)


@pytest.mark.parametrize("fail_at", [1, 5, 40])
def test_a_failing_pooled_estep_reaches_the_caller_and_stops_every_run(fail_at):
    spec = paper_spec()
    seqs = encode(simulate_design(paper_model(), 6, seed=1), spec)
    s = Structure(spec, seqs)
    work = Workspace(seqs, *s.dims, method="loop")
    runs = run_em(s, work, [s.random(np.random.default_rng(r)) for r in range(4)], tol=1e-3)
    settings = FitOptions(restarts=4).run(True, True)
    with pytest.raises(FitError, match="went away"):
        list(em.converge_runs(s, _Failing(work, fail_at), runs, settings))
    assert not [t for t in threading.enumerate() if t.name.startswith("trustseek-fit")]


class _Counting:
    """A workspace that counts the parameter sets of its E-steps."""

    def __init__(self, work):
        self.work, self.sets = work, 0

    def __getattr__(self, name):
        return getattr(self.work, name)

    def estep(self, p, active=None, posteriors=False):
        self.sets += len(p.initial) if p.batched else 1
        return self.work.estep(p, active, posteriors)


def test_leaving_the_pooled_runs_early_stops_their_threads():
    """The caller stops listening after the first run (an interrupt, an error of its own): the
    other runs stop at their next E-step, and their threads are gone."""
    spec = paper_spec()
    seqs = encode(simulate_design(paper_model(), 6, seed=1), spec)
    s = Structure(spec, seqs)
    work = Workspace(seqs, *s.dims, method="loop")
    settings = FitOptions(restarts=3).run(True, True)
    starts = run_em(s, work, [s.random(np.random.default_rng(r)) for r in range(3)], tol=1e-3)
    first = next(em.converge_runs(s, work, starts[:1], settings))  # a stationary point
    runs = [first, *starts[1:]]  # the first ends within a few E-steps, the others go on for many
    full = _Counting(work)
    assert all(r.converged for r in em.converge_runs(s, full, runs, settings))
    cut = _Counting(work)
    results = em.converge_runs(s, cut, runs, settings)
    assert next(results).converged
    results.close()
    assert not [t for t in threading.enumerate() if t.name.startswith("trustseek-fit")]
    assert cut.sets < full.sets / 2, (cut.sets, full.sets)


def blas_threads() -> list[int]:
    return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]


def test_one_blas_thread_is_lifted_by_the_last_thread_to_leave():
    with threadpool_limits(limits=2, user_api="blas"):
        left_as_found()


def left_as_found() -> None:
    before = blas_threads()
    assert set(before) == {2}
    seen: list[list[int]] = []
    with one_blas_thread():
        seen.append(blas_threads())
        with one_blas_thread():  # nested
            seen.append(blas_threads())
        seen.append(blas_threads())
    assert blas_threads() == before
    # two threads' finishes overlapping in time: the first leaves while the second is still inside
    first, second = one_blas_thread(), one_blas_thread()
    first.__enter__()
    second.__enter__()
    first.__exit__(None, None, None)
    seen.append(blas_threads())
    second.__exit__(None, None, None)
    assert all(set(x) == {1} for x in seen), seen
    assert blas_threads() == before


POOLED_BLAS = """
import sys
from threadpoolctl import threadpool_info
from trustseek.data import example_path, read_trials
from trustseek.estimation import em, encode, fit_iohmm, paper_spec

log = read_trials(example_path())
log = log[log["participant"].isin(log["participant"].unique()[:4])]  # 4 x 71, starts pooled
assert "scipy.linalg" not in sys.modules  # scipy's BLAS is loaded by the first finish
seen = set()
finish = em.finish

def watched(*args, **kwargs):
    out = finish(*args, **kwargs)
    seen.update(lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas")
    return out

em.finish = watched
spec = paper_spec()
fit_iohmm(encode(log, spec), spec, compiled=False)  # EM in lockstep, scipy's L-BFGS-B finish
print(sorted(seen))
"""


def test_pooled_finishes_hold_every_blas_to_one_thread():
    """scipy's BLAS, loaded by the first finish, is held to one thread on the finishes' threads
    too (a limit set on a worker thread missed it, and OpenBLAS's idle threads spun)."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "2", "OMP_NUM_THREADS": "2"}
    out = subprocess.run([sys.executable, "-c", POOLED_BLAS], capture_output=True, text=True, env=env, check=True)
    assert out.stdout.split() == ["[1]"]
