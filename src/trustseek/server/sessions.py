"""A study session, independent of HTTP: serving a trial (complexity from the plan, action from
the block's policy; or both from a schedule policy, given the items that remain), committing it
(outcome, experience, reward, belief update) and events; the answers are in ``answers``.

A trial is committed, with the belief update, before the next is served; the served trial is
stored in the session row.  Its action comes from a generator seeded by (seed, trial), its
outcome and scene layout from keys derived from the session's secret (HMAC-SHA256, a label
each): a restarted server serves and scores what it would have before, and nothing the page
receives says anything about an outcome before it is shown.  A repeated submission returns the
stored trial; a conflicting one is refused.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import logging
import secrets
from collections import Counter
from functools import partial
from typing import Any

import numpy as np
from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session as DBSession

from ..model.core import TrustModel
from ..model.task import Task
from ..vocab import ACTIONS, EXPERIENCES, HUMAN_ACTIONS
from .answers import quiz_due, still_due
from .cache import caches_of
from .errors import Conflict, NotAllowed, NotFound, TooLarge
from .orm import TRIAL_FIELDS, Event, EventBatch, Session, Study, Trial, row_dict, try_commit, utcnow
from .plan import PolicyPlan
from .studies import block_items

log = logging.getLogger(__name__)

#: stored UI events per trial (events outside any trial count together) and per session
MAX_EVENTS_PER_TRIAL = 2000
MAX_EVENTS_PER_SESSION = 50_000


def new_id() -> str:
    return secrets.token_hex(8)


def new_session(initial: Any, **columns: Any) -> Session:
    """A new session row: a fresh id and token, belief ``initial``, no trial done, score 0."""
    belief = [float(x) for x in initial]
    return Session(id=new_id(), token=secrets.token_urlsafe(32), belief=belief, trials_done=0, score=0.0, **columns)


def sealed(secret: str, label: str, n: int) -> int:
    """A 128-bit number of the session's ``secret`` for ``label`` (``outcome``, ``scene``) and
    trial ``n`` (HMAC-SHA256: one label's numbers say nothing of another's)."""
    digest = hmac.new(bytes.fromhex(secret), f"{label}:{n}".encode(), hashlib.sha256).digest()
    return int.from_bytes(digest[:16], "big")


def scene_seed(s: Session, n: int) -> int:
    """The seed of trial ``n``'s scene layout (sent to the page)."""
    return sealed(s.secret, "scene", n) % 2**31 if s.secret else (s.seed * 1000003 + n) % 2**31


def outcome_draws(s: Session, n: int) -> np.ndarray:
    """The two uniform numbers of trial ``n``'s outcome (success, then the kind of failure)."""
    rng = np.random.default_rng(sealed(s.secret, "outcome", n) if s.secret else [s.seed, n, 1])
    return rng.random(2)


def p_high(belief, n_trust: int | None = None) -> float | None:
    """P(trust = the highest level) of a stored belief; a belief over (supervisor type, trust),
    type-major, is summed over the types given the model's ``n_trust`` levels."""
    if belief is None:
        return None
    b = np.asarray(belief, dtype=float)
    if n_trust and b.size > n_trust and b.size % n_trust == 0:
        b = b.reshape(-1, n_trust).sum(axis=0)
    return float(b[-1])


def study_config(db: DBSession, study_id: str) -> dict[str, Any]:
    """A study's configuration (immutable once created, so remembered by the application)."""
    configs = caches_of(db).configs
    cfg = configs.get(study_id)
    if cfg is None:
        study = db.get(Study, study_id)
        if study is None:
            raise NotFound("no such study")
        cfg = configs.put(study_id, study.config)
    return cfg


def block_plan(db: DBSession, s: Session, block: int) -> PolicyPlan:
    """The plan of a study session's block (its policy with ``PolicyRunner``'s step, parsed once
    and remembered by the application); the index after the study's blocks is the practice's."""
    assert s.study_id is not None, "a study session"
    contexts = caches_of(db).contexts
    plans = contexts.get(s.study_id)
    if plans is None:
        cfg = study_config(db, s.study_id)
        task, model = Task.from_dict(cfg["task"]), TrustModel.from_dict(cfg["model"])
        policies = [*(b["policy"] for b in cfg["blocks"]), *([cfg["practice"]["policy"]] if cfg.get("practice") else [])]
        plans = [PolicyPlan(task, model, p["kind"], f"study:{s.study_id}:{b}", partial(dict, p)) for b, p in enumerate(policies)]
        contexts.put(s.study_id, plans)
    return plans[block]


def total_trials(s: Session) -> int:
    """The trials of a study session, practice included."""
    return len(s.plan["trials"])


# --------------------------------------------------------------------------- serving


def lock(db: DBSession, session_id: str) -> Session:
    """The session row, locked for update where the database supports it."""
    s = db.execute(select(Session).where(Session.id == session_id).with_for_update()).scalar_one_or_none()
    if s is None:
        raise NotFound("no such session")
    return s


def serve(db: DBSession, s: Session) -> dict[str, Any] | None:
    """The current trial of a study session (deciding and storing it if not yet served);
    None when the session is not running or is finished.  Commits."""
    if s.status != "running":
        return None
    n = s.trials_done + 1
    if n > total_trials(s):
        return None
    step = s.plan["trials"][n - 1]
    items = scheduled_items(db, s, step["block"]) if step["complexity"] is None else None
    if s.pending_trial != n:
        plan = block_plan(db, s, step["block"])
        if step.get("action"):  # a practice trial in which the robot asks, whatever the policy
            s.pending_complexity, s.pending_action = step["complexity"], step["action"]
        elif items is None:
            s.pending_complexity = step["complexity"]
            s.pending_action = plan.decide(s.belief, s.seed, n, step["complexity"])
        else:
            s.pending_complexity, s.pending_action = plan.pick(s.belief, *items)
        s.pending_trial = n
        s.updated_at = utcnow()
        db.commit()
    return served(s, n, items)


def scheduled_items(db: DBSession, s: Session, block: int) -> tuple[dict[str, int], dict[str, int] | None]:
    """(remaining, visible) items of a block whose policy picks them, before the session's next
    trial: the block's items less those of its committed trials, in their order."""
    picks = db.scalars(select(Trial.complexity).where(Trial.session_id == s.id, Trial.block == block).order_by(Trial.trial)).all()
    assert s.study_id is not None
    return block_items(study_config(db, s.study_id), s.plan, block, [str(c) for c in picks])


def pending(s: Session) -> dict[str, Any] | None:
    """The session's trial decided and not yet committed, or None."""
    if s.pending_trial is None:
        return None
    return {"trial": s.pending_trial, "complexity": s.pending_complexity, "robot_action": s.pending_action}


def served(s: Session, n: int, items: tuple[dict[str, int], dict[str, int] | None] | None = None) -> dict[str, Any]:
    """Trial ``n`` as served to the participant (``n`` is the session's pending trial); in a block
    whose policy picks the items, ``items`` (remaining, visible) before this trial's pick."""
    step = s.plan["trials"][n - 1]
    blocks = s.plan["block_order"]
    practice = bool(step.get("practice"))
    out = {
        "trial": n,
        "block": step["block"],
        "block_position": 0 if practice else blocks.index(step["block"]) + 1,
        "practice": practice,
        "complexity": s.pending_complexity,
        "robot_action": s.pending_action,
        "scene_seed": scene_seed(s, n),
    }
    if items is not None:
        out["items"] = {"remaining": items[0], "visible": items[1]}
    return out


def trial_dict(t: Any) -> dict[str, Any]:
    """A committed trial (a ``Trial`` row, or the decision API's ``store.committed``) as the API answers it."""
    return row_dict(t, TRIAL_FIELDS)


#: what a participant's page learns of a committed trial: never the belief or the experience
PARTICIPANT_TRIAL = ("trial", "block", "complexity", "robot_action", "human_action", "outcome", "reward")


def participant_trial(t: Trial) -> dict[str, Any]:
    return {**row_dict(t, PARTICIPANT_TRIAL), "practice": bool(t.practice)}


def scored(
    plan: PolicyPlan, belief: list, complexity: str, action: str, human: str, success: bool | None
) -> tuple[dict[str, Any], list | None]:
    """What a trial's human action and success (None: teleoperated) make of it: its experience,
    points (eq. (1)) and P(trust = high) before and after, and the belief after it (a study
    session's trial and a deploy session's alike)."""
    task = plan.task
    if action == "ask":
        experience = EXPERIENCES[task.ask_experience[task.complexity_index(complexity)]]
    else:
        experience = "reliable" if human == "rely" and success else "faulty"
    after = plan.update(belief, complexity, action, human, experience)
    reward = float(task.rewards.of(ACTIONS.index(action), HUMAN_ACTIONS.index(human), EXPERIENCES.index(experience)))
    before, later = p_high(belief, plan.n_trust), p_high(after, plan.n_trust)
    return {"experience": experience, "reward": reward, "belief": before, "belief_after": later}, after


def _commit_trial(db: DBSession, s: Session, row: Trial, after: list | None, events: list[dict] | None) -> Trial | None:
    """Commit ``row`` with the belief ``after`` it and the session's progress; None when another
    submission committed this trial first."""
    if row.practice:  # practice leaves the belief and the score as they were
        after, row.belief_after = None, row.belief
    db.add(row)
    db.add_all(_event(s, row.trial, ev) for ev in events or ())
    s.belief = [float(x) for x in after] if after is not None else s.belief
    s.trials_done = row.trial
    s.score = float(s.score + (0.0 if row.practice else row.reward))
    s.pending_trial = s.pending_complexity = s.pending_action = None
    if row.trial >= total_trials(s):
        s.status = "done"
    s.updated_at = utcnow()
    if not try_commit(db):
        return None
    if s.status == "done":
        log.info("session %s of study %s finished: %d trials, score %g", s.id, s.study_id, s.trials_done, s.score)
    return row


def _existing(db: DBSession, s: Session, n: int) -> Trial | None:
    return db.scalar(select(Trial).where(Trial.session_id == s.id, Trial.trial == n))


def submit_trial(
    db: DBSession,
    session_id: str,
    n: int,
    submission_id: str,
    human_action: str,
    effort_ms: float | None,
    events: list[dict] | None,
) -> tuple[Trial, bool]:
    """Commit trial ``n`` of a study session with the human action (``intervene`` or ``rely``, as
    ``schemas.TrialIn`` takes it); returns (trial, duplicate)."""
    s = lock(db, session_id)
    # trials are committed in order together with trials_done, so trial n exists iff n <= trials_done
    old = _existing(db, s, n) if n <= s.trials_done else None
    if old is not None:
        db.rollback()
        return _replayed(old, n, submission_id, human_action), True
    if s.status != "running":
        raise Conflict(f"the session is {s.status!r}, not running" + (" (consent first)" if s.status == "new" else ""))
    if n != s.trials_done + 1:
        raise Conflict(f"trial {n} is not the current trial; the current trial is {s.trials_done + 1}")
    cfg = study_config(db, s.study_id) if s.study_id else {}
    if quiz_due(s, cfg) is not None:
        raise Conflict("answer the comprehension quiz before the first trial")
    if still_due(db, s, cfg) != (None, None):
        raise Conflict(f"answer the questions after trial {s.trials_done} before trial {n}")
    action, complexity = s.pending_action, s.pending_complexity
    if s.pending_trial != n or action is None or complexity is None:
        raise Conflict(f"trial {n} has not been served yet; fetch the session state first")
    if action == "ask" and human_action != "intervene":
        why = f"the robot asked for help in trial {n}: human_action must be 'intervene' (teleoperation)"
        raise NotAllowed(f"{why}, got {human_action!r}")
    step = s.plan["trials"][n - 1]
    plan = block_plan(db, s, step["block"])
    if action == "autonomous" and human_action == "rely":
        r = outcome_draws(s, n)
        success = bool(r[0] < plan.task.success[plan.task.complexity_index(complexity)])
        outcome = "success" if success else ("collision" if r[1] < 0.5 else "dropped")
    else:
        success, outcome = None, "teleoperated"
    check_event_room(db, s, events or [], n)
    result, after = scored(plan, s.belief, complexity, action, human_action, success)
    row = Trial(
        session_id=s.id,
        trial=n,
        block=step["block"],
        policy=plan.kind,
        complexity=complexity,
        robot_action=action,
        human_action=human_action,
        outcome=outcome,
        effort_ms=effort_ms,
        practice=bool(step.get("practice")),
        submission_id=submission_id,
        **result,
    )
    committed = _commit_trial(db, s, row, after, events)
    if committed is not None:
        return committed, False
    old = _existing(db, s, n)
    if old is None:
        raise Conflict(f"trial {n} could not be committed; fetch the session state and retry")
    return _replayed(old, n, submission_id, human_action), True


def _replayed(old: Trial, n: int, submission_id: str, human_action: str | None) -> Trial:
    """The committed trial ``n``, if a submission repeats the one that committed it (same
    submission id and same human action); a conflicting submission is refused (409)."""
    if old.submission_id != submission_id:
        raise Conflict(f"trial {n} is already committed (by submission {old.submission_id!r})")
    if old.human_action != human_action:
        raise Conflict(
            f"submission {submission_id!r} committed trial {n} with human_action={old.human_action!r}, "
            f"not {human_action!r}: a retry must repeat the submission",
        )
    return old


def check_event_room(db: DBSession, s: Session, events: list[dict], trial: int | None = None) -> None:
    """Refuse (413) events beyond the per-trial and per-session bounds."""
    if not events:
        return
    query = select(Event.trial, func.count()).where(Event.session_id == s.id).group_by(Event.trial)
    stored: dict[int | None, int] = dict(db.execute(query).all())
    total = sum(stored.values())
    if total + len(events) > MAX_EVENTS_PER_SESSION:
        raise TooLarge(f"this session already holds {total} events; at most {MAX_EVENTS_PER_SESSION} are stored")
    per = Counter(trial if trial is not None else ev.get("trial") for ev in events)
    for k, m in per.items():
        if stored.get(k, 0) + m > MAX_EVENTS_PER_TRIAL:
            have = stored.get(k, 0)
            raise TooLarge(f"trial {k} already has {have} events; at most {MAX_EVENTS_PER_TRIAL} are stored per trial")


def _event(s: Session, trial: int | None, ev: dict) -> Event:
    """The row of a UI event (``schemas.EventIn``'s fields) of session ``s``."""
    data = json.dumps(ev.get("data", {}))
    return Event(
        session_id=s.id, trial=trial, client_time=ev.get("t"), page=ev.get("page"), type=str(ev.get("type", ""))[:40], data=data
    )


def add_events(db: DBSession, s: Session, events: list[dict], batch: str | None = None) -> tuple[int, bool]:
    """Store ``events``; with a ``batch`` id, a batch already stored is not stored again.
    Returns (events stored, whether the batch was a repeat)."""
    if batch is not None:
        if db.get(EventBatch, (s.id, batch)) is not None:
            return 0, True
        db.add(EventBatch(session_id=s.id, batch=batch, events=len(events)))
    check_event_room(db, s, events)
    db.add_all(_event(s, ev.get("trial"), ev) for ev in events)
    try:
        db.commit()
    except IntegrityError:  # the same batch committed by a concurrent request in the meantime
        db.rollback()
        if batch is not None and db.get(EventBatch, (s.id, batch)) is not None:
            return 0, True
        raise
    return len(events), False
