"""Trial logs: read, map, validate and write the canonical one-row-per-trial table.

Canonical columns, in order (see ``docs/data-format.md``)::

    participant  trial  complexity  robot_action  human_action  experience

``human_action`` may be empty (not recorded: unobserved).  Extra columns are kept.
A log from another study is read through a :class:`ColumnMapping`: its column
names (``columns``: canonical -> theirs) and category labels (``labels``:
canonical column -> {their label: canonical label}).  Every problem is reported
with file, row, column and value through :class:`DataError`.
"""

from __future__ import annotations

import json
import math
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
MAX_PROBLEMS = 30


class DataError(TrustseekError, ValueError):
    """A trial log is malformed.  ``problems`` holds one line per problem (file, row, column, value)."""


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
        except OSError as exc:
            raise DataError([f"cannot read mapping file: {exc.strerror or exc}"], str(path)) from None
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


# --------------------------------------------------------------------------- reading


def _as_text(v: Any) -> str | None:
    """A cell as text; None for an empty cell; 'nan' marker for a NaN."""
    if v is None or v is pd.NA:
        return None
    if isinstance(v, float):
        if math.isnan(v):
            return "\x00nan"
        if v.is_integer():
            return str(int(v))
        return repr(v)
    if isinstance(v, (bool, np.bool_)):
        return str(int(v))
    if isinstance(v, (np.integer, int)):
        return str(int(v))
    if isinstance(v, np.floating):
        return _as_text(float(v))
    s = str(v).strip()
    if s == "":
        return None
    if s.lower() in ("nan", "na", "n/a", "null", "none"):
        return "\x00nan"
    return s


def _load(source: Any) -> tuple[pd.DataFrame, str, bool]:
    """(raw frame, name for messages, rows are file lines?)"""
    if isinstance(source, pd.DataFrame):
        return source.copy(), "<table>", False
    path = Path(source)
    name = str(path)
    if not path.exists():
        raise DataError(["file not found"], name)
    suffix = path.suffix.lower()
    try:
        if suffix in (".parquet", ".pq"):
            return pd.read_parquet(path), name, False
        if suffix in (".csv", ".txt", ".tsv"):
            sep = "\t" if suffix == ".tsv" else ","
            return pd.read_csv(path, dtype=str, keep_default_na=False, sep=sep), name, True
    except (ValueError, OSError, pd.errors.ParserError) as exc:
        raise DataError([f"cannot read the file: {exc}"], name) from None
    raise DataError([f"unknown file type {suffix!r}: use .csv or .parquet"], name)


def read_trials(
    source: Any,
    mapping: ColumnMapping | Mapping | str | Path | None = None,
    *,
    required: Sequence[str] | None = None,
) -> pd.DataFrame:
    """Read, map and validate a trial log (CSV, Parquet or a DataFrame).

    Returns the canonical columns in order (``trial`` as int, the categorical
    columns as canonical labels, an unrecorded ``human_action`` as missing),
    followed by every extra column unchanged.  ``required`` names the canonical
    columns that must be present (default: all six); an absent optional column
    comes back empty.  Raises :class:`DataError` listing every problem.
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
    raw, name, lines = _load(source)
    required = tuple(CANONICAL if required is None else required)
    for col in ("participant", "trial"):
        if col not in required:
            required = (col, *required)

    def where(i: int) -> str:
        return f"line {i + 2}" if lines else f"row {i + 1}"

    theirs = {c: mapping.columns.get(c, c) for c in CANONICAL}
    problems: list[str] = []
    for c in required:
        if theirs[c] not in raw.columns:
            via = f" (mapped from canonical {c!r})" if theirs[c] != c else ""
            problems.append(f"missing column {theirs[c]!r}{via}; columns present: {list(map(str, raw.columns))}")
    if problems:
        raise DataError(problems, name)
    n = len(raw)
    if n == 0:
        raise DataError(["the log has no trials"], name)
    out: dict[str, Any] = {}
    texts: dict[str, list[str | None]] = {}
    for c in CANONICAL:
        col = theirs[c]
        if col not in raw.columns:
            texts[c] = [None] * n
            continue
        values = raw[col]
        if pd.api.types.is_numeric_dtype(values.dtype) or pd.api.types.is_bool_dtype(values.dtype):
            texts[c] = [_as_text(v) for v in values.tolist()]
        else:  # a null in a text column is an empty cell, not a NaN
            texts[c] = [None if (isinstance(v, float) and math.isnan(v)) else _as_text(v) for v in values.tolist()]

    def add(i: int, c: str, msg: str) -> None:
        problems.append(f"{where(i)}, column {theirs[c]!r}: {msg}")

    # participant
    for i, v in enumerate(texts["participant"]):
        if v is None:
            add(i, "participant", "empty participant id")
        elif v == "\x00nan":
            add(i, "participant", "value is NaN")
    # trial
    trial = np.zeros(n, dtype=np.int64)
    for i, v in enumerate(texts["trial"]):
        if v is None:
            add(i, "trial", "empty trial index (expected an integer >= 1)")
        elif v == "\x00nan":
            add(i, "trial", "value is NaN (expected an integer >= 1)")
        else:
            try:
                f = float(v)
            except ValueError:
                f = math.nan
            if f.is_integer() and f >= 1:
                trial[i] = int(f)
            else:
                add(i, "trial", f"value {v!r} is not an integer >= 1")
    # categories
    for c in CATEGORICAL:
        present = theirs[c] in raw.columns
        if not present:
            out[c] = [None] * n
            continue
        allowed = mapping.categories(c)
        table = mapping.labels.get(c, {})
        vals: list[str | None] = []
        for i, v in enumerate(texts[c]):
            if v is None:
                if c != "human_action":
                    add(i, c, f"empty value (expected one of {list(allowed)})")
                vals.append(None)
                continue
            if v == "\x00nan":
                hint = "; leave the cell empty for not recorded" if c == "human_action" else ""
                add(i, c, f"value is NaN (expected one of {list(allowed)}{hint})")
                vals.append(None)
                continue
            label = table.get(v, v) if table else v
            if label not in allowed:
                known = f"{sorted(table)} (mapped) or " if table else ""
                add(i, c, f"unknown category {v!r} (expected one of {known}{list(allowed)})")
            vals.append(label)
        out[c] = vals
    if len(problems) > MAX_PROBLEMS:
        extra = len(problems) - MAX_PROBLEMS
        problems = problems[:MAX_PROBLEMS] + [f"... and {extra} more problems"]
    if problems:
        raise DataError(problems, name)
    # trial indices: 1..n, consecutive, no duplicates, per participant
    pid = np.array(texts["participant"], dtype=object)
    frame = pd.DataFrame({"participant": pid.astype(str), "trial": trial})
    for p, idx in frame.groupby("participant", sort=False).indices.items():
        t = trial[idx]
        seen: dict[int, int] = {}
        for i, tv in zip(idx, t, strict=True):
            if tv in seen:
                problems.append(
                    f"{where(i)}, column {theirs['trial']!r}: duplicate trial index {tv} for participant {p!r} "
                    f"(first at {where(seen[tv])})"
                )
            else:
                seen[int(tv)] = int(i)
        expected = set(range(1, len(seen) + 1))
        missing = sorted(set(range(1, int(t.max()) + 1)) - set(seen))
        if missing:
            shown = ", ".join(map(str, missing[:8])) + (" ..." if len(missing) > 8 else "")
            problems.append(f"participant {p!r}: trial index {shown} missing (trials must run 1, 2, ... without gaps)")
        elif set(seen) != expected:  # pragma: no cover - covered by the two checks above
            problems.append(f"participant {p!r}: trial indices are not consecutive from 1")
    if len(problems) > MAX_PROBLEMS:
        extra = len(problems) - MAX_PROBLEMS
        problems = problems[:MAX_PROBLEMS] + [f"... and {extra} more problems"]
    if problems:
        raise DataError(problems, name)
    for c in CATEGORICAL:
        frame[c] = pd.Series(out[c], dtype=object)
    frame = frame[list(CANONICAL)]
    used = {theirs[c] for c in CANONICAL if theirs[c] in raw.columns}
    for col in raw.columns:
        if col not in used and col not in frame.columns:
            frame[col] = raw[col].to_numpy()
    return frame


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
