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
import math
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..errors import TrustseekError
from ..model.core import ASK, AUTONOMOUS, FAULTY, INTERVENE, RELIABLE, RELY, Task, TrustModel
from ..policies import always_ask, ask_regions, never_ask, randomized
from ..solvers.agnostic import trust_agnostic, trust_agnostic_from_data
from ..pomdp.problem import AssistancePOMDP
from ..model.presets import paper_model, paper_task
from ..simulation import Supervisors, crossover, simulate
from ..solvers.registry import make_solver
from ..vocab import PAPER_BLOCK_COUNTS, PAPER_DATA_COUNTS, TRIAL_COLUMNS

LOW, HIGH = 0, 1
AWARE, AGNOSTIC = "trust-aware", "trust-agnostic"

PAPER = {
    "threshold_high": 0.75,
    "median_aware": 57.0,
    "median_agnostic": 51.0,
    "participants_1": 9,
    "participants_2": 5,
}

CANONICAL = list(TRIAL_COLUMNS)


@dataclass
class ReproduceConfig:
    """Every setting of the reproduction (the defaults are the paper's design)."""

    seed: int = 0
    replicates: int = 20
    large_n: int = 10_000
    participants_1: int = 9
    counts_1: tuple[int, int] = PAPER_DATA_COUNTS
    ask_low: float = 0.10
    ask_high: float = 0.40
    participants_2: int = 5
    counts_2: tuple[int, int] = PAPER_BLOCK_COUNTS
    restarts: int = 10
    bootstrap: int = 20
    replicate_restarts: int = 4
    replicate_large_n: int = 2_000
    belief_update: str = "paper"
    grid: int = 1001
    concentration: float = 20.0
    pseudo: float = 0.5
    jobs: int = 2

    def problems(self) -> list[str]:
        p = []
        for name in ("replicates",):
            if getattr(self, name) < 0:
                p.append(f"--{name} must be >= 0, got {getattr(self, name)}")
        for name in ("large_n", "participants_1", "participants_2", "restarts", "replicate_restarts", "replicate_large_n", "jobs"):
            if getattr(self, name) < 1:
                p.append(f"--{name.replace('_', '-')} must be >= 1, got {getattr(self, name)}")
        if self.bootstrap < 0:
            p.append(f"--bootstrap must be >= 0, got {self.bootstrap}")
        if self.belief_update not in ("paper", "bayes"):
            p.append(f"--belief-update must be 'paper' or 'bayes', got {self.belief_update!r}")
        if not (0 <= self.ask_low <= 1 and 0 <= self.ask_high <= 1):
            p.append("ask probabilities must lie in [0, 1]")
        if self.grid < 3:
            p.append(f"--grid must be >= 3, got {self.grid}")
        return p


# --------------------------------------------------------------------------- helpers


def _ci(v: np.ndarray) -> tuple[float, float, float]:
    v = np.asarray(v, dtype=float)
    m = float(v.mean())
    h = 1.96 * float(v.std(ddof=1)) / math.sqrt(len(v)) if len(v) > 1 else float("nan")
    return m, m - h, m + h


def _pct(v, q) -> float | None:
    v = np.asarray([x for x in v if x is not None and np.isfinite(x)], dtype=float)
    return float(np.percentile(v, q)) if len(v) else None


def _dist(v) -> dict[str, Any]:
    vals = [x for x in v if x is not None and np.isfinite(x)]
    return {
        "n": len(vals),
        "median": _pct(vals, 50),
        "mean": float(np.mean(vals)) if vals else None,
        "p2.5": _pct(vals, 2.5),
        "p97.5": _pct(vals, 97.5),
        "values": [None if x is None or not np.isfinite(x) else float(x) for x in v],
    }


def wilcoxon(aware: np.ndarray, agnostic: np.ndarray) -> dict[str, Any]:
    """Two-sided Wilcoxon signed-rank test of the paired differences (scipy)."""
    from scipy.stats import wilcoxon as _w

    d = np.asarray(aware, float) - np.asarray(agnostic, float)
    out: dict[str, Any] = {"n": int(len(d)), "nonzero": int(np.count_nonzero(d))}
    if np.count_nonzero(d) == 0:
        out.update(statistic=None, p_value=None, note="all paired differences are zero")
        return out
    res = _w(aware, agnostic, zero_method="wilcox", alternative="two-sided")
    out.update(statistic=float(res.statistic), p_value=float(res.pvalue))
    return out


def _threshold(policy) -> float | None:
    """The high-complexity threshold of a policy that reads the belief (None when it never asks,
    when its ask region is not [0, θ) or when it ignores the belief)."""
    th = (policy.thresholds() or {}).get("high") if policy.belief_update is not None else None
    return None if th is None or not np.isfinite(th) else float(th)


def _policy_summary(policy) -> dict[str, Any]:
    return {**ask_regions(policy), "belief_update": policy.belief_update}


def _agnostic_summary(pol) -> dict[str, Any]:
    return {
        "p_ask": {cn: float(p) for cn, p in zip(pol.complexities, pol.p_ask)},
        "action": {cn: ("ask" if p == 1 else "autonomous") for cn, p in zip(pol.complexities, pol.p_ask)},
        "p_intervene": pol.info.get("p_intervene"),
        "expected_reward": pol.info.get("expected_reward"),
    }


def _per_policy(sim, keys=("cumulative_reward", "autonomous_collections", "interventions", "asks", "failures")):
    out = {}
    for key in keys:
        for lab, v in sim.by_policy(key).items():
            v = np.asarray(v, dtype=float)
            out.setdefault(lab, {})[key] = {"median": float(np.median(v)), "mean": float(v.mean()), "sum": float(v.sum())}
    return out


def _experiment2(sim) -> dict[str, Any]:
    r = sim.by_policy("cumulative_reward")
    aware, agn = np.asarray(r[AWARE], float), np.asarray(r[AGNOSTIC], float)
    d = aware - agn
    return {
        "participants": int(len(aware)),
        "median_aware": float(np.median(aware)),
        "median_agnostic": float(np.median(agn)),
        "mean_aware": float(aware.mean()),
        "mean_agnostic": float(agn.mean()),
        "median_difference": float(np.median(aware) - np.median(agn)),
        "mean_difference": float(d.mean()),
        "mean_difference_ci": list(_ci(d)[1:]) if len(d) > 1 else None,
        "share_aware_better": float(np.mean(d > 0)),
        "share_tied": float(np.mean(d == 0)),
        "wilcoxon": wilcoxon(aware, agn),
        "per_policy": _per_policy(sim),
    }


def _fit(frame, cfg: ReproduceConfig, restarts: int, seed: int, bootstrap: int, n_jobs: int, progress=None):
    from ..estimation.fit import fit_trust_model

    return fit_trust_model(
        frame[CANONICAL], preset="paper", restarts=restarts, seed=seed, bootstrap=bootstrap, n_jobs=n_jobs, progress=progress
    )


def _solve(model: TrustModel, task: Task, update: str, grid: int):
    return make_solver("grid", belief_update=update, grid=grid).solve(AssistancePOMDP(model, task))


def _ask_policy(cfg: ReproduceConfig):
    return randomized({"low": cfg.ask_low, "high": cfg.ask_high})


def _seed_int(ss: np.random.SeedSequence) -> int:
    return int(ss.generate_state(1, dtype=np.uint32)[0])


# --------------------------------------------------------------------------- one replicate


def run_replicate(args) -> dict[str, Any]:
    """Steps 1-4 with fresh participants (and the estimation cost), for the replicate study."""
    cfg, index, ss = args
    s1, sfit, s2, s3, scost = ss.spawn(5)
    truth, task = paper_model(), paper_task()
    out: dict[str, Any] = {"index": index}
    sim1 = simulate(truth, task, _ask_policy(cfg), cfg.participants_1, counts=cfg.counts_1, seed=s1)
    frame = sim1.trials()
    try:
        fit = _fit(frame, cfg, cfg.replicate_restarts, _seed_int(sfit), 0, 1)
    except TrustseekError as exc:
        out["error"] = "; ".join(exc.lines())
        return out
    model = fit.model
    aware = _solve(model, task, cfg.belief_update, cfg.grid)
    agn = trust_agnostic_from_data(frame, task)
    agn.kind = AGNOSTIC
    out["threshold"] = _threshold(aware)
    out["asks_low"] = bool(aware.ask_intervals()["low"])
    out["agnostic"] = _agnostic_summary(agn)["action"]
    out["params"] = _param_values(model)
    small = crossover(truth, task, [aware, agn], cfg.participants_2, counts=cfg.counts_2, seed=s2, record=False, belief_model=model)
    e2 = _experiment2(small)
    out["median_aware"] = e2["median_aware"]
    out["median_agnostic"] = e2["median_agnostic"]
    out["median_diff_small"] = e2["median_difference"]
    out["wilcoxon_p_small"] = e2["wilcoxon"]["p_value"]
    large = crossover(truth, task, [aware, agn], cfg.replicate_large_n, counts=cfg.counts_2, seed=s3, record=False, belief_model=model)
    e2l = _experiment2(large)
    out["mean_diff_large"] = e2l["mean_difference"]
    out["median_diff_large"] = e2l["median_difference"]
    # cost of estimation: the same participants under the true model's policy
    true_pol = _solve(truth, task, cfg.belief_update, cfg.grid)
    r_fit = simulate(truth, task, aware, cfg.replicate_large_n, counts=cfg.counts_2, seed=scost, record=False).by_policy()[AWARE]
    r_true = simulate(truth, task, true_pol, cfg.replicate_large_n, counts=cfg.counts_2, seed=scost, record=False).by_policy()[AWARE]
    out["estimation_loss"] = float(np.mean(r_true - r_fit))
    return out


# --------------------------------------------------------------------------- parameters and the comparison table

# (key, label, paper value, getter on a TrustModel)
def _param_specs():
    A, K = AUTONOMOUS, ASK
    specs = [("initial_high", "P(T_1 = high)", 1.0, lambda m: m.initial[1], ("initial", (1,)))]
    for c, cn in ((LOW, "low"), (HIGH, "high")):
        for t, tn in ((0, "low"), (1, "high")):
            specs.append((f"em_ask_{cn}_{tn}", f"Fig. 4a  P(intervene | T={tn}, C={cn}, ask)", 1.0,
                          (lambda m, c=c, t=t: m.emission[c, K, t, INTERVENE]), ("emission", (c, K, t, INTERVENE))))
    for c, cn, fig, vals in ((LOW, "low", "4b", (0.98, 1.0)), (HIGH, "high", "4c", (0.46, 0.95))):
        for t, tn in ((0, "low"), (1, "high")):
            specs.append((f"em_rely_{cn}_{tn}", f"Fig. {fig}  P(rely | T={tn}, C={cn}, autonomous)", vals[t],
                          (lambda m, c=c, t=t: m.emission[c, A, t, RELY]), ("emission", (c, A, t, RELY))))
    trans = [
        ("5a", LOW, A, RELIABLE, [("high", "high", 1.0), ("low", "low", 1.0)]),
        ("5b", LOW, A, FAULTY, [("high", "low", 0.39), ("low", "low", 0.99)]),
        ("5c", LOW, K, FAULTY, [("high", "high", 1.0), ("low", "low", 1.0)]),
        ("6a", HIGH, A, RELIABLE, [("high", "high", 1.0), ("low", "high", 1.0)]),
        ("6b", HIGH, A, FAULTY, [("high", "low", 1.0), ("low", "low", 0.7)]),
        ("6c", HIGH, K, RELIABLE, [("high", "high", 0.94), ("low", "high", 0.44)]),
    ]
    names = {"low": 0, "high": 1}
    an = {A: "autonomous", K: "ask"}
    en = {RELIABLE: "reliable", FAULTY: "faulty"}
    for fig, c, a, e, cells in trans:
        cn = "low" if c == LOW else "high"
        for fr, to, val in cells:
            t, u = names[fr], names[to]
            specs.append((f"tr_{fig}_{fr}_{to}", f"Fig. {fig}  P(T'={to} | T={fr}, E'={en[e]}, C={cn}, {an[a]})", val,
                          (lambda m, c=c, a=a, e=e, t=t, u=u: m.transition[c, a, e, t, u]), ("transition", (c, a, e, t, u))))
    return specs


def _param_values(model: TrustModel) -> dict[str, float]:
    return {key: float(get(model)) for key, _, _, get, _ in _param_specs()}


def _ci_of(fit, where) -> tuple[float, float] | None:
    ci = getattr(fit, "ci", None)
    if not ci:
        return None
    name, idx = where
    try:
        lo, hi = ci[name]
        return float(np.asarray(lo)[idx]), float(np.asarray(hi)[idx])
    except (KeyError, IndexError, TypeError, ValueError):
        return None


def _inside(v, lo, hi, tol=0.005) -> bool:
    return lo is not None and hi is not None and lo - tol <= v <= hi + tol


def _row(quantity, paper, ours, interval, kind, note=""):
    if interval is None or interval[0] is None:
        verdict = "no interval"
    elif _inside(paper, *interval):
        verdict = "agrees"
    else:
        verdict = "DISAGREES"
    return {"quantity": quantity, "paper": paper, "ours": ours, "interval": list(interval) if interval else None,
            "interval_kind": kind, "verdict": verdict, "note": note}


def comparison_rows(summary: dict) -> list[dict]:
    """Every number the paper reports, next to ours and an interval, with a verdict."""
    rows = []
    fitted = summary["fit"]["values"]
    boot = summary["fit"].get("bootstrap_ci") or {}
    reps = summary["replicates"]["params"]
    cfg = summary["config"]
    design = f"{cfg['participants_1']} × {sum(cfg['counts_1'])}"
    for key, label, paper_val, _, _ in _param_specs():
        rep = reps.get(key)
        interval = (rep["p2.5"], rep["p97.5"]) if rep and rep["n"] else None
        kind = "replicates 95%"
        if interval is None and key in boot:
            interval, kind = tuple(boot[key]), "bootstrap 95%"
        notes = []
        if interval is not None and interval[1] - interval[0] > 0.8:
            notes.append(f"not identified by a {design} sample (the range spans most of [0, 1])")
        if key in boot:
            notes.append(f"bootstrap 95% [{boot[key][0]:.3f}, {boot[key][1]:.3f}]")
        note = "; ".join(notes)
        rows.append(_row(label, paper_val, fitted[key], interval, kind, note))
    plan = summary["plan"]
    th = summary["replicates"]["threshold"]
    rows.append(_row("Threshold on P(T=high), high complexity (ask below)", PAPER["threshold_high"], plan["fitted"]["thresholds"]["high"],
                     (th["p2.5"], th["p97.5"]) if th["n"] else None, "replicates 95%",
                     f"true model: {plan['true_model']['thresholds']['high']:.3f}"))
    share_low = summary["replicates"]["share_never_ask_low"]
    rows.append({"quantity": "Trust-aware policy never asks in low complexity", "paper": "never asks",
                 "ours": "never asks" if not plan["fitted"]["ask_intervals"]["low"] else "asks somewhere",
                 "interval": None, "interval_kind": "share of replicates", "note": f"{share_low:.0%} of replicates",
                 "verdict": "agrees" if not plan["fitted"]["ask_intervals"]["low"] else "DISAGREES"})
    agn = plan["agnostic"]["action"]
    rep_agn = summary["replicates"]["agnostic_share_paper"]
    for cn, pv in (("low", "autonomous"), ("high", "ask")):
        rows.append({"quantity": f"Trust-agnostic policy, {cn} complexity", "paper": pv, "ours": agn[cn], "interval": None,
                     "interval_kind": "share of replicates", "note": f"{rep_agn[cn]:.0%} of replicates choose {pv}",
                     "verdict": "agrees" if agn[cn] == pv else "DISAGREES"})
    small, large = summary["experiment2"]["small"], summary["experiment2"]["large"]
    rr = summary["replicates"]
    for key, pk, lab in (("median_aware", "median_aware", "trust-aware"), ("median_agnostic", "median_agnostic", "trust-agnostic")):
        d = rr[key]
        rows.append(_row(f"Median cumulative reward, {lab} ({small['participants']} participants)", PAPER[pk], small[key],
                         (d["p2.5"], d["p97.5"]) if d["n"] else None, "replicates 95%",
                         f"{large['participants']:,} participants: {large[key]:g}"))
    d = rr["median_diff_small"]
    rows.append(_row("Median difference aware − agnostic", PAPER["median_aware"] - PAPER["median_agnostic"], small["median_difference"],
                     (d["p2.5"], d["p97.5"]) if d["n"] else None, "replicates 95%",
                     f"large N mean difference {large['mean_difference']:.2f} [{large['mean_difference_ci'][0]:.2f}, {large['mean_difference_ci'][1]:.2f}]"))
    rows.append({"quantity": "Trust-aware better for most participants", "paper": "most (Fig. 8)",
                 "ours": f"{large['share_aware_better']:.0%} of {large['participants']:,}", "interval": None,
                 "interval_kind": "", "note": f"{large['share_tied']:.0%} tied; {small['share_aware_better']:.0%} of {small['participants']} in the paper-sized run",
                 "verdict": "agrees" if large["share_aware_better"] > 0.5 else "DISAGREES"})
    aw = large["per_policy"][AWARE]["autonomous_collections"]["mean"]
    ag = large["per_policy"][AGNOSTIC]["autonomous_collections"]["mean"]
    rows.append({"quantity": "More autonomous collections with the trust-aware policy", "paper": "more",
                 "ours": f"{aw:.1f} vs {ag:.1f} per block", "interval": None, "interval_kind": "", "note": f"{large['participants']:,} participants",
                 "verdict": "agrees" if aw > ag else "DISAGREES"})
    return rows


def disagreements(rows: list[dict]) -> list[str]:
    out = []
    for r in rows:
        if r["verdict"] == "DISAGREES":
            iv = r["interval"]
            ivs = f" ({r['interval_kind']}: [{iv[0]:.3g}, {iv[1]:.3g}])" if iv else ""
            out.append(f"{r['quantity']}: the paper reports {r['paper']}, the simulation gives {_fmt(r['ours'])}{ivs}.")
    return out


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.3g}"
    return str(v)


# --------------------------------------------------------------------------- the pipeline


@dataclass
class Reproduction:
    summary: dict[str, Any]
    fit: Any
    fitted: TrustModel
    aware: Any
    agnostic: Any
    true_policy: Any
    experiment1: Any  # DataFrame
    experiment2: Any  # CrossoverSimulation (small)
    experiment2_large: Any
    heterogeneity: Any
    seconds: float = 0.0


def reproduce(cfg: ReproduceConfig | None = None, progress: Callable[[str, float], None] | None = None) -> Reproduction:
    """Run the reproduction; ``progress(stage, fraction_done)`` reports how far it got."""
    cfg = cfg or ReproduceConfig()
    problems = cfg.problems()
    if problems:
        raise TrustseekError(problems)
    t0 = time.perf_counter()
    say = progress or (lambda stage, frac: None)
    # work units: exp1+plan 1, fit 4 (+ bootstrap), exp2 1, costs 1, heterogeneity 1, replicates
    w_fit = 4.0 + cfg.bootstrap / 10.0
    w_rep = 1.2 * cfg.replicates
    total = 1 + w_fit + 1 + 1 + 1 + w_rep
    done = [0.0]

    def step(stage, w=0.0):
        done[0] += w
        say(stage, min(1.0, done[0] / total))

    ss = np.random.SeedSequence(cfg.seed)
    s1, sfit, s2, s2l, scost, shet, sreps = ss.spawn(7)
    truth, task = paper_model(), paper_task()
    summary: dict[str, Any] = {"config": _config_dict(cfg)}

    # 1. experiment 1
    step("experiment 1: data collection")
    sim1 = simulate(truth, task, _ask_policy(cfg), cfg.participants_1, counts=cfg.counts_1, seed=s1)
    frame1 = sim1.trials()
    auto = frame1[frame1["robot_action"] == "autonomous"]
    summary["experiment1"] = {
        "participants": cfg.participants_1,
        "trials": int(len(frame1)),
        "trials_per_participant": {"low": cfg.counts_1[0], "high": cfg.counts_1[1]},
        "ask_probability": {"low": cfg.ask_low, "high": cfg.ask_high},
        "asks": int((frame1["robot_action"] == "ask").sum()),
        "interventions": int((auto["human_action"] == "intervene").sum()),
        "failures": int(((auto["human_action"] == "rely") & (auto["experience"] == "faulty")).sum()),
        "p_intervene": {cn: float((auto[auto["complexity"] == cn]["human_action"] == "intervene").mean()) for cn in task.complexities},
        "time_in_low_trust": float((frame1["true_trust"] == "low").mean()),
    }
    step("fit", 1.0)

    # 2. fit
    def fit_progress(d, tot):
        say(f"fit: {d}/{tot}", min(1.0, (done[0] + w_fit * d / max(tot, 1)) / total))

    fit = _fit(frame1, cfg, cfg.restarts, _seed_int(sfit), cfg.bootstrap, cfg.jobs, progress=fit_progress)
    fitted = fit.model
    boot = {}
    for key, _, _, _, where in _param_specs():
        iv = _ci_of(fit, where)
        if iv is not None:
            boot[key] = list(iv)
    summary["fit"] = {
        "loglik": float(fit.loglik),
        "restart_logliks": [float(x) for x in fit.restart_logliks],
        "n_params": int(fit.n_params),
        "aic": float(fit.aic),
        "bic": float(fit.bic),
        "bootstrap": cfg.bootstrap,
        "values": _param_values(fitted),
        "paper_values": _param_values(truth),
        "bootstrap_ci": boot,
        "model": fitted.to_dict(),
    }
    step("plan", w_fit)

    # 3. plan
    aware = _solve(fitted, task, cfg.belief_update, cfg.grid)
    true_pol = _solve(truth, task, cfg.belief_update, cfg.grid)
    agn = trust_agnostic_from_data(frame1, task)
    agn.kind = AGNOSTIC
    summary["plan"] = {
        "belief_update": cfg.belief_update,
        "grid": cfg.grid,
        "fitted": _policy_summary(aware),
        "true_model": _policy_summary(true_pol),
        "agnostic": _agnostic_summary(agn),
        "agnostic_true_model": _agnostic_summary(trust_agnostic(truth, task)),
    }

    # 4. experiment 2
    step("experiment 2")
    small = crossover(truth, task, [aware, agn], cfg.participants_2, counts=cfg.counts_2, seed=s2, belief_model=fitted)
    large = crossover(truth, task, [aware, agn], cfg.large_n, counts=cfg.counts_2, seed=s2l, record=False, belief_model=fitted)
    summary["experiment2"] = {
        "small": _experiment2(small) | {"rewards": {k: v.tolist() for k, v in small.by_policy().items()},
                                        "first_policy": [small.block_labels[o[0]] for o in small.orders]},
        "large": _experiment2(large),
    }
    step("costs of estimation and of the belief update", 1.0)

    # 6. costs (same participants for every policy)
    summary["costs"] = _costs(cfg, truth, task, fitted, aware, true_pol, agn, scost)
    step("heterogeneous population (Remark 1)", 1.0)
    het = _heterogeneity(cfg, truth, task, aware, agn, fitted, shet)
    summary["heterogeneity"] = het["summary"]
    step("replicates", 1.0)

    # 5. replicates
    reps = []
    if cfg.replicates:
        args = [(cfg, i, child) for i, child in enumerate(sreps.spawn(cfg.replicates))]
        if cfg.jobs > 1 and cfg.replicates > 1:
            with ProcessPoolExecutor(max_workers=cfg.jobs) as ex:
                for r in ex.map(run_replicate, args):
                    reps.append(r)
                    step(f"replicates: {len(reps)}/{cfg.replicates}", 1.2)
        else:
            for a in args:
                reps.append(run_replicate(a))
                step(f"replicates: {len(reps)}/{cfg.replicates}", 1.2)
    summary["replicates"] = _replicate_summary(reps)
    summary["comparison"] = comparison_rows(summary)
    summary["disagreements"] = disagreements(summary["comparison"])
    say("done", 1.0)
    return Reproduction(
        summary=_clean(summary),
        fit=fit,
        fitted=fitted,
        aware=aware,
        agnostic=agn,
        true_policy=true_pol,
        experiment1=frame1,
        experiment2=small,
        experiment2_large=large,
        heterogeneity=het,
        seconds=time.perf_counter() - t0,
    )


def _config_dict(cfg: ReproduceConfig) -> dict[str, Any]:
    d = asdict(cfg)
    d["counts_1"] = list(cfg.counts_1)
    d["counts_2"] = list(cfg.counts_2)
    d.pop("jobs")  # does not change any number
    return d


def _costs(cfg, truth, task, fitted, aware, true_pol, agn, seed) -> dict[str, Any]:
    n = cfg.large_n
    other = "bayes" if cfg.belief_update == "paper" else "paper"
    true_other = _solve(truth, task, other, cfg.grid)
    fit_other = _solve(fitted, task, other, cfg.grid)
    agn_true = trust_agnostic(truth, task)
    variants = [
        (f"trust-aware, true model, {cfg.belief_update} update", true_pol, "true model"),
        (f"trust-aware, true model, {other} update", true_other, "true model"),
        (f"trust-aware, fitted model, {cfg.belief_update} update", aware, "fitted model"),
        (f"trust-aware, fitted model, {other} update", fit_other, "fitted model"),
        ("trust-agnostic, from experiment-1 data", agn, "baselines"),
        ("trust-agnostic, from the true model", agn_true, "baselines"),
        ("always ask", always_ask(task.complexities), "baselines"),
        ("never ask", never_ask(task.complexities), "baselines"),
    ]
    rewards = {}
    rows = []
    for label, pol, group in variants:
        sim = simulate(truth, task, pol, n, counts=cfg.counts_2, seed=seed, record=False, belief_model=fitted)
        r = sim.summary_arrays["cumulative_reward"][:, 0]
        rewards[label] = r
        m, lo, hi = _ci(r)
        th = _threshold(pol) if hasattr(pol, "thresholds") else None
        rows.append({"label": label, "group": group, "mean": m, "lo": lo, "hi": hi, "median": float(np.median(r)),
                     "threshold_high": th,
                     "autonomous_collections": float(sim.summary_arrays["autonomous_collections"][:, 0].mean()),
                     "interventions": float(sim.summary_arrays["interventions"][:, 0].mean())})
    ref = rewards[variants[0][0]]
    for row in rows:
        d = rewards[row["label"]] - ref
        m, lo, hi = _ci(d)
        row["vs_true_policy"] = {"mean": m, "lo": lo, "hi": hi}
    est = rewards[variants[2][0]] - ref
    upd = rewards[variants[1][0]] - ref
    return {
        "participants": n,
        "trials_per_block": int(sum(cfg.counts_2)),
        "rows": rows,
        "estimation_cost": dict(zip(("mean", "lo", "hi"), _ci(-est))),
        "belief_update_gain": {"from": cfg.belief_update, "to": other, **dict(zip(("mean", "lo", "hi"), _ci(upd)))},
    }


def _heterogeneity(cfg, truth, task, aware, agn, fitted, seed) -> dict[str, Any]:
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
        rows.append({
            "quartile": b + 1,
            "participants": int(sel.sum()),
            "mean_aware": float(r[AWARE][sel].mean()),
            "mean_agnostic": float(r[AGNOSTIC][sel].mean()),
            "mean_difference": float((r[AWARE][sel] - r[AGNOSTIC][sel]).mean()),
            "interventions_aware": float(ints[AWARE][sel].mean()),
            "interventions_agnostic": float(ints[AGNOSTIC][sel].mean()),
        })
    from scipy.stats import spearmanr

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


def _replicate_summary(reps: list[dict]) -> dict[str, Any]:
    ok = [r for r in reps if "error" not in r]
    keys = [k for k, *_ in _param_specs()]
    out = {
        "n": len(reps),
        "failed": [{"index": r["index"], "error": r["error"]} for r in reps if "error" in r],
        "threshold": _dist([r["threshold"] if r["threshold"] is not None else float("nan") for r in ok]),
        "share_threshold_policy": float(np.mean([r["threshold"] is not None for r in ok])) if ok else None,
        "share_never_ask_low": float(np.mean([not r["asks_low"] for r in ok])) if ok else 0.0,
        "agnostic_share_paper": {
            "low": float(np.mean([r["agnostic"]["low"] == "autonomous" for r in ok])) if ok else 0.0,
            "high": float(np.mean([r["agnostic"]["high"] == "ask" for r in ok])) if ok else 0.0,
        },
        "median_aware": _dist([r["median_aware"] for r in ok]),
        "median_agnostic": _dist([r["median_agnostic"] for r in ok]),
        "median_diff_small": _dist([r["median_diff_small"] for r in ok]),
        "mean_diff_large": _dist([r["mean_diff_large"] for r in ok]),
        "wilcoxon_p_small": _dist([r["wilcoxon_p_small"] if r["wilcoxon_p_small"] is not None else float("nan") for r in ok]),
        "share_aware_better_small": float(np.mean([r["median_diff_small"] > 0 for r in ok])) if ok else None,
        "share_aware_better_large": float(np.mean([r["mean_diff_large"] > 0 for r in ok])) if ok else None,
        "estimation_loss": _dist([r["estimation_loss"] for r in ok]),
        "params": {k: _dist([r["params"][k] for r in ok]) for k in keys},
    }
    return out


def _clean(o):
    """JSON-safe: numpy scalars to Python, NaN/inf to None, tuples to lists."""
    if isinstance(o, dict):
        return {str(k): _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean(v) for v in o]
    if isinstance(o, np.ndarray):
        return _clean(o.tolist())
    if isinstance(o, (np.floating, float)):
        v = float(o)
        return v if math.isfinite(v) else None
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    return o


def write_summary(summary: dict, path: str | Path) -> None:
    Path(path).write_text(json.dumps(summary, indent=1, sort_keys=False) + "\n", encoding="utf-8")
