"""A policy with ``PolicyRunner``'s step applied to any belief (``PolicyPlan``: a study block's
policy, or a deploy session's task, model and policy), remembered when it drew nothing from the
session's generator; the deploy sessions' plans, one per content, shared by every session
opened with the same ones (``Plans``, owned by the application)."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from typing import Any

import numpy as np

from ..model.core import TrustModel
from ..model.task import Task
from ..policies import PolicyRunner, policy_from_dict
from .cache import Bounded
from .errors import NotFound


def policy_sha256(policy: dict[str, Any]) -> str:
    """The address of a policy JSON: the SHA-256 of its key-sorted serialization, the same for
    any order of the keys."""
    return hashlib.sha256(json.dumps(policy, sort_keys=True).encode()).hexdigest()


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


class PolicyPlan:
    """A deploy session's task, model and policy (``plan`` of the session row), with the policy
    object and its ``PolicyRunner`` built once.  Decisions and belief updates are deterministic
    functions of (belief, complexity[, action, human action, experience]), except a decision
    that draws from the generator of (seed, trial): the others are remembered, so a belief that
    many robots reach (every robot's first trials start from the same prior) is decided and
    updated once."""

    MEMO = 50_000  # remembered decisions and updates per plan

    def __init__(self, task: Task, model: TrustModel, kind: str, sha: str):
        self.task, self.model, self.kind, self.sha = task, model, kind, sha
        self.n_trust = model.n_trust
        self._policy: Any = None
        self._runner: PolicyRunner | None = None
        self._decided: Bounded[tuple, str] = Bounded(self.MEMO)
        self._updated: Bounded[tuple, list[float]] = Bounded(self.MEMO)

    def policy(self, load: Callable[[], dict[str, Any]]) -> Any:
        """The policy object (``load`` gives its JSON when it is not parsed yet)."""
        if self._policy is None:
            self._policy = policy_from_dict(load(), f"policy:{self.sha}")
        return self._policy

    def runner(self, load: Callable[[], dict[str, Any]]) -> PolicyRunner:
        """The policy with its belief updater, as a robot's ``PolicyRunner``: the model is the
        policy's own, else the session's."""
        if self._runner is None:
            pol = self.policy(load)
            self._runner = PolicyRunner(pol, model=getattr(pol, "model", None) or self.model)
        return self._runner

    def decide(self, load: Callable[[], dict[str, Any]], belief: list, seed: int, n: int, complexity: str) -> str:
        """``PolicyRunner.decide`` at ``belief`` with the generator ``default_rng([seed, n, 0])``."""
        key = (tuple(belief), complexity)
        action = self._decided.get(key)
        if action is None:
            rng = _LazyRng([seed, n, 0])
            action = self.runner(load).action_at(np.asarray(belief, dtype=float), complexity, rng)  # type: ignore[arg-type]
            if not rng.used:
                self._decided.put(key, action)
        return action

    def update(
        self, load: Callable[[], dict[str, Any]], belief: list, complexity: str, action: str, human: str | None, experience: str
    ) -> list | None:
        """The belief after a trial, as ``PolicyRunner.observe`` updates it (None: no belief)."""
        key = (tuple(belief), complexity, action, human, experience)
        after = self._updated.get(key)
        if after is None:
            new = self.runner(load).belief_after(np.asarray(belief, dtype=float), complexity, action, human, experience)
            if new is None:
                return None
            after = self._updated.put(key, [float(x) for x in new])
        return after


class Plans:
    """Each deploy session's plan (read from the database once per process), and one parsed
    copy per content: 1000 robots opened with the paper's model share one."""

    def __init__(self, sessions: int = 200_000, contents: int = 256):
        self.by_session: Bounded[str, PolicyPlan] = Bounded(sessions)
        self.by_content: Bounded[str, PolicyPlan] = Bounded(contents)

    def shared(self, plan: dict[str, Any], make: Callable[[], PolicyPlan]) -> PolicyPlan:
        """The one plan of this content (``plan`` as stored in the session row)."""
        key = json.dumps([plan["task"], plan["model"], plan["policy_sha256"], plan["policy_kind"]], sort_keys=True)
        return self.by_content.get(key) or self.by_content.put(key, make())

    def of(self, store: Any, session_id: str) -> PolicyPlan:
        """The plan of deploy session ``session_id`` (``store`` reads it when not known here)."""
        found = self.by_session.get(session_id)
        if found is not None:
            return found
        d = store.plan(session_id)
        if d is None:
            raise NotFound("no such session")
        plan = self.shared(
            d,
            lambda: PolicyPlan(Task.from_dict(d["task"]), TrustModel.from_dict(d["model"]), d["policy_kind"], d["policy_sha256"]),
        )
        return self.by_session.put(session_id, plan)

    def remember(self, session_id: str, plan: dict[str, Any], task: Task, model: TrustModel) -> None:
        """Register a session just opened by this process, so that its first decision needs no
        database read nor parsing (``task`` and ``model`` are the ones ``plan`` describes)."""
        shared = self.shared(plan, lambda: PolicyPlan(task, model, plan["policy_kind"], plan["policy_sha256"]))
        self.by_session.put(session_id, shared)

    def clear(self) -> None:
        """Forget every plan (as a process that did not open the sessions)."""
        self.by_session.clear()
        self.by_content.clear()
