"""The two JSON formats of a :class:`~trustseek.model.core.TrustModel`: a trust model
(``trustseek.trust-model/1``: trust levels, complexities, never-estimated rows) and a general
model (``trustseek.iohmm/1``: levels, output, named inputs, the fitted structure, a rating
column).  Both write and read their tables alike: nested objects, the inputs' levels in
order, then the level, then the output category (or the next level)."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..vocab import ACTIONS, EXPERIENCES, HUMAN_ACTIONS
from .jsonfile import ModelError, check_names, get_key, nested, read_entry, read_notes, read_table, unknown_keys
from .rating import RatingTable

MODEL_FORMAT = "trustseek.trust-model/1"
IOHMM_FORMAT = "trustseek.iohmm/1"  # a general model with named inputs
PLANNING_INPUTS = ("complexity", "robot_action", "experience")  # the inputs of a trust model, which planning needs
EMISSION_INPUTS = ("complexity", "robot_action")  # a trust model's emissions depend on these
SYMBOLS = {"complexity": "C", "robot_action": "a", "experience": "E"}  # how a trust model's row names show its inputs


def trust_fields(trust_levels: Sequence[str], complexities: Sequence[str]) -> dict[str, Any]:
    """A trust model's configuration (the paper's): its levels, the human action as output, the
    inputs complexity (``complexities``), robot action and experience, emissions on the first two,
    transitions on all three, no fitted structure."""
    return {
        "levels": tuple(trust_levels),
        "output": "human_action",
        "output_categories": HUMAN_ACTIONS,
        "inputs": {"complexity": tuple(complexities), "robot_action": ACTIONS, "experience": EXPERIENCES},
        "emission_inputs": EMISSION_INPUTS,
        "transition_inputs": PLANNING_INPUTS,
        "structure": None,
    }


def planning_refusal(inputs: Sequence[str]) -> str:
    """The one line said where a trust model is needed and a general model (with ``inputs``) is given."""
    named = ", ".join(inputs) if inputs else "none"
    return (
        f"a general IOHMM model ({IOHMM_FORMAT}, inputs: {named}) is not a trust model: planning "
        f"(solve, simulate, policies) needs a trust model ({MODEL_FORMAT}) whose inputs are among "
        f"{', '.join(PLANNING_INPUTS)} (fit with --transitions-on/--emissions-on naming only those)"
    )


STRUCTURE_KEYS = ("fixed_emissions", "fixed_transitions", "tied_emissions", "tied_transitions", "order_by", "prior")
TRUST_KEYS = ("format", "notes", "trust_levels", "complexities", "initial", "emission", "transition", "not_estimated", "rating")
GENERAL_KEYS = ("format", "notes", "levels", "output", "inputs", "emission_inputs", "transition_inputs", "structure",
                "initial", "emission", "transition", "rating")  # fmt: skip


def _tables(m: Any) -> dict[str, Any]:
    L = list(m.levels)
    em_axes = [m.inputs[c] for c in m.emission_inputs]
    tr_axes = [m.inputs[c] for c in m.transition_inputs]
    return {
        "initial": nested(m.initial, [L]),
        "emission": nested(m.emission, [*em_axes, L, m.output_categories]),
        "transition": nested(m.transition, [*tr_axes, L, L]),
    }


def model_to_dict(m: Any) -> dict[str, Any]:
    """The model's JSON form, in its format (a trust model's, or a general model's)."""
    if not m.general:
        T, C = m.trust_levels, m.complexities
        return {
            "format": MODEL_FORMAT,
            "notes": m.notes,
            "trust_levels": list(T),
            "complexities": list(C),
            **_tables(m),
            **({"not_estimated": [_row_dict(t, idx, C) for t, idx in m.not_estimated]} if m.not_estimated else {}),
            **({"rating": m.rating.to_dict(T)} if m.rating is not None else {}),
        }
    d: dict[str, Any] = {
        "format": IOHMM_FORMAT,
        "notes": m.notes,
        "levels": list(m.levels),
        "output": {"name": m.output, "categories": list(m.output_categories)},
        "inputs": {c: list(v) for c, v in m.inputs.items()},
        "emission_inputs": list(m.emission_inputs),
        "transition_inputs": list(m.transition_inputs),
        "structure": json.loads(json.dumps(m.structure)),
        **_tables(m),
    }
    if m.rating is not None:
        d["rating"] = {"column": m.rating_column or "rating", **m.rating.to_dict(m.levels)}
    return d


def is_iohmm_file(d: Any) -> bool:
    """True for the parsed JSON of a general model file."""
    return isinstance(d, Mapping) and d.get("format") == IOHMM_FORMAT


def model_fields(d: Any, source: str | None = None, general: bool = False) -> dict[str, Any]:
    """The fields of a model (a :class:`~trustseek.model.core.TrustModel`'s) from its JSON form,
    every problem reported at once; a general model file only with ``general`` (else the planning
    refusal).  The header is read first: its problems are reported before the tables are read."""
    if general and is_iohmm_file(d):
        read = _general_fields
    elif not isinstance(d, Mapping):
        raise ModelError([f"a trust model must be a JSON object, got {type(d).__name__}"], source)
    elif d.get("format", MODEL_FORMAT) == IOHMM_FORMAT:
        named = [d.get("emission_inputs"), d.get("transition_inputs")]
        inputs = [c for names in named if isinstance(names, list) for c in names if isinstance(c, str)]
        raise ModelError([planning_refusal(list(dict.fromkeys(inputs)))], source)
    else:
        read = _trust_fields
    problems: list[str] = []
    fields = read(d, problems)
    if problems or fields is None:
        raise ModelError(problems, source)
    return fields


def _read_tables(d: Mapping[str, Any], kw: dict[str, Any], symbols: Mapping[str, str], problems: list[str]) -> dict[str, Any]:
    """The tables ``initial``, ``emission`` and ``transition`` of a model file whose levels,
    output categories and inputs are ``kw``'s (a cell not read is NaN)."""
    L, inputs = kw["levels"], kw["inputs"]
    initial = read_entry(d, "initial", "initial", L, problems)
    tables: dict[str, Any] = {"initial": np.full(len(L), np.nan) if initial is None else initial}
    for name, axes, keys in (
        ("emission", kw["emission_inputs"], kw["output_categories"]),
        ("transition", kw["transition_inputs"], L),
    ):
        arr = np.full((*[len(inputs[c]) for c in axes], len(L), len(keys)), np.nan)
        node = get_key(d, name, name, problems)
        if node is not None:
            outer = [(symbols.get(c, c), inputs[c]) for c in axes]
            read_table(node, name, outer, (symbols.get("level", "level"), L), keys, arr, problems)
        tables[name] = arr
    return tables


def _trust_fields(d: Mapping[str, Any], problems: list[str]) -> dict[str, Any] | None:
    """A trust model file's fields: the header, the tables, then the notes, the never-estimated
    rows and the rating."""
    fmt = d.get("format", MODEL_FORMAT)
    if fmt != MODEL_FORMAT:
        problems.append(f"format is {fmt!r}, expected {MODEL_FORMAT!r}")
    unknown_keys(d, TRUST_KEYS, "model", problems)
    T = check_names(get_key(d, "trust_levels", "trust_levels", problems), "trust_levels", problems)
    C = check_names(get_key(d, "complexities", "complexities", problems), "complexities", problems)
    if problems or not T or not C:
        return None
    kw = trust_fields(T, C)
    tables = _read_tables(d, kw, {**SYMBOLS, "level": "T"}, problems)
    notes = read_notes(d, problems)
    not_estimated = _read_not_estimated(d.get("not_estimated", []), C, problems)
    rating = RatingTable.read(d["rating"], T, problems) if d.get("rating") is not None else None
    return {**kw, **tables, "notes": notes, "not_estimated": not_estimated, "rating": rating}


def _general_fields(d: Mapping[str, Any], problems: list[str]) -> dict[str, Any] | None:
    """A general model file's fields: the header (levels, output, inputs, structure, notes), the
    tables, then the rating and its column."""
    unknown_keys(d, GENERAL_KEYS, "model", problems)
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
    notes = read_notes(d, problems)
    if problems or not levels or not out_cats:
        return None
    kw = {
        "levels": tuple(levels),
        "output": str(out_name),
        "output_categories": tuple(out_cats),
        "inputs": {c: tuple(v) for c, v in inputs.items()},
        "emission_inputs": tuple(em_in),
        "transition_inputs": tuple(tr_in),
        "structure": structure,
        "notes": notes,
    }
    kw.update(_read_tables(d, kw, {}, problems))
    if d.get("rating") is None:
        return kw
    r, column = d["rating"], None
    if isinstance(r, Mapping):
        column = r.get("column", "rating")
        if not isinstance(column, str) or not column:
            problems.append(f"rating.column must name the rating column, got {column!r}")
        r = {k: v for k, v in r.items() if k != "column"}
    return {**kw, "rating": RatingTable.read(r, levels, problems), "rating_column": column}


def _input_list(raw: Any, what: str, inputs: Mapping[str, Any], problems: list[str]) -> list[str]:
    if not isinstance(raw, list) or not all(isinstance(c, str) for c in raw):
        problems.append(f"{what} must list input names, got {raw!r}")
        return []
    problems += [f"{what}: {c!r} is not one of the inputs {list(inputs)}" for c in raw if c not in inputs]
    return [c for c in raw if c in inputs]


def _row_dict(table: str, idx: tuple[int, ...], C: Sequence[str]) -> dict[str, str]:
    d = {"table": table, "C": C[idx[0]], "a": ACTIONS[idx[1]]}
    if table == "transition":
        d["E"] = EXPERIENCES[idx[2]]
    return d


def _read_not_estimated(raw: Any, C: Sequence[str], problems: list[str]) -> tuple[tuple[str, tuple[int, ...]], ...]:
    """``not_estimated``: a list of rows ``{"table": "emission"|"transition", "C": .., "a": .., ["E": ..]}``."""
    if not isinstance(raw, list):
        problems.append(f"not_estimated must be a list of rows, got {raw!r}")
        return ()
    out = []
    for i, row in enumerate(raw):
        where = f"not_estimated[{i}]"
        if not isinstance(row, Mapping) or row.get("table") not in ("emission", "transition"):
            problems.append(f"{where}: expected {{'table': 'emission' or 'transition', 'C': ..., 'a': ...}}, got {row!r}")
            continue
        keys = [("C", list(C)), ("a", list(ACTIONS))] + ([("E", list(EXPERIENCES))] if row["table"] == "transition" else [])
        extra = set(row) - {"table", *(k for k, _ in keys)}
        if extra:
            problems.append(f"{where}: unknown keys {sorted(extra)}")
        idx = []
        for k, names in keys:
            if row.get(k) not in names:
                problems.append(f"{where}: {k} = {row.get(k)!r} is not one of {names}")
            else:
                idx.append(names.index(row[k]))
        if len(idx) == len(keys):
            out.append((str(row["table"]), tuple(idx)))
    return tuple(out)
