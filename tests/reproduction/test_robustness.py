"""The reproduction's cost study (reproduction/robustness.py): every policy variant on the same
simulated participants."""

import numpy as np

from trustseek.model.presets import paper_model, paper_task
from trustseek.reproduction.config import ReproduceConfig
from trustseek.reproduction.robustness import Plan, costs, solve_policy
from trustseek.solvers.agnostic import trust_agnostic


def test_variants_that_decide_alike_earn_alike_on_the_same_participants():
    """The variants were simulated from one SeedSequence, each drawing the next children from it:
    other participants for every variant, so that the true model's policy, fitted as itself, seemed
    to cost reward against itself (and every paired difference carried the noise of two samples)."""
    cfg = ReproduceConfig(large_n=300, grid=201)
    truth, task = paper_model(), paper_task()
    policy = solve_policy(truth, task, cfg.belief_update, cfg.grid)
    plan = Plan(truth, task, truth, policy, policy, trust_agnostic(truth, task))  # the fit found the truth
    out = costs(cfg, plan, np.random.SeedSequence(4))
    rows = {r["label"]: r for r in out["rows"]}
    fitted = rows[f"trust-aware, fitted model, {cfg.belief_update} update"]
    assert fitted["vs_true_policy"] == {"mean": 0.0, "lo": 0.0, "hi": 0.0}
    assert out["estimation_cost"]["mean"] == 0.0
    alike = [rows["trust-agnostic, from experiment-1 data"], rows["trust-agnostic, from the true model"]]
    assert alike[0]["mean"] == alike[1]["mean"]
