"""A log's layouts made into one row per trial, on the log as read and before the canonical
columns are checked (so every later check and message applies unchanged): per-trial lists of a
record per participant or block (the mapping's ``explode``), a row per participant or block
with a column per trial of each field (``wide``: ``choice_1``, ``choice_2``, ...), and a second
file joined by participant and block (``join``: CSV, JSON or Parquet, read as a log is, its
columns mapped, rated or used as inputs like any other); and those entries of a mapping checked.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from .cells import SHOWN, Column, DataError, Problems, RawLog, names_list, shorten, unknown_entries, value_ids
from .order import by_participant


def explode_hint(columns: list[str]) -> str:
    """The hint of a log with lists in ``columns``: the mapping entry that reads them."""
    listed = json.dumps([shorten(c, 80) for c in columns[:20]])
    return f'hint: per-trial lists of a record per participant or block are read by the mapping\'s "explode": {listed}'


# --------------------------------------------------------------------------- the mapping's entries


def explode_entry(entry: Any) -> Any:
    """An ``explode`` entry as ``{"columns": [...], "position": name or None}`` (a column name or a
    list of them is the columns alone); anything else is kept for :func:`explode_problems`."""
    entry = [entry] if isinstance(entry, str) else entry
    if isinstance(entry, list):
        return {"columns": entry, "position": None}
    if isinstance(entry, Mapping) and isinstance(entry.get("columns"), str):
        entry = {**entry, "columns": [entry["columns"]]}
    return {"position": None, **entry} if isinstance(entry, Mapping) else entry


def wide_entry(entry: Any) -> Any:
    """A ``wide`` entry as ``{"columns": [...], "separator": "_", "position": name or None}``
    (a list of names is the columns alone); anything else is kept for :func:`wide_problems`."""
    entry = {"columns": entry} if isinstance(entry, list) else entry
    return {"separator": "_", "position": None, **entry} if isinstance(entry, Mapping) else entry


def join_entry(entry: Any) -> Any:
    """A ``join`` entry with ``on`` as a list (a single column name is a list of one)."""
    if isinstance(entry, Mapping) and isinstance(entry.get("on"), str):
        return {**entry, "on": [entry["on"]]}
    return dict(entry) if isinstance(entry, Mapping) else entry


def _position(head: str, e: Mapping, what: str) -> list[str]:
    pos = e.get("position")
    return [f"{head}: 'position' names a new column {what}, got {pos!r}"] if pos is not None and not names_list([pos]) else []


def explode_problems(e: Any) -> list[str]:
    """Everything wrong with a mapping's ``explode`` entry."""
    expected = 'expected the columns holding per-trial lists (["choice", "difficulty"]) or {"columns": [...], "position": name}'
    if not isinstance(e, Mapping):
        return [f"explode: {expected}, got {e!r}"]
    p = unknown_entries("explode", e, ("columns", "position"))
    cols = e.get("columns")
    if not names_list(cols):
        p.append(f"explode: {expected}, got {cols!r}")
    elif len(set(cols)) != len(cols):
        p.append(f"explode: a column is listed twice in {cols!r}")
    return p + _position("explode", e, "numbering the items 1, 2, ...")


def wide_problems(w: Any) -> list[str]:
    """Everything wrong with a mapping's ``wide`` entry."""
    expected = 'expected the trial fields of a wide log (["choice", "difficulty"] for choice_1, choice_2, ...)'
    if not isinstance(w, Mapping):
        return [f"wide: {expected}, got {w!r}"]
    p = unknown_entries("wide", w, ("columns", "separator", "position"))
    cols = w.get("columns")
    if not names_list(cols) or len(set(cols)) < len(cols):
        p.append(f"wide: {expected}, got {cols!r}")
    if not isinstance(w.get("separator"), str):
        p.append(f"wide: 'separator' is the text between a field and its trial number (default '_'), got {w.get('separator')!r}")
    return p + _position("wide", w, "holding each trial's number")


def join_problems(j: Any) -> list[str]:
    """Everything wrong with a mapping's ``join`` entry."""
    if not isinstance(j, Mapping):
        return [f'join: expected {{"file": "ratings.csv", "on": ["participant"]}}, got {j!r}']
    p = unknown_entries("join", j, ("file", "on", "sheet"))
    if not isinstance(j.get("file"), str) or not j.get("file"):
        p.append(f"join: 'file' names the second file (CSV, JSON, Parquet or an Excel workbook), got {j.get('file')!r}")
    if "sheet" in j and (not isinstance(j["sheet"], str) or not j["sheet"]):
        p.append(f"join: 'sheet' names the second file's sheet, got {j['sheet']!r}")
    on = j.get("on")
    on = [on] if isinstance(on, str) else [*on.keys(), *on.values()] if isinstance(on, Mapping) else on
    if on is not None and not names_list(on):
        p.append(
            "join: 'on' lists the columns both files share (participant, and block), or maps the log's to the second "
            f'file\'s ({{"subject": "pid"}}), got {j.get("on")!r}'
        )
    return p


# --------------------------------------------------------------------------- explode, wide and join


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
    items 1, 2, ... within their row; a list of objects (a trial each) gives their fields as columns.
    Lists of different lengths within a row, a cell that is not a list, lists of lists and objects
    holding lists or objects are errors naming the ``unit`` (record, row) and column."""
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
        elif pa.types.is_struct(typ.value_type):  # a list of trial objects: their fields become columns
            fields = [f.name for f in typ.value_type]
            clash = [f for f in fields if f in table.column_names and f != c]
            lines += [f"explode: column {c!r}: its objects' field {f!r} is a column of the {unit} too" for f in clash]
            if any(pa.types.is_nested(f.type) for f in typ.value_type):
                lines.append(f"explode: column {c!r}: objects holding lists or objects (expected texts or numbers)")
        elif pa.types.is_nested(typ.value_type):
            lines.append(f"explode: column {c!r} holds lists of lists (expected a list of texts, numbers or objects)")
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
    unequal = np.flatnonzero(np.logical_or.reduce([lengths[c] != first for c in cols], axis=0))
    items = [f"{unit} {r + 1} ({', '.join(f'{c} {int(lengths[c][r])}' for c in cols)})" for r in unequal[:SHOWN]]
    p.add("explode: lists of different lengths within a record", items, len(unequal), unit=f"{unit}s")
    if p.lines:
        raise DataError(p.lines, name)
    parent = pc.list_parent_indices(table[cols[0]].chunk(0) if table.num_rows else pa.array([], pa.list_(pa.int8())))
    out = {c: pc.list_flatten(table[c]) if c in cols else table[c].take(parent) for c in table.column_names}
    for c in cols:
        if pa.types.is_struct(out[c].type):
            items = out.pop(c)
            out.update({f.name: pc.struct_field(items, [i]) for i, f in enumerate(items.type)})
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

    names = dict.fromkeys(k for r in records for k in r)  # in the order they first appear
    columns = {k: [r.get(k) for r in records] for k in names}
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


def _stack(raw: RawLog, names: list[str | None], rows: np.ndarray, k: np.ndarray) -> Column:
    """One column from per-trial columns ``names`` (None: absent): row i of the result is
    ``names[k[i]]`` at record ``rows[i]``, the texts merged."""
    merged: dict[str | None, int] = {None: 0}
    codes = np.zeros(len(rows), dtype=np.int32)
    for j, name in enumerate(names):
        if name is not None:
            col = raw.col(name)
            remap = np.array([merged.setdefault(t, len(merged)) for t in col.texts], dtype=np.int32)
            at = k == j
            codes[at] = remap[col.codes[rows[at]]]
    return Column(codes, list(merged))


def unpivot(raw: RawLog, spec: dict[str, Any]) -> RawLog:
    """One row per record and trial number found among the ``spec["columns"]`` fields' columns
    (``<field><separator><n>``); the record's other columns are copied onto each, and a trial
    number whose fields are all empty in a record is no trial (a participant with fewer trials)."""
    sep, fields, position = spec["separator"], list(spec["columns"]), spec.get("position")
    found: dict[str, dict[int, str]] = {}
    for f in fields:
        pattern = re.compile(re.escape(f) + re.escape(sep) + r"(\d+)$")
        found[f] = {int(m.group(1)): c for c in raw.columns if (m := pattern.match(c))}
    present = shorten(str(raw.columns))
    lines = [f"wide: no columns named {f}{sep}1, {f}{sep}2, ...; columns present: {present}" for f in fields if not found[f]]
    taken = {c for per in found.values() for c in per.values()}
    clash = [c for c in [*fields, *([position] if position else [])] if c in raw.columns and c not in taken]
    lines += [f"wide: the log has a column {c!r} already; name the field or position otherwise" for c in clash]
    if lines:
        raise DataError(lines, raw.name)
    numbers = sorted({n for per in found.values() for n in per})
    names = {f: [found[f].get(n) for n in numbers] for f in fields}
    rows = np.repeat(np.arange(raw.n), len(numbers))
    k = np.tile(np.arange(len(numbers)), raw.n)
    stacked = {f: _stack(raw, names[f], rows, k) for f in fields}
    trial = np.zeros(len(rows), dtype=bool)
    for cc in stacked.values():
        trial |= np.array([t is not None for t in cc.texts], dtype=bool)[cc.codes]
    keep = np.flatnonzero(trial)
    rows, k = rows[keep], k[keep]
    stacked = {f: c.take(keep) for f, c in stacked.items()}
    if position:
        stacked[position] = Column(k.astype(np.int32), [str(n) for n in numbers])
    others = [c for c in raw.columns if c not in taken]

    def col(c: str) -> Column:
        return stacked[c] if c in stacked else raw.col(c).take(rows)

    def extras(cs: list[str]) -> pd.DataFrame:
        mine = [c for c in cs if c not in stacked]
        frame = raw.extras(mine).iloc[rows].reset_index(drop=True) if mine else pd.DataFrame(index=pd.RangeIndex(len(rows)))
        for c in cs:
            if c in stacked:
                frame[c] = np.array(stacked[c].texts, dtype=object)[stacked[c].codes]
        return frame[cs]

    of = raw.place
    place = None if of is None else (lambda i: of(int(rows[i])))  # a folder's file and the trial's record
    return RawLog(raw.name, len(rows), [*others, *stacked], col, extras, place=place)


def _keys(raw: Any, on: list[str], tables: list[dict[str, int]]) -> np.ndarray:
    """Per row of ``raw`` the ids of its values in the ``on`` columns, (rows, len(on))."""
    return np.stack([value_ids(raw.col(c), t) for c, t in zip(on, tables, strict=True)], axis=1)


def join_file(raw: RawLog, second: RawLog, spec: dict[str, Any], participant: str) -> tuple[RawLog, list[str]]:
    """``raw`` with the columns of the second file ``second`` (``spec["file"]``) joined on ``spec["on"]``
    (default: the participant column, and ``block`` when both files have it; a dict maps the
    log's key columns to the second file's).  Duplicate keys in
    the second file and its keys that match no row of the log are errors, by count and
    participant; rows of the log without a match get empty cells (counted in the notes returned)."""
    sname = second.name
    given = spec.get("on") or [participant, *(["block"] if "block" in raw.columns and "block" in second.columns else [])]
    pairs = dict(given) if isinstance(given, dict) else {c: c for c in given}  # the log's column -> the second file's
    on, other = list(pairs), list(pairs.values())
    lines = [f"join: no column {c!r} in the log; its columns: {raw.columns}" for c in on if c not in raw.columns]
    lines += [f"join: no column {c!r} in {sname}; its columns: {second.columns}" for c in other if c not in second.columns]
    clash = [c for c in second.columns if c not in other and c in raw.columns]
    lines += [f"join: column {c!r} of {sname} is in the log too; rename one of them" for c in clash]
    if lines:
        raise DataError(lines, raw.name)
    tables: list[dict[str, int]] = [{} for _ in on]
    theirs = _keys(second, other, tables)
    ours = _keys(raw, on, tables)
    texts = [{v: k for k, v in t.items()} for t in tables]
    pi = on.index(participant) if participant in on else 0

    def who(key: np.ndarray) -> str:
        return " / ".join(repr(texts[i].get(int(k), "")) for i, k in enumerate(key))

    p = Problems()
    empty = np.flatnonzero((theirs < 0).any(axis=1))
    p.rows(f"join: empty {' / '.join(other)} in {sname}", empty)
    uniq, inverse, counts = np.unique(theirs, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    dup = np.flatnonzero(counts > 1)
    p.add(
        f"join: {sname} has more than one row for a {' / '.join(other)}",
        [f"{who(uniq[d])} ({counts[d]} rows)" for d in dup],
        len(dup),
        unit="keys",
    )
    # each log row's row of the second file (-1: none), by one integer per key
    radix = np.cumprod([1, *(len(t) + 1 for t in tables[:-1])]).astype(np.int64)
    k2, k1 = (theirs + 1) @ radix, (ours + 1) @ radix
    by = np.argsort(k2, kind="stable")
    at = np.minimum(np.searchsorted(k2[by], k1), max(len(k2) - 1, 0))
    found = (k2[by][at] == k1) & (ours >= 0).all(axis=1) if len(k2) else np.zeros(raw.n, dtype=bool)
    match = np.where(found, by[at] if len(k2) else 0, -1)
    hit = np.zeros(len(uniq), dtype=bool)  # per distinct key of the second file: some log row has it
    hit[inverse[match[match >= 0]]] = True
    unmatched = np.flatnonzero(~hit[inverse] & (theirs >= 0).all(axis=1))
    if len(unmatched):
        per = _by_participant(theirs[unmatched, pi], texts[pi])
        p.lines.append(f"join: rows that match no trial of {raw.name} by {' / '.join(on)}: {len(unmatched)} ({per})")
    if p.lines:
        raise DataError(p.lines, sname)
    notes = []
    lost = np.flatnonzero(match < 0)
    if len(lost):
        per = _by_participant(ours[lost, pi], texts[pi])
        notes.append(f"{len(lost)} trials have no row in {sname} (their joined cells are empty): {per}")
    added = [c for c in second.columns if c not in other]

    def col(c: str) -> Column:
        if c not in added:
            return raw.col(c)
        sc = second.col(c)
        return Column(np.where(match >= 0, sc.codes[np.maximum(match, 0)], len(sc.texts)).astype(np.int32), [*sc.texts, None])

    def extras(cs: list[str]) -> pd.DataFrame:
        mine = [c for c in cs if c not in added]
        frame = raw.extras(mine) if mine else pd.DataFrame(index=pd.RangeIndex(raw.n))
        more = [c for c in cs if c in added]
        if more:
            other = second.extras(more).reindex(match).reset_index(drop=True)
            for c in more:
                frame[c] = other[c].to_numpy()
        return frame[cs]

    release = raw.release and (lambda cs: raw.release([c for c in cs if c not in added]))
    return RawLog(raw.name, raw.n, [*raw.columns, *added], col, extras, release, raw.place), notes


def _by_participant(codes: np.ndarray, texts: dict[int, str]) -> str:
    n, shown = by_participant(codes, lambda w: texts.get(w, ""), 20)
    return f"by participant, {n}: {shown}"
