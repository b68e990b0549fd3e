"""The decision API's sessions, independent of HTTP: a robot opens a deploy session with a task,
a model and a policy (``create_deploy``); then, trial by trial, it posts the complexity and gets
the action (``deploy_decide``), and posts what the human did and the outcome (``deploy_observe``),
which commits the trial and updates the belief with ``PolicyRunner``'s step.  Each runs with the
statements of ``store`` (a transaction, or ``store.Known``) and the application's ``plan.Plans``.
"""

from __future__ import annotations

import math
import sys
from typing import Any

from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session as DBSession

from ...model.core import TrustModel
from ...model.task import Task
from ...policies.scheduling import SchedulePolicy
from ...vocab import HUMAN_ACTIONS
from ..errors import Conflict, NotAllowed, NotFound
from ..orm import PolicyBlob, Session, utcnow
from ..plan import Plans, policy_sha256
from ..schemas import MAX_TRIAL
from ..sessions import new_session, p_high, scored, trial_dict
from .store import LiveRow, Statements


def score_problems(task: Task) -> list[str]:
    """Why a deploy session of ``task`` could not keep its score, a sum of up to ``MAX_TRIAL``
    rewards, as a finite number (nor a policy its values); empty when it can."""
    largest = max(abs(v) for v in task.rewards.to_dict().values())
    if math.isfinite(largest * MAX_TRIAL):
        return []
    return [
        f"task rewards: the largest reward in magnitude, {largest:g}, overflows a session's score over {MAX_TRIAL} trials; "
        f"keep every reward within +-{sys.float_info.max / MAX_TRIAL:.3g}"
    ]


def create_deploy(
    db: DBSession, plans: Plans, label: str, task: Task, model: TrustModel, policy: dict[str, Any], seed: int
) -> Session:
    """A new deploy session (added to ``db``, not committed, and registered in ``plans``): its plan
    (task, model, and the policy by its SHA-256, the policy itself stored once per content) and
    its belief at the start (the initial trust of the policy's own model, else of ``model``).
    A policy that does not load raises its ``ModelError``."""
    sha = policy_sha256(policy)
    content = {"task": task.to_dict(), "model": model.to_dict(), "policy_sha256": sha, "policy_kind": policy["kind"]}
    plan = plans.shared(content, lambda: policy, task, model)  # sessions with the same plan share one parsed copy
    pol = plan.policy()
    pm = getattr(pol, "model", None) or model
    if db.get(PolicyBlob, sha) is None:
        # the stored form: the policy's own to_dict() (its loaders match keys by name, so rows
        # with sorted keys and databases that reorder JSON objects load alike)
        db.add(PolicyBlob(sha256=sha, policy=pol.to_dict()))
        try:
            db.flush()
        except IntegrityError:  # stored concurrently by another request
            db.rollback()
    s = new_session(pm.initial, kind="deploy", study_id=None, participant=label, seed=seed, plan=content, status="running")
    db.add(s)
    plans.by_session.put(s.id, plan)
    return s


def _live(store: Statements, session_id: str) -> LiveRow:
    row = store.live(session_id)
    if row is None:
        raise NotFound("no such session")
    return row


def _decision(n: int, complexity: Any, action: Any, belief: Any, committed: bool = False) -> dict[str, Any]:
    """``decide``'s answer: trial ``n``'s complexity and robot action, the belief they were
    decided at, and whether the trial is committed already."""
    return {"trial": n, "complexity": complexity, "robot_action": action, "belief": belief, "committed": committed}


def deploy_decide(
    store: Statements,
    plans: Plans,
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
    plan = plans.of(store, session_id)
    if complexity is not None and complexity not in plan.task.complexities:
        raise NotAllowed(f"complexity must be one of {list(plan.task.complexities)}, got {complexity!r}")
    if complexity is None and remaining is None:
        raise NotAllowed("post the trial's complexity (or, for a schedule policy, the remaining items)")
    # trials are committed in order together with trials_done, so trial n exists iff n <= trials_done
    old = store.committed(session_id, n) if n <= s.trials_done else None
    if old is not None:
        if complexity is not None and old.complexity != complexity:
            raise Conflict(f"trial {n} was committed with complexity {old.complexity!r}, not {complexity!r}")
        return _decision(n, old.complexity, old.robot_action, old.belief, committed=True)
    if n != s.trials_done + 1:
        raise Conflict(f"trial {n} is not the next trial; the next trial is {s.trials_done + 1}")
    if s.pending_trial == n:
        if complexity is not None and s.pending_complexity != complexity:
            raise Conflict(f"trial {n} was already decided for complexity {s.pending_complexity!r}, not {complexity!r}")
        return _decision(n, s.pending_complexity, s.pending_action, p_high(s.belief, plan.n_trust))
    if remaining is not None or visible is not None or plan.kind == SchedulePolicy.kind:
        complexity, action = plan.pick(s.belief, remaining, visible, complexity)
    else:
        assert complexity is not None
        action = plan.decide(s.belief, s.seed, n, complexity)
    store.decided(session_id, n, complexity, action, utcnow())
    return _decision(n, complexity, action, p_high(s.belief, plan.n_trust))


def deploy_observe(
    store: Statements, plans: Plans, session_id: str, n: int, human_action: str | None, outcome: str | None
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
        raise Conflict(f"trial {n} is already committed with human_action={old.human_action!r}, outcome={old.outcome!r}")
    if s.pending_trial != n:
        raise Conflict(f"trial {n} has no decision yet; post its complexity to /decide first (next trial: {s.trials_done + 1})")
    action, complexity = s.pending_action, s.pending_complexity
    assert action is not None and complexity is not None  # stored together with pending_trial
    plan = plans.of(store, session_id)
    if action == "ask" and human_action not in (None, "intervene"):
        why = f"the robot asked in trial {n}: human_action must be 'intervene' (teleoperation) or omitted"
        raise NotAllowed(f"{why}, got {human_action!r}")
    if action != "ask" and human_action not in HUMAN_ACTIONS:
        raise NotAllowed(f"human_action must be one of {list(HUMAN_ACTIONS)}, got {human_action!r}")
    teleoperated = action == "ask" or human_action == "intervene"
    if outcome not in ((None, "teleoperated") if teleoperated else ("success", "failure", "collision", "dropped")):
        if action == "ask":
            why = f"the robot asked in trial {n}: the human teleoperated, so outcome must be 'teleoperated' or omitted"
        elif teleoperated:
            why = f"the human intervened in trial {n} and teleoperated: outcome must be 'teleoperated' or omitted"
        else:
            why = "outcome must be 'success' or 'failure' (or 'collision'/'dropped') when the human relied"
        raise NotAllowed(f"{why}, got {outcome!r}")
    if teleoperated:
        human_action, outcome = "intervene", "teleoperated"
    assert human_action is not None
    result, after = scored(plan, s.belief, complexity, action, human_action, None if teleoperated else outcome == "success")
    t: dict[str, Any] = {
        "trial": n,
        "block": 0,
        "policy": plan.kind,
        "complexity": complexity,
        "robot_action": action,
        "human_action": human_action,
        "outcome": outcome,
        **result,
        "effort_ms": None,
        "submission_id": f"deploy-{n}",
    }
    new_belief = list(after) if after is not None else list(s.belief)
    store.observed(session_id, t, new_belief, float(s.score + t["reward"]), utcnow())
    return t, False
