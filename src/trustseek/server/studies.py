"""Study configuration: validation, policy resolution and per-participant plans.

A study is created from a JSON object (see ``docs/experiments.md``)::

    {"name": "pilot", "task": "paper", "model": "paper",
     "blocks": [{"name": "agnostic", "policy": {"kind": "trust-agnostic"},
                 "schedule": {"counts": {"low": 10, "high": 10}}},
                {"name": "aware", "policy": {"kind": "trust-aware"},
                 "schedule": {"trials": ["low", "high", "high"]}}],
     "counterbalance": "rotate", "self_report": "block", "animation_speed": 1.0, "seed": 7}

Policies are resolved once, at creation, into the core's policy JSON and stored with the
study, so a study keeps behaving identically whatever the code later computes.
"""

from __future__ import annotations

import json
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, Field, field_validator, model_validator

from ..errors import TrustseekError
from ..model.core import ModelError, Task, TrustModel
from ..model.presets import MODEL_PRESETS, TASK_PRESETS
from ..policies import policy_from_dict
from ..solvers import policy_from_spec
from .schemas import STRICT, check_preset

MAX_TRIALS_PER_BLOCK = 1000
MAX_GRID = 20001  # the largest belief grid a study may ask the server to solve


class ConfigError(TrustseekError, ValueError):
    """A study or deploy configuration is invalid; ``problems`` lists every reason."""


class Schedule(BaseModel):
    model_config = STRICT
    counts: dict[str, int] | None = Field(None, description="Trials per complexity, shuffled per participant.")
    trials: list[str] | None = Field(None, description="A fixed list of complexities, in order.")

    @model_validator(mode="after")
    def _one(self):
        if (self.counts is None) == (self.trials is None):
            raise ValueError("a schedule needs exactly one of 'counts' or 'trials'")
        if self.counts is not None and any(v < 0 for v in self.counts.values()):
            raise ValueError(f"counts must be non-negative, got {self.counts}")
        n = sum(self.counts.values()) if self.counts is not None else len(self.trials or [])
        if not 1 <= n <= MAX_TRIALS_PER_BLOCK:
            raise ValueError(f"a block needs between 1 and {MAX_TRIALS_PER_BLOCK} trials, got {n}")
        return self


class BlockIn(BaseModel):
    model_config = STRICT
    name: str | None = Field(None, max_length=100)
    policy: dict[str, Any] = Field(..., description="A policy spec ({'kind': ...}) or a full policy JSON.")
    schedule: Schedule


class StudyIn(BaseModel):
    model_config = STRICT
    name: str = Field(..., min_length=1, max_length=200)
    task: str | dict[str, Any] = "paper"
    model: str | dict[str, Any] = "paper"
    blocks: list[BlockIn] = Field(..., min_length=1, max_length=20)
    counterbalance: Literal["none", "rotate", "random"] = "none"
    self_report: Literal["none", "trial", "block"] = "none"
    animation_speed: float = Field(1.0, gt=0.05, le=50.0)
    seed: int = Field(0, ge=0, lt=2**31)
    consent_text: str | None = Field(None, max_length=20000)
    instructions: str | None = Field(None, max_length=20000)

    @field_validator("task", "model")
    @classmethod
    def _preset(cls, v, info):
        return check_preset(v, info.field_name)


def _unknown_preset(field: str, spec: str, presets) -> ConfigError:
    return ConfigError([f"unknown {field} preset {spec!r}; presets: {sorted(presets)}, or give the JSON object"])


def load_task_spec(spec: str | dict) -> Task:
    if isinstance(spec, str) and spec not in TASK_PRESETS:
        raise _unknown_preset("task", spec, TASK_PRESETS)
    try:
        return TASK_PRESETS[spec]() if isinstance(spec, str) else Task.from_dict(spec, "task")
    except ModelError as exc:
        raise ConfigError(exc.lines()) from None


def load_model_spec(spec: str | dict) -> TrustModel:
    if isinstance(spec, str) and spec not in MODEL_PRESETS:
        raise _unknown_preset("model", spec, MODEL_PRESETS)
    try:
        return MODEL_PRESETS[spec]() if isinstance(spec, str) else TrustModel.from_dict(spec, "model")
    except ModelError as exc:
        raise ConfigError(exc.lines()) from None


def resolve_policy(spec: dict[str, Any], model: TrustModel, task: Task, where: str = "policy") -> dict[str, Any]:
    """A policy spec (``trustseek.solvers.specs``) to the core's policy JSON, solving the POMDP
    for ``trust-aware`` (cached: many sessions open with the same model, task and spec)."""
    if not isinstance(spec, dict):
        raise ConfigError([f"{where} must be an object"])
    key = None if "format" in spec else json.dumps([model.to_dict(), task.to_dict(), spec], sort_keys=True)
    if key is not None and key in _RESOLVED:
        return _RESOLVED[key]
    try:
        policy = policy_from_spec(spec, model, task, where, max_grid=MAX_GRID).to_dict()
    except TrustseekError as exc:
        raise ConfigError(exc.lines()) from None
    if key is not None:
        if len(_RESOLVED) > 64:
            _RESOLVED.clear()
        _RESOLVED[key] = policy
    return policy


_RESOLVED: dict[str, dict[str, Any]] = {}


def build_study_config(study: StudyIn) -> dict[str, Any]:
    """Validate every part of a study and return the stored configuration."""
    problems: list[str] = []
    task = model = None
    try:
        task = load_task_spec(study.task)
    except ConfigError as exc:
        problems += exc.problems
    try:
        model = load_model_spec(study.model)
    except ConfigError as exc:
        problems += exc.problems
    if task is not None and model is not None and tuple(model.complexities) != tuple(task.complexities):
        problems.append(f"the model's complexities {list(model.complexities)} differ from the task's {list(task.complexities)}")
    if problems or task is None or model is None:
        raise ConfigError(problems)
    blocks = []
    for i, b in enumerate(study.blocks):
        where = f"blocks[{i}]"
        s = b.schedule
        names = list(s.counts) if s.counts is not None else list(s.trials or [])
        bad = sorted({c for c in names if c not in task.complexities})
        if bad:
            problems.append(f"{where}.schedule names unknown complexities {bad}; expected {list(task.complexities)}")
        try:
            pol = resolve_policy(b.policy, model, task, f"{where}.policy")
        except ConfigError as exc:
            problems += exc.problems
            continue
        blocks.append(
            {
                "name": b.name or f"block {i + 1}",
                "policy": pol,
                "schedule": {"counts": s.counts} if s.counts is not None else {"trials": s.trials},
            }
        )
    if problems:
        raise ConfigError(problems)
    cfg = study.model_dump(exclude={"blocks", "task", "model"})
    cfg.update(task=task.to_dict(), model=model.to_dict(), blocks=blocks)
    return cfg


def block_order(cfg: dict[str, Any], index: int, rng: np.random.Generator) -> list[int]:
    """The block order of the ``index``-th participant (0-based) under the study's counterbalancing."""
    n = len(cfg["blocks"])
    base = list(range(n))
    if cfg["counterbalance"] == "rotate":
        k = index % n
        return base[k:] + base[:k]
    if cfg["counterbalance"] == "random":
        return [int(x) for x in rng.permutation(n)]
    return base


def participant_plan(cfg: dict[str, Any], index: int, seed: int) -> dict[str, Any]:
    """Block order and each block's complexity sequence, drawn once per participant."""
    rng = np.random.default_rng([cfg["seed"], seed])
    order = block_order(cfg, index, rng)
    trials: list[dict[str, Any]] = []
    for b in order:
        sched = cfg["blocks"][b]["schedule"]
        if "trials" in sched:
            seq = list(sched["trials"])
        else:
            seq = [c for c, k in sched["counts"].items() for _ in range(k)]
            seq = [seq[i] for i in rng.permutation(len(seq))]
        trials.extend({"block": b, "complexity": c} for c in seq)
    return {"block_order": order, "trials": trials}


_POLICIES: dict[str, Any] = {}


def policy_object(key: str, policy_json):
    """The policy object of a stored (immutable) policy JSON, cached by ``key``: parsing a
    solved policy is not free, and stored policies never change.  ``policy_json`` may be a
    callable returning the JSON, called only when the policy is not cached."""
    pol = _POLICIES.get(key)
    if pol is None:
        if len(_POLICIES) > 4096:
            _POLICIES.clear()
        d = policy_json() if callable(policy_json) else policy_json
        pol = _POLICIES[key] = policy_from_dict(d, key)
    return pol
