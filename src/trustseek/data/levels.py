"""The levels of a log's named inputs and of its self-reported rating, as codes per row
(a rating given once per block kept on one trial of the block).

Each distinct cell value is looked up once (in the mapping's label table, then the declared
levels); values outside the levels are reported with their rows (:class:`~.cells.Problems`).
"""

from __future__ import annotations

import math
import shlex
from collections.abc import Callable
from typing import Any

import numpy as np
import pandas as pd

from .cells import (
    EMPTY,
    NAN_MARK,
    SHOWN,
    UNKNOWN,
    Column,
    DataError,
    Problems,
    column_from_pandas,
    level_lookup,
    report_kinds,
    spellings,
    value_ids,
)
from .mapping import ColumnMapping, format_number, label_key


def _mapped(entry: Any) -> tuple[dict[str, str], str]:
    """An entry's label table (the log's texts -> levels) and how an error names it."""
    table = {label_key(k): label_key(v) for k, v in (entry.get("labels") or {}).items()}
    return table, f"{sorted(table)} (mapped) or " if table else ""


def _level_of(levels: tuple[str, ...]) -> Callable[[str], int | None]:
    """The index of a level by any of its spellings (None: not a level)."""
    by_spelling = {s: i for i, lv in enumerate(levels) for s in spellings(lv)}
    return lambda label: next((by_spelling[s] for s in spellings(label) if s in by_spelling), None)


def input_codes(problems: Problems, cc: Column, mapping: ColumnMapping, name: str) -> np.ndarray:
    """Per row the code of input ``name``'s level (``cc``: its column); an empty cell, a NaN or a
    value outside the declared levels is reported with its rows (every row of a model's input
    needs a level)."""
    levels = mapping.input_levels()[name]
    table, known = _mapped(mapping.inputs[name])
    lookup, kind = level_lookup(cc, table, _level_of(levels), np.int16 if len(levels) < 2**15 else np.int32)
    expected = f"expected one of {known}the levels {list(levels)}"
    head = f"column {mapping.input_column(name)!r} (input {name!r})"
    heads = (
        f"{head}: empty value ({expected})",
        f"{head}: value is NaN ({expected})",
        f"{head}: value outside the declared levels ({expected})",
    )
    report_kinds(problems, cc, kind, heads)
    return cc.per_row(lookup)


def category_codes(problems: Problems, cc: Column, mapping: ColumnMapping, c: str, head: str) -> np.ndarray:
    """Per row the code of a categorical column's canonical label, each distinct value looked up
    once (in the mapping's labels, then the canonical labels); empty cells, NaNs and unknown labels
    reported, with a hint for labels in another case."""
    allowed = mapping.categories(c)
    table = mapping.labels.get(c, {})
    empty = 0 if c == "human_action" else EMPTY  # an empty human action: not recorded
    lookup, kind = level_lookup(cc, table, lambda label: allowed.index(label) if label in allowed else None, np.int8, empty)
    hint = "; an empty cell, or a NaN with --missing nan, is not recorded" if c == "human_action" else ""
    known_labels = f"{sorted(table)} (mapped) or " if table else ""
    heads = (
        f"{head}: empty value (expected one of {list(allowed)})",
        f"{head}: value is NaN (expected one of {list(allowed)}{hint})",
        f"{head}: unknown category (expected one of {known_labels}{list(allowed)})",
    )
    k = report_kinds(problems, cc, kind, heads)
    unknown = sorted(t for j, t in enumerate(cc.texts) if kind[j] == UNKNOWN and t is not None)
    near = {t: a for t in unknown for a in allowed if t.strip().lower() == a.lower()}
    if k is None or not (k == UNKNOWN).any():
        return cc.per_row(lookup)
    labelled = any(kind[j] == 0 and t not in (None, NAN_MARK) and t.strip() for j, t in enumerate(cc.texts))
    if not near and not labelled and 2 <= len(unknown) <= len(allowed) and all(len(t) <= 40 for t in unknown):
        # no label at all, two or more short values, no more than labels (0/1, y/n): a coding; which is which is theirs to say
        flags = " ".join(f"--label {shlex.quote(f'{c}:{t.strip()}=LABEL')}" for t in unknown)
        problems.lines.append(
            f"hint: if {', '.join(repr(t) for t in unknown)} code the labels of {c}, say which label each is: {flags}, "
            f"LABEL one of {list(allowed)} (or a mapping file's labels)"
        )
    if near:
        flags = " ".join(f"--label {c}:{t.strip()}={a}" for t, a in list(near.items())[:SHOWN])
        one = len(near) == 1
        problems.lines.append(
            f"hint: {', '.join(repr(t) for t in list(near)[:SHOWN])} {'is a label' if one else 'are labels'} written "
            f"in another case or with spaces: map {'it' if one else 'them'} with {flags} (or a mapping file's labels)"
        )
    return cc.per_row(lookup)


def rating_codes(problems: Problems, rc: Column, mapping: ColumnMapping, name: str) -> np.ndarray:
    """Per row the code of the rating's level (-1 = no rating); values outside the declared
    levels or bins are reported with their rows."""
    r = mapping.rating or {}
    find: Callable[[str], int | None]
    table: dict[str, str] = {}
    if "bins" in r:
        edges = np.array([float(e) for e in r["bins"]])

        def in_bins(t: str) -> int | None:
            try:
                x = float(t)
            except ValueError:
                return None
            if not math.isfinite(x) or x < edges[0] or x > edges[-1]:
                return None
            return min(int(np.searchsorted(edges, x, side="right")) - 1, len(edges) - 2)

        find = in_bins
        lo, hi = format_number(edges[0]), format_number(edges[-1])
        expected = f"a number in [{lo}, {hi}] (the bins {[format_number(e) for e in edges]})"
    else:
        levels = mapping.rating_levels()
        table, known = _mapped(r)
        find = _level_of(levels)
        expected = f"one of {known}the declared levels {list(levels)}"
    lookup, kind = level_lookup(rc, table, find, np.int16)
    problems.rows(
        f"column {name!r}: rating outside the declared levels (expected {expected}; leave the cell empty for no rating)",
        np.flatnonzero(rc.mask(kind == UNKNOWN)),
        lambda row: repr(rc.texts[rc.codes[row]]),
    )
    return rc.per_row(lookup)


def one_rating_per_block(
    problems: Problems, rated: np.ndarray, pcode: np.ndarray, block: Column, order: np.ndarray, per: str, rating: str
) -> np.ndarray:
    """The ratings ``rated`` (a level code per row, -1 = none) of a rating given once per block
    (column ``per``) and copied onto its trials: kept on the block's last trial (in trial order
    ``order``) only.  Different ratings within one block of a participant are an error."""
    n = len(rated)
    bids = value_ids(block, {})
    problems.rows(f"column {per!r} (the block of the rating {rating!r}): empty block", np.flatnonzero(bids < 0))
    nb = int(bids.max()) + 2 if n else 1
    group = pcode.astype(np.int64) * nb + (bids + 1)
    _, g = np.unique(group, return_inverse=True)
    g = g.reshape(-1)
    ng = int(g.max()) + 1 if n else 0
    pos = np.empty(n, dtype=np.int64)
    pos[order] = np.arange(n)
    last = np.full(ng, -1, dtype=np.int64)
    np.maximum.at(last, g, pos)
    has = rated >= 0
    lo, hi = _group_range(g[has], ng, rated[has])
    conflict = np.flatnonzero(has & (lo[g] != hi[g]))
    problems.rows(
        f"column {rating!r}: different ratings within one block (column {per!r}) of a participant; a rating per block "
        "has one value per block",
        conflict,
    )
    out = np.full(n, -1, dtype=rated.dtype)
    out[order[last]] = hi.astype(rated.dtype)
    return out


def _group_range(group: np.ndarray, n_groups: int, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per group (``group``: one per value) the least and the greatest of ``values`` (a group
    without a value: the largest int64 and -1)."""
    lo = np.full(n_groups, np.iinfo(np.int64).max)
    hi = np.full(n_groups, -1, dtype=np.int64)
    np.minimum.at(lo, group, values)
    np.maximum.at(hi, group, values)
    return lo, hi


def _rated_rows(frame: pd.DataFrame, column: str, block: str, missing: frozenset[str]) -> tuple[Any, ...]:
    """What a rating per block of a read log needs: the rating's cells, per row its code (-1 none),
    the participant codes, the block column and the trial order."""
    for c in (column, block):
        if c not in frame.columns:
            raise DataError([f"no column {c!r} in the log; its columns: {[str(x) for x in frame.columns]}"])
    cells = column_from_pandas(frame[column], missing)
    known = np.array([t is not None and t != NAN_MARK for t in cells.texts], dtype=bool)
    rated = np.where(known[cells.codes], cells.codes, -1).astype(np.int64)
    pcode = np.asarray(frame["participant"].cat.codes, dtype=np.int64)
    order = np.lexsort((frame["trial"].to_numpy(), pcode))
    return cells, rated, pcode, column_from_pandas(frame[block], missing), order


def one_per_block(
    frame: pd.DataFrame, column: str, block: str, missing: frozenset[str] = frozenset(), source: str | None = None
) -> pd.Series:
    """A read log's ``column`` (a rating given once per ``block`` and copied onto its trials)
    with its value on the block's last trial only (``--rating-per``, like a mapping's rating
    ``"per"``); different values within one block of a participant are an error."""
    cells, rated, pcode, blocks, order = _rated_rows(frame, column, block, missing)
    problems = Problems()
    kept = one_rating_per_block(problems, rated, pcode, blocks, order, block, column)
    if problems.lines:
        raise DataError(problems.lines, source)
    texts = np.array([*cells.texts, None], dtype=object)
    return pd.Series(texts[np.where(kept >= 0, kept, len(cells.texts))], index=frame.index, name=column)


def copied_per_block(
    frame: pd.DataFrame, column: str, missing: frozenset[str] = frozenset(), shown: str | None = None
) -> str | None:
    """A note when ``column`` looks like a rating per block copied onto every trial of it: a
    column named like a block (``block``, ``session``, ``round``) within each of whose groups the
    rating is one value on two or more trials; None otherwise.  ``shown`` is the column's name
    in the note (the log's name of a mapped rating)."""
    if column not in frame.columns:
        return None
    for block in [str(c) for c in frame.columns if any(w in str(c).lower() for w in ("block", "session", "round"))]:
        if block == column:
            continue
        _, rated, pcode, blocks, _ = _rated_rows(frame, column, block, missing)
        group = pcode * (len(blocks.texts) + 1) + blocks.codes
        has = rated >= 0
        if not has.any():
            return None
        g, inverse, count = np.unique(group[has], return_inverse=True, return_counts=True)
        lo, hi = _group_range(inverse, len(g), rated[has])
        if (lo == hi).all() and (count > 1).any():
            return (
                f"{shown or column!r} holds one value per {block!r}, on {int(has.sum()):,} trials of {len(g):,} blocks: "
                f'a rating given once per block counts once with --rating-per {block} (the mapping\'s rating "per")'
            )
    return None
