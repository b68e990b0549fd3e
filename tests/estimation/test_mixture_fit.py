"""Supervisor types: the mixture IOHMM's E-step, its EM, M = 1 against the pooled fit, recovery
of the paper + conservative population, empty types, shared parts, and the choice of M."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.special import logsumexp

from trustseek.estimation import encode, fit_iohmm, fit_trust_model, paper_spec
from trustseek.estimation.em import CAPPED, run_em
from trustseek.estimation.estep import Workspace
from trustseek.estimation.mixture import bootstrap_types, decode_types, fit_mixture, fit_types, mixture_loglik, mixture_warnings
from trustseek.estimation.mixture_em import EMPTY, MixtureParams, MixtureStructure, MixtureWorkspace, parse_differ
from trustseek.estimation.options import FitOptions
from trustseek.estimation.selection import select_types, type_selection_warnings
from trustseek.estimation.spec import FitError, Params
from trustseek.model.mixture import TypeMixture
from trustseek.model.presets import conservative_model, paper_conservative_mixture, paper_model
from trustseek.simulation.designs import simulate_design
from trustseek.simulation.populations import Supervisors

SPEC = paper_spec()


def mixed(n, seed=1, share=0.5):
    mix = paper_conservative_mixture(share)
    sup = Supervisors.from_mixture(mix, n, rng=seed)
    return mix, sup, simulate_design(sup, n, seed=seed + 1)


@pytest.fixture(scope="module")
def mixture_data():
    return mixed(120)


@pytest.fixture(scope="module")
def mixture_fit(mixture_data):
    _mix, _sup, df = mixture_data
    return fit_mixture(encode(df, SPEC), SPEC, 2, options=FitOptions(restarts=4, seed=0, n_jobs=1))


def test_one_type_is_the_pooled_fit():
    seqs = encode(simulate_design(paper_model(), 40, seed=3), SPEC)
    pooled = fit_iohmm(
        seqs, SPEC, options=FitOptions(restarts=3, seed=0, n_jobs=1), compiled=False
    )  # the same lockstep runs and finish
    one = fit_mixture(seqs, SPEC, 1, options=FitOptions(restarts=3, seed=0, n_jobs=1))
    assert one.loglik == pytest.approx(pooled.loglik, abs=1e-8)
    assert one.restart_logliks == pytest.approx(pooled.restart_logliks, abs=1e-8)
    np.testing.assert_allclose(one.params.type_params(0).emission, pooled.params.emission, atol=1e-10)
    np.testing.assert_allclose(one.params.type_params(0).transition, pooled.params.transition, atol=1e-10)
    assert one.n_params == pooled.n_params and one.bic == pytest.approx(pooled.bic, abs=1e-6)


def test_the_cap_is_a_warning_when_the_best_start_stopped_there_as_in_the_pooled_fit(mixture_fit):
    """A mixture warned of any start stopped at the cap ("1 of 4 starts stopped at the E-step cap"),
    though only the best start's end decides the estimates: the pooled fit's rule and words."""
    assert mixture_fit.runs[mixture_fit.best].converged
    runs = list(mixture_fit.runs)
    other = next(i for i in range(len(runs)) if i != mixture_fit.best)
    runs[other] = replace(runs[other], converged=False, ended=CAPPED)
    assert mixture_warnings(replace(mixture_fit, runs=runs)) == mixture_warnings(mixture_fit)
    assert not any("cap" in w for w in mixture_warnings(mixture_fit))
    runs[mixture_fit.best] = replace(runs[mixture_fit.best], converged=False, ended=CAPPED)
    (cap,) = [w for w in mixture_warnings(replace(mixture_fit, runs=runs)) if "cap" in w]
    assert cap.startswith("the best restart stopped at the cap on E-steps")


def test_fit_types_with_one_type_is_fit_trust_model():
    df = simulate_design(paper_model(), 30, seed=5)
    # the pooled fit runs compiled with its own finish: the two maxima agree to the fit's tolerance (1e-8 relative)
    assert fit_types(df, 1, options=FitOptions(restarts=2)).loglik == pytest.approx(
        fit_trust_model(df, options=FitOptions(restarts=2)).loglik, rel=1e-8
    )


@pytest.mark.parametrize("K", [2, 3])
def test_mixture_estep_is_the_responsibility_weighted_sum_of_per_participant_counts(K):
    """log-likelihood = sum_n logsumexp_m log P(trials, type m); counts of type m = sum_n r_nm * counts_nm."""
    spec = paper_spec(levels=K)
    seqs = encode(mixed(25, seed=4)[2], spec)
    s = MixtureStructure(spec, seqs, 3)
    p = s.random(np.random.default_rng(7))
    st = MixtureWorkspace(seqs, s).estep(p)
    per = Workspace(seqs, *s.dims, method="compiled")
    N = seqs.n_participants
    lls, counts = [], []
    for m in range(3):
        pm = Params.stack([Params(p.initial[m], p.emission[m], p.transition[m])])
        Bx, Ax = per.tables(pm)
        ll, ci, ce, ct = per._kernel.run_each(np.zeros(N, dtype=np.int64), pm.initial, Bx, Ax)
        lls.append(ll)
        counts.append((ci, ct[:, :-1], ce[:, :-1].reshape(N, s.Ue, s.M, K).transpose(0, 1, 3, 2)))
    lls = np.array(lls)  # (M, N): log P(trials, type) as the joint initial row carries the weight
    assert st.loglik == pytest.approx(logsumexp(lls, axis=0).sum(), rel=1e-12)
    np.testing.assert_allclose(st.sequence, lls, rtol=1e-12)
    r = np.exp(lls - logsumexp(lls, axis=0))
    for m in range(3):
        np.testing.assert_allclose(st.initial[m], (r[m][:, None] * counts[m][0]).sum(0), rtol=1e-10)
        np.testing.assert_allclose(st.transition[m], np.einsum("n,nuij->uij", r[m], counts[m][1]), rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(st.emission[m], np.einsum("n,nukx->ukx", r[m], counts[m][2]), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(st.initial.sum(-1).sum(), N, rtol=1e-12)


def test_mixture_estep_is_the_same_to_the_bit_on_two_threads():
    seqs = encode(mixed(200, seed=6)[2], SPEC)
    s = MixtureStructure(SPEC, seqs, 3)
    p = MixtureParams.stack([s.random(np.random.default_rng(i)) for i in range(3)])
    one = MixtureWorkspace(seqs, s, threads=1).estep(p)
    two = MixtureWorkspace(seqs, s, threads=2).estep(p)
    for name in ("loglik", "initial", "emission", "transition", "sequence"):
        assert np.array_equal(getattr(one, name), getattr(two, name)), name


def test_the_unweighted_estep_is_unchanged_by_two_equal_types():
    """Two copies of one model at weights 1/2 each: each type gets half of the pooled counts."""
    seqs = encode(simulate_design(paper_model(), 30, seed=2), SPEC)
    s = MixtureStructure(SPEC, seqs, 2)
    base = s.random(np.random.default_rng(3)).type_params(0)
    p = MixtureParams.from_types([0.5, 0.5], [base, base])
    st = MixtureWorkspace(seqs, s).estep(p)
    ref = Workspace(seqs, *s.dims).estep(base)
    assert st.loglik == pytest.approx(float(ref.loglik), rel=1e-12)
    for m in range(2):
        np.testing.assert_allclose(st.emission[m], ref.emission / 2, rtol=1e-12)
        np.testing.assert_allclose(st.transition[m], ref.transition / 2, rtol=1e-12)


@pytest.mark.parametrize("differ", ["all", "emission", "transition", "initial,emission"])
def test_every_run_climbs_and_ends_finite(mixture_data, differ):
    seqs = encode(mixture_data[2], SPEC).subset(np.arange(40))
    fit = fit_mixture(seqs, SPEC, 2, options=FitOptions(restarts=3, seed=1, max_iter=300, n_jobs=1), differ=differ)
    for run in fit.runs:
        h = np.array(run.history)
        assert np.all(np.isfinite(h))
        assert np.all(np.diff(h) >= -1e-9 * np.abs(h[:-1])), differ
    if "emission" not in parse_differ(differ):
        assert np.array_equal(fit.params.emission[0], fit.params.emission[1])
    if "transition" not in parse_differ(differ):
        assert np.array_equal(fit.params.transition[0], fit.params.transition[1])
    full = MixtureStructure(SPEC, seqs, 2).n_free
    assert fit.n_params == full if differ == "all" else fit.n_params < full


def test_parse_differ_refuses_unknown_parts():
    assert parse_differ("all") == ("initial", "emission", "transition")
    assert parse_differ("transition, emission") == ("emission", "transition")
    with pytest.raises(FitError):
        parse_differ("emissions")
    with pytest.raises(FitError):
        MixtureStructure(SPEC, encode(simulate_design(paper_model(), 3, seed=0), SPEC), 0)


def test_paper_and_conservative_types_are_recovered(mixture_data, mixture_fit):
    """The acceptance property at 120 participants (the full 200 x 71 figures: benchmarks/bench_mixture.py)."""
    mix, sup, df = mixture_data
    seqs = encode(df, SPEC)
    post = mixture_fit.type_posteriors()
    # type1 relies least: the conservative supervisor (index 1 of the generating mixture)
    truth = np.where(sup.index == mix.type_index("conservative"), 0, 1)
    assert (post.argmax(1) == truth).mean() >= 0.9
    assert mixture_fit.loglik >= mixture_loglik(seqs, mix)
    assert mixture_fit.weights == pytest.approx([0.5, 0.5], abs=0.12)
    m1, m2 = mixture_fit.models()
    assert m1.emission[0, 0, 0, 1] < m2.emission[0, 0, 0, 1]  # P(rely | low trust, low complexity)
    assert mixture_fit.empty_types == []


def test_outputs_keep_the_participants_and_round_trip(mixture_fit, mixture_data, tmp_path):
    df = mixture_data[2]
    table = mixture_fit.posterior_frame()
    assert list(table["participant"]) == list(mixture_fit.seqs.participants)
    assert set(table["participant"]) == set(df["participant"])
    np.testing.assert_allclose(table[["p_type_type1", "p_type_type2"]].sum(axis=1), 1.0)
    mix = mixture_fit.mixture()
    mix.save(tmp_path / "m.json")
    back = TypeMixture.load(tmp_path / "m.json")
    assert back.names == ("type1", "type2")
    assert mixture_loglik(mixture_fit.seqs, back) == pytest.approx(mixture_fit.loglik, abs=1e-6)
    dec = decode_types(df, back)
    assert len(dec) == len(df)
    np.testing.assert_allclose(dec["p_trust_low"] + dec["p_trust_high"], 1.0)
    per = dec.groupby("participant")["type"].first()
    assert (per.reindex(table["participant"]).to_numpy() == table["type"].to_numpy()).all()


def test_an_empty_type_is_carried_and_reported():
    """A type with weight exactly 0: the E-step skips it, the M-step keeps it at 0, the fit names it."""
    seqs = encode(simulate_design(paper_model(), 30, seed=8), SPEC)
    s = MixtureStructure(SPEC, seqs, 2)
    pooled = fit_iohmm(seqs, SPEC, options=FitOptions(restarts=1, seed=0, n_jobs=1)).params
    p = MixtureParams.from_types([1.0, 0.0], [pooled, s.random(np.random.default_rng(0)).type_params(0)])
    work = MixtureWorkspace(seqs, s)
    st = work.estep(p)
    assert st.loglik == pytest.approx(float(Workspace(seqs, *s.dims).loglik(pooled)), rel=1e-12)
    assert np.all(st.emission[1] == 0) and np.all(st.sequence[1] == -np.inf)
    q = s.mstep(st, p)
    assert np.all(q.initial[1] == 0)
    (run,) = run_em(s, work, [p], tol=1e-8, max_iter=50)
    assert np.all(run.params.initial[1] == 0) and np.isfinite(run.loglik)
    assert MixtureParams(run.params.initial, run.params.emission, run.params.transition).type_params(1).initial == pytest.approx(
        [0.5, 0.5]
    )


def test_selection_picks_two_types_on_the_mixture_and_one_on_the_paper_model(mixture_data):
    rows = select_types(mixture_data[2], types=(1, 2, 3), folds=3, options=FitOptions(restarts=3, seed=0, tol=1e-6, n_jobs=1))
    assert [r["types"] for r in rows if r["best_bic"]] == [2]
    assert [r["types"] for r in rows if r["best_heldout"]] == [2]
    assert all(r["reached_best"] >= 1 for r in rows)
    paper = simulate_design(paper_model(), 120, seed=2)
    rows = select_types(paper, types=(1, 2), folds=3, options=FitOptions(restarts=3, seed=0, tol=1e-6, n_jobs=1))
    assert [r["types"] for r in rows if r["best_bic"]] == [1]
    assert [r["types"] for r in rows if r["best_heldout"]] == [1]


def test_selection_warns_at_the_limit():
    rows = [
        {"types": 1, "best_bic": False, "best_heldout": False, "reached_best": 3, "starts": 3},
        {"types": 2, "best_bic": True, "best_heldout": True, "reached_best": 1, "starts": 4, "empty_types": ["type2"]},
    ]
    text = " ".join(type_selection_warnings(rows))
    assert "largest compared" in text and "--types 1..3" in text and "only 1 of 4" in text and "empty" in text


def test_conservative_preset_differs_from_the_paper_in_low_complexity():
    assert conservative_model().emission[0, 0, 0, 1] < paper_model().emission[0, 0, 0, 1] - 0.2
    assert EMPTY < 1


def test_bootstrap_intervals_contain_the_estimate_and_do_not_depend_on_processes():
    df = mixed(30, seed=9)[2]
    fit = fit_types(df, 2, options=FitOptions(restarts=2, seed=0, tol=1e-6))
    one = bootstrap_types(fit, 3, options=FitOptions(restarts=1, seed=1, tol=1e-6, n_jobs=1))
    two = bootstrap_types(fit, 3, options=FitOptions(restarts=1, seed=1, tol=1e-6, n_jobs=2))
    for m, (name, model) in enumerate(zip(fit.names, fit.models(), strict=True)):
        for table in ("initial", "emission", "transition"):
            lo, hi = one.cells[name][table]
            est = np.asarray(getattr(model, table))
            assert np.all(lo <= est + 1e-12) and np.all(est <= hi + 1e-12)
            np.testing.assert_array_equal(lo, two.cells[name][table][0])
        assert one.weights[name][0] <= fit.weights[m] <= one.weights[name][1]


def test_types_of_named_inputs_refuse_the_presets_options_as_the_selection_of_levels_does():
    """With a study's own input the types are general models: an option of the paper preset (here
    its complexities) is refused, where the types' fit left it unread and fitted on."""
    frame = simulate_design(paper_model(), 4, seed=0)
    frame["advice"] = np.where(np.arange(len(frame)) % 2 == 0, "agree", "disagree")
    named = {"transition_inputs": ("advice",), "emission_inputs": ()}
    for run in (
        lambda: fit_types(frame, 2, options=FitOptions(restarts=1, max_iter=3, n_jobs=1), complexities=("a", "b"), **named),
        lambda: select_types(frame, (1,), folds=2, options=FitOptions(restarts=1, max_iter=3), complexities=("a", "b"), **named),
    ):
        with pytest.raises(ValueError, match=r"options \['complexities'\] apply to the paper preset only"):
            run()


def test_cells_that_no_resample_moved_from_zero_get_likelihood_ratio_bounds(monkeypatch):
    """A types' bootstrap gave [0, 0] for a free cell estimated at 0 that every resample left there,
    as if the value were known: such cells (not the fixed ask rows, nor rows no trial informs) get
    the likelihood-ratio bound of a single fit's (bisection to 1/64), the mixture refitted; the
    other intervals are the percentile ones, and the intervals say how many."""
    from trustseek.data.trials import example_path, read_trials
    from trustseek.estimation import mixture

    fit = fit_types(read_trials(example_path()), 2, options=FitOptions(restarts=2, seed=0, tol=1e-6, n_jobs=1))
    options = FitOptions(restarts=1, seed=1, tol=1e-6, n_jobs=1)
    iv = bootstrap_types(fit, 4, options=options)
    with monkeypatch.context() as patch:  # the same replicates' percentile intervals alone
        patch.setattr(mixture, "_type_boundary_bounds", lambda fit, lo, hi, per: (lo, hi, 0))
        raw = bootstrap_types(fit, 4, options=options)
    expected = 0
    for name, model in zip(fit.names, fit.models(), strict=True):
        for table in ("emission", "transition"):
            est = np.asarray(getattr(model, table))
            lo, hi = iv.cells[name][table]
            assert np.all(lo <= est + 1e-12) and np.all(est <= hi + 1e-12)
            stuck = (est < 1e-6) & (raw.cells[name][table][1] < 1e-6)
            if table == "emission":
                stuck[:, 1] = False  # P(intervene | ask) = 1 is fixed by the preset
            for kind, where in model.not_estimated:
                if kind == table:
                    stuck[where] = False
            assert np.all(hi[stuck] > 0) and np.all(hi[stuck] * 64 == np.round(hi[stuck] * 64))  # a bisection's end
            np.testing.assert_array_equal(hi[~stuck], raw.cells[name][table][1][~stuck])
            expected += int(stuck.sum())
    assert iv.boundary == expected > 0 and raw.boundary == 0
    (note,) = [n for n in iv.notes() if "stayed there" in n]
    assert f"{expected} cells of the types" in note and "likelihood-ratio" in note
