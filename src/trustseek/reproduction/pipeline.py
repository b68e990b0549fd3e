"""The paper's Sections V and VI end to end, on simulated supervisors that are the paper's model.

:func:`reproduce` runs, from one seed: experiment 1 (9 participants x 71 trials under the
randomized policy); the fit of the IOHMM with bootstrap intervals (Figs. 4-6); the plan (Fig. 7,
and the trust-agnostic policy of Section VI-A); experiment 2 (a counterbalanced crossover with 5
participants and with a large N: medians, Wilcoxon test); replicates of all of that with fresh
participants; the costs of estimation and of the belief update; a heterogeneous population
(Remark 1).  Nothing is tuned to match the paper.  The summary is JSON-ready (``summary.json``);
:mod:`trustseek.report` writes the HTML report and figures.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..errors import TrustseekError
from ..estimation.fit import fit_trust_model
from ..estimation.options import FitOptions
from ..estimation.result import FitResult
from ..model.core import TrustModel
from ..model.jsonfile import json_safe
from ..model.presets import paper_model, paper_task
from ..model.task import Task
from ..parallel import beside, in_processes
from ..policies import ComplexityPolicy, Policy, ask_regions, randomized
from ..simulation import CrossoverSimulation, Simulation, crossover, simulate
from ..solvers.agnostic import trust_agnostic, trust_agnostic_from_data
from ..solvers.sensitivity import Sensitivity
from ..statistics import distribution, mean_ci, share_ci, wilcoxon
from ..vocab import TRIAL_COLUMNS
from .comparison import (
    RULES,
    comparison_rows,
    disagreements,
    param_specs,
    param_values,
    verdict_counts,
)
from .config import AGNOSTIC, AWARE, ReproduceConfig, seed_int
from .robustness import Plan, bound, costs, heterogeneity, solve_policy, threshold_of, threshold_sensitivity
from .scheduling import SchedulingSection, scheduling_section
from .supervisor_types import TypesSection, types_section

CANONICAL = list(TRIAL_COLUMNS)


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


def _per_policy(sim: Simulation) -> dict[str, dict[str, dict[str, float]]]:
    """Median, mean and sum of each of :data:`PER_POLICY`, per policy."""
    out: dict[str, dict[str, dict[str, float]]] = {}
    for key in PER_POLICY:
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
    """The paper-structured IOHMM fitted to the canonical columns of ``frame``."""
    return fit_trust_model(
        frame[CANONICAL],
        preset="paper",
        options=FitOptions(restarts=restarts, seed=seed, n_jobs=n_jobs),
        bootstrap=bootstrap,
        progress=progress,
    )


def _ask_policy(cfg: ReproduceConfig) -> ComplexityPolicy:
    """Experiment 1's data-collection policy."""
    return randomized({"low": cfg.ask_low, "high": cfg.ask_high})


def _plan(cfg: ReproduceConfig, truth: TrustModel, task: Task, fitted: TrustModel, frame1: pd.DataFrame) -> Plan:
    """Step 3: the trust-aware policies of the fitted and the true model and the trust-agnostic
    policy estimated from experiment 1's trials."""
    agnostic = trust_agnostic_from_data(frame1, task)
    agnostic.kind = AGNOSTIC
    aware, true_policy = (solve_policy(m, task, cfg.belief_update, cfg.grid) for m in (fitted, truth))
    return Plan(truth, task, fitted, aware, true_policy, agnostic)


def _crossover(
    cfg: ReproduceConfig, plan: Plan, participants: int, seed: np.random.SeedSequence, record: bool = True
) -> CrossoverSimulation:
    """Experiment 2 on ``participants`` supervisors of the true model: the trust-aware and the
    trust-agnostic policy in a counterbalanced crossover, the belief tracked with the fitted model."""
    return crossover(
        plan.truth, plan.task, [plan.aware, plan.agnostic], participants, counts=cfg.counts_2, seed=seed, record=record,
        belief_model=plan.fitted,
    )  # fmt: skip


# --------------------------------------------------------------------------- one replicate


def run_replicate(args: tuple[ReproduceConfig, int, np.random.SeedSequence]) -> dict[str, Any]:
    """Steps 1-4 with fresh participants (and the estimation cost), for the replicate study."""
    cfg, index, ss = args
    s1, sfit, s2, s3, scost = ss.spawn(5)
    truth, task = paper_model(), paper_task()
    out: dict[str, Any] = {"index": index}
    frame = simulate(truth, task, _ask_policy(cfg), cfg.participants_1, counts=cfg.counts_1, seed=s1).trials()
    try:
        fit = _fit(frame, cfg.replicate_restarts, seed_int(sfit), 0, 1)
    except TrustseekError as exc:
        out["error"] = "; ".join(exc.lines())
        return out
    plan = _plan(cfg, truth, task, fit.model, frame)
    out["threshold"] = threshold_of(plan.aware)
    out["asks_low"] = bool((plan.aware.ask_intervals() or {}).get("low"))
    out["agnostic"] = _agnostic_summary(plan.agnostic)["action"]
    out["params"] = param_values(plan.fitted)
    e2, e2l = (  # paper-sized, then large
        _experiment2(_crossover(cfg, plan, n, s, record=False))
        for n, s in ((cfg.participants_2, s2), (cfg.replicate_large_n, s3))
    )
    out["median_aware"] = e2["median_aware"]
    out["median_agnostic"] = e2["median_agnostic"]
    out["median_diff_small"] = e2["median_difference"]
    out["wilcoxon_p_small"] = e2["wilcoxon"]["p_value"]
    out["mean_diff_large"] = e2l["mean_difference"]
    out["share_better_large"] = e2l["share_aware_better"]
    out["median_diff_large"] = e2l["median_difference"]
    # cost of estimation: the same participants under the true model's policy
    r_fit, r_true = (
        simulate(truth, task, pol, cfg.replicate_large_n, counts=cfg.counts_2, seed=scost, record=False).by_policy()[AWARE]
        for pol in (plan.aware, plan.true_policy)
    )
    out["estimation_loss"] = float(np.mean(r_true - r_fit))
    return out


def _experiment1(
    cfg: ReproduceConfig, truth: TrustModel, task: Task, seed: np.random.SeedSequence
) -> tuple[pd.DataFrame, dict[str, Any]]:
    """Step 1, the data collection: its trials and their summary."""
    frame1 = simulate(truth, task, _ask_policy(cfg), cfg.participants_1, counts=cfg.counts_1, seed=seed).trials()
    auto = frame1[frame1["robot_action"] == "autonomous"]
    return frame1, {
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


def _fit_section(
    cfg: ReproduceConfig,
    frame1: pd.DataFrame,
    truth: TrustModel,
    seed: np.random.SeedSequence,
    report: Callable[[str, int, int], None],
) -> tuple[FitResult, dict[str, Any]]:
    """Step 2, the fit of experiment 1's trials with bootstrap intervals, next to the paper's values."""
    fit = _fit(frame1, cfg.restarts, seed_int(seed), cfg.bootstrap, cfg.jobs, progress=partial(report, "bootstrap"))
    fitted = fit.model
    boot: dict[str, list[float]] = {}
    fixed: list[str] = []
    for spec in param_specs():
        if not fit.estimated[spec.table][spec.cell]:
            fixed.append(spec.key)
        iv = spec.interval(fit.ci)
        if iv is not None:
            boot[spec.key] = list(iv)
    return fit, {
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


def _plan_section(
    cfg: ReproduceConfig, truth: TrustModel, task: Task, fitted: TrustModel, frame1: pd.DataFrame
) -> tuple[Plan, dict[str, Any]]:
    """Step 3, :func:`_plan` and its summary."""
    plan = _plan(cfg, truth, task, fitted, frame1)
    return plan, {
        "belief_update": cfg.belief_update,
        "grid": cfg.grid,
        "fitted": _policy_summary(plan.aware),
        "true_model": _policy_summary(plan.true_policy),
        "agnostic": _agnostic_summary(plan.agnostic),
        "agnostic_true_model": _agnostic_summary(trust_agnostic(truth, task)),
    }


@dataclass
class Reproduction:
    """What :func:`reproduce` produced: the JSON summary and the objects the report draws."""

    summary: dict[str, Any]
    fit: FitResult
    fitted: TrustModel
    aware: Policy
    agnostic: ComplexityPolicy
    experiment1: pd.DataFrame
    experiment2: CrossoverSimulation  # the paper-sized run
    experiment2_large: CrossoverSimulation
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
    # the steps of the paper's model alone start in other processes (in the order they are needed),
    # beside the fit and the plan; each has a seed of its own, so its numbers do not depend on where it runs
    sched_seed, types_seed = seed_int(ssched), seed_int(stypes)
    side: dict[str, Callable[[], Any]] = {"sensitivity": partial(threshold_sensitivity, cfg, truth, task)}
    if cfg.schedule_participants:
        n = cfg.schedule_participants
        side["scheduling"] = partial(scheduling_section, truth, task, counts=cfg.counts_2, participants=n, seed=sched_seed)
    if cfg.types_participants:
        side["types"] = partial(types_section, participants=cfg.types_participants, seed=types_seed)

    with beside(side, cfg.jobs) as result:
        frame1, summary["experiment1"] = _experiment1(cfg, truth, task, s1)
        step("experiment 1")
        fit, summary["fit"] = _fit_section(cfg, frame1, truth, sfit, report)
        step("fit")
        plan, summary["plan"] = _plan_section(cfg, truth, task, fit.model, frame1)
        step("plan")

        # why the printed parameters give 0.78 and not the paper's 0.75
        sens, summary["threshold_sensitivity"] = result("sensitivity")
        step("threshold sensitivity")

        small, large, summary["experiment2"] = _experiment2_section(cfg, plan, s2, s2l)
        step("experiment 2")

        # 6. costs (same participants for every policy)
        summary["costs"] = costs(cfg, plan, scost)
        step("costs")
        summary["heterogeneity"] = heterogeneity(cfg, plan, shet)
        step("heterogeneity")

        def section(name: str) -> Any:
            """A section of the paper's model alone (None when ``cfg`` leaves it out), its numbers in the summary."""
            out = result(name) if name in side else None
            if out is not None:
                summary[name] = out.numbers
            step(name)
            return out

        # the paper's future work: choosing the order of the items, under the paper's model
        sched: SchedulingSection | None = section("scheduling")
        # Remark 1 with supervisor types: planning for a population of types
        types: TypesSection | None = section("types")

    reps = _replicates(cfg, sreps, report)
    summary["replicates"] = _replicate_summary(reps)
    summary["bound"] = bound(summary)
    summary["comparison"] = comparison_rows(summary)
    summary["verdict_counts"] = verdict_counts(summary["comparison"])
    summary["verdict_rules"] = list(RULES)
    summary["disagreements"] = disagreements(summary["comparison"])
    step("replicates")
    return Reproduction(
        summary=json_safe(summary),
        fit=fit,
        fitted=plan.fitted,
        aware=plan.aware,
        agnostic=plan.agnostic,
        experiment1=frame1,
        experiment2=small,
        experiment2_large=large,
        sensitivity=sens,
        scheduling=sched,
        types=types,
        seconds=time.perf_counter() - t0,
    )


def _experiment2_section(
    cfg: ReproduceConfig, plan: Plan, seed: np.random.SeedSequence, seed_large: np.random.SeedSequence
) -> tuple[CrossoverSimulation, CrossoverSimulation, dict[str, Any]]:
    """Step 4, the crossover of the trust-aware and trust-agnostic policies: with the paper's
    participants and with a large N, and their summary."""
    small = _crossover(cfg, plan, cfg.participants_2, seed)
    large = _crossover(cfg, plan, cfg.large_n, seed_large, record=False)
    rewards = {k: v.tolist() for k, v in small.by_policy().items()}
    first = [small.block_labels[o[0]] for o in small.orders]
    return (
        small,
        large,
        {"small": _experiment2(small) | {"rewards": rewards, "first_policy": first}, "large": _experiment2(large)},
    )


def _replicates(
    cfg: ReproduceConfig, seed: np.random.SeedSequence, report: Callable[[str, int, int], None]
) -> list[dict[str, Any]]:
    """Step 5, the replicate experiments (in ``cfg.jobs`` processes)."""
    calls = [partial(run_replicate, (cfg, i, child)) for i, child in enumerate(seed.spawn(cfg.replicates))]
    return in_processes(calls, cfg.jobs, lambda i, done: report("replicates", done, cfg.replicates))


def _replicate_summary(reps: list[dict[str, Any]]) -> dict[str, Any]:
    """Distributions over the replicates of every number a replicate records."""
    ok = [r for r in reps if "error" not in r]

    def over(key: str) -> dict[str, Any]:  # a missing number (no threshold, no test) counts as NaN
        return distribution([float("nan") if r[key] is None else r[key] for r in ok])

    def share(flags: list[bool], without: float | None) -> float | None:  # ``without``: the share of no replicate
        return float(np.mean(flags)) if ok else without

    return {
        "n": len(reps),
        "failed": [{"index": r["index"], "error": r["error"]} for r in reps if "error" in r],
        "threshold": over("threshold"),
        "share_threshold_policy": share([r["threshold"] is not None for r in ok], None),
        "share_never_ask_low": share([not r["asks_low"] for r in ok], 0.0),
        "agnostic_share_paper": {
            "low": share([r["agnostic"]["low"] == "autonomous" for r in ok], 0.0),
            "high": share([r["agnostic"]["high"] == "ask" for r in ok], 0.0),
        },
        "median_aware": over("median_aware"),
        "median_agnostic": over("median_agnostic"),
        "median_diff_small": over("median_diff_small"),
        "mean_diff_large": over("mean_diff_large"),
        "share_better_large": over("share_better_large"),
        "wilcoxon_p_small": over("wilcoxon_p_small"),
        "share_aware_better_small": share([r["median_diff_small"] > 0 for r in ok], None),
        "share_aware_better_large": share([r["mean_diff_large"] > 0 for r in ok], None),
        "estimation_loss": over("estimation_loss"),
        "params": {spec.key: distribution([r["params"][spec.key] for r in ok]) for spec in param_specs()},
    }


def write_summary(summary: dict[str, Any], path: str | Path) -> None:
    """``summary`` as indented JSON at ``path``."""
    Path(path).write_text(json.dumps(summary, indent=1, sort_keys=False) + "\n", encoding="utf-8")
