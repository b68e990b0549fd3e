"""The cells of a log: texts, codes and located problems.

Every column of a log is read as integer codes into its few distinct texts (:class:`Column`),
so each distinct value is checked once; :class:`Problems` collects what is wrong, one line per
kind of problem with the file, the column, how many rows and the first few of them.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeGuard

import numpy as np
import pandas as pd

from ..errors import TrustseekError

SHOWN = 5  # locations shown per kind of problem
SHOWN_CHARS = 200  # characters shown of one location (a cell's value may be a megabyte)
NAN_WORDS = frozenset(("nan", "na", "n/a", "null", "none"))
NAN_MARK = "\x00nan"  # marker of a NaN cell among the texts of a column
GATHER_ROWS = 1 << 18  # rows looked up at a time by :meth:`Column.per_row`
ASCII_SPACE = "".join(chr(c) for c in range(128) if chr(c).isspace())  # what str.strip() takes off ASCII text
EMPTY, NAN, UNKNOWN = 1, 2, 3  # the kinds of a bad cell (0: a level, or an empty cell that may be empty)


class DataError(TrustseekError, ValueError):
    """A trial log is malformed.  ``problems`` holds one line per kind of problem (file, column, rows, values)."""


def shorten(text: str, limit: int = SHOWN_CHARS) -> str:
    """``text``, cut to ``limit`` characters with the length of what was left out."""
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... ({len(text) - limit:,} more characters)"


@dataclass
class Problems:
    """Problems grouped by kind: one line per kind with the count and the first locations.

    ``rowid`` maps the rows being checked to the file's data rows (rows left out by a
    drop rule are not checked, and locations still name the file's rows); ``place`` names the
    location of a row of the log (0-based) when it is not ``row N`` (a folder's files)."""

    rowid: np.ndarray | None = None
    place: Callable[[int], str] | None = None
    lines: list[str] = field(default_factory=list)

    def where(self, r: int) -> str:
        """The location of checked row ``r`` (0-based): ``row N``, the file's N-th data row."""
        i = int(self.rowid[r] if self.rowid is not None else r)
        return f"row {i + 1}" if self.place is None else self.place(i)

    def add(self, head: str, items: Sequence[str], count: int | None = None, unit: str = "rows") -> None:
        count = len(items) if count is None else count
        if count == 0:
            return
        items = [shorten(item) for item in items[:SHOWN]]
        if count == 1:
            self.lines.append(f"{head}: {items[0]}")
            return
        shown = "; ".join(items)
        more = f"; ... ({count - SHOWN} more)" if count > SHOWN else ""
        self.lines.append(f"{head} in {count} {unit}: {shown}{more}")

    def rows(self, head: str, rows: np.ndarray, describe: Any = None) -> None:
        """A kind of problem at checked rows ``rows`` (0-based), each described by ``describe(row)``."""
        items = [self.where(int(r)) + (f" {describe(int(r))}" if describe else "") for r in rows[:SHOWN]]
        self.add(head, items, len(rows))


def _clean(s: str | None, missing: frozenset[str]) -> str | None:
    """A cell's text: None for an empty cell or a missing-value marker, the NaN marker for a NaN word."""
    if s is None:
        return None
    s = s.strip()
    if s == "":
        return None
    low = s.lower()
    if low in missing:
        return None
    if low in NAN_WORDS:
        return NAN_MARK
    return s


def as_text(v: Any, missing: frozenset[str] = frozenset()) -> str | None:
    """A distinct cell value as text: None for an empty cell, the NaN marker for a NaN."""
    if v is None or v is pd.NA:
        return None
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, (float, np.floating)):
        f = float(v)
        if math.isnan(f):
            return None if missing & NAN_WORDS else NAN_MARK
        if f.is_integer() and abs(f) < 2**63:
            return str(int(f))
        return repr(f)
    if isinstance(v, (np.integer, int)):
        return str(int(v))
    if isinstance(v, bytes):
        v = v.decode("utf-8", "replace")
    if isinstance(v, (dict, list)):
        return json.dumps(v)
    return _clean(str(v), missing)


def spellings(text: str) -> tuple[str, ...]:
    """The ways a label may be written in a mapping: a number as read ('1.0') and as an
    integer ('1'); a boolean as true/false and as 1/0."""
    low = text.lower()
    if low in ("true", "false"):
        return tuple(dict.fromkeys((text, low, low.capitalize(), low.upper(), "1" if low == "true" else "0")))
    try:
        f = float(text)
    except ValueError:
        return (text,)
    if f.is_integer() and abs(f) < 2**63 and str(int(f)) != text:
        return (text, str(int(f)))
    return (text,)


def same_value_key(text: str) -> str:
    """The text two cells are compared by: numbers by value ('1.0' = '1'), booleans in any case."""
    low = text.lower()
    if low in ("true", "false"):
        return low
    try:
        f = float(text)
    except ValueError:
        return text
    if math.isfinite(f) and f.is_integer():
        return str(int(f))
    return repr(f)


@dataclass
class Column:
    """One column: per row a code into ``texts`` (the distinct values as text: None = an empty
    cell or a missing-value marker, the NaN marker = a NaN)."""

    codes: np.ndarray
    texts: list[str | None]
    last_unused: bool = False  # no row holds the last entry of ``texts`` (a column's empty-cell code, unused)

    def take(self, rows: np.ndarray) -> Column:
        return Column(self.codes[rows], self.texts, self.last_unused)

    def occurs(self, flags: Sequence[bool] | np.ndarray) -> bool:
        """Whether a row may hold a flagged value (one flag per entry of ``texts``): False only
        when none does, so the rows need not be looked at."""
        f = np.asarray(flags, dtype=bool)
        return bool(f[:-1].any() if self.last_unused else f.any())

    def mask(self, flags: Sequence[bool] | np.ndarray) -> np.ndarray:
        """Per row, ``flags`` of its distinct value (one flag per entry of ``texts``)."""
        if not self.occurs(flags):
            return np.zeros(len(self.codes), dtype=bool)
        return self.per_row(np.asarray(flags, dtype=bool))

    def per_row(self, values: np.ndarray) -> np.ndarray:
        """Per row the entry of ``values`` (one per entry of ``texts``) of its value: ``values[codes]``,
        taken a slice of rows at a time (the codes of a slice, not of the whole column, are widened
        to 64-bit indices: 2 MB at a time instead of 57 MB for 7.1 M rows)."""
        out = np.empty(len(self.codes), dtype=values.dtype)
        for i in range(0, len(self.codes), GATHER_ROWS):
            np.take(values, self.codes[i : i + GATHER_ROWS], out=out[i : i + GATHER_ROWS])
        return out


@dataclass
class RawLog:
    """A log as read: its rows, its column names and each column as codes on demand."""

    name: str
    n: int
    columns: list[str]
    col: Any  # name -> Column
    extras: Any  # list of names -> DataFrame of those columns
    release: Any = None  # list of names -> None: those columns are no longer needed (their memory goes)
    place: Callable[[int], str] | None = None  # row (0-based) -> its location, when not ``row N`` (a folder's files)
    from_files: bool = False  # the rows are a folder's files' (or files given together), a column naming each one's file


def column_from_pandas(values: pd.Series, missing: frozenset[str]) -> Column:
    numeric = pd.api.types.is_numeric_dtype(values.dtype) and not pd.api.types.is_bool_dtype(values.dtype)
    if isinstance(values.dtype, pd.CategoricalDtype):
        codes, uniques = values.cat.codes.to_numpy(), values.cat.categories
    else:
        codes, uniques = pd.factorize(values, use_na_sentinel=True)
    texts = [as_text(u, missing) for u in np.asarray(uniques, dtype=object)]
    null = NAN_MARK if numeric and not missing & NAN_WORDS else None
    codes = np.asarray(codes, dtype=np.int32)
    codes = np.where(codes < 0, np.int32(len(texts)), codes)
    return Column(codes, [*texts, null])


def _arrow_texts(dictionary: Any, missing: frozenset[str]) -> list[str | None]:
    """The texts of a column's distinct values, each computed once (array operations for text and integers)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    typ = dictionary.type
    if pa.types.is_string(typ) or pa.types.is_large_string(typ):
        values = dictionary.to_pylist()
        if len(values) > 64 and _clean_ascii(dictionary, missing):  # many values (ids): checked at once
            return values
        return [_clean(v, missing) for v in values]
    if pa.types.is_integer(typ):
        return list(pc.cast(dictionary, pa.string()).to_pylist())
    return [as_text(v, missing) for v in dictionary.to_pylist()]


def _clean_ascii(texts: Any, missing: frozenset[str]) -> bool:
    """Whether every text of an arrow string array is ASCII that :func:`_clean` keeps as it is
    (no space at either end, not empty, no missing-value marker or NaN word in any case)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    if texts.null_count or not pc.all(pc.string_is_ascii(texts)).as_py():
        return False
    marks = pa.array(sorted({"", *NAN_WORDS, *missing}), pa.string())
    trimmed = pc.equal(pc.utf8_trim(texts, characters=ASCII_SPACE), texts)
    return bool(pc.all(pc.and_(trimmed, pc.invert(pc.is_in(pc.ascii_lower(texts), marks)))).as_py())


def column_from_arrow(chunked: Any, missing: frozenset[str], null_is_nan: bool = False) -> Column:
    """A pyarrow column as codes; a null is an empty cell, or with ``null_is_nan`` in a numeric
    column a NaN (Parquet: pandas writes a float column's NaN as null)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    typ = chunked.type
    if pa.types.is_dictionary(typ):
        chunked = chunked.unify_dictionaries()
        value_type = typ.value_type
    else:
        value_type = typ
        chunked = pc.dictionary_encode(chunked)
    numeric = pa.types.is_integer(value_type) or pa.types.is_floating(value_type) or pa.types.is_decimal(value_type)
    null = NAN_MARK if null_is_nan and numeric and not missing & NAN_WORDS else None
    if chunked.num_chunks == 0:
        return Column(np.zeros(0, dtype=np.int32), [null])
    texts = _arrow_texts(chunked.chunk(0).dictionary, missing)
    parts = []
    for chunk in chunked.chunks:
        idx = chunk.indices.fill_null(len(texts)) if chunk.null_count else chunk.indices
        parts.append(idx.to_numpy(zero_copy_only=False).astype(np.int32, copy=False))
    codes = parts[0] if len(parts) == 1 else np.concatenate(parts)
    return Column(codes, [*texts, null], last_unused=chunked.null_count == 0)


def value_ids(col: Column, table: dict[str, int], nan: int = -1) -> np.ndarray:
    """Per row an id of its value, shared across columns and files through ``table`` (numbers by
    value); -1 empty, ``nan`` for a NaN."""
    ids = np.full(len(col.texts), -1, dtype=np.int64)
    for j, t in enumerate(col.texts):
        if t == NAN_MARK:
            ids[j] = nan
        elif t is not None:
            ids[j] = table.setdefault(same_value_key(t), len(table))
    return ids[col.codes]


def level_lookup(
    cc: Column, table: dict[str, str], find: Callable[[str], int | None], dtype: Any, empty: int = EMPTY
) -> tuple[np.ndarray, np.ndarray]:
    """Per distinct value of ``cc`` its level's code (-1: none) and its kind (0 ok, ``empty`` for an
    empty cell, ``NAN``, ``UNKNOWN``): a value is looked up once, in the label ``table`` (any
    spelling), then by ``find``."""
    lookup = np.full(len(cc.texts), -1, dtype=dtype)
    kind = np.zeros(len(cc.texts), dtype=np.int8)
    for j, t in enumerate(cc.texts):
        if t is None:
            kind[j] = empty
            continue
        if t == NAN_MARK:
            kind[j] = NAN
            continue
        label = next((table[s] for s in spellings(t) if s in table), t) if table else t
        hit = find(label)
        if hit is None:
            kind[j] = UNKNOWN
        else:
            lookup[j] = hit
    return lookup, kind


def report_kinds(problems: Problems, cc: Column, kind: np.ndarray, heads: tuple[str, str, str]) -> np.ndarray | None:
    """The rows of each kind of bad cell (``kind`` per distinct value: ``EMPTY``, ``NAN``,
    ``UNKNOWN``), under its head; an unknown value is shown.  Returns the kind per row (None:
    no row holds a bad cell)."""
    if not cc.occurs(kind != 0):
        return None
    k = cc.per_row(kind)
    problems.rows(heads[0], np.flatnonzero(k == EMPTY))
    problems.rows(heads[1], np.flatnonzero(k == NAN))
    problems.rows(heads[2], np.flatnonzero(k == UNKNOWN), lambda r: repr(cc.texts[cc.codes[r]]))
    return k


def names_list(x: Any) -> TypeGuard[list[str]]:
    """Whether ``x`` is a non-empty list of non-empty names."""
    return isinstance(x, list) and bool(x) and all(isinstance(c, str) and c for c in x)


def unknown_entries(head: str, entry: Mapping[str, Any], allowed: Sequence[str]) -> list[str]:
    """The problem of a mapping's entry with names it does not know (none: an empty list)."""
    extra = set(entry) - set(allowed)
    return [f"{head}: unknown entries {sorted(extra)} (expected {', '.join(allowed)})"] if extra else []
