"""A general fitted IOHMM (``IOHMMModel``): hidden levels, one output, named discrete inputs.

The trust model (:class:`~trustseek.model.core.TrustModel`) is this model with the paper's
inputs: emissions on complexity and the robot action, transitions on complexity, the robot
action and the experience.  A study may condition on anything it logs instead (a
between-subject condition, the aid's advice, an image's difficulty): the model then keeps
those inputs by name, each with its levels in their declared order, and its tables with
named axes.  Planning (solve, simulate, the policies) needs the trust model; decoding,
prediction and validation take either.

Tables (``numpy.float64``)::

    initial[k]                 P(S_1 = k)
    emission[u, k, y]          P(y_t = y | S_t = k, emission inputs of trial t = u)
    transition[u, k, j]        P(S_{t+1} = j | S_t = k, transition inputs of trial t = u)

``u`` is the combination of the inputs' levels, C order over the inputs as listed (the
first input varies slowest).  The JSON format (``trustseek.iohmm/1``, ``docs/formats.md``)
writes each table as nested objects: the inputs' levels in order, then the level, then the
output category (or the next level).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .core import IOHMM_FORMAT, PLANNING_INPUTS, RatingTable, TrustModel, planning_refusal
from .jsonfile import (
    JsonFile,
    ModelError,
    check_names,
    check_row_array,
    freeze_arrays,
    get_key,
    load_json,
    nested,
    raise_problems,
    read_row,
    read_table,
    unknown_keys,
)

__all__ = ["IOHMM_FORMAT", "PLANNING_INPUTS", "IOHMMModel", "is_iohmm_file", "load_any_model", "planning_refusal"]

STRUCTURE_KEYS = ("fixed_emissions", "fixed_transitions", "tied_emissions", "tied_transitions", "order_by", "prior")
KEYS = (
    "format",
    "notes",
    "levels",
    "output",
    "inputs",
    "emission_inputs",
    "transition_inputs",
    "structure",
    "initial",
    "emission",
    "transition",
    "rating",
)


@dataclass(frozen=True, eq=False)
class IOHMMModel(JsonFile):
    """A fitted IOHMM with named inputs (see the module docstring)."""

    levels: tuple[str, ...]
    output: str
    output_categories: tuple[str, ...]
    inputs: Mapping[str, tuple[str, ...]]  # every input's levels, in their declared order
    emission_inputs: tuple[str, ...]
    transition_inputs: tuple[str, ...]
    initial: np.ndarray
    emission: np.ndarray
    transition: np.ndarray
    structure: Mapping[str, Any] = field(default_factory=dict)  # fixed and tied rows, order_by, prior (as in the spec)
    rating: RatingTable | None = None
    rating_column: str | None = None
    notes: str = ""

    def __post_init__(self) -> None:
        for name in ("levels", "output_categories", "emission_inputs", "transition_inputs"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        object.__setattr__(self, "inputs", {str(k): tuple(v) for k, v in self.inputs.items()})
        object.__setattr__(self, "structure", dict(self.structure))
        freeze_arrays(self, "initial", "emission", "transition")
        raise_problems(self)

    @property
    def n_levels(self) -> int:
        return len(self.levels)

    def n_combinations(self, inputs: Sequence[str]) -> int:
        return int(np.prod([len(self.inputs[c]) for c in inputs])) if inputs else 1

    @property
    def used_inputs(self) -> tuple[str, ...]:
        """The inputs of either table, emission inputs first."""
        return tuple(dict.fromkeys((*self.emission_inputs, *self.transition_inputs)))

    def problems(self) -> list[str]:
        p: list[str] = []
        for what, names in (("levels", self.levels), ("output categories", self.output_categories)):
            if not all(isinstance(n, str) and n for n in names) or len(set(names)) != len(names):
                p.append(f"{what} must be distinct non-empty names, got {list(names)}")
        if len(self.output_categories) < 2:
            p.append(f"the output {self.output!r} needs at least 2 categories")
        if not self.levels:
            p.append("a model needs at least one level")
        for name, cols in (("emission_inputs", self.emission_inputs), ("transition_inputs", self.transition_inputs)):
            if len(set(cols)) != len(cols):
                p.append(f"{name} repeat an input: {list(cols)}")
            for c in cols:
                if c not in self.inputs:
                    p.append(f"{name}: {c!r} is not one of the inputs {list(self.inputs)}")
        for c, lv in self.inputs.items():
            if not lv or not all(isinstance(x, str) and x for x in lv) or len(set(lv)) != len(lv):
                p.append(f"input {c!r}: levels must be distinct non-empty names, got {list(lv)}")
        if p:
            return p
        K, M = self.n_levels, len(self.output_categories)
        shapes = {
            "initial": (K,),
            "emission": (self.n_combinations(self.emission_inputs), K, M),
            "transition": (self.n_combinations(self.transition_inputs), K, K),
        }
        for name, shape in shapes.items():
            if getattr(self, name).shape != shape:
                p.append(f"{name} has shape {getattr(self, name).shape}, expected {shape}")
        if p:
            return p
        check_row_array(self.initial[None, :], lambda i: "initial", p)
        check_row_array(self.emission, lambda i: self.row_name("emission", i[0], i[1]), p)
        check_row_array(self.transition, lambda i: self.row_name("transition", i[0], i[1]), p)
        if self.rating is not None:
            p += self.rating.problems(self.levels)
        return p

    def combination(self, table: str, u: int) -> dict[str, str]:
        """The input levels of combination ``u`` of ``table`` (``emission`` or ``transition``)."""
        inputs = self.emission_inputs if table == "emission" else self.transition_inputs
        if not inputs:
            return {}
        idx = np.unravel_index(u, [len(self.inputs[c]) for c in inputs])
        return {c: self.inputs[c][int(i)] for c, i in zip(inputs, idx, strict=True)}

    def row_name(self, table: str, u: int, k: int | None = None) -> str:
        """``emission[advice=agree, difficulty=hard][level=low]``."""
        where = ", ".join(f"{c}={v}" for c, v in self.combination(table, u).items())
        s = f"{table}[{where}]" if where else table
        return s if k is None else f"{s}[level={self.levels[k]}]"

    # -- JSON --------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        L = list(self.levels)
        em_axes = [self.inputs[c] for c in self.emission_inputs]
        tr_axes = [self.inputs[c] for c in self.transition_inputs]
        shape_e = (*[len(a) for a in em_axes], self.n_levels, len(self.output_categories))
        shape_t = (*[len(a) for a in tr_axes], self.n_levels, self.n_levels)
        d: dict[str, Any] = {
            "format": IOHMM_FORMAT,
            "notes": self.notes,
            "levels": L,
            "output": {"name": self.output, "categories": list(self.output_categories)},
            "inputs": {c: list(v) for c, v in self.inputs.items()},
            "emission_inputs": list(self.emission_inputs),
            "transition_inputs": list(self.transition_inputs),
            "structure": json.loads(json.dumps(self.structure)),
            "initial": nested(self.initial, [L]),
            "emission": nested(self.emission.reshape(shape_e), [*em_axes, L, self.output_categories]),
            "transition": nested(self.transition.reshape(shape_t), [*tr_axes, L, L]),
        }
        if self.rating is not None:
            d["rating"] = {"column": self.rating_column or "rating", **self.rating.to_dict(L)}
        return d

    @classmethod
    def from_dict(cls, d: Any, source: str | None = None) -> IOHMMModel:
        problems: list[str] = []
        if not isinstance(d, Mapping):
            raise ModelError([f"a model must be a JSON object, got {type(d).__name__}"], source)
        if d.get("format") != IOHMM_FORMAT:
            problems.append(f"format is {d.get('format')!r}, expected {IOHMM_FORMAT!r}")
        unknown_keys(d, KEYS, "model", problems)
        levels = check_names(get_key(d, "levels", "levels", problems), "levels", problems, minimum=1)
        out = get_key(d, "output", "output", problems)
        out_name, out_cats = None, []
        if isinstance(out, Mapping):
            unknown_keys(out, ["name", "categories"], "output", problems)
            out_name = out.get("name")
            if not isinstance(out_name, str) or not out_name:
                problems.append(f"output.name must name the output column, got {out_name!r}")
            out_cats = check_names(get_key(out, "categories", "output.categories", problems), "output.categories", problems)
        elif out is not None:
            problems.append(f"output must be an object with 'name' and 'categories', got {out!r}")
        raw_inputs = d.get("inputs", {})
        inputs: dict[str, list[str]] = {}
        if not isinstance(raw_inputs, Mapping):
            problems.append(f"inputs must map each input's name to its levels, got {raw_inputs!r}")
        else:
            for c, lv in raw_inputs.items():
                inputs[str(c)] = check_names(lv, f"inputs.{c}", problems, minimum=1)
        em_in = _input_list(d.get("emission_inputs", []), "emission_inputs", inputs, problems)
        tr_in = _input_list(d.get("transition_inputs", []), "transition_inputs", inputs, problems)
        structure = d.get("structure", {})
        if not isinstance(structure, Mapping):
            problems.append(f"structure must be an object, got {structure!r}")
            structure = {}
        unknown_keys(structure, STRUCTURE_KEYS, "structure", problems)
        notes = d.get("notes", "")
        if not isinstance(notes, str):
            problems.append(f"notes must be a string, got {notes!r}")
        if problems or not levels or not out_cats:
            raise ModelError(problems, source)
        K, M = len(levels), len(out_cats)
        Ue = int(np.prod([len(inputs[c]) for c in em_in])) if em_in else 1
        Ut = int(np.prod([len(inputs[c]) for c in tr_in])) if tr_in else 1
        initial = np.full(K, np.nan)
        emission = np.full((*[len(inputs[c]) for c in em_in], K, M), np.nan)
        transition = np.full((*[len(inputs[c]) for c in tr_in], K, K), np.nan)
        init = get_key(d, "initial", "initial", problems)
        if init is not None:
            row = read_row(init, levels, "initial", problems)
            if row is not None:
                initial[:] = row
        for name, axes, arr, keys in (
            ("emission", em_in, emission, out_cats),
            ("transition", tr_in, transition, levels),
        ):
            node = get_key(d, name, name, problems)
            if node is not None:
                read_table(node, name, [(c, inputs[c]) for c in axes], ("level", levels), keys, arr, problems)
        rating, rating_column = None, None
        if d.get("rating") is not None:
            r = d["rating"]
            if isinstance(r, Mapping):
                rating_column = r.get("column", "rating")
                if not isinstance(rating_column, str) or not rating_column:
                    problems.append(f"rating.column must name the rating column, got {rating_column!r}")
                r = {k: v for k, v in r.items() if k != "column"}
            rating = RatingTable.read(r, levels, problems)
        if problems:
            raise ModelError(problems, source)
        try:
            return cls(
                tuple(levels),
                str(out_name),
                tuple(out_cats),
                {c: tuple(v) for c, v in inputs.items()},
                tuple(em_in),
                tuple(tr_in),
                initial,
                emission.reshape(Ue, K, M),
                transition.reshape(Ut, K, K),
                structure,
                rating,
                rating_column,
                notes,
            )
        except ModelError as exc:
            raise ModelError(exc.problems, source) from None

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, IOHMMModel):
            return NotImplemented
        return (
            self.levels == other.levels
            and self.output == other.output
            and self.output_categories == other.output_categories
            and dict(self.inputs) == dict(other.inputs)
            and self.emission_inputs == other.emission_inputs
            and self.transition_inputs == other.transition_inputs
            and np.array_equal(self.initial, other.initial)
            and np.array_equal(self.emission, other.emission)
            and np.array_equal(self.transition, other.transition)
            and dict(self.structure) == dict(other.structure)
            and self.rating == other.rating
            and self.rating_column == other.rating_column
        )


def _input_list(raw: Any, what: str, inputs: Mapping[str, Any], problems: list[str]) -> list[str]:
    if not isinstance(raw, list) or not all(isinstance(c, str) for c in raw):
        problems.append(f"{what} must list input names, got {raw!r}")
        return []
    bad = [c for c in raw if c not in inputs]
    for c in bad:
        problems.append(f"{what}: {c!r} is not one of the inputs {list(inputs)}")
    return [c for c in raw if c not in bad]


def is_iohmm_file(d: Any) -> bool:
    """True for the parsed JSON of a general model file."""
    return isinstance(d, Mapping) and d.get("format") == IOHMM_FORMAT


def load_any_model(path: str | Path) -> TrustModel | IOHMMModel:
    """A trust model file (``trustseek.trust-model/1``, or no format) or a general model file
    (``trustseek.iohmm/1``), by its ``format``."""
    d, source = load_json(path)
    if is_iohmm_file(d):
        return IOHMMModel.from_dict(d, source)
    return TrustModel.from_dict(d, source)
