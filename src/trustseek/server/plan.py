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
from ..policies import PolicyError, PolicyRunner, policy_from_dict
from ..policies.scheduling import SchedulePolicy
from ..vocab import ACTIONS
from .cache import Bounded
from .errors import NotAllowed, NotFound

#: items per complexity (remaining, visible), or None
Counts = dict[str, int] | None


def policy_sha256(policy: dict[str, Any]) -> str:
    """The address of a policy JSON: the SHA-256 of its key-sorted serialization."""
    return hashlib.sha256(json.dumps(policy, sort_keys=True).encode()).hexdigest()


class _LazyRng:
    """The generator ``np.random.default_rng(seed)``, made only when a policy draws from it
    (most never do, and making one costs more than the decision): ``used`` tells whether the
    decision depended on it."""

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
    """A task, model and policy (``load`` gives the policy's JSON, parsed on first use) with its
    ``PolicyRunner``.  Decisions that drew nothing from the generator of (seed, trial), and belief
    updates, are remembered: many robots reach the same beliefs (every one starts from the prior)."""

    MEMO = 50_000  # remembered decisions and updates per plan

    def __init__(self, task: Task, model: TrustModel, kind: str, sha: str, load: Callable[[], dict[str, Any]]):
        self.task, self.model, self.kind, self.sha, self._load = task, model, kind, sha, load
        self.n_trust = model.n_trust
        self._policy: Any = None
        self._runner: PolicyRunner | None = None
        self._decided: Bounded[tuple, str] = Bounded(self.MEMO)
        self._updated: Bounded[tuple, list[float]] = Bounded(self.MEMO)

    def policy(self, load: Callable[[], dict[str, Any]] | None = None) -> Any:
        """The policy object, parsed on first use from ``load`` (by default the plan's own)."""
        if self._policy is None:
            self._policy = policy_from_dict((load or self._load)(), f"policy:{self.sha}")
        return self._policy

    def runner(self) -> PolicyRunner:
        """The policy with its belief updater: the model is the policy's own, else the plan's."""
        if self._runner is None:
            pol = self.policy()
            self._runner = PolicyRunner(pol, model=getattr(pol, "model", None) or self.model)
        return self._runner

    def decide(self, belief: list, seed: int, n: int, complexity: str) -> str:
        """``PolicyRunner.decide`` at ``belief`` with the generator ``default_rng([seed, n, 0])``."""
        key = (tuple(belief), complexity)
        action = self._decided.get(key)
        if action is None:
            rng = _LazyRng([seed, n, 0])
            action = self.runner().action_at(np.asarray(belief, dtype=float), complexity, rng)  # type: ignore[arg-type]
            if not rng.used:
                self._decided.put(key, action)
        return action

    def update(self, belief: list, complexity: str, action: str, human: str | None, experience: str) -> list | None:
        """The belief after a trial, as ``PolicyRunner.observe`` updates it (None: no belief)."""
        key = (tuple(belief), complexity, action, human, experience)
        after = self._updated.get(key)
        if after is None:
            new = self.runner().belief_after(np.asarray(belief, dtype=float), complexity, action, human, experience)
            if new is None:
                return None
            after = self._updated.put(key, [float(x) for x in new])
        return after

    def pick(self, belief: Any, remaining: Counts, visible: Counts, complexity: str | None = None) -> tuple[str, str]:
        """(complexity, action) of a schedule policy: its pick among the remaining (and visible)
        items per complexity, or its action for an imposed item in that state."""
        pol = self.policy()
        if not isinstance(pol, SchedulePolicy):
            raise NotAllowed(f"remaining and visible items are for a schedule policy; this session runs a {pol.kind} policy")
        rem = self._counts(remaining, "remaining")
        if rem is None:
            raise NotAllowed("a schedule policy needs the remaining items: post remaining (per complexity)")
        vis, b = self._counts(visible, "visible"), np.asarray(belief, dtype=float)
        try:
            if complexity is None:
                k, a = pol.choose(b, rem, vis)
                return self.task.complexities[k], ACTIONS[a]
            return complexity, ACTIONS[pol.at(rem, vis).action(b, self.task.complexity_index(complexity))]
        except (PolicyError, KeyError) as exc:
            raise NotAllowed("; ".join(exc.problems) if isinstance(exc, PolicyError) else str(exc)) from None

    def _counts(self, counts: Counts, what: str) -> tuple[int, ...] | None:
        cx = self.task.complexities
        if counts is None:
            return None
        if set(counts) - set(cx) or any(not isinstance(v, int) or v < 0 for v in counts.values()):
            raise NotAllowed(f"{what} must map complexities {list(cx)} to non-negative numbers, got {counts!r}")
        return tuple(int(counts.get(c, 0)) for c in cx)


class Plans:
    """Each deploy session's plan (read from the database once per process), and one parsed
    copy per content: 1000 robots opened with the paper's model share one."""

    def __init__(self, sessions: int = 200_000, contents: int = 256):
        self.by_session: Bounded[str, PolicyPlan] = Bounded(sessions)
        self.by_content: Bounded[str, PolicyPlan] = Bounded(contents)

    def shared(
        self, plan: dict[str, Any], load: Callable[[], dict[str, Any]], task: Task | None = None, model: TrustModel | None = None
    ) -> PolicyPlan:
        """The one plan of this content (``plan`` as stored in the session row; its ``task`` and
        ``model`` parsed from it unless given), its policy parsed."""
        key = json.dumps([plan["task"], plan["model"], plan["policy_sha256"], plan["policy_kind"]], sort_keys=True)
        found = self.by_content.get(key)
        if found is None:  # shared at once: sessions opened meanwhile share it too
            task = Task.from_dict(plan["task"]) if task is None else task
            model = TrustModel.from_dict(plan["model"]) if model is None else model
            found = self.by_content.put(key, PolicyPlan(task, model, plan["policy_kind"], plan["policy_sha256"], load))
        try:
            found.policy(load)  # parsed by this caller's ``load`` unless parsed already
        except BaseException:
            self.by_content.pop(key)
            raise
        return found

    def of(self, store: Any, session_id: str) -> PolicyPlan:
        """The plan of deploy session ``session_id`` (``store`` reads it when not known here)."""
        found = self.by_session.get(session_id)
        if found is not None:
            return found
        d = store.plan(session_id)
        if d is None:
            raise NotFound("no such session")
        return self.by_session.put(session_id, self.shared(d, lambda: store.policy(d["policy_sha256"])))

    def clear(self) -> None:
        """Forget every plan (as a process that did not open the sessions)."""
        self.by_session.clear()
        self.by_content.clear()
