"""Conformance of every policy kind (in the spirit of POMDPTools' test_solver and
scikit-learn's check_estimator).

For each kind in ``POLICY_KINDS`` one small instance is built -- through the solver registry
where a solver makes it, by hand where none does -- and checked the same way: its JSON (a dict
and a file) loads back into a policy that decides the same; ``PolicyRunner`` over a fixed run of
trials takes the actions and holds the beliefs that stepping the policy and the belief filter by
hand gives, one trial at a time and all at once (the simulation's numpy path); decisions are
``autonomous``/``ask``; a policy that asks at random repeats itself from a seed; the ask
regions it reports agree with its decisions; a corrupted file is refused with a ``ModelError``
naming the problem.  A new kind without an instance here fails; a kind that honestly lacks a
property says why in ``CASES`` (and the check makes sure it refuses rather than answers).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

from pomdp_oracles import TIGER
from trustseek.interop.files import read_pomdp
from trustseek.model import paper_conservative_mixture, paper_model, paper_task
from trustseek.model.jsonfile import ModelError, json_safe
from trustseek.policies import (
    POLICY_KINDS,
    PolicyError,
    PolicyRunner,
    always_ask,
    load_policy,
    never_ask,
    policy_from_dict,
    randomized,
)
from trustseek.policies.base import ask_bounds
from trustseek.policies.scheduling import ScheduleRunner
from trustseek.pomdp.belief import make_updater
from trustseek.pomdp.problem import AssistancePOMDP
from trustseek.pomdp.scheduling import SchedulingProblem
from trustseek.solvers.registry import make_solver
from trustseek.solvers.type_aware import solve_type_aware
from trustseek.vocab import ACTIONS, ASK, EXPERIENCES, HUMAN_ACTIONS, PAPER_ASK_PROBABILITIES, UNOBSERVED

#: (complexity, human action or None when unobserved, experience) of the fixed run of trials;
#: three of each complexity, as many as the schedule instance has items
TRIALS = (
    ("high", "rely", "faulty"),
    ("low", "rely", "reliable"),
    ("high", "intervene", "reliable"),
    ("low", None, "faulty"),
    ("high", "rely", "reliable"),
    ("low", "intervene", "reliable"),
)
COUNTS = (3, 3)


def _paper() -> AssistancePOMDP:
    return AssistancePOMDP(paper_model(), paper_task())


@dataclass(frozen=True)
class Case:
    """How to build one small policy of a kind, and the checks it honestly has not (check -> why)."""

    build: Callable[[], Any]
    random: bool = False
    lacks: dict[str, str] = field(default_factory=dict)


FLAT = "a flat POMDP's policy chooses among the file's own actions, with no trust model"
CASES: dict[str, Case] = {
    "trust-aware": Case(
        lambda: make_solver("grid", grid=201).solve(_paper()),
        lacks={
            "exact-json": "its Q is written to 12 decimals, so the thresholds of the loaded policy move in the 12th",
            "checked-grid": "its grid only tells people the number of points: the loader reads the length of q",
        },
    ),
    "alpha-vector": Case(lambda: make_solver("alpha", gap=1e-2).solve(_paper())),
    "trust-agnostic": Case(lambda: make_solver("trust-agnostic").solve(_paper())),
    "randomized": Case(lambda: randomized(PAPER_ASK_PROBABILITIES), random=True),
    "always-ask": Case(always_ask),
    "never-ask": Case(never_ask),
    "flat-alpha-vector": Case(
        lambda: make_solver("point", gap=1e-2).solve(read_pomdp("tiger.pomdp", TIGER)),
        lacks={"runner": f"{FLAT} for PolicyRunner's belief", "vocabulary": FLAT, "regions": FLAT},
    ),
    "schedule": Case(
        lambda: make_solver("schedule", schedule_grid=101).solve(SchedulingProblem(_paper(), COUNTS)),
        lacks={"numpy-path": "actions_many decides in the state the policy is bound to, not in each trial's own"},
    ),
    "type-aware": Case(
        lambda: solve_type_aware(paper_conservative_mixture(0.3), paper_task(), gap=0.5, max_seconds=0.1),
        lacks={"regions": "its belief is over (type, trust) pairs: ask intervals need two trust levels"},
    ),
}


@pytest.fixture(scope="module")
def built() -> dict[str, Any]:
    return {}


def _policy(kind: str, built: dict[str, Any]) -> Any:
    case = CASES.get(kind)
    if case is None:
        pytest.fail(f"policy kind {kind!r} has no instance in tests/policies/test_policy_conformance.py: add one to CASES")
    if kind not in built:
        built[kind] = case.build()
        assert built[kind].kind == kind
    return built[kind]


def _lacks(kind: str, check: str) -> str | None:
    case = CASES.get(kind)
    return None if case is None else case.lacks.get(check)


def test_every_kind_has_an_instance() -> None:
    assert set(CASES) == set(POLICY_KINDS)


# -- helpers -------------------------------------------------------------------------------


def _width(policy: Any) -> int:
    """The length of a belief row of ``policy``."""
    if policy.model is not None:
        return int(policy.model.n_trust)
    return len(getattr(policy, "states", ("low", "high")))


def _beliefs(policy: Any) -> np.ndarray:
    """A grid of beliefs: P(trust = high) on 0, 0.025, ..., 1 for two levels; the corners and a
    fixed spread of the simplex otherwise."""
    K = _width(policy)
    if K == 2:
        x = np.linspace(0.0, 1.0, 41)
        return np.stack([1 - x, x], axis=1)
    return np.vstack([np.eye(K), np.random.default_rng(0).dirichlet(np.ones(K), size=60)])


def _decisions(policy: Any, beliefs: np.ndarray, seed: int | None = 0) -> np.ndarray:
    """Actions (n, N): each belief in each complexity."""
    n = len(beliefs)
    rng = None if seed is None else np.random.default_rng(seed)
    return np.stack([policy.actions(beliefs, np.full(n, c), rng) for c in range(len(policy.complexities))], axis=1)


def _close(a: Any, b: Any, where: str = "") -> None:
    """Two JSON values equal, numbers to 1e-9."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b), where
        for k in a:
            _close(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _close(x, y, f"{where}[{i}]")
    elif isinstance(a, float) and isinstance(b, (int, float)) and not isinstance(b, bool):
        assert math.isclose(a, b, abs_tol=1e-9), where
    else:
        assert a == b, where


def _plain(policy: Any) -> dict[str, Any]:
    """The policy's JSON as a file holds it."""
    return json.loads(json.dumps(json_safe(policy.to_dict()), allow_nan=False))


# -- the checks ----------------------------------------------------------------------------


@pytest.mark.parametrize("kind", list(POLICY_KINDS))
def test_json_round_trip_keeps_the_decisions(kind, built, tmp_path) -> None:
    policy = _policy(kind, built)
    path = tmp_path / f"{kind}.json"
    policy.save(path)
    B = _beliefs(policy)
    for again in (policy_from_dict(_plain(policy), "round trip"), load_policy(path)):
        assert (again.kind, again.complexities, again.belief_update) == (policy.kind, policy.complexities, policy.belief_update)
        assert again.model == policy.model
        if _lacks(kind, "exact-json"):
            _close(_plain(again), _plain(policy))
            assert _plain(policy_from_dict(_plain(again))) == _plain(again)  # exact from the first load on
        else:
            assert _plain(again) == _plain(policy)
        np.testing.assert_array_equal(_decisions(again, B), _decisions(policy, B))


def _by_hand(policy: Any, trials: int, seed: int) -> tuple[list[str], list[np.ndarray]]:
    """The actions and beliefs of the fixed run, from ``actions`` and the belief filter alone."""
    model = policy.model or paper_model()
    update = make_updater(policy.belief_update or "bayes", model)
    rng = np.random.default_rng(seed)
    belief, remaining = update.initial(), list(COUNTS)
    actions, beliefs = [], []
    for cn, human, experience in TRIALS[:trials]:
        c = policy.complexities.index(cn)
        at = policy.at(remaining) if policy.kind == "schedule" else policy
        a = int(at.actions(belief[None, :], np.array([c]), rng)[0])
        o = UNOBSERVED if human is None else HUMAN_ACTIONS.index(human)
        belief = update.update(belief, c, a, o, EXPERIENCES.index(experience))
        remaining[c] -= 1
        actions.append(ACTIONS[a])
        beliefs.append(belief)
    return actions, beliefs


@pytest.mark.parametrize("kind", list(POLICY_KINDS))
def test_the_runner_steps_as_the_policy_and_the_filter_do(kind, built) -> None:
    policy = _policy(kind, built)
    if _lacks(kind, "runner"):
        with pytest.raises(PolicyError, match="trust model"):  # it refuses, rather than answers
            PolicyRunner(policy)
        return
    model = None if policy.model is not None else paper_model()  # a belief to log for policies without one
    make = ScheduleRunner if kind == "schedule" else PolicyRunner
    runner = make(policy, model=model, rng=np.random.default_rng(11))
    actions, beliefs = _by_hand(policy, len(TRIALS), seed=11)
    for (cn, human, experience), action, belief in zip(TRIALS, actions, beliefs, strict=True):
        assert runner.decide(cn) == action
        np.testing.assert_array_equal(runner.observe(cn, action, human, experience), belief)
        np.testing.assert_array_equal(runner.belief, belief)
    assert runner.trial == len(TRIALS)

    # the numpy path (one row per trial here): the same step at many beliefs at once
    before = np.vstack([runner.initial_beliefs(1), *beliefs[:-1]])
    cx = np.array([policy.complexities.index(cn) for cn, _, _ in TRIALS])
    codes = np.array([ACTIONS.index(a) for a in actions])
    human = np.array([UNOBSERVED if h is None else HUMAN_ACTIONS.index(h) for _, h, _ in TRIALS])
    experience = np.array([EXPERIENCES.index(e) for _, _, e in TRIALS])
    np.testing.assert_allclose(runner.beliefs_after_many(before, cx, codes, human, experience), np.vstack(beliefs), atol=1e-12)
    if not _lacks(kind, "numpy-path"):
        np.testing.assert_array_equal(runner.actions_many(before, cx, np.random.default_rng(11)), codes)


@pytest.mark.parametrize("kind", list(POLICY_KINDS))
def test_decisions_are_autonomous_or_ask(kind, built) -> None:
    policy = _policy(kind, built)
    B = _beliefs(policy)
    if _lacks(kind, "vocabulary"):  # its decisions index the file's own actions
        names = _plain(policy)["actions"]
        assert len(names) > 2 and set(np.unique(_decisions(policy, B))) <= set(range(len(names)))
        return
    assert set(np.unique(_decisions(policy, B))) <= {0, 1}
    rng = np.random.default_rng(0)
    for cn in policy.complexities:  # one trial by complexity name: the same decision as the batch
        c = policy.complexities.index(cn)
        one = [policy.action(b, cn, np.random.default_rng(0)) for b in B[:5]]
        assert one == [int(policy.actions(b[None, :], np.array([c]), np.random.default_rng(0))[0]) for b in B[:5]]
    with pytest.raises(KeyError, match="complexity"):
        policy.action(B[0], "medium", rng)


@pytest.mark.parametrize("kind", list(POLICY_KINDS))
def test_random_decisions_repeat_from_a_seed(kind, built) -> None:
    policy = _policy(kind, built)
    B = np.repeat(_beliefs(policy), 5, axis=0)
    np.testing.assert_array_equal(_decisions(policy, B, seed=3), _decisions(policy, B, seed=3))
    if CASES[kind].random:
        assert not np.array_equal(_decisions(policy, B, seed=3), _decisions(policy, B, seed=4))
        with pytest.raises(PolicyError, match="rng"):
            _decisions(policy, B, seed=None)
    else:  # a deterministic policy needs no generator, and one changes nothing
        np.testing.assert_array_equal(_decisions(policy, B, seed=None), _decisions(policy, B, seed=3))


@pytest.mark.parametrize("kind", list(POLICY_KINDS))
def test_reported_ask_regions_agree_with_the_decisions(kind, built) -> None:
    policy = _policy(kind, built)
    if _lacks(kind, "regions"):
        with pytest.raises(PolicyError):  # it refuses, rather than answers
            policy.ask_intervals()
        return
    intervals, thresholds, bounds = policy.ask_intervals(), policy.thresholds(), ask_bounds(policy)
    if CASES[kind].random:
        assert intervals is None and thresholds is None and bounds is None
        return
    x = np.linspace(0.0, 1.0, 2001)
    asks = _decisions(policy, np.stack([1 - x, x], axis=1)) == ASK
    for c, cn in enumerate(policy.complexities):
        ends = np.array([e for iv in intervals[cn] for e in iv])
        clear = np.all(np.abs(x[:, None] - ends[None, :]) > 1e-6, axis=1) if len(ends) else np.ones(len(x), bool)
        inside = np.zeros(len(x), dtype=bool)
        for lo, hi in intervals[cn]:
            inside |= (x >= lo) & (x <= hi)
        np.testing.assert_array_equal(asks[clear, c], inside[clear], err_msg=cn)
        th = thresholds[cn]
        if th is None:
            assert not asks[:, c].any()
        elif not math.isnan(th):
            np.testing.assert_array_equal(asks[clear, c], x[clear] < th if th < 1 else np.ones(clear.sum(), bool))
        if bounds is not None:
            assert bounds[c] == (-np.inf if th is None else np.inf if th >= 1 else pytest.approx(th))


# -- corrupted files -----------------------------------------------------------------------

#: keys that are not tables of numbers
HEADER = ("format", "kind", "complexities", "belief_update", "info", "thresholds", "counts", "window", "grid")
#: keys a file may leave out (key -> what it means then); when given, they must still be right
OPTIONAL = {
    "info": "no notes",
    "thresholds": "written for people: recomputed from the tables",
    "grid": "the number of grid points: read from the tables",
    "window": "null: every item is visible",
}


def _wrong(value: Any) -> tuple[Any, ...]:
    """Values of the wrong type where the file has ``value`` (a bool is not a number)."""
    ints = isinstance(value, list) and value and all(type(v) is int for v in value)
    return (7 if isinstance(value, str) else "seven", True, *([[True] * len(value)] if ints else []))


def _poisoned(d: dict[str, Any], bad: Any = math.nan) -> tuple[dict[str, Any], str] | None:
    """``d`` with the first number of the policy's own tables set to ``bad``, and the key it is
    under (a bad number in the trust model or the mixture is theirs to refuse: tests/model)."""
    for key, value in d.items():
        if key in (*HEADER, "model", "mixture"):
            continue
        out = json.loads(json.dumps(value))
        if _poison(out, bad):
            return {**d, key: out}, key
    return None


def _poison(node: Any, bad: Any) -> bool:
    """Set the first number in ``node`` (outside names and formats) to ``bad``; whether there was one."""
    if isinstance(node, dict):
        slots = [(node, k) for k in node if k not in ("trust_levels", "complexities", "names", "format")]
    elif isinstance(node, list):
        slots = [(node, i) for i in range(len(node))]
    else:
        return False
    for parent, k in slots:
        v = parent[k]
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            parent[k] = bad
            return True
        if _poison(v, bad):
            return True
    return False


def _refused(d: Any, tmp_path: Any, name: str, key: str, *what: str) -> None:
    """``d`` is refused as a dict and as a file, with a ModelError naming the source, ``key``
    and, if given, one of ``what``."""
    with pytest.raises(ModelError) as exc:
        policy_from_dict(d, "bad.json")
    message = str(exc.value)
    assert "bad.json" in message and key in message, message
    assert not what or any(w in message for w in what), message
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps(json_safe(d)), encoding="utf-8")
    with pytest.raises(ModelError, match=path.name):
        load_policy(path)


@pytest.mark.parametrize("kind", list(POLICY_KINDS))
def test_a_corrupted_file_is_refused_naming_the_problem(kind, built, tmp_path) -> None:
    d = _plain(_policy(kind, built))
    for key, value in d.items():
        if key not in OPTIONAL:
            _refused({k: v for k, v in d.items() if k != key}, tmp_path, f"missing-{key}", key)
        if _lacks(kind, f"checked-{key}"):
            continue
        for i, wrong in enumerate(_wrong(value)):
            _refused({**d, key: wrong}, tmp_path, f"wrong-{key}-{i}", key)
    poisoned = _poisoned(d)
    assert poisoned is not None
    bad, key = poisoned
    _refused(bad, tmp_path, "nan", key, "NaN", "nan", "finite")
    # a true where a number belongs (numpy would read it as 1.0)
    poisoned = _poisoned(d, True)
    assert poisoned is not None
    bad, key = poisoned
    _refused(bad, tmp_path, "true", key, "true or false")
