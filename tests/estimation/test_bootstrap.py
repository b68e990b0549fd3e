"""Bootstrap intervals: replicate levels aligned to the estimate; every interval contains its estimate."""

import numpy as np
import pytest

from trustseek import paper_model
from trustseek.data.trials import example_path, read_trials
from trustseek.estimation import fit_trust_model
from trustseek.estimation.bootstrap import MIN_REPLICATES, align
from trustseek.estimation.options import FitOptions
from trustseek.estimation.spec import Params
from trustseek.estimation.trust_iohmm import from_model
from trustseek.simulation.designs import simulate_design

# few resamples keep the suite fast; MIN_REPLICATES is what a report should use
REPLICATES = 20


def random_params(rng, K, Ue=4, Ut=8, M=2):
    return Params(rng.dirichlet(np.ones(K)), rng.dirichlet(np.ones(M), (Ue, K)), rng.dirichlet(np.ones(K), (Ut, K)))


@pytest.mark.parametrize("K", [2, 3, 4])
def test_align_undoes_any_relabelling(K):
    rng = np.random.default_rng(K)
    ref = random_params(rng, K)
    noisy = Params(
        ref.initial,
        np.clip(ref.emission + rng.normal(0, 0.02, ref.emission.shape), 0, 1),
        ref.transition,
    )
    for perm in [np.roll(np.arange(K), 1), np.arange(K)[::-1], rng.permutation(K)]:
        swapped = noisy.permuted(perm)
        back = swapped.permuted(align(ref, swapped))
        np.testing.assert_allclose(back.emission, noisy.emission)
        np.testing.assert_allclose(back.transition, noisy.transition)


def test_align_follows_the_weights():
    # the levels agree on a heavily weighted row and are swapped on a row with no data behind it
    _, ref = from_model(paper_model())
    other = Params(ref.initial.copy(), ref.emission.copy(), ref.transition.copy())
    other.emission[0] = ref.emission[0][::-1]
    w = {"initial": np.zeros(2), "emission": np.ones((4, 2)), "transition": np.zeros((8, 2))}
    w["emission"][0] = 0.0
    np.testing.assert_array_equal(align(ref, other, w), [0, 1])
    w["emission"][:] = 0.0
    w["emission"][0] = 1.0
    np.testing.assert_array_equal(align(ref, other, w), [1, 0])


def contained(res):
    out = []
    for c in res.cells():
        if not c["lower"] - 1e-12 <= c["estimate"] <= c["upper"] + 1e-12:
            out.append(f"{c['cell']}: {c['estimate']:.3f} outside [{c['lower']:.3f}, {c['upper']:.3f}]")
    return out


def test_shipped_example_every_interval_contains_its_estimate():
    # the README's round trip: P(rely | T=low, C=high, a=autonomous) = 0.378 had the interval [0.000, 0.364].
    # The likelihood has a second maximum 0.11 below the best (that cell at 0.115), which most
    # resamples prefer: the percentile interval lies below the estimate and is widened to it.
    res = fit_trust_model(
        read_trials(example_path()), options=FitOptions(restarts=10, seed=0, tol=1e-6, n_jobs=1), bootstrap=REPLICATES
    )
    assert contained(res) == []
    cell = next(c for c in res.cells() if c["cell"] == "P(rely | T=low, C=high, a=autonomous)")
    assert cell["estimate"] == pytest.approx(0.378, abs=0.002)
    assert cell["widened"] and cell["upper"] == cell["estimate"]
    assert res.intervals is not None and res.intervals.other_maximum > 0
    assert any("widened to contain" in w for w in res.warnings)
    assert any(f"{REPLICATES} resamples are too few" in w for w in res.warnings)


@pytest.mark.parametrize(("participants", "seed"), [(9, 1), (9, 2), (30, 4)])
def test_simulated_percentile_intervals_contain_their_estimates(participants, seed):
    # on data from the paper's model the aligned replicates straddle every estimate:
    # nothing needs widening, each percentile interval contains its estimate on its own
    df = simulate_design(paper_model(), participants, seed=seed)
    res = fit_trust_model(df, options=FitOptions(restarts=4, seed=seed, tol=1e-6, n_jobs=1), bootstrap=REPLICATES)
    assert contained(res) == []
    assert res.intervals is not None
    widened = [c["cell"] for c in res.cells() if c["widened"]]
    assert widened == []
    assert not any("widened" in w for w in res.warnings)


def test_enough_resamples_give_no_warning_about_their_number():
    from trustseek.estimation.bootstrap import Intervals

    z = {"initial": np.zeros(2, dtype=bool)}
    enough = Intervals({}, MIN_REPLICATES, 0.95, z, 0)
    assert enough.notes() == []
    few = Intervals({}, MIN_REPLICATES - 1, 0.95, z, 0)
    assert "too few" in few.notes()[0]


def test_an_interval_at_the_boundary_can_move():
    """The reproduction's experiment 1 (9 x 71): Fig. 5b's P(T'=low | T=high, E'=faulty, C=low, autonomous)
    is estimated at 0, and every resample's own maximum is 0 too (the percentile interval was
    [1e-12, 1e-12]); there the interval is the likelihood-ratio one, and the row's other cell mirrors it."""
    from trustseek.estimation.bootstrap import boundary_bounds, cell_tables
    from trustseek.estimation.spec import TABLES
    from trustseek.reproduction import pipeline
    from trustseek.reproduction.config import ReproduceConfig, seed_int
    from trustseek.simulation import simulate

    cfg = ReproduceConfig()
    s1, sfit, *_ = np.random.SeedSequence(cfg.seed).spawn(9)
    model, task = paper_model(), pipeline.paper_task()
    frame = simulate(model, task, pipeline._ask_policy(cfg), cfg.participants_1, counts=cfg.counts_1, seed=s1).trials()
    fit = fit_trust_model(frame[pipeline.CANONICAL], options=FitOptions(restarts=3, seed=seed_int(sfit), n_jobs=1))
    ref = cell_tables(fit.spec, fit.params)
    shape = ref["transition"].shape
    cell, other = (0, 0, 0, 1, 0), (0, 0, 0, 1, 1)  # C=low, autonomous, E'=faulty, T=high -> T'=low, high
    assert ref["transition"][cell] < 1e-6
    est = np.concatenate([ref[t].ravel() for t in TABLES])
    lo, hi = np.zeros_like(est), np.ones_like(est)
    at = ref["initial"].size + ref["emission"].size + np.ravel_multi_index(cell, shape)
    mirror = ref["initial"].size + ref["emission"].size + np.ravel_multi_index(other, shape)
    hi[at], lo[mirror] = est[at], est[mirror]  # the percentile interval collapsed at the estimate
    new_lo, new_hi, moved = boundary_bounds(fit.seqs, fit.spec, fit.params, lo, hi)
    assert 0.05 < new_hi[at] < 1.0 and new_lo[at] == lo[at], new_hi[at]
    assert new_lo[mirror] == pytest.approx(1 - new_hi[at]) and moved[[at, mirror]].all()
    assert moved.sum() == 2  # the rest kept their (not collapsed) intervals
