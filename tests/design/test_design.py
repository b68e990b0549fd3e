"""Study design and power analysis: exact policy evaluation against Monte-Carlo, the signed-rank
test against scipy, and the same sweep whatever runs it (in process, local processes, a Dask
LocalCluster)."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import wilcoxon

from trustseek.design import DesignConfig, FitSettings, ask_search, evaluate_policy, high_threshold, run_design
from trustseek.errors import TrustseekError
from trustseek.model.presets import paper_model, paper_task
from trustseek.policies import randomized
from trustseek.pomdp.problem import AssistancePOMDP
from trustseek.simulation import simulate
from trustseek.solvers.agnostic import trust_agnostic
from trustseek.solvers.registry import make_solver
from trustseek.statistics import paired_tests, signed_rank_p


def _other_model():
    """The paper's model with low trust set in more easily and kept longer: a stand-in for a fit."""
    m = paper_model()
    tr = m.transition.copy()
    tr[..., 1, 0] = np.clip(tr[..., 1, 0] * 1.6 + 0.02, 0, 1)
    tr[..., 1, 1] = 1 - tr[..., 1, 0]
    tr[..., 0, 1] = tr[..., 0, 1] * 0.6
    tr[..., 0, 0] = 1 - tr[..., 0, 1]
    return m.replace(transition=tr, notes="")


def _monte_carlo(policy, truth, task, belief_model=None, n=20_000, trials=1_000, seed=5):
    """Mean discounted reward over ``trials`` i.i.d. trials (γ^1000 ≈ 2e-6: the tail is negligible)
    and its standard error."""
    sim = simulate(truth, task, policy, n, trials=trials, seed=seed, record=False, belief_model=belief_model)
    d = sim.summary_arrays["discounted_reward"][:, 0]
    return float(d.mean()), float(d.std(ddof=1) / np.sqrt(n))


@pytest.mark.parametrize("case", ["optimal", "mismatched belief", "agnostic", "randomized", "bayes"])
def test_exact_evaluation_agrees_with_monte_carlo(case):
    truth, task = paper_model(), paper_task()
    if case == "optimal":
        pol, bm = make_solver("grid", belief_update="paper", grid=201).solve(AssistancePOMDP(truth, task)), None
    elif case == "mismatched belief":
        other = _other_model()
        pol, bm = make_solver("grid", belief_update="paper", grid=201).solve(AssistancePOMDP(other, task)), other
    elif case == "bayes":
        other = _other_model()
        pol, bm = make_solver("grid", belief_update="bayes", grid=201).solve(AssistancePOMDP(other, task)), other
    elif case == "agnostic":
        pol, bm = trust_agnostic(truth, task), None
    else:
        pol, bm = randomized({"low": 0.3, "high": 0.7}), None
    exact = evaluate_policy(pol, truth, task).value
    mc, se = _monte_carlo(pol, truth, task, belief_model=bm)
    assert abs(exact - mc) < 4 * se + 1e-3, (exact, mc, se)


def test_exact_evaluation_tells_policies_and_beliefs_apart():
    """The evaluation sees the difference the Monte-Carlo check must resolve: the optimal
    policy beats the trust-agnostic one by more than the check's tolerance, and a policy tracking
    trust with a wrong model loses value."""
    truth, task = paper_model(), paper_task()
    best = make_solver("grid", belief_update="paper", grid=201).solve(AssistancePOMDP(truth, task))
    v_best = evaluate_policy(best, truth, task).value
    v_agn = evaluate_policy(trust_agnostic(truth, task), truth, task).value
    other = _other_model()
    wrong = make_solver("grid", belief_update="paper", grid=201).solve(AssistancePOMDP(other, task))
    v_wrong = evaluate_policy(wrong, truth, task).value
    _, se = _monte_carlo(best, truth, task, n=20_000)
    assert v_best - v_agn > 8 * se
    assert v_best > v_wrong
    # an evaluation that tracked the belief with the true model, or let the supervisors follow
    # the policy's model, would miss the Monte-Carlo value by many standard errors
    assert abs(evaluate_policy(wrong, truth, task, belief_model=truth).value - v_wrong) > 8 * se
    assert abs(evaluate_policy(wrong, other, task).value - v_wrong) > 5 * se
    assert 0 < high_threshold(best) < 1


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-5, 5, allow_nan=False).filter(lambda x: abs(x) > 1e-3), min_size=1, max_size=18, unique=True))
def test_signed_rank_matches_scipy_exact(values):
    d = np.array(values)
    if len(np.unique(np.abs(d))) < len(d):
        return  # ties: covered below
    assert signed_rank_p(d) == pytest.approx(wilcoxon(d, method="exact").pvalue, rel=1e-9)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(-4, 4), min_size=2, max_size=10))
def test_signed_rank_with_ties_and_zeros_is_the_exact_permutation_test(values):
    d = np.array(values, dtype=float)
    nz = d[d != 0]
    if len(nz) == 0:
        assert signed_rank_p(d) == 1.0
        return
    # brute force over the 2^n sign patterns of the nonzero differences, mid-ranks for ties
    a = np.abs(nz)
    ranks = np.array([np.sum(a < x) + (np.sum(a == x) + 1) / 2 for x in a])
    obs = ranks[nz > 0].sum()
    signs = (np.arange(2 ** len(nz))[:, None] >> np.arange(len(nz))) & 1
    w = signs @ ranks
    p = min(1.0, 2 * min(np.mean(w <= obs + 1e-9), np.mean(w >= obs - 1e-9)))
    assert signed_rank_p(d) == pytest.approx(p, rel=1e-12)


def test_paired_tests_edge_cases():
    assert paired_tests(np.array([3.0, 3.0]), np.array([3.0, 3.0])) == {"mean_difference": 0.0, "wilcoxon": 1.0, "t": 1.0}
    out = paired_tests(np.arange(10.0) + 2, np.arange(10.0))
    assert out["t"] == 0.0 and out["wilcoxon"] == pytest.approx(2 / 2**10)


def _small(seed: int = 3) -> DesignConfig:
    return DesignConfig(
        seed=seed,
        replicates=3,
        participants_1=(6, 9),
        trials_1=(40,),
        participants_2=(4, 8),
        trials_2=(20,),
        fit=FitSettings(restarts=1, grid=101, evaluation_grid=201),
    )


def test_sweep_is_the_same_in_process_and_in_local_processes():
    a = run_design(_small(), jobs=1)
    b = run_design(_small(), jobs=2)
    assert json.dumps(a.summary, sort_keys=True) == json.dumps(b.summary, sort_keys=True)
    assert json.dumps(a.replicates, sort_keys=True) == json.dumps(b.replicates, sort_keys=True)
    c = run_design(_small(seed=4), jobs=1)
    assert c.replicates != a.replicates  # the seed matters
    s = a.summary
    assert [p["experiment1"]["participants"] for p in s["points"]] == [6, 9]
    curve = s["points"][1]["experiment2"][0]["curve"]
    assert [c["participants"] for c in curve] == [4, 8]
    for c in curve:
        for test in ("wilcoxon", "t"):
            assert c[test]["n"] == 3 and 0 <= c[test]["lo"] <= c[test]["power"] <= c[test]["hi"] <= 1


def _dies(study, part):
    os._exit(9)


def test_sweep_a_worker_that_dies_is_one_clear_error(monkeypatch):
    """A local worker killed (out of memory, kill -9) ended the sweep with a BrokenProcessPool traceback."""
    from trustseek.design import sweep

    cfg = _small()
    study = sweep.study_of(cfg)
    monkeypatch.setattr(sweep, "run_chunk", _dies)
    with pytest.raises(TrustseekError, match=r"a worker process ended abruptly .* run again, or with --jobs 1"):
        sweep.execute(study, cfg.designs(), cfg.replicates, jobs=2)


def test_sweep_is_the_same_on_a_dask_local_cluster():
    distributed = pytest.importorskip("distributed")
    local = run_design(_small(), jobs=1)
    with (
        distributed.LocalCluster(
            n_workers=2, processes=True, threads_per_worker=1, host="127.0.0.1", dashboard_address=None
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        remote = run_design(_small(), client=client)
    assert json.dumps(remote.summary, sort_keys=True) == json.dumps(local.summary, sort_keys=True)


def test_config_problems_name_the_options():
    cfg = DesignConfig(replicates=1, participants_2=(1,), alpha=1.5, test="z", ask_low=(1.2,))
    with pytest.raises(TrustseekError) as exc:
        run_design(cfg)
    text = " ".join(exc.value.lines())
    for opt in ("--replicates", "--participants-2", "--alpha", "--test", "--ask-low"):
        assert opt in text


def test_agnostic_from_arrays_is_the_solvers():
    from trustseek.design.replicate import agnostic_of
    from trustseek.solvers.agnostic import trust_agnostic_from_data

    truth, task = paper_model(), paper_task()
    for seed in range(5):
        sim = simulate(truth, task, randomized({"low": 0.1, "high": 0.4}), 3, counts=(10, 8), seed=seed)
        ours, ref = agnostic_of(sim), trust_agnostic_from_data(sim.trials(), task)
        assert ours.p_ask.tolist() == ref.p_ask.tolist() and ours.info == ref.info


def test_sizes_beyond_the_machine_are_refused_before_any_replicate():
    """A billion replicates, participants or workers ran until killed (or forked a pool of that
    many processes); each is refused at once, naming its option."""
    from trustseek.design.sweep import execute

    cases = [
        (DesignConfig(replicates=10**9), "--replicates must be between 2 and 10,000"),
        (DesignConfig(participants_2=(10**9,)), "experiment 2 of 1,000,000,000 participants"),
        (DesignConfig(participants_1=tuple(range(1, 102)), replicates=10_000), "more than 1,000,000 replicate pipelines"),
        (DesignConfig(fit=FitSettings(restarts=10**9)), "--restarts must be between 1 and 1000"),
        (DesignConfig(fit=FitSettings(tol=float("nan"))), "--tol must be a finite number > 0"),
        (DesignConfig(fit=FitSettings(grid=10**9)), "--grid must be between 3 and 1,000,001"),
        (DesignConfig(regret_target=float("nan")), "--regret-target must be a finite number"),
    ]
    for cfg, expected in cases:
        with pytest.raises(TrustseekError, match=expected):
            run_design(cfg)
    with pytest.raises(TrustseekError, match="--jobs must be between 1 and 256"):
        execute(None, [], 1, jobs=10**9)  # type: ignore[arg-type]
    with pytest.raises(TrustseekError, match="--search-ask-low needs values in"):
        ask_search(DesignConfig(), [float("nan")], [0.4])


def _curve(powers: list[tuple[int, float, float, float]]) -> list[dict]:
    return [{"participants": n, "wilcoxon": {"power": p, "lo": lo, "hi": hi}} for n, p, lo, hi in powers]


def test_participants_needed_says_how_many_or_how_far_the_grid_falls_short():
    """'beyond the grid (interval ends: - to beyond the grid)' named neither the power reached nor
    what to try next."""
    from trustseek.design import participants_needed

    curve = _curve([(30, 0.07, 0.03, 0.14), (60, 0.10, 0.05, 0.18)])
    short = {"curve": curve, "participants_for_power": {"estimate": None, "lo": None, "hi": None}}
    assert participants_needed(short, 0.8, "wilcoxon") == (
        "more than 60, the largest of the grid (power 0.10 [0.05, 0.18] there): widen it, e.g. --participants-2 60,120,240,480"
    )
    met = {"curve": curve, "participants_for_power": {"estimate": 20, "lo": 5, "hi": None}}
    assert participants_needed(met, 0.1, "wilcoxon") == "20 (5 by the interval's upper end; beyond the grid by its lower end)"
    failed = {
        "curve": _curve([(60, None, float("nan"), float("nan"))]),
        "participants_for_power": short["participants_for_power"],
    }
    assert participants_needed(failed, 0.8, "wilcoxon").startswith("more than 60, the largest of the grid (power - [-, -] there)")
    both = {"curve": curve, "participants_for_power": {"estimate": 20, "lo": 5, "hi": 40}}
    assert participants_needed(both, 0.1, "wilcoxon") == "20 (5 by the interval's upper end; 40 by its lower end)"
