"""The decision API's sessions, independent of HTTP: a robot opens a deploy session with a task,
a model and a policy (``create_deploy``); then, trial by trial, it posts the complexity and gets
the action (``deploy_decide``), and posts what the human did and the outcome
(``deploy_observe``), which commits the trial and updates the belief as ``PolicyRunner`` does.

The decision API is the latency-critical path, so it runs on the driver's own connection
(``store.DeployStore``): a locked read of the session's live columns, then one UPDATE (decide)
or one INSERT and one UPDATE (observe), in one transaction; or, from the live columns this
process knows, the same write made conditional on the row being unchanged (``store.Known``).
The task, model and parsed policy of a session are cached per process (they never change).
"""

from __future__ import annotations

import hashlib
import json
import math
import sys
from typing import Any

import numpy as np
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session as DBSession

from ..model.core import ACTIONS, EXPERIENCES, HUMAN_ACTIONS, TrustModel
from ..model.task import Task
from ..policies import PolicyError
from ..policies.schedule import SchedulePolicy
from ..pomdp.belief import make_updater
from .orm import PolicyBlob, Session, utcnow
from .schemas import MAX_TRIAL
from .sessions import Context, SessionError, new_id, new_token, p_high, trial_dict, trial_experience
from .store import LiveRow, Statements, TrialRow
from .studies import policy_object


def canonical_policy(pol) -> dict[str, Any]:
    """The stored form of a policy: the policy's own ``to_dict()`` (keys in the order the policy
    writes them).  Stored policies also load whatever the order of their keys (rows written with
    sorted keys, databases that reorder JSON objects): the loaders match keys by name."""
    return pol.to_dict()


def policy_sha256(policy: dict[str, Any]) -> str:
    """The address of a policy JSON: the SHA-256 of its key-sorted serialization, the same for
    any order of the keys."""
    return hashlib.sha256(json.dumps(policy, sort_keys=True).encode()).hexdigest()


def score_problem(task: Task) -> str | None:
    """Why a deploy session of ``task`` could not keep its score, a sum of up to ``MAX_TRIAL``
    rewards, as a finite number (nor a policy its values), or None."""
    largest = max(abs(v) for v in task.rewards.to_dict().values())
    if math.isfinite(largest * MAX_TRIAL):
        return None
    return (
        f"task rewards: the largest reward in magnitude, {largest:g}, overflows a session's score over {MAX_TRIAL} trials; "
        f"keep every reward within +-{sys.float_info.max / MAX_TRIAL:.3g}"
    )


def create_deploy(db: DBSession, label: str, task: Task, model: TrustModel, policy: dict[str, Any], seed: int) -> Session:
    """A new deploy session (added to ``db``, not committed): its plan (task, model, and the policy
    by its SHA-256, the policy itself stored once per content) and its belief at the start
    (the initial trust of the policy's own model, else of ``model``)."""
    sid = new_id()
    sha = policy_sha256(policy)
    pol = policy_object(f"policy:{sha}", policy)  # sessions with the same policy share one parsed copy
    pm = getattr(pol, "model", None) or model
    if db.get(PolicyBlob, sha) is None:
        db.add(PolicyBlob(sha256=sha, policy=canonical_policy(pol)))
        try:
            db.flush()
        except IntegrityError:  # stored concurrently by another request
            db.rollback()
    s = Session(
        id=sid,
        token=new_token(),
        kind="deploy",
        study_id=None,
        participant=label,
        seed=seed,
        plan={"task": task.to_dict(), "model": model.to_dict(), "policy_sha256": sha, "policy_kind": policy["kind"]},
        status="running",
        belief=[float(x) for x in pm.initial],
        trials_done=0,
        score=0.0,
    )
    db.add(s)
    return s


def _live(store: Statements, session_id: str) -> LiveRow:
    row = store.live(session_id)
    if row is None:
        raise SessionError(404, "no such session")
    return row


def committed_trial(store: Statements, session_id: str, n: int) -> TrialRow | None:
    return store.committed(session_id, n)


class _LazyRng:
    """The generator ``np.random.default_rng(seed)``, made only when a policy draws from it
    (most policies never do, and making one costs more than the decision): ``used`` tells
    whether the decision depended on it."""

    __slots__ = ("_rng", "_seed")

    def __init__(self, seed: list[int]):
        self._seed = seed
        self._rng: np.random.Generator | None = None

    @property
    def used(self) -> bool:
        return self._rng is not None

    def __getattr__(self, name: str) -> Any:
        if self._rng is None:
            self._rng = np.random.default_rng(self._seed)
        return getattr(self._rng, name)


class DeployPlan:
    """What never changes in a deploy session: its task, model and policy (``plan`` of the
    session row), shared by every session opened with the same ones, with the policy object and
    its belief updater built once.  Decisions and belief updates are deterministic functions of
    (belief, complexity[, action, human action, experience]), except a decision that draws from
    the generator of (seed, trial): the others are remembered, so a belief that many robots
    reach (every robot's first trials start from the same prior) is decided and updated once."""

    MEMO = 50_000  # remembered decisions and updates per plan (then forgotten at once)

    def __init__(self, task: Task, model: TrustModel, kind: str, sha: str):
        self.task, self.model, self.kind, self.sha = task, model, kind, sha
        self.key = f"policy:{sha}"
        self.n_trust = model.n_trust
        self._policy: Any = None
        self._updater: Any = None
        self._decided: dict[tuple, int] = {}
        self._updated: dict[tuple, list[float]] = {}

    def context(self, store: Statements) -> Context:
        return Context(self.task, self.model, [self.kind], [self.key], lambda b: store.policy(self.sha), None)

    def policy(self, store: Statements) -> Any:
        if self._policy is None:
            self._policy = policy_object(self.key, lambda: store.policy(self.sha))
        return self._policy

    def decide(self, store: Statements, belief: list, seed: int, n: int, complexity: str) -> str:
        """The action of ``PolicyRunner(policy, belief, rng=default_rng([seed, n, 0])).decide``."""
        key = (tuple(belief), complexity)
        a = self._decided.get(key)
        if a is None:
            pol = self.policy(store)
            rng = _LazyRng([seed, n, 0])
            a = pol.action(np.asarray(belief, dtype=float), pol.complexity_index(complexity), rng)
            if not rng.used:
                if len(self._decided) >= self.MEMO:
                    self._decided.clear()
                self._decided[key] = a
        return ACTIONS[a]

    def update(self, store: Statements, belief: list, complexity: str, action: str, human: str, experience: str) -> list | None:
        """The belief after a trial, as ``PolicyRunner.observe`` updates it (None: the policy
        tracks no belief)."""
        key = (tuple(belief), complexity, action, human, experience)
        after = self._updated.get(key)
        if after is None:
            pol = self.policy(store)
            if self._updater is None:  # as PolicyRunner makes it
                model = getattr(pol, "model", None) or self.model
                self._updater = make_updater(pol.belief_update or "bayes", model) if model is not None else False
            if self._updater is False:
                return None
            new = self._updater.update(
                np.asarray(belief, dtype=float),
                pol.complexity_index(complexity),
                ACTIONS.index(action),
                HUMAN_ACTIONS.index(human),
                EXPERIENCES.index(experience),
            )
            after = [float(x) for x in new]
            if len(self._updated) >= self.MEMO:
                self._updated.clear()
            self._updated[key] = after
        return after


_DEPLOY_PLANS: dict[str, DeployPlan] = {}  # session id -> its plan
_SHARED_PLANS: dict[str, DeployPlan] = {}  # the plan's content -> the one parsed copy


def _plan_key(task: dict[str, Any], model: dict[str, Any], sha: str, kind: str) -> str:
    return json.dumps([task, model, sha, kind], sort_keys=True)


def _shared_plan(key: str, make) -> DeployPlan:
    plan = _SHARED_PLANS.get(key)
    if plan is None:
        if len(_SHARED_PLANS) > 256:
            _SHARED_PLANS.clear()
        plan = _SHARED_PLANS[key] = make()
    return plan


def _remember(session_id: str, plan: DeployPlan) -> DeployPlan:
    if len(_DEPLOY_PLANS) > 200_000:
        _DEPLOY_PLANS.clear()
    _DEPLOY_PLANS[session_id] = plan
    return plan


def deploy_plan(store: Statements, session_id: str) -> DeployPlan:
    """The deploy session's plan (read from the database once per process)."""
    plan = _DEPLOY_PLANS.get(session_id)
    if plan is None:
        d = store.plan(session_id)
        if d is None:
            raise SessionError(404, "no such session")
        key = _plan_key(d["task"], d["model"], d["policy_sha256"], d["policy_kind"])
        plan = _remember(
            session_id,
            _shared_plan(
                key,
                lambda: DeployPlan(
                    Task.from_dict(d["task"]), TrustModel.from_dict(d["model"]), d["policy_kind"], d["policy_sha256"]
                ),
            ),
        )
    return plan


def remember_deploy(s: Session, task: Task, model: TrustModel) -> None:
    """Register a session just opened by this process, so that its first decision needs no
    database read nor parsing (``create_deploy``'s objects are the ones its plan describes)."""
    p = s.plan
    key = _plan_key(p["task"], p["model"], p["policy_sha256"], p["policy_kind"])
    _remember(s.id, _shared_plan(key, lambda: DeployPlan(task, model, p["policy_kind"], p["policy_sha256"])))


def deploy_context(store: Statements, session_id: str) -> Context:
    return deploy_plan(store, session_id).context(store)


def _counts(ctx: Context, counts: dict[str, int] | None, what: str) -> tuple[int, ...] | None:
    if counts is None:
        return None
    unknown = sorted(set(counts) - set(ctx.task.complexities))
    if unknown or any(not isinstance(v, int) or v < 0 for v in counts.values()):
        raise SessionError(
            400, f"{what} must map complexities {list(ctx.task.complexities)} to non-negative numbers, got {counts!r}"
        )
    return tuple(int(counts.get(c, 0)) for c in ctx.task.complexities)


def _scheduled(ctx: Context, belief, complexity: str | None, remaining, visible) -> tuple[str, str]:
    """(complexity, action) of a schedule policy: the policy's pick among the remaining (visible)
    items, or the action for an imposed item in that state."""
    pol = policy_object(ctx.keys[0], lambda: ctx.load_policy(0))
    if not isinstance(pol, SchedulePolicy):
        raise SessionError(400, f"remaining and visible items are for a schedule policy; this session runs a {pol.kind} policy")
    rem = _counts(ctx, remaining, "remaining")
    if rem is None:
        raise SessionError(400, "a schedule policy needs the remaining items: post remaining (per complexity)")
    vis = _counts(ctx, visible, "visible")
    try:
        if complexity is None:
            k, a = pol.choose(belief, rem, vis)
            return ctx.task.complexities[k], ACTIONS[a]
        bound = pol.at(rem, vis)
        return complexity, ACTIONS[bound.action(belief, ctx.task.complexity_index(complexity))]
    except (PolicyError, KeyError) as exc:
        raise SessionError(400, "; ".join(exc.problems) if isinstance(exc, PolicyError) else str(exc)) from None


def deploy_decide(
    store: Statements,
    session_id: str,
    n: int,
    complexity: str | None,
    remaining: dict[str, int] | None = None,
    visible: dict[str, int] | None = None,
) -> dict[str, Any]:
    """The robot action for trial ``n`` (decided once, stored as the session's pending trial;
    repeated calls return the stored decision).  With ``remaining`` (a ``schedule`` policy)
    the policy also picks the item's complexity when none is given.  Runs in the caller's
    transaction (``store.transaction()``)."""
    s = _live(store, session_id)
    plan = deploy_plan(store, session_id)
    if complexity is not None and complexity not in plan.task.complexities:
        raise SessionError(400, f"complexity must be one of {list(plan.task.complexities)}, got {complexity!r}")
    if complexity is None and remaining is None:
        raise SessionError(400, "post the trial's complexity (or, for a schedule policy, the remaining items)")
    # trials are committed in order together with trials_done, so trial n exists iff n <= trials_done
    old = store.committed(session_id, n) if n <= s.trials_done else None
    if old is not None:
        if complexity is not None and old.complexity != complexity:
            raise SessionError(409, f"trial {n} was committed with complexity {old.complexity!r}, not {complexity!r}")
        return {
            "trial": n,
            "complexity": old.complexity,
            "robot_action": old.robot_action,
            "belief": old.belief,
            "committed": True,
        }
    if n != s.trials_done + 1:
        raise SessionError(409, f"trial {n} is not the next trial; the next trial is {s.trials_done + 1}")
    if s.pending_trial == n:
        if complexity is not None and s.pending_complexity != complexity:
            raise SessionError(409, f"trial {n} was already decided for complexity {s.pending_complexity!r}, not {complexity!r}")
        return {
            "trial": n,
            "complexity": s.pending_complexity,
            "robot_action": s.pending_action,
            "belief": p_high(s.belief, plan.n_trust),
            "committed": False,
        }
    if remaining is None and plan.kind == SchedulePolicy.kind:
        raise SessionError(400, "a schedule policy needs the remaining items: post remaining (per complexity)")
    if remaining is not None or visible is not None:
        complexity, action = _scheduled(plan.context(store), np.asarray(s.belief, dtype=float), complexity, remaining, visible)
    else:
        assert complexity is not None
        action = plan.decide(store, s.belief, s.seed, n, complexity)
    store.decided(session_id, n, complexity, action, utcnow())
    return {
        "trial": n,
        "complexity": complexity,
        "robot_action": action,
        "belief": p_high(s.belief, plan.n_trust),
        "committed": False,
    }


def deploy_observe(
    store: Statements, session_id: str, n: int, human_action: str | None, outcome: str | None
) -> tuple[dict[str, Any], bool]:
    """Commit trial ``n`` from the observed human action and outcome; returns (trial, duplicate).
    Runs in the caller's transaction (``store.transaction()``)."""
    s = _live(store, session_id)
    # trials are committed in order together with trials_done, so trial n exists iff n <= trials_done
    old = store.committed(session_id, n) if n <= s.trials_done else None
    if old is not None:
        same_h = old.human_action == (human_action if human_action is not None or old.robot_action != "ask" else "intervene")
        same_o = outcome is None or old.outcome == outcome
        if same_h and same_o:
            return trial_dict(old), True
        raise SessionError(409, f"trial {n} is already committed with human_action={old.human_action!r}, outcome={old.outcome!r}")
    if s.pending_trial != n:
        raise SessionError(
            409, f"trial {n} has no decision yet; post its complexity to /decide first (next trial: {s.trials_done + 1})"
        )
    action, complexity = s.pending_action, s.pending_complexity
    assert action is not None and complexity is not None  # stored together with pending_trial
    plan = deploy_plan(store, session_id)
    task = plan.task
    c = task.complexity_index(complexity)
    if action == "ask":
        if human_action not in (None, "intervene"):
            raise SessionError(
                400,
                f"the robot asked in trial {n}: human_action must be 'intervene' (teleoperation) or omitted, "
                f"got {human_action!r}",
            )
        if outcome not in (None, "teleoperated"):
            raise SessionError(
                400,
                f"the robot asked in trial {n}: the human teleoperated, so outcome must be 'teleoperated' or omitted, "
                f"got {outcome!r}",
            )
        human_action, success, outcome = "intervene", None, "teleoperated"
    else:
        if human_action not in HUMAN_ACTIONS:
            raise SessionError(400, f"human_action must be one of {list(HUMAN_ACTIONS)}, got {human_action!r}")
        if human_action == "intervene":
            if outcome not in (None, "teleoperated"):
                raise SessionError(
                    400,
                    f"the human intervened in trial {n} and teleoperated: outcome must be 'teleoperated' or omitted, "
                    f"got {outcome!r}",
                )
            success, outcome = None, "teleoperated"
        else:
            if outcome not in ("success", "failure", "collision", "dropped"):
                raise SessionError(
                    400,
                    f"outcome must be 'success' or 'failure' (or 'collision'/'dropped') when the human relied, got {outcome!r}",
                )
            success = outcome == "success"
    experience = trial_experience(task, c, action, human_action, success)
    after = plan.update(store, s.belief, complexity, action, human_action, experience)
    a, o = ACTIONS.index(action), HUMAN_ACTIONS.index(human_action)
    t: dict[str, Any] = {
        "trial": n,
        "block": 0,
        "policy": plan.kind,
        "complexity": complexity,
        "robot_action": action,
        "human_action": human_action,
        "outcome": outcome,
        "experience": experience,
        "reward": float(task.rewards.of(a, o, EXPERIENCES.index(experience))),
        "belief": p_high(s.belief, plan.n_trust),
        "belief_after": p_high(after, plan.n_trust),
        "effort_ms": None,
        "submission_id": f"deploy-{n}",
    }
    new_belief = list(after) if after is not None else list(s.belief)
    store.observed(session_id, t, new_belief, float(s.score + t["reward"]), utcnow())
    return t, False
