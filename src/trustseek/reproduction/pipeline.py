"""The paper's Sections V and VI end to end, on simulated supervisors.

:func:`reproduce` runs, from one seed:

1. **Experiment 1** (data collection): 9 participants x 71 trials (41 low, 30 high, random
   order) under the randomized policy (ask w.p. 0.10 in low, 0.40 in high complexity);
   supervisors behave like the ``paper`` preset.
2. **Fit** of the IOHMM to those trials (:func:`trustseek.fit.fit_trust_model`, bootstrap
   intervals), the Fig. 4-6 equivalents next to the paper's values.
3. **Plan**: the trust-aware policy of the fitted model (Fig. 7) and the trust-agnostic
   policy estimated from the experiment-1 data (Section VI-A).
4. **Experiment 2**: every participant does one block of 17 low + 17 high trials per
   policy, counterbalanced order; with 5 participants as in the paper and with a large N.
   Medians, Wilcoxon signed-rank test, autonomous collections and interventions.
5. **Replicates** of the whole pipeline (1-4) with fresh simulated participants: the
   distributions of the estimated threshold and of the aware - agnostic reward difference.
6. **Costs** of estimation (policy of the true model vs of the fitted one) and of the belief
   update (``paper`` eq. (3) vs ``bayes``), on the same simulated participants; and a
   heterogeneous population around the pooled model (Remark 1).

Nothing is tuned to match the paper: the supervisors are the paper's model, everything
else is estimated from simulated data exactly as the paper estimated it from people.
The result is a JSON-serializable summary (``summary.json``); :mod:`trustseek.report`
writes the HTML report and figures.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..errors import TrustseekError
from ..estimation.fit import fit_trust_model
from ..estimation.kernels import many_fits
from ..estimation.result import FitResult
from ..model.core import AUTONOMOUS, FAULTY, INTERVENE, TrustModel
from ..model.jsonfile import json_safe
from ..model.presets import paper_model, paper_task
from ..model.task import Task
from ..policies import ComplexityPolicy, Policy, always_ask, ask_regions, never_ask, randomized
from ..pomdp.problem import AssistancePOMDP
from ..simulation import CrossoverSimulation, Simulation, Supervisors, crossover, simulate
from ..solvers.agnostic import trust_agnostic, trust_agnostic_from_data
from ..solvers.registry import make_solver
from ..solvers.sensitivity import Sensitivity, evaluate, sensitivity
from ..vocab import TRIAL_COLUMNS
from .comparison import (
    RULES,
    bootstrap_interval,
    comparison_rows,
    disagreements,
    param_specs,
    param_values,
    verdict_counts,
)
from .config import AGNOSTIC, AWARE, LOW, PAPER, ReproduceConfig, seed_int
from .scheduling import SchedulingSection, scheduling_section
from .statistics import distribution, mean_ci, share_ci, wilcoxon
from .supervisor_types import TypesSection, types_section

CANONICAL = list(TRIAL_COLUMNS)


def _threshold(policy: Policy) -> float | None:
    """The high-complexity threshold of a policy that reads the belief (None when it never asks,
    when its ask region is not [0, θ) or when it ignores the belief)."""
    th = (policy.thresholds() or {}).get("high") if policy.belief_update is not None else None
    return None if th is None or not np.isfinite(th) else float(th)


def _policy_summary(policy: Policy) -> dict[str, Any]:
    """Where a trust-aware policy asks, and with which belief update."""
    return {**ask_regions(policy), "belief_update": policy.belief_update}


def _agnostic_summary(pol: ComplexityPolicy) -> dict[str, Any]:
    """What a trust-agnostic policy does per complexity, and what its solver expected."""
    return {
        "p_ask": {cn: float(p) for cn, p in zip(pol.complexities, pol.p_ask, strict=True)},
        "action": {cn: ("ask" if p == 1 else "autonomous") for cn, p in zip(pol.complexities, pol.p_ask, strict=True)},
        "p_intervene": pol.info.get("p_intervene"),
        "expected_reward": pol.info.get("expected_reward"),
    }


PER_POLICY = ("cumulative_reward", "autonomous_collections", "interventions", "asks", "failures")


def _per_policy(sim: Simulation, keys: tuple[str, ...] = PER_POLICY) -> dict[str, dict[str, dict[str, float]]]:
    """Median, mean and sum of each quantity, per policy."""
    out: dict[str, dict[str, dict[str, float]]] = {}
    for key in keys:
        for lab, values in sim.by_policy(key).items():
            v = np.asarray(values, dtype=float)
            out.setdefault(lab, {})[key] = {"median": float(np.median(v)), "mean": float(v.mean()), "sum": float(v.sum())}
    return out


def _experiment2(sim: Simulation) -> dict[str, Any]:
    """Experiment 2's numbers: the medians and means of both policies, their paired
    differences and the Wilcoxon test."""
    r = sim.by_policy("cumulative_reward")
    aware, agn = np.asarray(r[AWARE], float), np.asarray(r[AGNOSTIC], float)
    d = aware - agn
    auto = sim.by_policy("autonomous_collections")
    d_auto = np.asarray(auto[AWARE], float) - np.asarray(auto[AGNOSTIC], float)
    return {
        "participants": len(aware),
        "median_aware": float(np.median(aware)),
        "median_agnostic": float(np.median(agn)),
        "mean_aware": float(aware.mean()),
        "mean_agnostic": float(agn.mean()),
        "median_difference": float(np.median(aware) - np.median(agn)),
        "mean_difference": float(d.mean()),
        "mean_difference_ci": list(mean_ci(d)[1:]) if len(d) > 1 else None,
        "share_aware_better": float(np.mean(d > 0)),
        "share_aware_better_ci": list(share_ci(int(np.sum(d > 0)), len(d))),
        "autonomous_difference_ci": list(mean_ci(d_auto)[1:]) if len(d) > 1 else None,
        "share_tied": float(np.mean(d == 0)),
        "wilcoxon": wilcoxon(aware, agn),
        "per_policy": _per_policy(sim),
    }


def _fit(
    frame: pd.DataFrame,
    restarts: int,
    seed: int,
    bootstrap: int,
    n_jobs: int,
    progress: Callable[[int, int], None] | None = None,
) -> FitResult:
    """The paper-structured IOHMM fitted to the canonical columns of ``frame`` (compiled: the
    reproduction is many fits)."""
    with many_fits():
        return fit_trust_model(
            frame[CANONICAL], preset="paper", restarts=restarts, seed=seed, bootstrap=bootstrap, n_jobs=n_jobs, progress=progress
        )


def _solve(model: TrustModel, task: Task, update: str, grid: int) -> Policy:
    """The trust-aware policy of ``model`` on a belief grid."""
    return make_solver("grid", belief_update=update, grid=grid).solve(AssistancePOMDP(model, task))


def _ask_policy(cfg: ReproduceConfig) -> ComplexityPolicy:
    """Experiment 1's data-collection policy."""
    return randomized({"low": cfg.ask_low, "high": cfg.ask_high})


# --------------------------------------------------------------------------- one replicate


def run_replicate(args: tuple[ReproduceConfig, int, np.random.SeedSequence]) -> dict[str, Any]:
    """Steps 1-4 with fresh participants (and the estimation cost), for the replicate study."""
    cfg, index, ss = args
    s1, sfit, s2, s3, scost = ss.spawn(5)
    truth, task = paper_model(), paper_task()
    out: dict[str, Any] = {"index": index}
    sim1 = simulate(truth, task, _ask_policy(cfg), cfg.participants_1, counts=cfg.counts_1, seed=s1)
    frame = sim1.trials()
    try:
        fit = _fit(frame, cfg.replicate_restarts, seed_int(sfit), 0, 1)
    except TrustseekError as exc:
        out["error"] = "; ".join(exc.lines())
        return out
    model = fit.model
    aware = _solve(model, task, cfg.belief_update, cfg.grid)
    agn = trust_agnostic_from_data(frame, task)
    agn.kind = AGNOSTIC
    out["threshold"] = _threshold(aware)
    out["asks_low"] = bool((aware.ask_intervals() or {}).get("low"))
    out["agnostic"] = _agnostic_summary(agn)["action"]
    out["params"] = param_values(model)
    small = crossover(
        truth, task, [aware, agn], cfg.participants_2, counts=cfg.counts_2, seed=s2, record=False, belief_model=model
    )
    e2 = _experiment2(small)
    out["median_aware"] = e2["median_aware"]
    out["median_agnostic"] = e2["median_agnostic"]
    out["median_diff_small"] = e2["median_difference"]
    out["wilcoxon_p_small"] = e2["wilcoxon"]["p_value"]
    large = crossover(
        truth, task, [aware, agn], cfg.replicate_large_n, counts=cfg.counts_2, seed=s3, record=False, belief_model=model
    )
    e2l = _experiment2(large)
    out["mean_diff_large"] = e2l["mean_difference"]
    out["share_better_large"] = e2l["share_aware_better"]
    out["median_diff_large"] = e2l["median_difference"]
    # cost of estimation: the same participants under the true model's policy
    true_pol = _solve(truth, task, cfg.belief_update, cfg.grid)
    r_fit = simulate(truth, task, aware, cfg.replicate_large_n, counts=cfg.counts_2, seed=scost, record=False).by_policy()[AWARE]
    r_true = simulate(truth, task, true_pol, cfg.replicate_large_n, counts=cfg.counts_2, seed=scost, record=False).by_policy()[
        AWARE
    ]
    out["estimation_loss"] = float(np.mean(r_true - r_fit))
    return out


@dataclass
class Reproduction:
    """What :func:`reproduce` produced: the JSON summary and the objects the report draws."""

    summary: dict[str, Any]
    fit: FitResult
    fitted: TrustModel
    aware: Policy
    agnostic: ComplexityPolicy
    true_policy: Policy
    experiment1: pd.DataFrame
    experiment2: CrossoverSimulation  # the paper-sized run
    experiment2_large: CrossoverSimulation
    heterogeneity: dict[str, Any]
    sensitivity: Sensitivity | None = None
    scheduling: SchedulingSection | None = None
    types: TypesSection | None = None
    seconds: float = 0.0


#: the steps :func:`reproduce` reports to ``progress`` as ``progress("steps", done, STEPS)``
STEP_NAMES = (
    "experiment 1",
    "fit",
    "plan",
    "threshold sensitivity",
    "experiment 2",
    "costs",
    "heterogeneity",
    "scheduling",
    "types",
    "replicates",
)


def reproduce(cfg: ReproduceConfig | None = None, progress: Callable[[str, int, int], None] | None = None) -> Reproduction:
    """Run the reproduction.

    ``progress(label, done, total)``, when given, is called as work finishes: with label
    ``"<step>"`` and ``done`` of :data:`STEP_NAMES`'s ``total`` steps after each step,
    ``"bootstrap"`` after each bootstrap resample of the main fit and ``"replicates"`` after
    each replicate experiment (``done`` of ``total`` in that series)."""
    cfg = cfg or ReproduceConfig()
    problems = cfg.problems()
    if problems:
        raise TrustseekError(problems)
    t0 = time.perf_counter()
    report = progress or (lambda label, done, total: None)
    finished = [0]

    def step(name: str) -> None:
        finished[0] += 1
        report(name, finished[0], len(STEP_NAMES))

    ss = np.random.SeedSequence(cfg.seed)
    # (a ninth child leaves the first eight, and so every earlier number, unchanged)
    s1, sfit, s2, s2l, scost, shet, sreps, ssched, stypes = ss.spawn(9)
    truth, task = paper_model(), paper_task()
    summary: dict[str, Any] = {"config": cfg.to_summary()}

    # 1. experiment 1
    sim1 = simulate(truth, task, _ask_policy(cfg), cfg.participants_1, counts=cfg.counts_1, seed=s1)
    frame1 = sim1.trials()
    auto = frame1[frame1["robot_action"] == "autonomous"]
    summary["experiment1"] = {
        "participants": cfg.participants_1,
        "trials": len(frame1),
        "trials_per_participant": {"low": cfg.counts_1[0], "high": cfg.counts_1[1]},
        "ask_probability": {"low": cfg.ask_low, "high": cfg.ask_high},
        "asks": int((frame1["robot_action"] == "ask").sum()),
        "interventions": int((auto["human_action"] == "intervene").sum()),
        "failures": int(((auto["human_action"] == "rely") & (auto["experience"] == "faulty")).sum()),
        "p_intervene": {
            cn: float((auto[auto["complexity"] == cn]["human_action"] == "intervene").mean()) for cn in task.complexities
        },
        "time_in_low_trust": float((frame1["true_trust"] == "low").mean()),
    }
    step("experiment 1")

    # 2. fit
    def fit_progress(d: int, tot: int) -> None:
        report("bootstrap", d, tot)

    fit = _fit(frame1, cfg.restarts, seed_int(sfit), cfg.bootstrap, cfg.jobs, progress=fit_progress)
    fitted = fit.model
    boot: dict[str, list[float]] = {}
    fixed: list[str] = []
    for spec in param_specs():
        if not fit.estimated[spec.table][spec.cell]:
            fixed.append(spec.key)
        iv = bootstrap_interval(fit, spec)
        if iv is not None:
            boot[spec.key] = list(iv)
    summary["fit"] = {
        "loglik": float(fit.loglik),
        "restart_logliks": [float(x) for x in fit.restart_logliks],
        "n_params": int(fit.n_params),
        "aic": float(fit.aic),
        "bic": float(fit.bic),
        "bootstrap": cfg.bootstrap,
        "values": param_values(fitted),
        "paper_values": param_values(truth),
        "bootstrap_ci": boot,
        "fixed": fixed,
        "model": fitted.to_dict(),
    }
    step("fit")

    # 3. plan
    aware = _solve(fitted, task, cfg.belief_update, cfg.grid)
    true_pol = _solve(truth, task, cfg.belief_update, cfg.grid)
    agn = trust_agnostic_from_data(frame1, task)
    agn.kind = AGNOSTIC
    plan = _Plan(truth, task, fitted, aware, true_pol, agn)
    summary["plan"] = {
        "belief_update": cfg.belief_update,
        "grid": cfg.grid,
        "fitted": _policy_summary(aware),
        "true_model": _policy_summary(true_pol),
        "agnostic": _agnostic_summary(agn),
        "agnostic_true_model": _agnostic_summary(trust_agnostic(truth, task)),
    }
    step("plan")

    # why the printed parameters give 0.78 and not the paper's 0.75
    sens, summary["threshold_sensitivity"] = _threshold_sensitivity(cfg, truth, task)
    step("threshold sensitivity")

    # 4. experiment 2
    small = crossover(truth, task, [aware, agn], cfg.participants_2, counts=cfg.counts_2, seed=s2, belief_model=fitted)
    large = crossover(truth, task, [aware, agn], cfg.large_n, counts=cfg.counts_2, seed=s2l, record=False, belief_model=fitted)
    summary["experiment2"] = {
        "small": _experiment2(small)
        | {
            "rewards": {k: v.tolist() for k, v in small.by_policy().items()},
            "first_policy": [small.block_labels[o[0]] for o in small.orders],
        },
        "large": _experiment2(large),
    }
    step("experiment 2")

    # 6. costs (same participants for every policy)
    summary["costs"] = _costs(cfg, plan, scost)
    step("costs")
    het = _heterogeneity(cfg, plan, shet)
    summary["heterogeneity"] = het["summary"]
    step("heterogeneity")

    # the paper's future work: choosing the order of the items, under the paper's model
    sched = None
    if cfg.schedule_participants:
        sched = scheduling_section(
            truth, task, counts=cfg.counts_2, participants=cfg.schedule_participants, seed=int(ssched.generate_state(1)[0])
        )
        summary["scheduling"] = sched.numbers
    step("scheduling")

    # Remark 1 with supervisor types: planning for a population of types
    types = None
    if cfg.types_participants:
        types = types_section(participants=cfg.types_participants, seed=int(stypes.generate_state(1)[0]))
        summary["types"] = types.numbers
    step("types")

    # 5. replicates
    reps: list[dict[str, Any]] = []
    if cfg.replicates:
        args = [(cfg, i, child) for i, child in enumerate(sreps.spawn(cfg.replicates))]
        if cfg.jobs > 1 and cfg.replicates > 1:
            with ProcessPoolExecutor(max_workers=cfg.jobs) as ex:
                for r in ex.map(run_replicate, args):
                    reps.append(r)
                    report("replicates", len(reps), cfg.replicates)
        else:
            for a in args:
                reps.append(run_replicate(a))
                report("replicates", len(reps), cfg.replicates)
    summary["replicates"] = _replicate_summary(reps)
    summary["bound"] = _bound(summary)
    summary["comparison"] = comparison_rows(summary)
    summary["verdict_counts"] = verdict_counts(summary["comparison"])
    summary["verdict_rules"] = list(RULES)
    summary["disagreements"] = disagreements(summary["comparison"])
    step("replicates")
    return Reproduction(
        summary=json_safe(summary),
        fit=fit,
        fitted=fitted,
        aware=aware,
        agnostic=agn,
        true_policy=true_pol,
        experiment1=frame1,
        experiment2=small,
        experiment2_large=large,
        heterogeneity=het,
        sensitivity=sens,
        scheduling=sched,
        types=types,
        seconds=time.perf_counter() - t0,
    )


@dataclass(frozen=True)
class _Plan:
    """The paper's model and task, the fitted model and the policies planned from both."""

    truth: TrustModel
    task: Task
    fitted: TrustModel
    aware: Policy
    true_policy: Policy
    agnostic: ComplexityPolicy


def _costs(cfg: ReproduceConfig, plan: _Plan, seed: np.random.SeedSequence) -> dict[str, Any]:
    """Rewards of every policy variant on the same simulated participants: the cost of
    estimating the model and the gain of the other belief update."""
    truth, task, fitted = plan.truth, plan.task, plan.fitted
    aware, true_pol, agn = plan.aware, plan.true_policy, plan.agnostic
    n = cfg.large_n
    other = "bayes" if cfg.belief_update == "paper" else "paper"
    true_other = _solve(truth, task, other, cfg.grid)
    fit_other = _solve(fitted, task, other, cfg.grid)
    agn_true = trust_agnostic(truth, task)
    variants: list[tuple[str, Policy, str]] = [
        (f"trust-aware, true model, {cfg.belief_update} update", true_pol, "true model"),
        (f"trust-aware, true model, {other} update", true_other, "true model"),
        (f"trust-aware, fitted model, {cfg.belief_update} update", aware, "fitted model"),
        (f"trust-aware, fitted model, {other} update", fit_other, "fitted model"),
        ("trust-agnostic, from experiment-1 data", agn, "baselines"),
        ("trust-agnostic, from the true model", agn_true, "baselines"),
        ("always ask", always_ask(task.complexities), "baselines"),
        ("never ask", never_ask(task.complexities), "baselines"),
    ]
    rewards: dict[str, np.ndarray] = {}
    rows: list[dict[str, Any]] = []
    for label, pol, group in variants:
        sim = simulate(truth, task, pol, n, counts=cfg.counts_2, seed=seed, record=False, belief_model=fitted)
        r = sim.summary_arrays["cumulative_reward"][:, 0]
        rewards[label] = r
        m, lo, hi = mean_ci(r)
        th = _threshold(pol)
        rows.append(
            {
                "label": label,
                "group": group,
                "mean": m,
                "lo": lo,
                "hi": hi,
                "median": float(np.median(r)),
                "threshold_high": th,
                "autonomous_collections": float(sim.summary_arrays["autonomous_collections"][:, 0].mean()),
                "interventions": float(sim.summary_arrays["interventions"][:, 0].mean()),
            }
        )
    ref = rewards[variants[0][0]]
    for row in rows:
        d = rewards[row["label"]] - ref
        m, lo, hi = mean_ci(d)
        row["vs_true_policy"] = {"mean": m, "lo": lo, "hi": hi}
    est = rewards[variants[2][0]] - ref
    upd = rewards[variants[1][0]] - ref
    return {
        "model_gain": _model_gain(cfg, ref, rewards[variants[5][0]]),
        "participants": n,
        "trials_per_block": int(sum(cfg.counts_2)),
        "rows": rows,
        "estimation_cost": dict(zip(("mean", "lo", "hi"), mean_ci(-est), strict=True)),
        "belief_update_gain": {
            "from": cfg.belief_update,
            "to": other,
            **dict(zip(("mean", "lo", "hi"), mean_ci(upd), strict=True)),
        },
    }


#: groups of participants drawn for the distribution of the paper's 5-participant statistic
GROUPS = 20_000


def _model_gain(cfg: ReproduceConfig, aware: np.ndarray, agnostic: np.ndarray) -> dict[str, Any]:
    """What the paper's own model lets a trust-aware policy gain per block over the trust-agnostic
    one: the true model's optimal policy against the true model's agnostic policy on the same
    simulated participants (common random numbers), per participant and, as in the paper's
    experiment 2, as the difference of medians over groups of ``participants_2`` participants."""
    d = aware - agnostic
    m, lo, hi = mean_ci(d)
    k = cfg.participants_2
    rng = np.random.default_rng([cfg.seed, 2, 71])
    groups = rng.integers(0, len(d), size=(GROUPS, k))  # with replacement: k is tiny next to len(d)
    stat = np.median(aware[groups], axis=1) - np.median(agnostic[groups], axis=1)
    return {
        "participants": len(d),
        "mean": m,
        "lo": lo,
        "hi": hi,
        "sd": float(d.std(ddof=1)),
        "p2.5": float(np.percentile(d, 2.5)),
        "p97.5": float(np.percentile(d, 97.5)),
        "group_size": k,
        "groups": GROUPS,
        "group_median_difference": {
            "mean": float(stat.mean()),
            "p2.5": float(np.percentile(stat, 2.5)),
            "p97.5": float(np.percentile(stat, 97.5)),
            "share_at_least_paper": float(np.mean(stat >= PAPER["median_aware"] - PAPER["median_agnostic"])),
        },
    }


def _bound(summary: dict[str, Any]) -> dict[str, Any]:
    """Where the paper's +6 lies: against the gain the paper's model allows and against the
    5-participant median differences of the replicate experiments."""
    paper = PAPER["median_aware"] - PAPER["median_agnostic"]
    gain = summary["costs"]["model_gain"]
    reps = [v for v in summary["replicates"]["median_diff_small"]["values"] if v is not None]
    return {
        "paper_difference": paper,
        "model_gain": gain,
        "replicates": len(reps),
        "replicates_at_least_paper": int(sum(v >= paper for v in reps)),
        "replicate_min": min(reps) if reps else None,
        "replicate_max": max(reps) if reps else None,
    }


def _threshold_sensitivity(cfg: ReproduceConfig, truth: TrustModel, task: Task) -> tuple[Sensitivity, dict[str, Any]]:
    """The threshold of the printed parameters, its range when each moves within its printed
    precision (alone and jointly), and under the two assumptions that rounding hides: the
    design's share of high-complexity trials (30/71) and 25/30 successes for 0.83."""
    q = "threshold[high]"
    res = sensitivity(
        truth, task, belief_update=cfg.belief_update, grid=cfg.grid, samples=cfg.sensitivity_samples, starts=1, seed=cfg.seed
    )
    lo, hi = res.range_of(q)
    share = cfg.counts_1[1] / sum(cfg.counts_1)
    p_design = np.array([1 - share, share])
    success = np.array(task.success, dtype=float)
    success[1] = 25 / 30
    variants = {
        "printed": task,
        "p_high_design": replace(task, complexity_probs=p_design),
        "p_suc_high_25_of_30": replace(task, success=success),
        "both": replace(task, complexity_probs=p_design, success=success),
    }
    values = {k: evaluate(truth, t, cfg.belief_update, cfg.grid) for k, t in variants.items()}
    swings = sorted(res.one_at_a_time, key=lambda r: -abs(r["at_upper"][q] - r["at_lower"][q]))
    return res, {
        "quantity": q,
        "nominal": res.nominal[q],
        "range": [lo, hi],
        "optimised": [res.joint[q]["min"], res.joint[q]["max"]],
        "sampled": res.sampled.get(q),
        "value_range": list(res.range_of("V")),
        "value_nominal": res.nominal["V"],
        "parameters": len(res.parameters),
        "half_width": 0.005,
        "method": res.joint[q]["method"] + f"; checked by {cfg.sensitivity_samples} Latin-hypercube points",
        "largest": [
            {"name": r["name"], "value": r["value"], "at_lower": r["at_lower"][q], "at_upper": r["at_upper"][q]}
            for r in swings[:5]
        ],
        "p_high_design": share,
        "variants": {k: {"threshold": v[q], "V": v["V"]} for k, v in values.items()},
    }


def _heterogeneity(cfg: ReproduceConfig, plan: _Plan, seed: np.random.SeedSequence) -> dict[str, Any]:
    """Experiment 2 on a heterogeneous population around the pooled model (Remark 1), by
    quartile of how easily and how conservatively low trust sets in."""
    truth, task, fitted = plan.truth, plan.task, plan.fitted
    aware, agn = plan.aware, plan.agnostic
    s_pop, s_run = seed.spawn(2)
    sup = Supervisors.dirichlet(truth, cfg.large_n, cfg.concentration, np.random.default_rng(s_pop), pseudo=cfg.pseudo)
    sim = crossover(sup, task, [aware, agn], cfg.large_n, counts=cfg.counts_2, seed=s_run, record=False, belief_model=fitted)
    # how easily low trust is triggered: P(high -> low | faulty, low complexity, autonomous),
    # and how conservative low trust is: P(intervene | low trust, low complexity, autonomous)
    trig = sup.transition[sup.index, LOW, AUTONOMOUS, FAULTY, 1, 0]
    cons = sup.emission[sup.index, LOW, AUTONOMOUS, 0, INTERVENE]
    score = trig * cons
    q = np.quantile(score, [0.25, 0.5, 0.75])
    bins = np.digitize(score, q)
    r = sim.by_policy()
    ints = sim.by_policy("interventions")
    rows = []
    for b in range(4):
        sel = bins == b
        rows.append(
            {
                "quartile": b + 1,
                "participants": int(sel.sum()),
                "mean_aware": float(r[AWARE][sel].mean()),
                "mean_agnostic": float(r[AGNOSTIC][sel].mean()),
                "mean_difference": float((r[AWARE][sel] - r[AGNOSTIC][sel]).mean()),
                "interventions_aware": float(ints[AWARE][sel].mean()),
                "interventions_agnostic": float(ints[AGNOSTIC][sel].mean()),
            }
        )
    from scipy.stats import spearmanr  # slow to import: only where it is used

    rho = spearmanr(score, r[AWARE] + r[AGNOSTIC]).statistic
    return {
        "summary": {
            "participants": cfg.large_n,
            "concentration": cfg.concentration,
            "pseudo": cfg.pseudo,
            "score": "P(high -> low | faulty, low, autonomous) x P(intervene | low trust, low, autonomous)",
            "quartiles": rows,
            "spearman_score_vs_reward": float(rho),
            "median_aware": float(np.median(r[AWARE])),
            "median_agnostic": float(np.median(r[AGNOSTIC])),
        },
        "simulation": sim,
        "score": score,
    }


def _replicate_summary(reps: list[dict[str, Any]]) -> dict[str, Any]:
    """Distributions over the replicates of every number a replicate records."""
    ok = [r for r in reps if "error" not in r]
    keys = [spec.key for spec in param_specs()]
    out = {
        "n": len(reps),
        "failed": [{"index": r["index"], "error": r["error"]} for r in reps if "error" in r],
        "threshold": distribution([r["threshold"] if r["threshold"] is not None else float("nan") for r in ok]),
        "share_threshold_policy": float(np.mean([r["threshold"] is not None for r in ok])) if ok else None,
        "share_never_ask_low": float(np.mean([not r["asks_low"] for r in ok])) if ok else 0.0,
        "agnostic_share_paper": {
            "low": float(np.mean([r["agnostic"]["low"] == "autonomous" for r in ok])) if ok else 0.0,
            "high": float(np.mean([r["agnostic"]["high"] == "ask" for r in ok])) if ok else 0.0,
        },
        "median_aware": distribution([r["median_aware"] for r in ok]),
        "median_agnostic": distribution([r["median_agnostic"] for r in ok]),
        "median_diff_small": distribution([r["median_diff_small"] for r in ok]),
        "mean_diff_large": distribution([r["mean_diff_large"] for r in ok]),
        "share_better_large": distribution([r["share_better_large"] for r in ok]),
        "wilcoxon_p_small": distribution(
            [r["wilcoxon_p_small"] if r["wilcoxon_p_small"] is not None else float("nan") for r in ok]
        ),
        "share_aware_better_small": float(np.mean([r["median_diff_small"] > 0 for r in ok])) if ok else None,
        "share_aware_better_large": float(np.mean([r["mean_diff_large"] > 0 for r in ok])) if ok else None,
        "estimation_loss": distribution([r["estimation_loss"] for r in ok]),
        "params": {k: distribution([r["params"][k] for r in ok]) for k in keys},
    }
    return out


def write_summary(summary: dict[str, Any], path: str | Path) -> None:
    """``summary`` as indented JSON at ``path``."""
    Path(path).write_text(json.dumps(summary, indent=1, sort_keys=False) + "\n", encoding="utf-8")
