"""The task (`Task`): complexities with their probabilities and success probabilities, the
experience recorded when the robot asks, the rewards of eq. (1) (`Rewards`) and the discount;
its JSON format (``trustseek.task/1``, docs/formats.md).

* ``Task.complexity_probs[c]``                   P(C = c), i.i.d. over trials
* ``Task.success[c]``                            P(autonomous collection succeeds | C = c)
* ``Task.ask_experience[c]``                     experience index recorded when the robot asks in complexity c
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from ..vocab import ASK, EXPERIENCES, FAULTY, INTERVENE, RELIABLE
from .core import TrustModel
from .jsonfile import (
    ATOL,
    JsonFile,
    ModelError,
    build,
    check_names,
    check_row_array,
    complexity_index,
    fmt_number,
    get_key,
    is_number,
    unknown_keys,
)

TASK_FORMAT = "trustseek.task/1"


# --------------------------------------------------------------------------- Task


@dataclass(frozen=True)
class Rewards:
    """The per-trial team reward of eq. (1)."""

    autonomous_success: float = 2.0  # (autonomous, rely, reliable)
    ask: float = 1.0  # robot asked; human teleoperates
    intervene: float = 0.0  # (autonomous, intervene)
    autonomous_failure: float = -3.0  # (autonomous, rely, faulty)

    def to_dict(self) -> dict[str, float]:
        return asdict(self)

    def of(self, action: int, human_action: int, experience: int) -> float:
        """Reward of one trial from its robot action, human action and experience indices."""
        if action == ASK:
            return self.ask
        if human_action == INTERVENE:
            return self.intervene
        return self.autonomous_success if experience == RELIABLE else self.autonomous_failure


#: the largest reward magnitude: values (rewards / (1 - discount), summed over outcomes) stay far from overflow
MAX_REWARD = 1e12


@dataclass(frozen=True, eq=False)
class Task(JsonFile):
    """The object-collection task: complexity distribution, robot skill, rewards, discount."""

    complexities: tuple[str, ...]
    complexity_probs: np.ndarray
    success: np.ndarray
    ask_experience: tuple[int, ...]
    rewards: Rewards = field(default_factory=Rewards)
    discount: float = 0.987

    def __post_init__(self) -> None:
        object.__setattr__(self, "complexities", tuple(self.complexities))
        object.__setattr__(self, "ask_experience", tuple(int(x) for x in self.ask_experience))
        self._freeze_and_check("complexity_probs", "success")

    @property
    def n_complexity(self) -> int:
        return len(self.complexities)

    def problems(self) -> list[str]:
        N = len(self.complexities)
        problems: list[str] = []
        check_names(list(self.complexities), "complexities", problems)
        if self.complexity_probs.shape != (N,) or self.success.shape != (N,) or len(self.ask_experience) != N:
            problems.append("complexity_probs, success and ask_experience need one entry per complexity")
            return problems
        check_row_array(self.complexity_probs[None, :], lambda i: "complexity probabilities", problems)
        for c, cn in enumerate(self.complexities):
            s = self.success[c]
            if not (math.isfinite(s) and 0.0 <= s <= 1.0):
                problems.append(f"complexities[{cn}].success = {fmt_number(float(s))} is outside [0, 1]")
            if self.ask_experience[c] not in (FAULTY, RELIABLE):
                problems.append(f"complexities[{cn}].ask_experience must be 'faulty' or 'reliable'")
        if not (math.isfinite(self.discount) and 0.0 <= self.discount < 1.0):
            problems.append(f"discount = {fmt_number(self.discount)} must lie in [0, 1)")
        for k, v in self.rewards.to_dict().items():
            if not math.isfinite(v):
                problems.append(f"rewards[{k}] = {v!r} must be a finite number")
            elif abs(v) > MAX_REWARD:
                problems.append(
                    f"rewards[{k}] = {fmt_number(v)} is outside [-1e12, 1e12] (larger rewards overflow the values; rescale them)"
                )
        return problems

    def complexity_index(self, name: str) -> int:
        return complexity_index(self.complexities, name)

    def p_experience(self, c: int, a: int, o: int) -> np.ndarray:
        """P(E_{t+1} | o_t, C_t = c, a_t = a) as a length-2 array over (faulty, reliable)."""
        if a == ASK:
            e = self.ask_experience[c]
            return np.array([1.0 - e, float(e)])
        if o == INTERVENE:
            return np.array([1.0, 0.0])
        s = float(self.success[c])
        return np.array([1.0 - s, s])

    def experience_table(self) -> np.ndarray:
        """P(E' | o, C, a) as an array indexed [c, a, o, e]."""
        return np.array([[[self.p_experience(c, a, o) for o in range(2)] for a in range(2)] for c in range(self.n_complexity)])

    def reward_table(self) -> np.ndarray:
        """Reward of eq. (1) as an array indexed [a, o, e]."""
        return np.array([[[self.rewards.of(a, o, e) for e in range(2)] for o in range(2)] for a in range(2)], dtype=float)

    def check_compatible(self, model: TrustModel) -> None:
        """Refuse a model whose complexities differ, or with never-estimated rows this task can reach."""
        if tuple(model.complexities) != tuple(self.complexities):
            raise ModelError(
                [
                    f"the model's complexities {list(model.complexities)} differ from the task's "
                    f"{list(self.complexities)} (names and order must match)"
                ]
            )
        used = self.unestimated_rows_used(model)
        if used:
            raise ModelError(
                [
                    f"{r} was never estimated (the data had no such trials) and planning or simulating with this task uses it"
                    for r in used
                ]
                + [
                    "supply those rows: refit with 'trustseek fit ... --fill-from paper' (or another model file), "
                    'or write them into the model file and remove them from its "not_estimated" list '
                    "(docs/formats.md)"
                ]
            )

    def unestimated_rows_used(self, model: TrustModel) -> list[str]:
        """Never-estimated rows of ``model`` a trial of this task can reach: every emission row, the
        transitions after acting autonomously (either experience) and after asking (its experience)."""
        out = []
        for table, idx in model.not_estimated:
            if table == "transition" and idx[1] == ASK and idx[2] != self.ask_experience[idx[0]]:
                continue
            out.append(model.row_name(table, idx))
        return out

    # -- JSON --------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return {
            "format": TASK_FORMAT,
            "complexities": {
                cn: {
                    "probability": float(self.complexity_probs[c]),
                    "success": float(self.success[c]),
                    "ask_experience": EXPERIENCES[self.ask_experience[c]],
                }
                for c, cn in enumerate(self.complexities)
            },
            "rewards": self.rewards.to_dict(),
            "discount": self.discount,
        }

    @classmethod
    def from_dict(cls, d: Any, source: str | None = None) -> Task:
        problems: list[str] = []
        if not isinstance(d, Mapping):
            raise ModelError([f"a task must be a JSON object, got {type(d).__name__}"], source)
        fmt = d.get("format", TASK_FORMAT)
        if fmt != TASK_FORMAT:
            problems.append(f"format is {fmt!r}, expected {TASK_FORMAT!r}")
        unknown_keys(d, ["format", "complexities", "rewards", "discount"], "task", problems)
        cx = get_key(d, "complexities", "complexities", problems)
        names: list[str] = []
        probs: list[float] = []
        succ: list[float] = []
        askx: list[int] = []
        if cx is not None:
            if not isinstance(cx, Mapping) or len(cx) < 2:
                problems.append("complexities must be an object with at least 2 named levels")
            else:
                for cn, spec in cx.items():
                    names.append(cn)
                    lab = f"complexities[{cn}]"
                    if not isinstance(spec, Mapping):
                        problems.append(f"{lab} must be an object, got {spec!r}")
                        continue
                    unknown_keys(spec, ["probability", "success", "ask_experience"], lab, problems)
                    for key, store in (("probability", probs), ("success", succ)):
                        v = get_key(spec, key, f"{lab}.{key}", problems)
                        if v is not None and (not is_number(v) or not 0.0 <= v <= 1.0):
                            problems.append(f"{lab}.{key} = {v!r} must be a probability in [0, 1]")
                        elif v is not None:
                            store.append(float(v))
                    ae = get_key(spec, "ask_experience", f"{lab}.ask_experience", problems)
                    if ae is not None and ae not in EXPERIENCES:
                        problems.append(f"{lab}.ask_experience = {ae!r} must be one of {list(EXPERIENCES)}")
                    elif ae is not None:
                        askx.append(EXPERIENCES.index(ae))
                if not problems and abs(sum(probs) - 1.0) > ATOL:
                    problems.append(f"complexity probabilities sum to {fmt_number(sum(probs))}")
        rw = d.get("rewards", {})
        rewards = Rewards()
        paper = {"rewards": json.dumps(rewards.to_dict()), "discount": fmt_number(Task.discount)}  # the defaults
        for key in ("rewards", "discount"):
            if key not in d:
                problems.append(
                    f"{key} is missing (the paper's task has {key} = {paper[key]}; 'trustseek preset "
                    "--task-out task.json' writes a complete task to start from)"
                )
        if not isinstance(rw, Mapping):
            problems.append(f"rewards must be an object, got {rw!r}")
        else:
            keys = Rewards().to_dict()
            unknown_keys(rw, keys, "rewards", problems)
            problems.extend(f"rewards[{k}] is missing" for k in keys if "rewards" in d and k not in rw)
            vals = {}
            for k, v in rw.items():
                if k in keys and (not is_number(v) or not math.isfinite(float(v))):
                    problems.append(f"rewards[{k}] = {v!r} must be a finite number")
                elif k in keys:
                    vals[k] = float(v)
            rewards = Rewards(**vals)
        disc = d.get("discount", Task.discount)
        if not is_number(disc) or not (0.0 <= float(disc) < 1.0):
            problems.append(f"discount = {disc!r} must be a number in [0, 1)")

        def make() -> Task:  # only once the reader found no problem: ``disc`` is then a number
            return cls(tuple(names), np.array(probs), np.array(succ), tuple(askx), rewards, float(disc))

        return build(problems, source, make)
