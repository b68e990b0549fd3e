"""Trial logs: read, map, validate and write the canonical one-row-per-trial table.

Canonical columns, in order (see ``docs/data-format.md``)::

    participant  trial  complexity  robot_action  human_action  experience

``human_action`` may be empty (not recorded: unobserved).  Extra columns are kept.
A log from another study is read through a :class:`ColumnMapping`: its column
names (``columns``: canonical -> theirs) and category labels (``labels``:
canonical column -> {their label: canonical label}).

Reading is column-wise: every column becomes integer codes into its few distinct
values, each distinct value is checked once, and the problems are found with array
operations.  Problems are reported through :class:`DataError`, one line per kind
of problem with the file, the column, how many rows and the first few of them
(``row N`` is the N-th data row, the header not counted, in every format).
"""

from __future__ import annotations

import csv
import io
import itertools
import json
import math
import sys
import tomllib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..errors import TrustseekError
from ..vocab import ACTIONS, CATEGORICAL_COLUMNS, EXPERIENCES, HUMAN_ACTIONS, TRIAL_COLUMNS

CANONICAL = TRIAL_COLUMNS
CATEGORICAL = CATEGORICAL_COLUMNS
DEFAULT_COMPLEXITIES = ("low", "high")
SHOWN = 5  # locations shown per kind of problem
MAX_TRIAL = 2**31 - 1
NAN_WORDS = ("nan", "na", "n/a", "null", "none")
DELIMITERS = (",", ";", "\t", "|")
_NAN = "\x00nan"  # marker of a NaN cell among the texts of a column
NAN_SET = frozenset(NAN_WORDS)
ALL = slice(None)  # the order of rows that are in trial order already


class DataError(TrustseekError, ValueError):
    """A trial log is malformed.  ``problems`` holds one line per kind of problem (file, column, rows, values)."""


@dataclass
class ColumnMapping:
    """How another study's log maps onto the canonical columns and labels.

    ``columns``      canonical name -> the log's column name (or a derived column's name)
    ``labels``       canonical column -> {the log's label: canonical label}; a list value
                     maps a set of the log's labels to the canonical label named by its key
    ``complexities`` the complexity names, lowest first (default ``low``, ``high``)
    ``order``        columns that order the trials within a participant (block, then trial
                     within block; or a timestamp): the canonical trial becomes 1, 2, ...
    ``derived``      new columns: ``{"name": {"equal": [a, b]}}`` (``true`` where the two
                     columns hold the same value) or ``{"name": {"shift": col, "by": 1}}``
                     (the value ``by`` trials earlier of the same participant; ``"fill"``
                     is the value where there is no such trial, default empty)
    ``drop``         rows to leave out: ``[{"column": col, "values": [...]}, ...]``
    ``missing``      cell texts meaning "not recorded" (besides the empty cell), e.g. ``NA``
    ``delimiter``    a CSV's delimiter (default: sniffed from the header)
    ``rating``       a self-reported trust rating (optional): ``{"column": theirs, "levels": [...]}``
                     with the ordinal levels lowest first (numbers or labels; ``"labels"``
                     maps the log's texts to levels), or ``{"column": theirs, "bins": [edges]}``
                     for a numeric rating binned into ``[e0, e1), [e1, e2), ... [e_{n-1}, e_n]``
                     (``"levels"`` then names the bins); an empty cell is no rating.  It
                     becomes the ``rating`` column, an ordered categorical of the levels.
    ``inputs``       named discrete inputs of a model (optional): ``{"condition": {"column": theirs,
                     "levels": ["control", "aid"]}}`` with the levels in their order (``"labels"``
                     maps the log's texts to levels, as for ``labels``; ``"column"`` defaults to the
                     input's name and may be a derived column).  Each becomes a column named by
                     the input, a categorical of its levels in the declared order; an empty cell
                     or a value outside the levels is an error.
    """

    columns: dict[str, str] = field(default_factory=dict)
    labels: dict[str, dict[str, str]] = field(default_factory=dict)
    complexities: tuple[str, ...] | None = None
    order: tuple[str, ...] | None = None
    derived: dict[str, dict[str, Any]] = field(default_factory=dict)
    drop: list[dict[str, Any]] = field(default_factory=list)
    missing: tuple[str, ...] | None = None
    delimiter: str | None = None
    rating: dict[str, Any] | None = None
    inputs: dict[str, dict[str, Any]] = field(default_factory=dict)

    def problems(self) -> list[str]:
        p = []
        if self.rating is not None:
            p += _rating_problems(self.rating)
        for name, entry in self.inputs.items():
            p += _input_problems(name, entry)
        for canon, theirs in self.columns.items():
            if canon not in CANONICAL:
                p.append(f"column mapping: {canon!r} is not a canonical column {list(CANONICAL)}")
            if not isinstance(theirs, str) or not theirs:
                p.append(f"column mapping: {canon} must map to a column name, got {theirs!r}")
        for canon, table in self.labels.items():
            if canon not in CATEGORICAL:
                p.append(f"label mapping: {canon!r} is not a categorical column {list(CATEGORICAL)}")
                continue
            if not isinstance(table, Mapping):
                p.append(f"label mapping: {canon} must map labels to labels, got {table!r}")
                continue
            allowed = self.categories(canon)
            for theirs, ours in table.items():
                if ours not in allowed:
                    p.append(f"label mapping: {canon}:{theirs}={ours!r} is not one of {list(allowed)}")
        if self.order is not None:
            if not self.order or not all(isinstance(c, str) and c for c in self.order):
                p.append(f"order: expected a column name or a list of column names, got {list(self.order)!r}")
            if "trial" in self.columns:
                p.append("order: give either 'order' or a 'trial' column, not both")
        known: set[str] = set()
        for name, d in self.derived.items():
            if not isinstance(d, Mapping) or len(set(d) & {"equal", "shift"}) != 1:
                p.append(f"derived column {name!r}: expected {{'equal': [a, b]}} or {{'shift': column, 'by': 1}}, got {d!r}")
            elif "equal" in d:
                eq = d["equal"]
                if (
                    set(d) != {"equal"}
                    or not isinstance(eq, list)
                    or len(eq) != 2
                    or not all(isinstance(c, str) and c for c in eq)
                ):
                    p.append(f"derived column {name!r}: 'equal' takes a list of two column names, got {eq!r}")
            else:
                by = d.get("by", 1)
                if set(d) - {"shift", "by", "fill"} or not isinstance(d["shift"], str) or not d["shift"]:
                    p.append(f"derived column {name!r}: 'shift' takes a column name (and 'by', 'fill'), got {dict(d)!r}")
                elif not isinstance(by, int) or isinstance(by, bool) or by == 0:
                    p.append(f"derived column {name!r}: 'by' must be a non-zero integer (1 = the previous trial), got {by!r}")
            known.add(name)
        for i, rule in enumerate(self.drop, 1):
            ok = isinstance(rule, Mapping) and set(rule) == {"column", "values"}
            ok = ok and isinstance(rule["column"], str) and isinstance(rule["values"], list) and bool(rule["values"])
            if not ok:
                p.append(f"drop rule {i}: expected {{'column': name, 'values': [value, ...]}}, got {rule!r}")
        if self.missing is not None and not all(isinstance(m, str) for m in self.missing):
            p.append(f'missing: expected a list of texts (e.g. ["NA", "null"]), got {list(self.missing)!r}')
        if self.delimiter is not None and (not isinstance(self.delimiter, str) or len(self.delimiter) != 1):
            p.append(f"delimiter: expected one character, got {self.delimiter!r}")
        return p

    def categories(self, column: str) -> tuple[str, ...]:
        if column == "complexity":
            return tuple(self.complexities or DEFAULT_COMPLEXITIES)
        return {"robot_action": ACTIONS, "human_action": HUMAN_ACTIONS, "experience": EXPERIENCES}[column]

    def merged(self, other: ColumnMapping) -> ColumnMapping:
        """This mapping overridden by ``other`` (e.g. a file overridden by command-line flags)."""
        labels = {k: dict(v) for k, v in self.labels.items()}
        for k, v in other.labels.items():
            labels.setdefault(k, {}).update(v)
        return ColumnMapping(
            {**self.columns, **other.columns},
            labels,
            other.complexities or self.complexities,
            other.order or self.order,
            {**self.derived, **other.derived},
            [*self.drop, *other.drop],
            other.missing if other.missing is not None else self.missing,
            other.delimiter or self.delimiter,
            other.rating or self.rating,
            {**self.inputs, **other.inputs},
        )

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"columns": dict(self.columns), "labels": {k: dict(v) for k, v in self.labels.items()}}
        if self.complexities:
            d["complexities"] = list(self.complexities)
        if self.order:
            d["order"] = list(self.order)
        if self.derived:
            d["derived"] = {k: dict(v) for k, v in self.derived.items()}
        if self.drop:
            d["drop"] = [dict(r) for r in self.drop]
        if self.missing is not None:
            d["missing"] = list(self.missing)
        if self.delimiter:
            d["delimiter"] = self.delimiter
        if self.rating is not None:
            d["rating"] = dict(self.rating)
        if self.inputs:
            d["inputs"] = {k: dict(v) for k, v in self.inputs.items()}
        return d

    def input_levels(self) -> dict[str, tuple[str, ...]]:
        """Every declared input's levels, in their declared order."""
        return {name: tuple(_label_key(v) for v in entry["levels"]) for name, entry in self.inputs.items()}

    def input_column(self, name: str) -> str:
        """The log's (or a derived) column an input is read from."""
        return str(self.inputs[name].get("column", name))

    def rating_levels(self) -> tuple[str, ...]:
        """The declared rating levels, lowest first (the bins' names for a binned rating)."""
        if self.rating is None:
            return ()
        levels = self.rating.get("levels")
        if levels is not None:
            return tuple(_label_key(v) for v in levels)
        edges = [float(e) for e in self.rating["bins"]]
        return tuple(f"{_num(lo)}-{_num(hi)}" for lo, hi in itertools.pairwise(edges))

    @classmethod
    def from_dict(cls, d: Any, source: str | None = None) -> ColumnMapping:
        if not isinstance(d, Mapping):
            raise DataError(["a mapping must be an object with 'columns' and/or 'labels'"], source)
        unknown = set(d) - set(MAPPING_KEYS)
        problems = [f"unknown entry {k!r} (expected {', '.join(MAPPING_KEYS)})" for k in sorted(unknown)]
        cols = d.get("columns", {})
        labels = d.get("labels", {})
        cx = d.get("complexities")
        order = d.get("order")
        derived = d.get("derived", {})
        drop = d.get("drop", [])
        missing = d.get("missing")
        inputs = d.get("inputs", {})
        if not isinstance(inputs, Mapping):
            problems.append(f"'inputs' must map input names to {{'column': ..., 'levels': [...]}}, got {inputs!r}")
            inputs = {}
        if not isinstance(cols, Mapping):
            problems.append(f"'columns' must map canonical names to the log's names, got {cols!r}")
            cols = {}
        if not isinstance(labels, Mapping):
            problems.append(f"'labels' must map canonical columns to label tables, got {labels!r}")
            labels = {}
        if cx is not None and (not isinstance(cx, list) or not all(isinstance(c, str) and c for c in cx) or len(cx) < 2):
            problems.append(f"'complexities' must list at least 2 names, got {cx!r}")
            cx = None
        if isinstance(order, str):
            order = [order]
        if order is not None and not isinstance(order, list):
            problems.append(f"'order' must be a column name or a list of them, got {order!r}")
            order = None
        if not isinstance(derived, Mapping):
            problems.append(f"'derived' must map new column names to their definitions, got {derived!r}")
            derived = {}
        if not isinstance(drop, list):
            problems.append(f"'drop' must be a list of rules, got {drop!r}")
            drop = []
        if isinstance(missing, str):
            missing = [missing]
        if missing is not None and not isinstance(missing, list):
            problems.append(f"'missing' must list texts, got {missing!r}")
            missing = None
        m = cls(
            {str(k): v for k, v in cols.items()},
            {str(k): (_label_table(v) if isinstance(v, Mapping) else v) for k, v in labels.items()},
            tuple(cx) if cx else None,
            tuple(order) if order is not None else None,
            {str(k): v for k, v in derived.items()},
            list(drop),
            tuple(missing) if missing is not None else None,
            d.get("delimiter"),
            dict(d["rating"]) if isinstance(d.get("rating"), Mapping) else d.get("rating"),
            {str(k): (_input_entry(v) if isinstance(v, Mapping) else v) for k, v in inputs.items()},
        )
        problems += m.problems()
        if problems:
            raise DataError(problems, source)
        return m

    @classmethod
    def load(cls, path: str | Path) -> ColumnMapping:
        """A mapping file: JSON (``.json``) or TOML (``.toml``)."""
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
            raise DataError([f"cannot read mapping file: {reason}"], str(path)) from None
        try:
            d = tomllib.loads(text) if path.suffix.lower() == ".toml" else json.loads(text)
        except (json.JSONDecodeError, tomllib.TOMLDecodeError) as exc:
            raise DataError([f"invalid {'TOML' if path.suffix.lower() == '.toml' else 'JSON'}: {exc}"], str(path)) from None
        return cls.from_dict(d, str(path))

    @classmethod
    def from_flags(
        cls,
        columns: Iterable[str] = (),
        labels: Iterable[str] = (),
        file: str | Path | None = None,
        missing: Iterable[str] | None = None,
        delimiter: str | None = None,
        rating: Mapping[str, Any] | None = None,
    ) -> ColumnMapping:
        """Command-line flags: ``--column canonical=theirs``, ``--label column:theirs=canonical``,
        ``--missing TEXT`` and ``--delimiter CHAR``; ``rating`` as in a mapping file (``--rating``
        with ``--rating-levels`` or ``--rating-bins``)."""
        base = cls.load(file) if file else cls()
        problems = []
        cols: dict[str, str] = {}
        labs: dict[str, dict[str, str]] = {}
        for item in columns:
            canon, sep, theirs = item.partition("=")
            if not sep or not canon or not theirs:
                problems.append(f"--column {item!r}: expected canonical=theirs, e.g. human_action=rely")
                continue
            cols[canon.strip()] = theirs.strip()
        for item in labels:
            head, sep, ours = item.partition("=")
            canon, sep2, theirs = head.partition(":")
            if not sep or not sep2 or not canon or not ours:
                problems.append(f"--label {item!r}: expected column:theirs=canonical, e.g. human_action:1=rely")
                continue
            labs.setdefault(canon.strip(), {})[theirs.strip()] = ours.strip()
        if delimiter is not None:
            delimiter = {"\\t": "\t", "tab": "\t", "TAB": "\t"}.get(delimiter, delimiter)
        if problems:
            raise DataError(problems)
        flags = cls(
            cols,
            labs,
            missing=tuple(missing) if missing else None,
            delimiter=delimiter,
            rating=dict(rating) if rating is not None else None,
        )
        problems = flags.problems()
        if problems:
            raise DataError(problems)
        return base.merged(flags)


MAPPING_KEYS = ("columns", "labels", "complexities", "order", "derived", "drop", "missing", "delimiter", "rating", "inputs")
RATING = "rating"  # the canonical name of the rating column a mapping declares


def _num(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else repr(float(x))


def _rating_problems(r: Any) -> list[str]:
    """Everything wrong with a mapping's ``rating`` entry."""
    head = "rating"
    if not isinstance(r, Mapping):
        return [f'{head}: expected {{"column": name, "levels": [...]}} or {{"column": name, "bins": [edges]}}, got {r!r}']
    p = []
    extra = set(r) - {"column", "levels", "labels", "bins"}
    if extra:
        p.append(f"{head}: unknown entries {sorted(extra)} (expected column, levels, labels, bins)")
    col = r.get("column")
    if not isinstance(col, str) or not col:
        p.append(f"{head}: 'column' must name the log's rating column, got {col!r}")
    levels, bins, labels = r.get("levels"), r.get("bins"), r.get("labels")
    if levels is None and bins is None:
        p.append(f"{head}: declare the levels, lowest first ('levels': [1, 2, 3, 4, 5]) or numeric bins ('bins': [edges])")
    names: list[str] = []
    if levels is not None:
        ok = isinstance(levels, list) and all(isinstance(v, (str, int, float)) and not isinstance(v, bool) for v in levels)
        names = [_label_key(v) for v in levels] if ok else []
        if not ok or len(names) < 2 or len(set(names)) != len(names) or not all(n.strip() for n in names):
            p.append(f"{head}: 'levels' must list at least 2 distinct levels, lowest first, got {levels!r}")
    if bins is not None:
        ok = isinstance(bins, list) and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in bins)
        edges = [float(v) for v in bins] if ok else []
        if (
            not ok
            or len(edges) < 3
            or not all(math.isfinite(e) for e in edges)
            or any(b <= a for a, b in itertools.pairwise(edges))
        ):
            p.append(f"{head}: 'bins' must list at least 3 increasing finite edges (2 bins), got {bins!r}")
        elif levels is not None and names and len(names) != len(edges) - 1:
            p.append(f"{head}: {len(edges) - 1} bins need {len(edges) - 1} level names, got {len(names)}")
        if labels is not None:
            p.append(f"{head}: 'labels' apply to declared levels, not to bins")
    if labels is not None and bins is None:
        if not isinstance(labels, Mapping):
            p.append(f"{head}: 'labels' must map the log's texts to levels, got {labels!r}")
        elif names:
            for theirs, ours in labels.items():
                if _label_key(ours) not in names:
                    p.append(f"{head}: label {theirs}={ours!r} is not one of the levels {names}")
    return p


def _input_entry(entry: Mapping) -> dict[str, Any]:
    """An ``inputs`` entry with its label table read like ``labels`` (set entries turned around)."""
    out = dict(entry)
    if isinstance(out.get("labels"), Mapping):
        out["labels"] = _label_table(out["labels"])
    return out


def _input_problems(name: str, entry: Any) -> list[str]:
    """Everything wrong with one entry of a mapping's ``inputs``."""
    head = f"input {name!r}"
    if not isinstance(entry, Mapping):
        return [f'{head}: expected {{"column": name, "levels": [...]}}, got {entry!r}']
    p = []
    if name in CANONICAL or name == RATING or not name:
        p.append(f"{head}: the name is taken (canonical columns and 'rating'); name the input otherwise")
    extra = set(entry) - {"column", "levels", "labels"}
    if extra:
        p.append(f"{head}: unknown entries {sorted(extra)} (expected column, levels, labels)")
    col = entry.get("column", name)
    if not isinstance(col, str) or not col:
        p.append(f"{head}: 'column' must name the log's column, got {col!r}")
    levels = entry.get("levels")
    ok = isinstance(levels, list) and all(isinstance(v, (str, int, float, bool)) for v in levels)
    names = [_label_key(v) for v in levels] if ok and isinstance(levels, list) else []
    if not names or len(set(names)) != len(names) or not all(n.strip() for n in names):
        p.append(f"{head}: 'levels' must list its distinct levels in their order, got {levels!r}")
    labels = entry.get("labels")
    if labels is not None:
        if not isinstance(labels, Mapping):
            p.append(f"{head}: 'labels' must map the log's texts to levels, got {labels!r}")
        elif names:
            for theirs, ours in labels.items():
                if _label_key(ours) not in names:
                    p.append(f"{head}: label {theirs}={ours!r} is not one of the levels {names}")
    return p


def _label_table(table: Mapping) -> dict[str, Any]:
    """A label table with its set entries (canonical -> [their labels]) turned into their -> canonical."""
    out: dict[str, Any] = {}
    for k, v in table.items():
        if isinstance(v, list):
            for theirs in v:
                out[_label_key(theirs)] = str(k)
        else:
            out[_label_key(k)] = v
    return out


def _label_key(v: Any) -> str:
    """A label written in a mapping file as text (a TOML/JSON number or boolean as the reader's text)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    return str(v)


# --------------------------------------------------------------------------- problems, grouped by kind


class _Problems:
    """Problems grouped by kind: one line per kind with the count and the first locations.

    ``rowid`` maps the rows being checked to the file's data rows (rows left out by a
    drop rule are not checked, and locations still name the file's rows)."""

    def __init__(self, rowid: np.ndarray | None = None) -> None:
        self.lines: list[str] = []
        self.rowid = rowid

    def row(self, r: int) -> int:
        """The file's data row (1-based) of checked row ``r`` (0-based)."""
        return int(self.rowid[r] if self.rowid is not None else r) + 1

    def add(self, head: str, items: Sequence[str], count: int | None = None, unit: str = "rows") -> None:
        count = len(items) if count is None else count
        if count == 0:
            return
        if count == 1:
            self.lines.append(f"{head}: {items[0]}")
            return
        shown = "; ".join(items[:SHOWN])
        more = f"; ... ({count - SHOWN} more)" if count > SHOWN else ""
        self.lines.append(f"{head} in {count} {unit}: {shown}{more}")

    def rows(self, head: str, rows: np.ndarray, describe: Any = None) -> None:
        """A kind of problem at checked rows ``rows`` (0-based), each described by ``describe(row)``."""
        if len(rows) == 0:
            return
        first = rows[:SHOWN]
        items = [f"row {self.row(int(r))}" + (f" {describe(int(r))}" if describe else "") for r in first]
        self.add(head, items, len(rows))


# --------------------------------------------------------------------------- columns as codes into distinct values


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
        return _NAN
    return s


def _as_text(v: Any, missing: frozenset[str] = frozenset()) -> str | None:
    """A distinct cell value as text: None for an empty cell, the NaN marker for a NaN."""
    if v is None or v is pd.NA:
        return None
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, (float, np.floating)):
        f = float(v)
        if math.isnan(f):
            return None if missing & NAN_SET else _NAN
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


def _spellings(text: str) -> tuple[str, ...]:
    """The ways a label may be written in a mapping: a number as read ('1.0') and as an
    integer ('1'); a boolean as true/false and as 1/0."""
    if text.lower() in ("true", "false"):
        low = text.lower()
        return tuple(dict.fromkeys((text, low, low.capitalize(), low.upper(), "1" if low == "true" else "0")))
    try:
        f = float(text)
    except ValueError:
        return (text,)
    if f.is_integer() and abs(f) < 2**63 and str(int(f)) != text:
        return (text, str(int(f)))
    return (text,)


def _same_value_key(text: str) -> str:
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
class _Col:
    """One column: per row a code into ``texts`` (the distinct values as text: None = an empty
    cell or a missing-value marker, the NaN marker = a NaN)."""

    codes: np.ndarray
    texts: list[str | None]

    def take(self, rows: np.ndarray) -> _Col:
        return _Col(self.codes[rows], self.texts)

    def mask(self, flags: Sequence[bool] | np.ndarray) -> np.ndarray:
        """Per row, ``flags`` of its distinct value (one flag per entry of ``texts``)."""
        return np.asarray(flags, dtype=bool)[self.codes]


def _col_from_pandas(values: pd.Series, missing: frozenset[str]) -> _Col:
    numeric = pd.api.types.is_numeric_dtype(values.dtype) and not pd.api.types.is_bool_dtype(values.dtype)
    if isinstance(values.dtype, pd.CategoricalDtype):
        codes, uniques = values.cat.codes.to_numpy(), values.cat.categories
    else:
        codes, uniques = pd.factorize(values, use_na_sentinel=True)
    texts = [_as_text(u, missing) for u in np.asarray(uniques, dtype=object)]
    null = _NAN if numeric and not missing & NAN_SET else None
    codes = np.asarray(codes, dtype=np.int32)
    codes = np.where(codes < 0, np.int32(len(texts)), codes)
    return _Col(codes, [*texts, null])


def _arrow_texts(dictionary: Any, missing: frozenset[str]) -> list[str | None]:
    """The texts of a column's distinct values, each computed once (array operations for text and integers)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    typ = dictionary.type
    if pa.types.is_string(typ) or pa.types.is_large_string(typ):
        return [_clean(v, missing) for v in dictionary.to_pylist()]
    if pa.types.is_integer(typ):
        return list(pc.cast(dictionary, pa.string()).to_pylist())
    return [_as_text(v, missing) for v in dictionary.to_pylist()]


def _col_from_arrow(chunked: Any, missing: frozenset[str]) -> _Col:
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
    null = _NAN if numeric and not missing & NAN_SET else None
    if chunked.num_chunks == 0:
        return _Col(np.zeros(0, dtype=np.int32), [null])
    texts = _arrow_texts(chunked.chunk(0).dictionary, missing)
    parts = []
    for chunk in chunked.chunks:
        idx = chunk.indices.fill_null(len(texts)) if chunk.null_count else chunk.indices
        parts.append(idx.to_numpy(zero_copy_only=False).astype(np.int32, copy=False))
    codes = parts[0] if len(parts) == 1 else np.concatenate(parts)
    return _Col(codes, [*texts, null])


# --------------------------------------------------------------------------- sources


@dataclass
class _Raw:
    name: str
    n: int
    columns: list[str]
    col: Any  # name -> _Col
    extras: Any  # list of names -> DataFrame of those columns
    release: Any = None  # list of names -> None: those columns are no longer needed (their memory goes)


def _sniff(path: Path, sep: str | None) -> tuple[str, list[str]]:
    """The delimiter (given, by suffix, or the most frequent candidate in the header) and the header names."""
    with path.open("rb") as fh:
        head = fh.read(1 << 16)
    text = head.decode("utf-8", "replace").lstrip("\ufeff")
    first = text.splitlines()[0] if text.strip() else ""
    if sep is None:
        if path.suffix.lower() == ".tsv":
            sep = "\t"
        else:
            counts = {d: first.count(d) for d in DELIMITERS}
            best = max(counts, key=lambda d: counts[d])
            sep = best if counts[best] > 0 else ","
    names = next(csv.reader(io.StringIO(first), delimiter=sep), []) if first else []
    return sep, [n.strip() for n in names]


CSV_SUFFIXES = (".csv", ".txt", ".tsv")
PARQUET_SUFFIXES = (".parquet", ".pq")
JSONL_SUFFIXES = (".jsonl", ".ndjson")
JSON_SUFFIXES = (".json",)


def _load(source: Any, sep: str | None, missing: frozenset[str]) -> _Raw:
    if isinstance(source, pd.DataFrame):
        frame = source

        def col(c: str) -> _Col:
            return _col_from_pandas(frame[c], missing)

        return _Raw("<table>", len(frame), [str(c) for c in frame.columns], col, lambda cs: frame[cs].reset_index(drop=True))
    path = Path(source)
    name = str(path)
    if not path.exists():
        raise DataError(["file not found"], name)
    if path.is_dir():
        raise DataError(["is a directory, not a trial log"], name)
    suffix = path.suffix.lower()
    if suffix in PARQUET_SUFFIXES:
        return _load_parquet(path, name, missing)
    if suffix in CSV_SUFFIXES:
        return _load_csv(path, name, sep, missing)
    if suffix in JSONL_SUFFIXES + JSON_SUFFIXES:
        return _load_json(path, name, suffix in JSONL_SUFFIXES, missing)
    raise DataError([f"unknown file type {suffix!r}: use .csv, .tsv, .parquet, .jsonl or .json"], name)


def _arrow_raw(table: Any, name: str, missing: frozenset[str]) -> _Raw:
    names = [str(c) for c in table.column_names]
    dupes = sorted({c for c in names if names.count(c) > 1})
    if dupes:
        raise DataError([f"column {c!r} appears {names.count(c)} times" for c in dupes], name)
    return _arrow_source(table, name, names, missing)


def _arrow_source(table: Any, name: str, names: list[str], missing: frozenset[str]) -> _Raw:
    import pyarrow as pa

    held = {"table": table}

    def release(cs: list[str]) -> None:
        held["table"] = held["table"].drop_columns([c for c in cs if c in held["table"].column_names])
        pa.default_memory_pool().release_unused()

    return _Raw(
        name,
        table.num_rows,
        names,
        lambda c: _col_from_arrow(held["table"].column(c), missing),
        lambda cs: held["table"].select(cs).to_pandas(),
        release,
    )


def _load_parquet(path: Path, name: str, missing: frozenset[str]) -> _Raw:
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        schema = pq.read_schema(path)
        texts = [f.name for f in schema if pa.types.is_string(f.type) or pa.types.is_large_string(f.type)]
        # text columns come as codes into their distinct values (no string per row)
        table = pq.read_table(path, read_dictionary=texts)
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise DataError([f"cannot read the file as Parquet: {exc}"], name) from None
    return _arrow_raw(table, name, missing)


def _load_json(path: Path, name: str, lines: bool, missing: frozenset[str]) -> _Raw:
    """JSON lines (one object per line) or a JSON array of objects; row N is the N-th record."""
    import pyarrow as pa

    if lines:
        import pyarrow.json as pjson

        try:
            return _arrow_raw(pjson.read_json(path), name, missing)
        except (pa.ArrowException, OSError):
            pass  # mixed types in a column, or a bad line: read record by record to say where
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise DataError(["the file is not UTF-8 text"], name) from None
    except OSError as exc:
        raise DataError([f"cannot read the file: {exc.strerror or exc}"], name) from None
    p = _Problems()
    records: list[Any] = []
    where: list[str] = []
    if lines:
        bad: list[str] = []
        for i, line in enumerate(text.splitlines(), 1):
            if not line.strip():
                continue
            try:
                records.append(json.loads(line))
                where.append(f"line {i}")
            except json.JSONDecodeError as exc:
                bad.append(f"line {i}: {exc.msg}")
        p.add("lines that are not JSON", bad, unit="lines")
    else:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise DataError([f"invalid JSON: {exc}"], name) from None
        if not isinstance(data, list):
            raise DataError(["a JSON trial log must be an array of records (objects), one per trial"], name)
        records = data
        where = [f"record {i}" for i in range(1, len(data) + 1)]
    p.add("records that are not objects", [w for w, r in zip(where, records, strict=True) if not isinstance(r, dict)])
    if p.lines:
        raise DataError(p.lines, name)
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
            arrays[k] = pa.array([None if v is None else _as_text(v) for v in vals], type=pa.string())
    table = pa.table(arrays) if arrays else pa.table({})
    return _arrow_raw(table, name, missing)


def _load_csv(path: Path, name: str, sep: str | None, missing: frozenset[str]) -> _Raw:
    import pyarrow as pa
    import pyarrow.csv as pcsv

    sep, header = _sniff(path, sep)
    if not header:
        raise DataError(["the file is empty (expected a header line naming the columns)"], name)
    dupes = sorted({c for c in header if header.count(c) > 1})
    if dupes:
        raise DataError([f"column {c!r} appears {header.count(c)} times in the header" for c in dupes], name)
    bad_rows: list[tuple[int, int, str]] = []

    def invalid(row: Any) -> str:
        try:
            text = str(row.text)
        except UnicodeDecodeError:
            text = "(not UTF-8 text)"
        bad_rows.append((row.expected_columns, row.actual_columns, text))
        return "skip"

    # every column as codes into its distinct texts: no Python string per cell
    dictionary = pa.dictionary(pa.int32(), pa.string())
    types = dict.fromkeys(header, dictionary)
    # pyarrow decodes a malformed row's text for the handler; a row that is not UTF-8 fails there,
    # outside any caller, so such failures are collected here instead of being printed
    undecodable: list[Any] = []
    hook = sys.unraisablehook
    sys.unraisablehook = undecodable.append
    try:
        # one thread: a process that has read a CSV on pyarrow's thread pool can abort at exit
        # ("terminate called without an active exception") under load, instead of exiting with
        # its status; the single-threaded parse costs ~0.5 s on 7.1 M rows (benchmarks/bench_read.py)
        table = pcsv.read_csv(
            path,
            read_options=pcsv.ReadOptions(column_names=header, skip_rows=1, block_size=1 << 24, use_threads=False),
            parse_options=pcsv.ParseOptions(delimiter=sep, invalid_row_handler=invalid, newlines_in_values=False),
            convert_options=pcsv.ConvertOptions(
                column_types=types, null_values=[], strings_can_be_null=False, quoted_strings_can_be_null=False
            ),
        )
    except (pa.ArrowException, OSError) as exc:
        msg = str(exc)
        if "UTF8" in msg or "UTF-8" in msg:
            raise DataError(["the file is not UTF-8 text (save it as UTF-8 CSV)"], name) from None
        raise DataError([f"cannot read the file as CSV (delimiter {sep!r}): {msg}"], name) from None
    finally:
        sys.unraisablehook = hook
    if undecodable:
        raise DataError(["the file is not UTF-8 text (save it as UTF-8 CSV)"], name)
    if bad_rows:
        p = _Problems()
        p.add(
            f"rows whose number of fields differs from the header's {len(header)} (delimiter {sep!r})",
            [f"{got} fields: {text[:60]!r}" for _, got, text in bad_rows],
        )
        raise DataError(p.lines, name)
    return _arrow_source(table, name, header, missing)


# --------------------------------------------------------------------------- reading


def _missing_column_hint(missing: list[str], present: list[str], sep: str | None) -> list[str]:
    hints = ["name another column with --column canonical=theirs or a --mapping file (Python: ColumnMapping)"]
    if {"complexity", "robot_action"} & set(missing):
        hints.append(
            "a log without complexity/robot_action can be fitted by a model that does not use them: "
            "--transitions-on experience --emissions-on none"
        )
    if len(present) == 1 and any(d in present[0] for d in DELIMITERS if d != sep):
        hints.append(f"the header has a single column {present[0]!r}: is the file separated by another delimiter?")
    return [f"hint: {h}" for h in hints]


def _as_mapping(mapping: ColumnMapping | Mapping | str | Path | None) -> ColumnMapping:
    if mapping is None:
        return ColumnMapping()
    if isinstance(mapping, (str, Path)):
        return ColumnMapping.load(mapping)
    if not isinstance(mapping, ColumnMapping):
        return ColumnMapping.from_dict(mapping)
    p = mapping.problems()
    if p:
        raise DataError(p)
    return mapping


def read_trials(
    source: Any,
    mapping: ColumnMapping | Mapping | str | Path | None = None,
    *,
    required: Sequence[str] | None = None,
    delimiter: str | None = None,
    check_experience: bool = True,
) -> pd.DataFrame:
    """Read, map and validate a trial log (CSV/TSV, Parquet, JSON lines, a JSON array or a DataFrame).

    Returns the canonical columns in order (``participant`` and the categorical
    columns as pandas categoricals with the canonical labels, ``trial`` as int64,
    an unrecorded ``human_action`` as missing), followed by every extra column.
    Rows keep the file's order, less the rows a drop rule of the mapping leaves out
    (their counts are in ``frame.attrs["dropped"]``: one ``(rule, rows)`` pair per rule).
    ``required`` names the canonical columns that must be present (default: all
    six; participant, trial and human_action for a mapping that declares ``inputs``); an
    absent optional column comes back empty.  Each of the mapping's ``inputs`` becomes a
    column named by the input (a categorical of its declared levels; ``frame.attrs["inputs"]``
    holds every input's levels).  A CSV's delimiter is taken
    from ``delimiter`` (or the mapping's), else ``.tsv`` means tab, else the most
    frequent of ``, ; TAB |`` in the header.  ``check_experience`` checks the
    experience rule of the data format where the columns it needs are present.
    Raises :class:`DataError` listing every kind of problem at once.
    """
    mapping = _as_mapping(mapping)
    ordered = mapping.order is not None
    if required is None:  # a mapping that declares inputs is for a model of those: the canonical inputs are optional
        required = ("participant", "trial", "human_action") if mapping.inputs else CANONICAL
    required = tuple(required)
    for col in ("trial", "participant"):
        if col not in required:
            required = (col, *required)
    if ordered:
        required = tuple(c for c in required if c != "trial")
    theirs = {c: mapping.columns.get(c, c) for c in CANONICAL}
    markers = frozenset(m.strip().lower() for m in (mapping.missing or ()))
    raw = _load(source, delimiter or mapping.delimiter, markers)
    name = raw.name
    derived = mapping.derived

    # every column the mapping names must exist: in the log, or derived from earlier columns
    lines = []
    known = set(raw.columns)
    for new, d in derived.items():
        sources = list(d["equal"]) if "equal" in d else [d["shift"]]
        for s in sources:
            if s not in known:
                lines.append(f"derived column {new!r}: no column {s!r}; columns present: {raw.columns}")
        known.add(new)
    for rule in mapping.drop:
        if rule["column"] not in raw.columns:
            lines.append(f"drop rule: no column {rule['column']!r}; columns present: {raw.columns}")
    for c in mapping.order or ():
        if c not in raw.columns:
            lines.append(f"order: no column {c!r}; columns present: {raw.columns}")
    rating_col = mapping.rating["column"] if mapping.rating is not None else None
    if rating_col is not None and rating_col not in known:
        lines.append(f"missing column {rating_col!r} (the mapping's rating column); columns present: {raw.columns}")
    for inp in mapping.inputs:
        src = mapping.input_column(inp)
        if src not in known:
            lines.append(f"missing column {src!r} (the mapping's input {inp!r}); columns present: {raw.columns}")
        elif inp != src and inp in raw.columns:
            lines.append(f"input {inp!r}: the log has a column {inp!r} too; give the input another name")
    absent = [c for c in required if theirs[c] not in known]
    for c in absent:
        via = f" (mapped from canonical {c!r})" if theirs[c] != c else ""
        lines.append(f"missing column {theirs[c]!r}{via}; columns present: {raw.columns}")
    if lines:
        hints = _missing_column_hint(absent, raw.columns, delimiter or mapping.delimiter) if absent else []
        raise DataError(lines + hints, name)
    if raw.n == 0:
        raise DataError(["the log has no trials (only a header)"], name)

    # rows to drop, each rule counted on the rows the rules before it left
    rowid: np.ndarray | None = None
    keep = np.ones(raw.n, dtype=bool)
    dropped: list[tuple[str, int]] = []
    for rule in mapping.drop:
        cc = raw.col(rule["column"])
        wanted = {s for v in rule["values"] for s in _spellings(_label_key(v))}
        blank = "" in wanted or any(str(v).strip().lower() in markers for v in rule["values"])
        hit = cc.mask([t in wanted if t is not None else blank for t in cc.texts]) & keep
        count = int(hit.sum())
        keep &= ~hit
        dropped.append((f"{rule['column']} in {rule['values']}", count))
    if not keep.all():
        rowid = np.flatnonzero(keep)
    n = raw.n if rowid is None else len(rowid)
    if n == 0:
        raise DataError([f"every row is dropped by the drop rules ({'; '.join(f'{r}: {k}' for r, k in dropped)})"], name)
    del keep
    cols: dict[str, _Col] = {}

    def get(c: str) -> _Col:
        if c not in cols:
            col = raw.col(c)
            cols[c] = col if rowid is None else col.take(rowid)
        return cols[c]

    present = [c for c in CANONICAL if theirs[c] in known]
    canonical = [theirs[c] for c in present if theirs[c] in raw.columns]
    if raw.release is not None:  # the canonical columns as codes; the file's copy of them goes
        for c in canonical:
            get(c)
        raw.release(canonical)
    problems = _Problems(rowid)

    def column(c: str) -> str:
        return f"column {theirs[c]!r}"

    # participant: codes into the distinct ids, in order of first appearance
    pc_ = get(theirs["participant"])
    pcode, ids = _participant_codes(pc_)
    empty = pc_.mask([t is None for t in pc_.texts])
    problems.rows(f"{column('participant')}: empty participant id", np.flatnonzero(empty))
    problems.rows(f"{column('participant')}: value is NaN", np.flatnonzero((pcode < 0) & ~empty))
    del empty

    perm: np.ndarray | slice | None = None
    if ordered:
        trial, valid, perm = _order_trials(problems, get, list(mapping.order or ()), pcode, ids)
    else:
        trial, valid = _trial_numbers(problems, get(theirs["trial"]), column("trial"))
        valid &= pcode >= 0
        if valid.all():  # the usual case: no copies of the columns
            perm = _check_trials(problems, pcode, trial, None, ids, column("trial"))
        elif valid.any():
            ok = np.flatnonzero(valid)
            _check_trials(problems, pcode[ok], trial[ok], ok, ids, column("trial"))

    # derived columns, in the order they are defined
    for new, d in derived.items():
        if "equal" in d:
            a, b = (get(s) for s in d["equal"])
            cols[new] = _equal(a, b)
        elif perm is not None:
            fill = d.get("fill")
            cols[new] = _shift(get(d["shift"]), pcode, perm, int(d.get("by", 1)), None if fill is None else _label_key(fill))
        else:  # the trial order is broken (reported above): nothing to shift by
            cols[new] = _Col(np.zeros(n, np.int32), [None])

    # categories: each distinct value is looked up once (in the mapping's labels, then the canonical labels)
    codes: dict[str, np.ndarray] = {}
    for c in CATEGORICAL:
        if c not in present:
            codes[c] = np.full(n, -1, dtype=np.int8)
            continue
        cc = get(theirs[c])
        allowed = mapping.categories(c)
        table = mapping.labels.get(c, {})
        lookup = np.full(len(cc.texts), -1, dtype=np.int8)
        kind = np.zeros(len(cc.texts), dtype=np.int8)  # 0 ok or empty human action, 1 empty, 2 NaN, 3 unknown
        for j, t in enumerate(cc.texts):
            if t is None:
                kind[j] = 0 if c == "human_action" else 1
                continue
            if t == _NAN:
                kind[j] = 2
                continue
            label = next((table[s] for s in _spellings(t) if s in table), t)
            if label in allowed:
                lookup[j] = allowed.index(label)
            else:
                kind[j] = 3
        codes[c] = lookup[cc.codes]
        k = kind[cc.codes]
        hint = "; leave the cell empty for not recorded" if c == "human_action" else ""
        known_labels = f"{sorted(table)} (mapped) or " if table else ""
        problems.rows(f"{column(c)}: empty value (expected one of {list(allowed)})", np.flatnonzero(k == 1))
        problems.rows(f"{column(c)}: value is NaN (expected one of {list(allowed)}{hint})", np.flatnonzero(k == 2))
        problems.rows(
            f"{column(c)}: unknown category (expected one of {known_labels}{list(allowed)})",
            np.flatnonzero(k == 3),
            lambda r, cc=cc: repr(cc.texts[cc.codes[r]]),
        )
        del k
    nothing_recorded = "human_action" in present and not (codes["human_action"] >= 0).any()
    if "human_action" in required and nothing_recorded and not any(column("human_action") in x for x in problems.lines):
        problems.lines.append(
            f"{column('human_action')}: no trial has a recorded human action (every cell is empty): nothing to fit"
        )

    rating_codes = None
    if rating_col is not None:
        rc = cols[rating_col] if rating_col in cols else get(rating_col)
        rating_codes = _rating_codes(problems, rc, mapping, rating_col)
    input_codes = {
        inp: _input_codes(problems, cols[src] if src in cols else get(src), mapping, inp, src)
        for inp in mapping.inputs
        for src in (mapping.input_column(inp),)
    }
    if check_experience:
        _check_experience(problems, codes, mapping, present, column)
    if problems.lines:
        raise DataError(problems.lines, name)

    frame = pd.DataFrame(
        {
            "participant": pd.Categorical.from_codes(pcode, categories=pd.Index(ids, dtype=object)),
            "trial": trial,
        }
    )
    for c in CATEGORICAL:
        frame[c] = pd.Categorical.from_codes(codes[c], categories=pd.Index(list(mapping.categories(c)), dtype=object))
    del codes
    used = {theirs[c] for c in present}
    if not ordered:
        used.add(theirs["trial"])
    if rating_codes is not None and rating_col is not None:
        levels = pd.Index(list(mapping.rating_levels()), dtype=object)
        frame[RATING] = pd.Categorical.from_codes(rating_codes, categories=levels, ordered=True)
        frame.attrs["rating_levels"] = tuple(levels)
        frame.attrs["rating_column"] = rating_col
        used.add(rating_col)
    for inp, levels in mapping.input_levels().items():
        frame[inp] = pd.Categorical.from_codes(input_codes[inp], categories=pd.Index(list(levels), dtype=object))
        used.add(mapping.input_column(inp))
    if mapping.inputs:
        frame.attrs["inputs"] = mapping.input_levels()
    extras = [c for c in raw.columns if c not in used and c not in frame.columns]
    if extras:
        more = raw.extras(extras)
        for c in extras:
            values = more[c] if rowid is None else more[c].iloc[rowid]
            frame[c] = values.to_numpy() if isinstance(source, pd.DataFrame) else values.values
    frame.attrs["dropped"] = dropped
    return frame


def _input_codes(problems: _Problems, cc: _Col, mapping: ColumnMapping, name: str, src: str) -> np.ndarray:
    """Per row the code of an input's level; an empty cell, a NaN or a value outside the declared
    levels is reported with its rows (every row of a model's input needs a level)."""
    entry = mapping.inputs[name]
    levels = mapping.input_levels()[name]
    table = {_label_key(k): _label_key(v) for k, v in (entry.get("labels") or {}).items()}
    by_spelling = {s: i for i, lv in enumerate(levels) for s in _spellings(lv)}
    lookup = np.full(len(cc.texts), -1, dtype=np.int16 if len(levels) < 2**15 else np.int32)
    kind = np.zeros(len(cc.texts), dtype=np.int8)  # 0 ok, 1 empty, 2 NaN, 3 outside the levels
    for j, t in enumerate(cc.texts):
        if t is None:
            kind[j] = 1
            continue
        if t == _NAN:
            kind[j] = 2
            continue
        label = next((table[s] for s in _spellings(t) if s in table), t)
        hit = next((by_spelling[s] for s in _spellings(label) if s in by_spelling), None)
        if hit is None:
            kind[j] = 3
        else:
            lookup[j] = hit
    k = kind[cc.codes]
    known = f"{sorted(table)} (mapped) or " if table else ""
    expected = f"expected one of {known}the levels {list(levels)}"
    head = f"column {src!r} (input {name!r})"
    problems.rows(f"{head}: empty value ({expected})", np.flatnonzero(k == 1))
    problems.rows(f"{head}: value is NaN ({expected})", np.flatnonzero(k == 2))
    problems.rows(
        f"{head}: value outside the declared levels ({expected})",
        np.flatnonzero(k == 3),
        lambda r: repr(cc.texts[cc.codes[r]]),
    )
    return lookup[cc.codes]


def _rating_codes(problems: _Problems, rc: _Col, mapping: ColumnMapping, name: str) -> np.ndarray:
    """Per row the code of the rating's level (-1 = no rating); values outside the declared
    levels or bins are reported with their rows."""
    r = mapping.rating or {}
    levels = mapping.rating_levels()
    lookup = np.full(len(rc.texts) + 1, -1, dtype=np.int16)
    bad = np.zeros(len(rc.texts) + 1, dtype=bool)
    if "bins" in r:
        edges = np.array([float(e) for e in r["bins"]])
        for j, t in enumerate(rc.texts):
            if t is None or t == _NAN:
                continue
            try:
                x = float(t)
            except ValueError:
                x = math.nan
            if not math.isfinite(x) or x < edges[0] or x > edges[-1]:
                bad[j] = True
            else:
                lookup[j] = min(int(np.searchsorted(edges, x, side="right")) - 1, len(edges) - 2)
        expected = f"a number in [{_num(edges[0])}, {_num(edges[-1])}] (the bins {[_num(e) for e in edges]})"
    else:
        table = {_label_key(k): _label_key(v) for k, v in (r.get("labels") or {}).items()}
        by_spelling = {s: i for i, lv in enumerate(levels) for s in _spellings(lv)}
        for j, t in enumerate(rc.texts):
            if t is None or t == _NAN:
                continue
            label = next((table[s] for s in _spellings(t) if s in table), t)
            hit = next((by_spelling[s] for s in _spellings(label) if s in by_spelling), None)
            if hit is None:
                bad[j] = True
            else:
                lookup[j] = hit
        known = f"{sorted(table)} (mapped) or " if table else ""
        expected = f"one of {known}the declared levels {list(levels)}"
    codes = lookup[rc.codes]
    problems.rows(
        f"column {name!r}: rating outside the declared levels (expected {expected}; leave the cell empty for no rating)",
        np.flatnonzero(bad[rc.codes]),
        lambda row: repr(rc.texts[rc.codes[row]]),
    )
    return codes


def _participant_codes(pc_: _Col) -> tuple[np.ndarray, list[str]]:
    """Per row the participant's index (-1 = no id), the ids in order of first appearance."""
    valid = np.array([t is not None and t != _NAN for t in pc_.texts], dtype=bool)
    # the first row of every distinct value: rows where the code changes are enough
    c = pc_.codes
    first = np.full(len(pc_.texts), len(c), dtype=np.int64)
    change = np.flatnonzero(np.r_[True, c[1:] != c[:-1]]) if len(c) else np.zeros(0, dtype=np.int64)
    np.minimum.at(first, c[change], change)
    ids: dict[str, int] = {}
    lookup = np.full(len(pc_.texts), -1, dtype=np.int32)
    for j in np.argsort(first, kind="stable"):
        t = pc_.texts[j]
        if valid[j] and first[j] < len(c):
            lookup[j] = ids.setdefault(str(t), len(ids))
    used = int(c.max()) + 1 if len(c) else 0
    if c.dtype == np.int32 and np.array_equal(lookup[:used], np.arange(used)):
        return c, list(ids)  # the codes are the ids' indices already (a file's distinct values in order)
    return lookup[c], list(ids)


def _trial_numbers(problems: _Problems, tc: _Col, column: str) -> tuple[np.ndarray, np.ndarray]:
    """Trial numbers (integers >= 0; the distinct values are parsed once) and where they are valid."""
    t_lookup = np.zeros(len(tc.texts), dtype=np.int64)
    t_kind = np.zeros(len(tc.texts), dtype=np.int8)  # 0 ok, 1 empty, 2 NaN, 3 not an integer >= 0
    for j, t in enumerate(tc.texts):
        if t is None:
            t_kind[j] = 1
        elif t == _NAN:
            t_kind[j] = 2
        else:
            try:
                f = float(t)
            except ValueError:
                f = math.nan
            if f.is_integer() and 0 <= f <= MAX_TRIAL:
                t_lookup[j] = int(f)
            else:
                t_kind[j] = 3
    tkind = t_kind[tc.codes]
    expect = "expected an integer: trials numbered in increasing order, e.g. 1, 2, ... or 0, 1, ..."
    problems.rows(f"{column}: empty trial index ({expect})", np.flatnonzero(tkind == 1))
    problems.rows(f"{column}: value is NaN ({expect})", np.flatnonzero(tkind == 2))
    problems.rows(
        f"{column}: value is not an integer between 0 and {MAX_TRIAL}",
        np.flatnonzero(tkind == 3),
        lambda r: repr(tc.texts[tc.codes[r]]),
    )
    return t_lookup[tc.codes], tkind == 0


def _order_values(problems: _Problems, cc: _Col, name: str) -> tuple[np.ndarray, np.ndarray]:
    """An order column's sort key per row (numbers, else timestamps) and where it is valid."""
    texts = [t for t in cc.texts if t is not None and t != _NAN]
    values = np.zeros(len(cc.texts), dtype=np.float64)
    ok = np.zeros(len(cc.texts), dtype=bool)
    try:
        nums = {t: float(t) for t in texts}
        what = "a number"
        for j, t in enumerate(cc.texts):
            if t in nums and math.isfinite(nums[t]):
                values[j], ok[j] = nums[t], True
        key: np.ndarray = values[cc.codes]
    except ValueError:
        what = "a number or a timestamp"
        stamps = pd.to_datetime(pd.Series(texts, dtype=object), errors="coerce", utc=True, format="mixed")
        ns = np.zeros(len(cc.texts), dtype=np.int64)
        parsed = dict(zip(texts, stamps, strict=True))
        for j, t in enumerate(cc.texts):
            s = parsed.get(t) if t is not None else None
            if s is not None and not pd.isna(s):
                ns[j], ok[j] = s.value, True
        key = ns[cc.codes]
    valid = ok[cc.codes]
    problems.rows(
        f"column {name!r}: not {what} (the column orders the trials)",
        np.flatnonzero(~valid),
        lambda r: repr(cc.texts[cc.codes[r]]),
    )
    return key, valid


def _order_trials(
    problems: _Problems, get: Any, order: list[str], pcode: np.ndarray, ids: list[str]
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Trials ordered by the ``order`` columns within each participant: numbered 1, 2, ...;
    rows with the same participant and order values are an error."""
    n = len(pcode)
    keys, valid = [], pcode >= 0
    for c in order:
        k, ok = _order_values(problems, get(c), c)
        keys.append(k)
        valid &= ok
    trial = np.zeros(n, dtype=np.int64)
    if not valid.all():
        return trial, valid, None
    perm = np.lexsort((*reversed(keys), pcode))
    ps = pcode[perm]
    same = ps[1:] == ps[:-1]
    for k in keys:
        ks = k[perm]
        same &= ks[1:] == ks[:-1]
    dup = np.flatnonzero(same) + 1
    if len(dup):
        items = [
            f"row {problems.row(int(perm[d]))}: same {' / '.join(order)} as row {problems.row(int(perm[d - 1]))} "
            f"for participant {ids[ps[d]]!r}"
            for d in dup[:SHOWN]
        ]
        problems.add(f"column {order[0]!r}: trials with the same order values", items, len(dup))
        return trial, valid, None
    lengths = np.bincount(pcode, minlength=len(ids))
    offsets = np.cumsum(lengths) - lengths
    trial[perm] = np.arange(n) - offsets[ps] + 1
    return trial, valid, perm


def _equal(a: _Col, b: _Col) -> _Col:
    """``true`` where two columns hold the same value (numbers by value); empty where either is
    empty, NaN where either is NaN (an error where the column needs a value)."""
    keys: dict[str, int] = {}

    def ids(col: _Col) -> np.ndarray:
        out = np.full(len(col.texts), -1, dtype=np.int64)  # -1 empty, -2 NaN
        for j, t in enumerate(col.texts):
            if t == _NAN:
                out[j] = -2
            elif t is not None:
                out[j] = keys.setdefault(_same_value_key(t), len(keys))
        return out

    va, vb = ids(a)[a.codes], ids(b)[b.codes]
    codes = (va == vb).astype(np.int32)
    codes[(va == -1) | (vb == -1)] = 2
    codes[(va == -2) | (vb == -2)] = 3
    return _Col(codes, ["false", "true", None, _NAN])


def _shift(col: _Col, pcode: np.ndarray, perm: np.ndarray | slice, by: int, fill: str | None = None) -> _Col:
    """The value ``by`` trials earlier (later for ``by`` < 0) of the same participant; ``fill``
    (default: empty) where there is none."""
    none = len(col.texts)
    ps = pcode[perm]
    cs = col.codes[perm]
    out = np.full(len(pcode), none, dtype=np.int32)
    k = abs(by)
    if k < len(pcode):
        if by > 0:
            out[k:] = np.where(ps[k:] == ps[:-k], cs[:-k], none)
        else:
            out[:-k] = np.where(ps[:-k] == ps[k:], cs[k:], none)
    codes = np.empty_like(out)
    codes[perm] = out
    return _Col(codes, [*col.texts, fill])


def _check_experience(
    problems: _Problems, codes: dict[str, np.ndarray], mapping: ColumnMapping, present: list[str], column: Any
) -> None:
    """The experience rule of the data format: an intervention ends ``faulty``; an ask ends ``faulty``
    in ``low`` and ``reliable`` in ``high`` complexity (other complexity names are not checked)."""
    if "experience" not in present or "robot_action" not in present:
        return
    e, a = codes["experience"], codes["robot_action"]
    faulty, reliable = EXPERIENCES.index("faulty"), EXPERIENCES.index("reliable")
    ask, autonomous = ACTIONS.index("ask"), ACTIONS.index("autonomous")
    if "human_action" in present:
        bad = (a == autonomous) & (codes["human_action"] == HUMAN_ACTIONS.index("intervene")) & (e == reliable)
        problems.rows(
            f"{column('experience')}: 'reliable' after an intervention (the experience rule: an intervention ends faulty)",
            np.flatnonzero(bad),
        )
    if "complexity" in present:
        cx = mapping.categories("complexity")
        for level, expected, wrong in (("low", "faulty", reliable), ("high", "reliable", faulty)):
            if level not in cx:
                continue
            bad = (a == ask) & (codes["complexity"] == cx.index(level)) & (e == wrong)
            problems.rows(
                f"{column('experience')}: {EXPERIENCES[wrong]!r} after an ask in {level} complexity "
                f"(the experience rule: an ask in {level} complexity ends {expected})",
                np.flatnonzero(bad),
            )


def _check_trials(
    problems: _Problems, p: np.ndarray, t: np.ndarray, rows: np.ndarray | None, ids: list[str], column: str
) -> np.ndarray | slice | None:
    """Duplicate trial indices, with array operations on the (participant, trial) keys of ``rows``
    (None: every row).  Returns the order of the rows by participant and trial: None when
    there are duplicates, the rows themselves when they are in that order already.  Gaps are
    allowed: consecutive trial numbers of a participant are consecutive trials."""
    span = int(t.max()) + 1
    key = p.astype(np.int64)
    key *= span
    key += t
    if len(key) < 2 or bool(np.all(key[1:] > key[:-1])):  # sorted, no duplicates: nothing to copy
        return ALL if rows is None else rows
    order = np.argsort(key, kind="stable")
    ks = key[order]
    del key
    dup = np.flatnonzero(ks[1:] == ks[:-1]) + 1
    if len(dup):
        first = np.searchsorted(ks, ks[dup], side="left")

        def at(i: int) -> int:
            return problems.row(int(order[i] if rows is None else rows[order[i]]))

        items = [
            f"row {at(d)}: duplicate trial index {t[order[d]]} for participant {ids[p[order[d]]]!r} (first at row {at(f)})"
            for d, f in zip(dup[:SHOWN], first[:SHOWN], strict=True)
        ]
        problems.add(f"{column}: duplicate trial indices", items, len(dup))
        return None
    return order if rows is None else rows[order]


def write_trials(frame: pd.DataFrame, path: str | Path) -> None:
    """Write a trial table as CSV or Parquet, chosen by the suffix of ``path``."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in (".parquet", ".pq"):
        frame.to_parquet(path, index=False)
    elif suffix == ".csv":
        frame.to_csv(path, index=False)
    else:
        raise DataError([f"unknown file type {suffix!r}: use .csv or .parquet"], str(path))


def example_path(name: str = "paper_trials.csv") -> Path:
    """Path of an example file shipped in ``trustseek/examples``."""
    return Path(__file__).resolve().parent.parent / "examples" / name
