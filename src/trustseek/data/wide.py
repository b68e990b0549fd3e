"""A wide log, one row per participant (or block) with a column per trial for each trial field
(``choice_1``, ``choice_2``, ...), turned into one row per trial: the mapping's ``wide``.

Works on the log as read (:class:`~.sources.RawLog`, any format) before the canonical columns
are checked, so every later check and message applies unchanged.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from .cells import Column, DataError, shorten, unknown_entries
from .sources import RawLog


def wide_entry(entry: Any) -> Any:
    """A ``wide`` entry as ``{"columns": [...], "separator": "_", "position": name or None}``
    (a list of names is the columns alone); anything else is kept for :func:`wide_problems`."""
    if isinstance(entry, list):
        entry = {"columns": entry}
    if isinstance(entry, Mapping):
        return {"separator": "_", "position": None, **entry}
    return entry


def wide_problems(w: Any) -> list[str]:
    """Everything wrong with a mapping's ``wide`` entry."""
    expected = 'expected the trial fields of a wide log (["choice", "difficulty"] for choice_1, choice_2, ...)'
    if not isinstance(w, Mapping):
        return [f"wide: {expected}, got {w!r}"]
    p = unknown_entries("wide", w, ("columns", "separator", "position"))
    cols = w.get("columns")
    if not isinstance(cols, list) or not cols or not all(isinstance(c, str) and c for c in cols) or len(set(cols)) < len(cols):
        p.append(f"wide: {expected}, got {cols!r}")
    if not isinstance(w.get("separator"), str):
        p.append(f"wide: 'separator' is the text between a field and its trial number (default '_'), got {w.get('separator')!r}")
    pos = w.get("position")
    if pos is not None and (not isinstance(pos, str) or not pos):
        p.append(f"wide: 'position' names a new column holding each trial's number, got {pos!r}")
    return p


def _stack(raw: RawLog, names: list[str | None], rows: np.ndarray, k: np.ndarray) -> Column:
    """One column from per-trial columns ``names`` (None: absent): row i of the result is
    ``names[k[i]]`` at record ``rows[i]``, the texts merged."""
    texts: list[str | None] = [None]
    index: dict[str | None, int] = {None: 0}
    codes = np.zeros(len(rows), dtype=np.int32)
    for j, name in enumerate(names):
        if name is None:
            continue
        col = raw.col(name)
        for t in col.texts:
            if t not in index:
                index[t] = len(texts)
                texts.append(t)
        remap = np.array([index[t] for t in col.texts], dtype=np.int32)
        at = k == j
        codes[at] = remap[col.codes[rows[at]]]
    return Column(codes, texts)


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

    return RawLog(raw.name, len(rows), [*others, *stacked], col, extras)
