"""Per-trial lists exploded from a record per participant (or per block) into one row per trial,
and the mapping's ``explode`` and ``join`` entries checked.

Exploding works on the log as read (a pyarrow table) before the canonical columns are checked,
so every later check and message applies unchanged; the join is :mod:`.joins`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import numpy as np

from .cells import SHOWN, DataError, Problems, shorten, unknown_entries


def explode_hint(columns: list[str]) -> str:
    """The hint of a log with lists in ``columns``: the mapping entry that reads them."""
    listed = json.dumps([shorten(c, 80) for c in columns[:20]])
    return f'hint: per-trial lists of a record per participant or block are read by the mapping\'s "explode": {listed}'


# --------------------------------------------------------------------------- the mapping's entries


def explode_entry(entry: Any) -> Any:
    """An ``explode`` entry as ``{"columns": [...], "position": name or None}`` (a column name or a
    list of them is the columns alone); anything else is kept for :func:`explode_problems`."""
    if isinstance(entry, str):
        entry = [entry]
    if isinstance(entry, list):
        return {"columns": entry, "position": None}
    if isinstance(entry, Mapping):
        out = dict(entry)
        if isinstance(out.get("columns"), str):
            out["columns"] = [out["columns"]]
        out.setdefault("position", None)
        return out
    return entry


def join_entry(entry: Any) -> Any:
    """A ``join`` entry with ``on`` as a list (a single column name is a list of one)."""
    if not isinstance(entry, Mapping):
        return entry
    out = dict(entry)
    if isinstance(out.get("on"), str):
        out["on"] = [out["on"]]
    return out


def explode_problems(e: Any) -> list[str]:
    """Everything wrong with a mapping's ``explode`` entry."""
    expected = 'expected the columns holding per-trial lists (["choice", "difficulty"]) or {"columns": [...], "position": name}'
    if not isinstance(e, Mapping):
        return [f"explode: {expected}, got {e!r}"]
    p = unknown_entries("explode", e, ("columns", "position"))
    cols = e.get("columns")
    if not isinstance(cols, list) or not cols or not all(isinstance(c, str) and c for c in cols):
        p.append(f"explode: {expected}, got {cols!r}")
    elif len(set(cols)) != len(cols):
        p.append(f"explode: a column is listed twice in {cols!r}")
    pos = e.get("position")
    if pos is not None and (not isinstance(pos, str) or not pos):
        p.append(f"explode: 'position' names a new column numbering the items 1, 2, ..., got {pos!r}")
    return p


def join_problems(j: Any) -> list[str]:
    """Everything wrong with a mapping's ``join`` entry."""
    if not isinstance(j, Mapping):
        return [f'join: expected {{"file": "ratings.csv", "on": ["participant"]}}, got {j!r}']
    p = unknown_entries("join", j, ("file", "on"))
    if not isinstance(j.get("file"), str) or not j.get("file"):
        p.append(f"join: 'file' names the second file (CSV, JSON or Parquet), got {j.get('file')!r}")
    on = j.get("on")
    if isinstance(on, str):
        on = [on]
    if isinstance(on, Mapping):
        on = [*on.keys(), *on.values()]
    if on is not None and (not isinstance(on, list) or not on or not all(isinstance(c, str) and c for c in on)):
        p.append(
            "join: 'on' lists the columns both files share (participant, and block), or maps the log's to the second "
            f'file\'s ({{"subject": "pid"}}), got {j.get("on")!r}'
        )
    return p


# --------------------------------------------------------------------------- explode


def nested_columns(table: Any) -> list[str]:
    """The columns of a pyarrow table that hold lists or objects."""
    import pyarrow as pa

    return [f.name for f in table.schema if pa.types.is_nested(f.type)]


def refuse_nested(table: Any, name: str) -> None:
    """Columns of lists or objects the mapping does not explode are an error naming them."""
    bad = nested_columns(table)
    if bad:
        p = Problems()
        p.add("lists or objects where a text or number was expected", [repr(shorten(c, 80)) for c in bad], unit="columns")
        import pyarrow as pa

        lists = [f.name for f in table.schema if f.name in bad and (pa.types.is_list(f.type) or pa.types.is_large_list(f.type))]
        raise DataError([*p.lines, *([explode_hint(lists)] if lists else [])], name)


def explode_table(table: Any, spec: dict[str, Any], name: str, unit: str = "record") -> Any:
    """One row per item of the ``spec["columns"]`` lists of each row of ``table`` (a pyarrow table);
    the row's other cells are copied onto each item, ``spec["position"]`` (if named) numbers the
    items 1, 2, ... within their row.  Lists of different lengths within a row, a cell that is not
    a list and lists of lists or objects are errors naming the ``unit`` (record, row) and column."""
    import pyarrow as pa
    import pyarrow.compute as pc

    cols: list[str] = list(spec["columns"])
    position = spec.get("position")
    absent = [c for c in cols if c not in table.column_names]
    if absent:
        raise DataError([f"explode: no column {c!r}; columns present: {table.column_names}" for c in absent], name)
    if position is not None and position in table.column_names:
        raise DataError([f"explode: the log has a column {position!r} already; name the position otherwise"], name)
    table = table.combine_chunks()
    lines = []
    for c in cols:
        typ = table.schema.field(c).type
        if not (pa.types.is_list(typ) or pa.types.is_large_list(typ)):
            lines.append(f"explode: column {c!r} holds {typ}, not lists (expected a list of per-trial values per {unit})")
        elif pa.types.is_nested(typ.value_type):
            lines.append(f"explode: column {c!r} holds lists of lists or objects (expected a list of texts or numbers)")
    others = [c for c in nested_columns(table) if c not in cols]
    lines += [f"column {shorten(c, 80)!r}: lists or objects, and not listed in the mapping's explode" for c in others]
    if lines:
        raise DataError(lines, name)
    lengths = {c: pc.list_value_length(table[c]).to_numpy(zero_copy_only=False) for c in cols}
    p = Problems()
    for c in cols:
        none = np.flatnonzero(np.isnan(lengths[c].astype(float)))
        p.add(f"explode: column {c!r} is empty (expected a list)", [f"{unit} {r + 1}" for r in none[:SHOWN]], len(none))
    if p.lines:
        raise DataError(p.lines, name)
    first = lengths[cols[0]]
    differs = np.zeros(len(first), dtype=bool)
    for c in cols[1:]:
        differs |= lengths[c] != first
    unequal = np.flatnonzero(differs)
    items = [f"{unit} {r + 1} ({', '.join(f'{c} {int(lengths[c][r])}' for c in cols)})" for r in unequal[:SHOWN]]
    p.add("explode: lists of different lengths within a record", items, len(unequal), unit=f"{unit}s")
    if p.lines:
        raise DataError(p.lines, name)
    parent = pc.list_parent_indices(table[cols[0]].chunk(0) if table.num_rows else pa.array([], pa.list_(pa.int8())))
    out = {}
    for c in table.column_names:
        if c in cols:
            out[c] = pc.list_flatten(table[c])
        else:
            out[c] = table[c].take(parent)
    if position is not None:
        idx = parent.to_numpy(zero_copy_only=False)
        offsets = np.cumsum(first.astype(np.int64)) - first
        out[position] = pa.array(np.arange(len(idx), dtype=np.int64) - offsets[idx] + 1)
    return pa.table(out)


def table_from_records(records: list[dict[str, Any]], lists: set[str]) -> Any:
    """A pyarrow table of JSON records; a column of mixed types (and the items of a ``lists``
    column of mixed types) as the reader's text."""
    import pyarrow as pa

    from .cells import as_text

    columns: dict[str, list[Any]] = {}
    for i, r in enumerate(records):
        for k in r:
            if k not in columns:
                columns[k] = [None] * i
        for k, vals in columns.items():
            vals.append(r.get(k))
    arrays = {}
    for k, vals in columns.items():
        try:
            arrays[k] = pa.array(vals)
        except (pa.ArrowInvalid, pa.ArrowTypeError):  # mixed types: every value as the reader's text
            if k in lists:
                arrays[k] = pa.array(
                    [[None if x is None else as_text(x) for x in v] if isinstance(v, list) else v for v in vals],
                    type=pa.list_(pa.string()),
                )
            else:
                arrays[k] = pa.array([None if v is None else as_text(v) for v in vals], type=pa.string())
    return pa.table(arrays) if arrays else pa.table({})
