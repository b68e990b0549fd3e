"""What the reproduction's policies cost and how robust they are (steps 6 of
:mod:`.pipeline`): the cost of estimating the model and of the other belief update, the
paper's 5-participant statistic against the model's gain, why the printed parameters give
their threshold, and a heterogeneous population around the pooled model (Remark 1)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..model.core import TrustModel
from ..model.task import Task
from ..policies import ComplexityPolicy, Policy, always_ask, never_ask
from ..pomdp.problem import AssistancePOMDP
from ..simulation import Supervisors, crossover, simulate
from ..solvers.agnostic import trust_agnostic
from ..solvers.registry import make_solver
from ..solvers.sensitivity import Sensitivity, evaluate, sensitivity
from ..statistics import mean_interval
from ..vocab import AUTONOMOUS, FAULTY, INTERVENE
from .config import AGNOSTIC, AWARE, LOW, PAPER, ReproduceConfig


def high_threshold(policy: Policy) -> float:
    """The belief in high trust below which ``policy`` asks in the last (highest) complexity: 0
    when it never asks there, 1 when it always does; NaN when its ask region is not [0, θ) or it
    ignores the belief."""
    th = policy.thresholds() if policy.belief_update is not None else None
    v = th.get(policy.complexities[-1]) if th else float("nan")
    return 0.0 if v is None else float(v)


def threshold_of(policy: Policy) -> float | None:
    """:func:`high_threshold`, None when the policy never asks there or has no threshold."""
    th = high_threshold(policy)
    return th if th > 0 else None


def solve_policy(model: TrustModel, task: Task, update: str, grid: int) -> Policy:
    """The trust-aware policy of ``model`` on a belief grid."""
    return make_solver("grid", belief_update=update, grid=grid).solve(AssistancePOMDP(model, task))


@dataclass(frozen=True)
class Plan:
    """The paper's model and task, the fitted model and the policies planned from both."""

    truth: TrustModel
    task: Task
    fitted: TrustModel
    aware: Policy
    true_policy: Policy
    agnostic: ComplexityPolicy


def _lo_hi(values: np.ndarray) -> dict[str, float]:
    return mean_interval(values, names=("mean", "lo", "hi"))


def costs(cfg: ReproduceConfig, plan: Plan, seed: np.random.SeedSequence) -> dict[str, Any]:
    """Rewards of every policy variant on the same simulated participants: the cost of
    estimating the model and the gain of the other belief update."""
    truth, task, fitted = plan.truth, plan.task, plan.fitted
    aware, true_pol, agn = plan.aware, plan.true_policy, plan.agnostic
    n = cfg.large_n
    other = "bayes" if cfg.belief_update == "paper" else "paper"
    true_other = solve_policy(truth, task, other, cfg.grid)
    fit_other = solve_policy(fitted, task, other, cfg.grid)
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
        rows.append(
            {
                "label": label,
                "group": group,
                **_lo_hi(r),
                "median": float(np.median(r)),
                "threshold_high": threshold_of(pol),
                "autonomous_collections": float(sim.summary_arrays["autonomous_collections"][:, 0].mean()),
                "interventions": float(sim.summary_arrays["interventions"][:, 0].mean()),
            }
        )
    ref = rewards[variants[0][0]]
    for row in rows:
        row["vs_true_policy"] = _lo_hi(rewards[row["label"]] - ref)
    est = rewards[variants[2][0]] - ref
    upd = rewards[variants[1][0]] - ref
    return {
        "model_gain": model_gain(cfg, ref, rewards[variants[5][0]]),
        "participants": n,
        "trials_per_block": int(sum(cfg.counts_2)),
        "rows": rows,
        "estimation_cost": _lo_hi(-est),
        "belief_update_gain": {"from": cfg.belief_update, "to": other, **_lo_hi(upd)},
    }


#: groups of participants drawn for the distribution of the paper's 5-participant statistic
GROUPS = 20_000


def model_gain(cfg: ReproduceConfig, aware: np.ndarray, agnostic: np.ndarray) -> dict[str, Any]:
    """What the paper's own model lets a trust-aware policy gain per block over the trust-agnostic
    one: the true model's optimal policy against the true model's agnostic policy on the same
    simulated participants (common random numbers), per participant and, as in the paper's
    experiment 2, as the difference of medians over groups of ``participants_2`` participants."""
    d = aware - agnostic
    k = cfg.participants_2
    rng = np.random.default_rng([cfg.seed, 2, 71])
    groups = rng.integers(0, len(d), size=(GROUPS, k))  # with replacement: k is tiny next to len(d)
    stat = np.median(aware[groups], axis=1) - np.median(agnostic[groups], axis=1)
    return {
        "participants": len(d),
        **_lo_hi(d),
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


def bound(summary: dict[str, Any]) -> dict[str, Any]:
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


def threshold_sensitivity(cfg: ReproduceConfig, truth: TrustModel, task: Task) -> tuple[Sensitivity, dict[str, Any]]:
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


def heterogeneity(cfg: ReproduceConfig, plan: Plan, seed: np.random.SeedSequence) -> dict[str, Any]:
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
        "participants": cfg.large_n,
        "concentration": cfg.concentration,
        "pseudo": cfg.pseudo,
        "score": "P(high -> low | faulty, low, autonomous) x P(intervene | low trust, low, autonomous)",
        "quartiles": rows,
        "spearman_score_vs_reward": float(rho),
        "median_aware": float(np.median(r[AWARE])),
        "median_agnostic": float(np.median(r[AGNOSTIC])),
    }
