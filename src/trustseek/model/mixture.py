"""Supervisor types: a population of M trust models with the same structure, and each
participant belonging to one of them (the paper's Remark 1: "low trust is easily triggered
for some participants compared to others").

A :class:`TypeMixture` holds the types' names, their weights (the share of the population)
and one model per type: every type a :class:`~trustseek.model.core.TrustModel`, or (a study
with other inputs) every type a general model (:class:`~trustseek.model.iohmm.IOHMMModel`)
with the same levels, output and inputs.  A plain model is the mixture of one type.  Planning
needs trust models: :meth:`TypeMixture.from_dict` refuses general types unless asked
(``general=True``: decoding, prediction, per-person models).  JSON::

    {"format": "trustseek.mixture/1", "notes": "...",
     "types": [{"name": "paper", "weight": 0.7, "model": {<trust model or general model>}}, ...]}
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import numpy as np

from .core import TrustModel, planning_refusal
from .iohmm import IOHMMModel, is_iohmm_file
from .jsonfile import JsonFile, ModelError, freeze_arrays, raise_problems

MIXTURE_FORMAT = "trustseek.mixture/1"
M = TypeVar("M", bound="TrustModel | IOHMMModel")  # every type a trust model, or every type a general model
N = TypeVar("N", bound="TrustModel | IOHMMModel")


@dataclass(frozen=True, eq=False)
class TypeMixture(JsonFile, Generic[M]):
    """M supervisor types: ``names[m]`` with population share ``weights[m]`` behaves like ``models[m]``."""

    names: tuple[str, ...]
    weights: np.ndarray
    models: tuple[M, ...]
    notes: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "names", tuple(str(n) for n in self.names))
        object.__setattr__(self, "models", tuple(self.models))
        object.__setattr__(self, "weights", np.reshape(np.asarray(self.weights, dtype=np.float64), -1))
        freeze_arrays(self, "weights")
        raise_problems(self)

    @property
    def n_types(self) -> int:
        return len(self.models)

    @property
    def general(self) -> bool:
        """True when the types are general models (inputs a trust model does not have)."""
        return isinstance(self.models[0], IOHMMModel)

    @property
    def trust_levels(self) -> tuple[str, ...]:
        m = self.models[0]
        return m.levels if isinstance(m, IOHMMModel) else m.trust_levels

    @property
    def complexities(self) -> tuple[str, ...]:
        m = self.models[0]
        if isinstance(m, IOHMMModel):
            raise ModelError([planning_refusal(m.used_inputs)])
        return m.complexities

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
        if isinstance(first, IOHMMModel):
            return problems + self._general_problems()
        for name, m in zip(self.names, self.models, strict=False):
            if not isinstance(m, TrustModel):
                problems.append(f"type {name!r}: expected a TrustModel, got {type(m).__name__}")
            elif m.trust_levels != first.trust_levels or m.complexities != first.complexities:
                problems.append(
                    f"type {name!r} has trust levels {list(m.trust_levels)} and complexities {list(m.complexities)}; "
                    f"type {self.names[0]!r} has {list(first.trust_levels)} and {list(first.complexities)}: "
                    "every type must share them"
                )
        return problems

    def _general_problems(self) -> list[str]:
        """General types must share levels, output and inputs (their tables differ)."""
        first = self.models[0]
        assert isinstance(first, IOHMMModel)

        def shape(m: IOHMMModel) -> tuple:
            return (m.levels, m.output, m.output_categories, dict(m.inputs), m.emission_inputs, m.transition_inputs)

        problems = []
        for name, m in zip(self.names, self.models, strict=False):
            if not isinstance(m, IOHMMModel):
                problems.append(f"type {name!r}: expected a general model like type {self.names[0]!r}, got a trust model")
            elif shape(m) != shape(first):
                problems.append(
                    f"type {name!r} has levels {list(m.levels)}, output {m.output!r} and inputs {dict(m.inputs)} "
                    f"(emissions on {list(m.emission_inputs)}, transitions on {list(m.transition_inputs)}); type "
                    f"{self.names[0]!r} has {list(first.levels)}, {first.output!r} and {dict(first.inputs)} (emissions on "
                    f"{list(first.emission_inputs)}, transitions on {list(first.transition_inputs)}): every type must share them"
                )
        return problems

    # -- constructors -------------------------------------------------------
    @classmethod
    def single(cls, model: N, name: str = "pooled") -> TypeMixture[N]:
        """The mixture of one type."""
        return TypeMixture((name,), np.ones(1), (model,))

    def type_index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise ModelError([f"unknown supervisor type {name!r}; types: {list(self.names)}"]) from None

    def with_weights(self, weights: Sequence[float]) -> TypeMixture[M]:
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
            if general and is_iohmm_file(d):
                return cls.single(IOHMMModel.from_dict(d, source))
            return cls.single(TrustModel.from_dict(d, source))
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
            if isinstance(weight, bool) or not isinstance(weight, int | float) or not math.isfinite(weight) or weight < 0:
                problems.append(f"{where}.weight must be a non-negative number, got {weight!r}")
                weight = 0.0
            try:
                raw = t.get("model")
                if is_iohmm_file(raw) and not general:
                    inputs = raw.get("inputs") if isinstance(raw, Mapping) and isinstance(raw.get("inputs"), Mapping) else {}
                    raise ModelError([planning_refusal(tuple(inputs or ()))])
                models.append(IOHMMModel.from_dict(raw, None) if is_iohmm_file(raw) else TrustModel.from_dict(raw, None))
            except ModelError as exc:
                problems.extend(f"{where}.model: {p}" for p in exc.problems)
                continue
            names.append(name)
            weights.append(float(weight))
        notes = d.get("notes", "")
        if not isinstance(notes, str):
            problems.append(f"notes must be a string, got {notes!r}")
        if problems:
            raise ModelError(problems, source)
        try:
            return cls(tuple(names), np.asarray(weights), tuple(models), notes)
        except ModelError as exc:
            raise ModelError(exc.problems, source) from None

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, TypeMixture):
            return NotImplemented
        return (
            self.names == other.names
            and np.array_equal(self.weights, other.weights)
            and all(a == b for a, b in zip(self.models, other.models, strict=True))
        )

    __hash__ = None  # type: ignore[assignment]
