"""Schedule evaluation: the simulator against the exact values, common random numbers, the report section."""

import numpy as np
import pytest

from trustseek import AssistancePOMDP, paper_model, paper_task
from trustseek.simulation.scheduling import SCHEDULES, exact_values, schedule_policies, simulate_schedules

PAPER = AssistancePOMDP(paper_model(), paper_task())


@pytest.fixture(scope="module")
def small():
    pols = schedule_policies(PAPER, (3, 3), grid=501)
    return pols, simulate_schedules(PAPER.model, PAPER.task, pols, (3, 3), 40000, seed=5)


def test_simulated_means_match_the_exact_values(small):
    pols, runs = small
    for name, v in exact_values(pols).items():
        if v is None:
            continue
        d = runs.discounted[:, runs.column(name)]
        assert abs(d.mean() - v) < 4 * d.std() / np.sqrt(len(d)) + 1e-3, name


def test_schedules_follow_their_rules_and_share_the_random_numbers(small):
    _, runs = small
    assert runs.names == list(SCHEDULES)
    easy = runs.complexity[runs.column("easy first")]
    assert (easy == np.array([0, 0, 0, 1, 1, 1])).all()
    # the two random-order schedules see the same queue: identical item sequences
    a, b = runs.column("random + trust-aware"), runs.column("random + finite-horizon")
    np.testing.assert_array_equal(runs.complexity[a], runs.complexity[b])
    first_hard = runs.complexity[runs.column("ask on first hard")].argmax(axis=1)
    acts = runs.action[runs.column("ask on first hard")]
    assert (acts[np.arange(len(acts)), first_hard] == 1).all()
    # every session collects each item exactly once
    assert (runs.complexity.sum(axis=2) == 3).all()


def test_window_policy_in_the_simulator_picks_only_visible_items():
    pols = schedule_policies(PAPER, (3, 3), names=("optimal",))
    from trustseek.pomdp.scheduling import SchedulingProblem
    from trustseek.solvers.scheduling import ScheduleSolver

    pols["w2"] = ScheduleSolver(grid=501).solve(SchedulingProblem(PAPER, (3, 3), 2))
    runs = simulate_schedules(PAPER.model, PAPER.task, pols, (3, 3), 20000, seed=2)
    d = runs.discounted[:, 1]
    assert abs(d.mean() - pols["w2"].info["value"]) < 4 * d.std() / np.sqrt(len(d)) + 1e-3


def test_report_section_numbers_and_figure(tmp_path):
    from trustseek.plots.scheduling import plot_scheduling_section
    from trustseek.reproduction.scheduling import scheduling_section

    section = scheduling_section(counts=(4, 4), participants=2000, windows=(1, 2))
    plot_scheduling_section(section, tmp_path / "s.png")
    out = section.numbers
    rows = {r["schedule"]: r for r in out["schedules"]}
    assert (
        rows["optimal"]["exact_discounted"]
        >= max(r["exact_discounted"] for r in rows.values() if r["exact_discounted"] is not None) - 1e-12
    )
    assert out["window_values"]["1"] <= out["window_values"]["2"] + 1e-9 <= out["window_values"]["all"] + 2e-9
    assert "order" in out["explanation"] and (tmp_path / "s.png").stat().st_size > 0
