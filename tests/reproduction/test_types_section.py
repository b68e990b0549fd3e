"""The supervisor-types comparison (Remark 1): paired runs, the oracle, groups and verdicts."""

from __future__ import annotations

import numpy as np
import pytest

from cli_runner import run_cli
from trustseek.model import TypeMixture, paper_conservative_mixture, paper_task
from trustseek.reproduction.supervisor_types import (
    AGNOSTIC,
    FITTED,
    ORACLE,
    POOLED,
    TYPE_AWARE,
    PopulationRuns,
    _numbers,
    _verdicts,
    types_section,
)
from trustseek.simulation import Supervisors
from trustseek.simulation.engine import simulate


@pytest.fixture(scope="module")
def section():
    return types_section(
        paper_conservative_mixture(0.5),
        participants=300,
        block_counts=((10, 10),),
        fit_participants=40,
        restarts=1,
        seed=3,
        gap=0.1,
    )


def test_groups_and_counts(section):
    mix, one = section.numbers["populations"]
    assert [g["group"] for g in mix["groups"]] == ["paper", "conservative", "all"]
    assert sum(g["participants"] for g in mix["groups"][:2]) == mix["groups"][2]["participants"] == 300
    assert [g["group"] for g in one["groups"]] == ["paper"]
    for g in mix["groups"]:
        assert set(g["reward"]) == {POOLED, FITTED, TYPE_AWARE, ORACLE, AGNOSTIC}
        for r in g["reward"].values():
            assert r["low"] <= r["mean"] <= r["high"]


def test_the_oracle_is_each_persons_own_type_policy(section):
    """The oracle's reward of a person is the reward of their own type's policy run alone on the
    same people with the same seed (common random numbers)."""
    runs = section.runs[0]
    oracle = section.policies["oracle"]
    mix = paper_conservative_mixture(0.5)
    seed = int(np.random.SeedSequence(3).generate_state(4)[2])
    sup = Supervisors.from_mixture(mix, 300, rng=seed)
    assert np.array_equal(sup.index, runs.types)
    for m, pol in enumerate(oracle):
        alone = simulate(sup, paper_task(), pol, counts=(10, 10), seed=seed, record=False).reward_matrix()[:, 0]
        mask = runs.types == m
        assert np.array_equal(runs.rewards[ORACLE][mask], alone[mask])


def test_differences_are_paired():
    """A policy that beats another by exactly 1 for every person gives the interval [1, 1],
    however spread the rewards are."""
    rng = np.random.default_rng(0)
    base = rng.normal(40, 8, size=50)
    runs = PopulationRuns(
        "x",
        ("a", "b"),
        np.arange(50) % 2,
        (5, 5),
        {POOLED: base, TYPE_AWARE: base + 1, ORACLE: base + 1, AGNOSTIC: base},
        {p: np.zeros(50) for p in (POOLED, TYPE_AWARE, ORACLE, AGNOSTIC)},
    )
    nums = _numbers(runs)
    d = next(d for d in nums["groups"][2]["differences"] if d["policy"] == TYPE_AWARE and d["against"] == POOLED)
    assert d["mean"] == pytest.approx(1) and d["low"] == pytest.approx(1) and d["high"] == pytest.approx(1)
    text = _verdicts([nums], "b")
    assert "gains" in text[0] and "+1.00 [+1.00, +1.00]" in text[0]
    assert "their own type's policy would change their reward by +1.00" in text[1]


def test_a_one_type_mixture_makes_the_type_aware_policy_the_single_type_one():
    """With one type the type-aware policy plans for that type alone: on the one-type population it
    earns what that type's own (oracle) policy earns, person by person."""
    mix = TypeMixture.single(paper_conservative_mixture().models[0], "paper")
    sec = types_section(mix, participants=200, block_counts=((8, 8),), fit_participants=30, restarts=1, seed=1, gap=0.1)
    for runs in sec.runs:
        assert np.allclose(runs.rewards[TYPE_AWARE], runs.rewards[ORACLE])


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["-m", "paper", "--share", "0.3"], "--share needs a mixture of two types"),
        (["-m", "nobody"], "unknown mixture preset"),
        (["--types", "nobody"], "unknown mixture preset"),  # --types names the mixture, as in solve and simulate
    ],
)
def test_compare_types_bad_input(args, needle):
    code, err = run_cli(["compare-types", *args], stdout=False)
    assert code == 2 and needle in err and "Traceback" not in err


def test_fitted_types_on_a_one_type_population_cost_nothing(section):
    """On the paper's supervisor alone BIC picks one type, and the fitted-types policy is the
    pooled structure's own: it earns what the pooled policy earns, person by person."""
    assert section.numbers["fitted_types"]["paper alone"]["chosen"] == 1
    alone = section.runs[1]
    assert np.array_equal(alone.rewards[FITTED], alone.rewards[POOLED])
