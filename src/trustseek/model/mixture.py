"""Supervisor types: a population of M trust models with the same structure, and each
participant belonging to one of them (the paper's Remark 1: "low trust is easily triggered
for some participants compared to others").

A :class:`TypeMixture` holds the types' names, their weights (the share of the population)
and one model per type (:class:`~trustseek.model.core.TrustModel`): every type a trust model,
or (a study with other inputs) every type a general model with the same levels, output and
inputs.  A plain model is the mixture of one type.  Planning
needs trust models: :meth:`TypeMixture.from_dict` refuses general types unless asked
(``general=True``: decoding, prediction, per-person models).  The JSON (``trustseek.mixture/1``)
is in docs/formats.md.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .core import TrustModel
from .jsonfile import JsonFile, ModelError, build, is_number, read_notes

MIXTURE_FORMAT = "trustseek.mixture/1"


@dataclass(frozen=True, eq=False)
class TypeMixture(JsonFile):
    """M supervisor types: ``names[m]`` with population share ``weights[m]`` behaves like ``models[m]``."""

    names: tuple[str, ...]
    weights: np.ndarray
    models: tuple[TrustModel, ...]
    notes: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "names", tuple(str(n) for n in self.names))
        object.__setattr__(self, "models", tuple(self.models))
        object.__setattr__(self, "weights", np.reshape(np.asarray(self.weights, dtype=np.float64), -1))
        self._freeze_and_check("weights")

    @property
    def n_types(self) -> int:
        return len(self.models)

    @property
    def general(self) -> bool:
        """True when the types are general models (inputs a trust model does not have)."""
        return self.models[0].general

    @property
    def trust_levels(self) -> tuple[str, ...]:
        return self.models[0].levels

    @property
    def complexities(self) -> tuple[str, ...]:
        return self.models[0].complexities

    def problems(self) -> list[str]:
        """Every violation of the mixture's constraints, as human-readable lines."""
        problems: list[str] = []
        M = len(self.models)
        if M < 1:
            return ["a mixture needs at least one type"]
        if len(self.names) != M:
            problems.append(f"{len(self.names)} type names for {M} models")
        if len(set(self.names)) != len(self.names):
            problems.append(f"type names must differ, got {list(self.names)}")
        if self.weights.shape != (M,):
            problems.append(f"{self.weights.size} weights for {M} types")
        elif not np.all(np.isfinite(self.weights)) or np.any(self.weights < 0) or abs(self.weights.sum() - 1) > 1e-6:
            problems.append(f"type weights must be non-negative and sum to 1, got {self.weights.tolist()}")
        first = self.models[0]
        for name, m in zip(self.names, self.models, strict=False):
            if not isinstance(m, TrustModel):
                problems.append(f"type {name!r}: expected a TrustModel, got {type(m).__name__}")
            elif m.general != first.general:
                kinds = ("a general model", "a trust model") if first.general else ("a trust model", "a general model")
                problems.append(f"type {name!r}: expected {kinds[0]} like type {self.names[0]!r}, got {kinds[1]}")
            elif _configuration(m) != _configuration(first):
                problems.append(
                    f"type {name!r} has {_described(m)}; type {self.names[0]!r} has {_described(first)}: "
                    "every type must share them"
                )
        return problems

    # -- constructors -------------------------------------------------------
    @classmethod
    def single(cls, model: TrustModel, name: str = "pooled") -> TypeMixture:
        """The mixture of one type."""
        return TypeMixture((name,), np.ones(1), (model,))

    def type_index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise ModelError([f"unknown supervisor type {name!r}; types: {list(self.names)}"]) from None

    def with_weights(self, weights: Sequence[float]) -> TypeMixture:
        """The same types in other proportions (normalised; refused if negative or all zero)."""
        w = np.asarray(weights, dtype=np.float64).reshape(-1)
        if w.shape != (self.n_types,) or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
            raise ModelError([f"need {self.n_types} non-negative weights, not all zero; got {list(weights)}"])
        return TypeMixture(self.names, w / w.sum(), self.models, self.notes)

    def sample_types(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """The types of ``n`` participants drawn from the population (as type indices)."""
        return rng.choice(self.n_types, size=int(n), p=self.weights)

    def counts(self, n: int) -> np.ndarray:
        """Type indices for ``n`` participants in the population's proportions, largest remainder first
        (for designs that fix the shares rather than draw them)."""
        exact = self.weights * n
        base = np.floor(exact).astype(np.int64)
        order = np.argsort(-(exact - base), kind="stable")
        base[order[: n - int(base.sum())]] += 1
        return np.repeat(np.arange(self.n_types), base)

    # -- JSON ---------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return {
            "format": MIXTURE_FORMAT,
            "notes": self.notes,
            "types": [
                {"name": n, "weight": float(w), "model": m.to_dict()}
                for n, w, m in zip(self.names, self.weights, self.models, strict=True)
            ],
        }

    @classmethod
    def from_dict(cls, d: Any, source: str | None = None, general: bool = False) -> TypeMixture:
        """A mixture from its JSON form; a plain model is read as one type named ``pooled``.  General
        types (``trustseek.iohmm/1``) are read only with ``general`` (not for planning)."""
        if isinstance(d, Mapping) and d.get("format", "") != MIXTURE_FORMAT and "types" not in d:
            return cls.single(TrustModel.from_dict(d, source, general))
        problems: list[str] = []
        if not isinstance(d, Mapping):
            raise ModelError([f"a mixture must be a JSON object, got {type(d).__name__}"], source)
        if d.get("format") != MIXTURE_FORMAT:
            problems.append(f"format is {d.get('format')!r}, expected {MIXTURE_FORMAT!r}")
        unknown = sorted(set(d) - {"format", "notes", "types"})
        if unknown:
            problems.append(f"mixture: unknown keys {unknown}; allowed: format, notes, types")
        types = d.get("types")
        if not isinstance(types, list) or not types:
            problems.append("types must be a non-empty list of {name, weight, model}")
            raise ModelError(problems, source)
        names: list[str] = []
        weights: list[float] = []
        models: list[Any] = []
        for i, t in enumerate(types):
            where = f"types[{i}]"
            if not isinstance(t, Mapping):
                problems.append(f"{where} must be an object with name, weight and model")
                continue
            extra = sorted(set(t) - {"name", "weight", "model"})
            if extra:
                problems.append(f"{where}: unknown keys {extra}; allowed: name, weight, model")
            name, weight = t.get("name"), t.get("weight")
            if not isinstance(name, str) or not name:
                problems.append(f"{where}.name must be a non-empty string, got {name!r}")
                name = f"type{i}"
            if not is_number(weight) or not math.isfinite(weight) or weight < 0:
                problems.append(f"{where}.weight must be a non-negative number, got {weight!r}")
                weight = 0.0
            try:
                models.append(TrustModel.from_dict(t.get("model"), None, general))
            except ModelError as exc:
                problems.extend(f"{where}.model: {p}" for p in exc.problems)
                continue
            names.append(name)
            weights.append(float(weight))
        notes = read_notes(d, problems)
        return build(problems, source, lambda: cls(tuple(names), np.asarray(weights), tuple(models), notes))


def _configuration(m: TrustModel) -> tuple:
    """What every type shares: levels, output and inputs (their tables differ)."""
    return (m.levels, m.output, m.output_categories, dict(m.inputs), m.emission_inputs, m.transition_inputs)


def _described(m: TrustModel) -> str:
    if not m.general:
        return f"trust levels {list(m.trust_levels)} and complexities {list(m.complexities)}"
    return (
        f"levels {list(m.levels)}, output {m.output!r} and inputs {dict(m.inputs)} (emissions on "
        f"{list(m.emission_inputs)}, transitions on {list(m.transition_inputs)})"
    )
