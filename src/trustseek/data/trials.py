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


class DataError(TrustseekError, ValueError):
    """A trial log is malformed.  ``problems`` holds one line per kind of problem (file, column, rows, values)."""


@dataclass
class ColumnMapping:
    """How another study's log maps onto the canonical columns and labels.

    ``columns``     canonical name -> the log's column name
    ``labels``      canonical column -> {the log's label: canonical label}
    ``complexities`` the complexity names, lowest first (default ``low``, ``high``)
    """

    columns: dict[str, str] = field(default_factory=dict)
    labels: dict[str, dict[str, str]] = field(default_factory=dict)
    complexities: tuple[str, ...] | None = None

    def problems(self) -> list[str]:
        p = []
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
        return ColumnMapping({**self.columns, **other.columns}, labels, other.complexities or self.complexities)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"columns": dict(self.columns), "labels": {k: dict(v) for k, v in self.labels.items()}}
        if self.complexities:
            d["complexities"] = list(self.complexities)
        return d

    @classmethod
    def from_dict(cls, d: Any, source: str | None = None) -> ColumnMapping:
        if not isinstance(d, Mapping):
            raise DataError(["a mapping must be an object with 'columns' and/or 'labels'"], source)
        unknown = set(d) - {"columns", "labels", "complexities"}
        problems = [f"unknown entry {k!r} (expected columns, labels, complexities)" for k in sorted(unknown)]
        cols = d.get("columns", {})
        labels = d.get("labels", {})
        cx = d.get("complexities")
        if not isinstance(cols, Mapping):
            problems.append(f"'columns' must map canonical names to the log's names, got {cols!r}")
            cols = {}
        if not isinstance(labels, Mapping):
            problems.append(f"'labels' must map canonical columns to label tables, got {labels!r}")
            labels = {}
        if cx is not None and (not isinstance(cx, list) or not all(isinstance(c, str) and c for c in cx) or len(cx) < 2):
            problems.append(f"'complexities' must list at least 2 names, got {cx!r}")
            cx = None
        m = cls(
            {str(k): v for k, v in cols.items()},
            {str(k): ({str(a): b for a, b in v.items()} if isinstance(v, Mapping) else v) for k, v in labels.items()},
            tuple(cx) if cx else None,
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
    def from_flags(cls, columns: Iterable[str] = (), labels: Iterable[str] = (), file: str | Path | None = None) -> ColumnMapping:
        """Command-line flags: ``--column canonical=theirs`` and ``--label column:theirs=canonical``."""
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
        if problems:
            raise DataError(problems)
        flags = cls(cols, labs)
        problems = flags.problems()
        if problems:
            raise DataError(problems)
        return base.merged(flags)


# --------------------------------------------------------------------------- problems, grouped by kind


class _Problems:
    """Problems grouped by kind: one line per kind with the count and the first locations."""

    def __init__(self) -> None:
        self.lines: list[str] = []

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
        """A kind of problem at data rows ``rows`` (0-based), each described by ``describe(row)``."""
        if len(rows) == 0:
            return
        first = rows[:SHOWN]
        items = [f"row {r + 1}" + (f" {describe(int(r))}" if describe else "") for r in first]
        self.add(head, items, len(rows))


# --------------------------------------------------------------------------- columns as codes into distinct values


def _as_text(v: Any) -> str | None:
    """A distinct cell value as text: None for an empty cell, the NaN marker for a NaN."""
    if v is None or v is pd.NA:
        return None
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, (float, np.floating)):
        f = float(v)
        if math.isnan(f):
            return _NAN
        if f.is_integer() and abs(f) < 2**63:
            return str(int(f))
        return repr(f)
    if isinstance(v, (np.integer, int)):
        return str(int(v))
    if isinstance(v, bytes):
        v = v.decode("utf-8", "replace")
    s = str(v).strip()
    if s == "":
        return None
    if s.lower() in NAN_WORDS:
        return _NAN
    return s


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


@dataclass
class _Col:
    """One column: per row a code into ``texts`` (the distinct values as text; the last
    entry is what a null cell means: empty, or NaN in a numeric column)."""

    codes: np.ndarray
    texts: list[str | None]


def _col_from_pandas(values: pd.Series) -> _Col:
    numeric = pd.api.types.is_numeric_dtype(values.dtype) and not pd.api.types.is_bool_dtype(values.dtype)
    codes, uniques = pd.factorize(values, use_na_sentinel=True)
    texts = [_as_text(u) for u in np.asarray(uniques, dtype=object)]
    null = _NAN if numeric else None
    codes = np.asarray(codes, dtype=np.int64)
    codes[codes < 0] = len(texts)
    return _Col(codes, [*texts, null])


def _col_from_arrow(chunked: Any) -> _Col:
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
    if chunked.num_chunks == 0:
        return _Col(np.zeros(0, dtype=np.int64), [None])
    dictionary = chunked.chunk(0).dictionary
    texts = [_as_text(u) for u in dictionary.to_pylist()]
    parts = []
    for chunk in chunked.chunks:
        idx = chunk.indices.fill_null(len(texts)) if chunk.null_count else chunk.indices
        parts.append(idx.to_numpy(zero_copy_only=False))
    codes = np.concatenate(parts).astype(np.int64, copy=False) if parts else np.zeros(0, dtype=np.int64)
    return _Col(codes, [*texts, _NAN if numeric else None])


# --------------------------------------------------------------------------- sources


@dataclass
class _Raw:
    name: str
    n: int
    columns: list[str]
    col: Any  # name -> _Col
    extras: Any  # list of names -> DataFrame of those columns


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


def _load(source: Any, theirs: set[str], sep: str | None) -> _Raw:
    if isinstance(source, pd.DataFrame):
        frame = source

        def col(c: str) -> _Col:
            return _col_from_pandas(frame[c])

        return _Raw("<table>", len(frame), [str(c) for c in frame.columns], col, lambda cs: frame[cs].reset_index(drop=True))
    path = Path(source)
    name = str(path)
    if not path.exists():
        raise DataError(["file not found"], name)
    if path.is_dir():
        raise DataError(["is a directory, not a trial log"], name)
    suffix = path.suffix.lower()
    if suffix in (".parquet", ".pq"):
        return _load_parquet(path, name)
    if suffix in (".csv", ".txt", ".tsv"):
        return _load_csv(path, name, theirs, sep)
    raise DataError([f"unknown file type {suffix!r}: use .csv, .tsv or .parquet"], name)


def _load_parquet(path: Path, name: str) -> _Raw:
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise DataError([f"cannot read the file as Parquet: {exc}"], name) from None
    names = [str(c) for c in table.column_names]
    dupes = sorted({c for c in names if names.count(c) > 1})
    if dupes:
        raise DataError([f"column {c!r} appears {names.count(c)} times" for c in dupes], name)
    return _Raw(
        name,
        table.num_rows,
        names,
        lambda c: _col_from_arrow(table.column(c)),
        lambda cs: table.select(cs).to_pandas(),
    )


def _load_csv(path: Path, name: str, theirs: set[str], sep: str | None) -> _Raw:
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

    dictionary = pa.dictionary(pa.int32(), pa.string())
    types = {c: (dictionary if c in theirs else pa.string()) for c in header}
    # pyarrow decodes a malformed row's text for the handler; a row that is not UTF-8 fails there,
    # outside any caller, so such failures are collected here instead of being printed
    undecodable: list[Any] = []
    hook = sys.unraisablehook
    sys.unraisablehook = undecodable.append
    try:
        table = pcsv.read_csv(
            path,
            read_options=pcsv.ReadOptions(column_names=header, skip_rows=1),
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
    return _Raw(
        name,
        table.num_rows,
        header,
        lambda c: _col_from_arrow(table.column(c)),
        lambda cs: table.select(cs).to_pandas(),
    )


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


def read_trials(
    source: Any,
    mapping: ColumnMapping | Mapping | str | Path | None = None,
    *,
    required: Sequence[str] | None = None,
    delimiter: str | None = None,
    check_experience: bool = True,
) -> pd.DataFrame:
    """Read, map and validate a trial log (CSV/TSV, Parquet or a DataFrame).

    Returns the canonical columns in order (``participant`` and the categorical
    columns as pandas categoricals with the canonical labels, ``trial`` as int64,
    an unrecorded ``human_action`` as missing), followed by every extra column.
    Rows keep the file's order: row ``i`` of the result is data row ``i + 1`` of
    the file.  ``required`` names the canonical columns that must be present
    (default: all six); an absent optional column comes back empty.  A CSV's
    delimiter is taken from ``delimiter``, else ``.tsv`` means tab, else the
    most frequent of ``, ; TAB |`` in the header.  ``check_experience`` checks
    the experience rule of the data format where the columns it needs are present.
    Raises :class:`DataError` listing every kind of problem at once.
    """
    if mapping is None:
        mapping = ColumnMapping()
    elif isinstance(mapping, (str, Path)):
        mapping = ColumnMapping.load(mapping)
    elif not isinstance(mapping, ColumnMapping):
        mapping = ColumnMapping.from_dict(mapping)
    else:
        p = mapping.problems()
        if p:
            raise DataError(p)
    required = tuple(CANONICAL if required is None else required)
    for col in ("trial", "participant"):
        if col not in required:
            required = (col, *required)
    theirs = {c: mapping.columns.get(c, c) for c in CANONICAL}
    raw = _load(source, set(theirs.values()), delimiter)
    name = raw.name
    missing = [c for c in required if theirs[c] not in raw.columns]
    if missing:
        lines = []
        for c in missing:
            via = f" (mapped from canonical {c!r})" if theirs[c] != c else ""
            lines.append(f"missing column {theirs[c]!r}{via}; columns present: {raw.columns}")
        raise DataError(lines + _missing_column_hint(missing, raw.columns, delimiter), name)
    n = raw.n
    if n == 0:
        raise DataError(["the log has no trials (only a header)"], name)
    present = [c for c in CANONICAL if theirs[c] in raw.columns]
    cols = {c: raw.col(theirs[c]) for c in present}
    problems = _Problems()

    def column(c: str) -> str:
        return f"column {theirs[c]!r}"

    # participant: codes into the distinct ids, in order of first appearance
    pc_ = cols["participant"]
    ids: dict[str, int] = {}
    p_lookup = np.full(len(pc_.texts), -1, dtype=np.int64)
    for j, t in enumerate(pc_.texts):
        if t is not None and t != _NAN:
            p_lookup[j] = ids.setdefault(t, len(ids))
    pcode = p_lookup[pc_.codes]
    empty = np.array([t is None for t in pc_.texts])[pc_.codes]
    problems.rows(f"{column('participant')}: empty participant id", np.flatnonzero(empty))
    problems.rows(f"{column('participant')}: value is NaN", np.flatnonzero((pcode < 0) & ~empty))

    # trial: integers; the distinct values are parsed once
    tc = cols["trial"]
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
    trial = t_lookup[tc.codes]
    tkind = t_kind[tc.codes]
    expect = "expected an integer: trials count 1, 2, ... (or 0, 1, ...)"
    problems.rows(f"{column('trial')}: empty trial index ({expect})", np.flatnonzero(tkind == 1))
    problems.rows(f"{column('trial')}: value is NaN ({expect})", np.flatnonzero(tkind == 2))
    problems.rows(
        f"{column('trial')}: value is not an integer between 0 and {MAX_TRIAL}",
        np.flatnonzero(tkind == 3),
        lambda r: repr(tc.texts[tc.codes[r]]),
    )

    # categories: each distinct value is looked up once (in the mapping's labels, then the canonical labels)
    codes: dict[str, np.ndarray] = {}
    for c in CATEGORICAL:
        if c not in cols:
            codes[c] = np.full(n, -1, dtype=np.int8)
            continue
        cc = cols[c]
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
        known = f"{sorted(table)} (mapped) or " if table else ""
        problems.rows(f"{column(c)}: empty value (expected one of {list(allowed)})", np.flatnonzero(k == 1))
        problems.rows(f"{column(c)}: value is NaN (expected one of {list(allowed)}{hint})", np.flatnonzero(k == 2))
        problems.rows(
            f"{column(c)}: unknown category (expected one of {known}{list(allowed)})",
            np.flatnonzero(k == 3),
            lambda r, cc=cc: repr(cc.texts[cc.codes[r]]),
        )
    nothing_recorded = "human_action" in cols and not (codes["human_action"] >= 0).any()
    if "human_action" in required and nothing_recorded and not any(column("human_action") in x for x in problems.lines):
        problems.lines.append(
            f"{column('human_action')}: no trial has a recorded human action (every cell is empty): nothing to fit"
        )

    if check_experience:
        _check_experience(problems, codes, mapping, present, column)

    # trial indices per participant: consecutive from 1 (or from 0 in a log that counts from 0), no duplicates
    ok = np.flatnonzero((pcode >= 0) & (tkind == 0))
    base = 1
    if len(ok):
        base = 0 if int(trial[ok].min()) == 0 else 1
        _check_trials(problems, pcode[ok], trial[ok], ok, base, list(ids), column("trial"))
    if problems.lines:
        raise DataError(problems.lines, name)

    frame = pd.DataFrame(
        {
            "participant": pd.Categorical.from_codes(pcode.astype(np.int32), categories=pd.Index(list(ids), dtype=object)),
            "trial": trial.astype(np.int64),
        }
    )
    for c in CATEGORICAL:
        frame[c] = pd.Categorical.from_codes(codes[c], categories=pd.Index(list(mapping.categories(c)), dtype=object))
    used = {theirs[c] for c in present}
    extras = [c for c in raw.columns if c not in used and c not in frame.columns]
    if extras:
        more = raw.extras(extras)
        for c in extras:
            frame[c] = more[c].to_numpy() if isinstance(source, pd.DataFrame) else more[c].values
    return frame


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
    problems: _Problems, p: np.ndarray, t: np.ndarray, rows: np.ndarray, base: int, ids: list[str], column: str
) -> None:
    """Duplicate and missing trial indices, with array operations on the (participant, trial) keys."""
    span = int(t.max()) + 1
    key = p * span + t
    order = np.argsort(key, kind="stable") if len(key) > 1 and np.any(key[1:] <= key[:-1]) else np.arange(len(key))
    ks, ps, ts = key[order], p[order], t[order]
    dup = np.flatnonzero(ks[1:] == ks[:-1]) + 1
    if len(dup):
        first = np.searchsorted(ks, ks[dup], side="left")
        items = [
            f"row {rows[order[d]] + 1}: duplicate trial index {ts[d]} for participant {ids[ps[d]]!r} "
            f"(first at row {rows[order[f]] + 1})"
            for d, f in zip(dup[:SHOWN], first[:SHOWN], strict=True)
        ]
        problems.add(f"{column}: duplicate trial indices", items, len(dup))
    # gaps: the first trial of a participant above the base, or a step of more than 1
    starts = np.flatnonzero(np.r_[True, ps[1:] != ps[:-1]])
    prev = np.r_[base - 1, ts[:-1]].astype(np.int64)
    prev[starts] = base - 1
    gap = np.flatnonzero(ts - prev > 1)
    if len(gap):
        participants = np.unique(ps[gap])
        items = []
        for q in participants[:SHOWN]:
            at = gap[ps[gap] == q]
            miss: list[int] = []
            for g in at:
                miss.extend(range(int(prev[g]) + 1, min(int(ts[g]), int(prev[g]) + 1 + 9)))
                if len(miss) > 8:
                    break
            shown = ", ".join(map(str, miss[:8])) + (" ..." if len(miss) > 8 else "")
            items.append(f"participant {ids[q]!r}: trial index {shown} missing")
        first = "0, 1" if base == 0 else "1, 2"
        problems.add(f"{column}: trials must run {first}, ... without gaps", items, len(participants), "participants")


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
