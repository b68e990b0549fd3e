"""How another study's log maps onto the canonical columns and labels (:class:`ColumnMapping`).

A mapping names the log's columns (``columns``: canonical -> theirs), its labels (``labels``),
the declared complexities, derived and dropped rows, a rating column and other named inputs;
it is checked as a whole and reports every problem at once (``docs/data-format.md``).
"""

from __future__ import annotations

import itertools
import math
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from ..model.jsonfile import ModelError, is_number, load_json, read_text
from ..vocab import ACTIONS, CATEGORICAL_COLUMNS, EXPERIENCES, HUMAN_ACTIONS, LEVELS, TRIAL_COLUMNS
from .cells import DataError, names_list, shorten, unknown_entries
from .layouts import explode_entry, explode_problems, join_entry, join_problems, wide_entry, wide_problems

CANONICAL = TRIAL_COLUMNS


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
    ``sheet``        an Excel workbook's sheet that holds the log (default: its only sheet with values)
    ``rating``       a self-reported trust rating (optional): ``{"column": theirs, "levels": [...]}``
                     with the ordinal levels lowest first (numbers or labels; ``"labels"``
                     maps the log's texts to levels), or ``{"column": theirs, "bins": [edges]}``
                     for a numeric rating binned into ``[e0, e1), [e1, e2), ... [e_{n-1}, e_n]``
                     (``"levels"`` then names the bins); an empty cell is no rating.  It
                     becomes the ``rating`` column, an ordered categorical of the levels.
                     ``"per": "block"`` says a rating belongs to a block (a column), copied
                     onto its trials: it is kept on the block's last trial only.
    ``inputs``       named discrete inputs of a model (optional): ``{"condition": {"column": theirs,
                     "levels": ["control", "aid"]}}`` with the levels in their order (``"labels"``
                     maps the log's texts to levels, as for ``labels``; ``"column"`` defaults to the
                     input's name and may be a derived column).  Each becomes a column named by
                     the input, a categorical of its levels in the declared order; an empty cell
                     or a value outside the levels is an error.
    ``explode``      per-trial lists in a record per participant (or per block): ``["choice",
                     "difficulty"]``, or ``{"columns": [...], "position": "item"}`` to number each
                     item 1, 2, ... in a new column; every listed column of a record holds a list of
                     the same length, and each item becomes one trial (the record's other fields
                     are copied onto each)
    ``wide``         a row per participant (or block) with a column per trial of each field:
                     ``["choice", "difficulty"]`` for ``choice_1``, ``choice_2``, ..., or
                     ``{"columns": [...], "separator": "_", "position": "trial"}`` to keep each
                     trial's number in a new column
    ``join``         a second file joined onto the log: ``{"file": "ratings.csv", "on": ["pid",
                     "block"]}`` (``on`` defaults to the participant column, and ``block`` when both
                     files have it); a relative path is taken from the mapping file's folder
    ``experience_rule`` ``false`` where the paper's experience rule (an intervention ends
                     ``faulty``, an ask ends as the task says) is not the study's, e.g. advice
                     taking, where the aid can be right when the person overrides it.
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
    experience_rule: bool | None = None  # False: the paper's experience rule does not hold in this study
    explode: dict[str, Any] | None = None  # {"columns": [...], "position": name or None}
    join: dict[str, Any] | None = None  # {"file": path, "on": [columns] or None}
    wide: dict[str, Any] | None = None  # {"columns": [...], "separator": "_", "position": name or None}
    sheet: str | None = None

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
            if canon not in CATEGORICAL_COLUMNS:
                p.append(f"label mapping: {canon!r} is not a categorical column {list(CATEGORICAL_COLUMNS)}")
                continue
            if not isinstance(table, Mapping):
                p.append(f"label mapping: {canon} must map labels to labels, got {table!r}")
                continue
            allowed = self.categories(canon)
            for theirs, ours in table.items():
                if ours not in allowed:
                    p.append(f"label mapping: {canon}:{theirs}={ours!r} is not one of {list(allowed)}")
        if self.order is not None:
            if not names_list(list(self.order)):
                p.append(f"order: expected a column name or a list of column names, got {list(self.order)!r}")
            if "trial" in self.columns:
                p.append("order: give either 'order' or a 'trial' column, not both")
        for name, d in self.derived.items():
            if not isinstance(d, Mapping) or len(set(d) & {"equal", "shift"}) != 1:
                p.append(f"derived column {name!r}: expected {{'equal': [a, b]}} or {{'shift': column, 'by': 1}}, got {d!r}")
            elif "equal" in d:
                eq = d["equal"]
                if set(d) != {"equal"} or not names_list(eq) or len(eq) != 2:
                    p.append(f"derived column {name!r}: 'equal' takes a list of two column names, got {eq!r}")
            else:
                by = d.get("by", 1)
                if set(d) - {"shift", "by", "fill"} or not isinstance(d["shift"], str) or not d["shift"]:
                    p.append(f"derived column {name!r}: 'shift' takes a column name (and 'by', 'fill'), got {dict(d)!r}")
                elif not isinstance(by, int) or isinstance(by, bool) or by == 0:
                    p.append(f"derived column {name!r}: 'by' must be a non-zero integer (1 = the previous trial), got {by!r}")
        for i, rule in enumerate(self.drop, 1):
            ok = isinstance(rule, Mapping) and set(rule) == {"column", "values"}
            ok = ok and isinstance(rule["column"], str) and isinstance(rule["values"], list) and bool(rule["values"])
            if not ok:
                p.append(f"drop rule {i}: expected {{'column': name, 'values': [value, ...]}}, got {rule!r}")
        if self.missing is not None and not all(isinstance(m, str) for m in self.missing):
            p.append(f'missing: expected a list of texts (e.g. ["NA", "null"]), got {list(self.missing)!r}')
        elif self.missing is not None:
            p += self._marker_problems()
        if self.explode is not None:
            p += explode_problems(self.explode)
        if self.join is not None:
            p += join_problems(self.join)
        if self.wide is not None:
            p += wide_problems(self.wide)
            if self.explode is not None:
                p.append("give either 'wide' (a column per trial) or 'explode' (a list per record), not both")
        if self.experience_rule is not None and not isinstance(self.experience_rule, bool):
            p.append(f"experience_rule: expected true or false, got {self.experience_rule!r}")
        if self.delimiter is not None and (not isinstance(self.delimiter, str) or len(self.delimiter) != 1):
            p.append(f"delimiter: expected one character, got {self.delimiter!r}")
        if self.sheet is not None and (not isinstance(self.sheet, str) or not self.sheet):
            p.append(f"sheet: expected the name of a workbook's sheet, got {self.sheet!r}")
        return p

    def _marker_problems(self) -> list[str]:
        """A missing-value marker that is also a label of a categorical column would turn that label's
        cells into unrecorded ones."""
        labels: dict[str, str] = {}
        for col in CATEGORICAL_COLUMNS:
            table = self.labels.get(col)
            theirs = list(table) if isinstance(table, Mapping) else []
            for text in (*self.categories(col), *theirs):
                labels.setdefault(str(text).strip().lower(), col)
        return [
            f"missing: {m!r} is also a label of {labels[m.strip().lower()]}; a marker of unrecorded cells cannot be a "
            "value (drop it from --missing / 'missing', or map the label to another text)"
            for m in self.missing or ()
            if m.strip().lower() in labels
        ]

    def categories(self, column: str) -> tuple[str, ...]:
        if column == "complexity":
            return tuple(self.complexities or LEVELS)
        return {"robot_action": ACTIONS, "human_action": HUMAN_ACTIONS, "experience": EXPERIENCES}[column]

    def merged(self, other: ColumnMapping) -> ColumnMapping:
        """This mapping overridden by ``other`` (e.g. a file overridden by command-line flags): tables
        merged, drop rules added, any other entry of ``other`` given replacing this one's."""
        out: dict[str, Any] = {}
        for f in fields(self):
            mine, theirs = getattr(self, f.name), getattr(other, f.name)
            if f.name == "labels":
                out[f.name] = {k: {**mine.get(k, {}), **theirs.get(k, {})} for k in {**mine, **theirs}}
            elif f.default_factory is dict:
                out[f.name] = {**mine, **theirs}
            elif f.default_factory is list:
                out[f.name] = [*mine, *theirs]
            elif f.name in ("missing", "experience_rule"):  # an empty list, or false, is given too
                out[f.name] = theirs if theirs is not None else mine
            else:
                out[f.name] = theirs or mine
        return ColumnMapping(**out)

    def to_dict(self) -> dict[str, Any]:
        """The mapping as a file holds it: every entry given, in lists and objects."""
        d: dict[str, Any] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in ("columns", "labels") or (v is not None if f.name in ("missing", "experience_rule") else v):
                d[f.name] = _plain(v)
        return d

    def input_levels(self) -> dict[str, tuple[str, ...]]:
        """Every declared input's levels, in their declared order."""
        return {name: tuple(label_key(v) for v in entry["levels"]) for name, entry in self.inputs.items()}

    def input_column(self, name: str) -> str:
        """The log's (or a derived) column an input is read from."""
        return str(self.inputs[name].get("column", name))

    def rating_levels(self) -> tuple[str, ...]:
        """The declared rating levels, lowest first (the bins' names for a binned rating)."""
        if self.rating is None:
            return ()
        levels = self.rating.get("levels")
        if levels is not None:
            return tuple(label_key(v) for v in levels)
        edges = [float(e) for e in self.rating["bins"]]
        return tuple(f"{format_number(lo)}-{format_number(hi)}" for lo, hi in itertools.pairwise(edges))

    @classmethod
    def from_dict(cls, d: Any, source: str | None = None) -> ColumnMapping:
        if not isinstance(d, Mapping):
            raise DataError(["a mapping must be an object with 'columns' and/or 'labels'"], source)
        unknown = set(d) - set(MAPPING_KEYS)
        problems = [f"unknown entry {k!r} (expected {', '.join(MAPPING_KEYS)})" for k in sorted(unknown)]
        given: dict[str, Any] = {}
        for key, absent, what in _SHAPES:
            v = d.get(key, absent)
            v = [v] if isinstance(v, str) and key in ("order", "missing") else v
            ok = isinstance(v, Mapping if isinstance(absent, dict) else list)
            if not (ok and (key != "complexities" or (names_list(v) and len(v) >= 2))) and (v is not None or absent is not None):
                problems.append(f"'{key}' must {what}, got {v!r}")
                v = absent
            given[key] = v
        cx, order, missing, labels = given["complexities"], given["order"], given["missing"], given["labels"]
        m = cls(
            columns={str(k): v for k, v in given["columns"].items()},
            labels={
                str(k): _label_table(v, problems, f"labels[{k}]") if isinstance(v, Mapping) else v for k, v in labels.items()
            },
            complexities=tuple(cx) if cx else None,
            order=tuple(order) if order is not None else None,
            derived={str(k): v for k, v in given["derived"].items()},
            drop=list(given["drop"]),
            missing=tuple(missing) if missing is not None else None,
            delimiter=d.get("delimiter"),
            rating=dict(d["rating"]) if isinstance(d.get("rating"), Mapping) else d.get("rating"),
            inputs={str(k): (_input_entry(v) if isinstance(v, Mapping) else v) for k, v in given["inputs"].items()},
            experience_rule=d.get("experience_rule"),
            explode=explode_entry(d["explode"]) if "explode" in d else None,
            join=join_entry(d["join"]) if "join" in d else None,
            wide=wide_entry(d["wide"]) if "wide" in d else None,
            sheet=d.get("sheet"),
        )
        problems += m.problems()
        if problems:
            raise DataError(problems, source)
        return m

    @staticmethod
    def read(path: str | Path) -> Any:
        """The content of a mapping file: TOML (``.toml``), else JSON.  Every way it can fail to be
        read is a :class:`DataError` naming the file: missing, a folder, binary or not UTF-8, invalid
        (JSON with the line and column) or nested too deeply, a JSON file whose top level is not an object."""
        try:
            if Path(path).suffix.lower() != ".toml":
                return load_json(path)[0]
            text = read_text(path, "JSON or TOML", ModelError, hint=": save it as UTF-8 TOML")
            try:
                return tomllib.loads(text)
            except tomllib.TOMLDecodeError as exc:
                raise ModelError([f"invalid TOML: {exc}"], str(path)) from None
            except RecursionError:  # as load_json says of JSON
                raise ModelError(["invalid TOML: nested too deeply"], str(path)) from None
        except ModelError as exc:
            raise DataError(exc.problems, str(path)) from None

    @classmethod
    def load(cls, path: str | Path) -> ColumnMapping:
        """A mapping file (:meth:`read`, then :meth:`from_file`)."""
        return cls.from_file(cls.read(path), path)

    @classmethod
    def from_file(cls, d: Any, path: str | Path) -> ColumnMapping:
        """The mapping a file at ``path`` holds, its content ``d`` already read: a joined file
        named relative to it is beside it."""
        m = cls.from_dict(d, str(path))
        if m.join is not None and not Path(m.join["file"]).is_absolute():
            m.join = {**m.join, "file": str((Path(path).parent / m.join["file"]).absolute())}
        return m

    @classmethod
    def from_flags(
        cls,
        columns: Iterable[str] = (),
        labels: Iterable[str] = (),
        file: str | Path | ColumnMapping | None = None,
        missing: Iterable[str] | None = None,
        delimiter: str | None = None,
        rating: Mapping[str, Any] | None = None,
        order: Iterable[str] | None = None,
        sheet: str | None = None,
    ) -> ColumnMapping:
        """Command-line flags: ``--column canonical=theirs``, ``--label column:theirs=canonical``,
        ``--missing TEXT``, ``--delimiter CHAR``, ``--order COLUMN[,COLUMN]`` (the columns, each
        flag one or more separated by commas) and ``--sheet NAME``; ``rating`` as in a mapping file (``--rating``
        with ``--rating-levels`` or ``--rating-bins``); ``file`` a mapping file or one already read."""
        base = file if isinstance(file, ColumnMapping) else (cls.load(file) if file else cls())
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
            canon, theirs, ours = canon.strip(), theirs.strip(), ours.strip()
            table = labs.setdefault(canon, {})
            if table.get(theirs, ours) != ours:
                problems.append(
                    f"--label {canon}:{theirs}: the label is mapped to two categories, {table[theirs]!r} and {ours!r}"
                )
            table[theirs] = ours
        delimiter = {"\\t": "\t", "tab": "\t", "TAB": "\t"}.get(delimiter or "", delimiter)
        by = [c.strip() for item in order or () for c in item.split(",")]
        if order and not all(by):
            problems.append(f"--order {','.join(order)!r}: expected column names separated by commas, e.g. block,trial")
        if problems:
            raise DataError(problems)
        flags = cls(
            cols,
            labs,
            missing=tuple(missing) if missing else None,
            delimiter=delimiter,
            rating=dict(rating) if rating is not None else None,
            order=tuple(by) if by else None,
            sheet=sheet,
        )
        if by and "trial" in base.columns:  # --order replaces the file's trial column
            base = replace(base, columns={k: v for k, v in base.columns.items() if k != "trial"})
        problems = flags.problems()
        if problems:
            raise DataError(problems)
        return base.merged(flags)


MAPPING_KEYS = tuple(f.name for f in fields(ColumnMapping))
_SHAPES: tuple[tuple[str, Any, str], ...] = (  # an entry checked in from_dict, its value when absent, what it must be
    ("inputs", {}, "map input names to {'column': ..., 'levels': [...]}"),
    ("columns", {}, "map canonical names to the log's names"),
    ("labels", {}, "map canonical columns to label tables"),
    ("complexities", None, "list at least 2 names"),
    ("order", None, "be a column name or a list of them"),
    ("derived", {}, "map new column names to their definitions"),
    ("drop", [], "be a list of rules"),
    ("missing", None, "list texts"),
)


RATING = "rating"  # the canonical name of the rating column a mapping declares


def _plain(v: Any) -> Any:
    """A value as JSON holds it: objects and lists copied, tuples as lists."""
    if isinstance(v, Mapping):
        return {k: _plain(x) for k, x in v.items()}
    return [_plain(x) for x in v] if isinstance(v, (list, tuple)) else v


def format_number(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else repr(float(x))


def _rating_problems(r: Any) -> list[str]:
    """Everything wrong with a mapping's ``rating`` entry."""
    head = "rating"
    if not isinstance(r, Mapping):
        return [f'{head}: expected {{"column": name, "levels": [...]}} or {{"column": name, "bins": [edges]}}, got {r!r}']
    p = unknown_entries(head, r, ("column", "levels", "labels", "bins", "per"))
    per = r.get("per")
    if per is not None and (not isinstance(per, str) or not per):
        p.append(f"{head}: 'per' names the column of the block a rating belongs to (e.g. \"block\"), got {per!r}")
    col = r.get("column")
    if not isinstance(col, str) or not col:
        p.append(f"{head}: 'column' must name the log's rating column, got {col!r}")
    levels, bins, labels = r.get("levels"), r.get("bins"), r.get("labels")
    if levels is None and bins is None:
        p.append(f"{head}: declare the levels, lowest first ('levels': [1, 2, 3, 4, 5]) or numeric bins ('bins': [edges])")
    names: list[str] = []
    if levels is not None:
        ok = isinstance(levels, list) and all(isinstance(v, str) or is_number(v) for v in levels)
        names = [label_key(v) for v in levels] if ok else []
        if not ok or len(names) < 2 or len(set(names)) != len(names) or not all(n.strip() for n in names):
            p.append(f"{head}: 'levels' must list at least 2 distinct levels, lowest first, got {levels!r}")
    if bins is not None:
        ok = isinstance(bins, list) and all(is_number(v) for v in bins)
        edges = [float(v) for v in bins] if ok else []
        if not ok or len(edges) < 3 or not all(map(math.isfinite, edges)) or any(b <= a for a, b in itertools.pairwise(edges)):
            p.append(f"{head}: 'bins' must list at least 3 increasing finite edges (2 bins), got {bins!r}")
        elif levels is not None and names and len(names) != len(edges) - 1:
            p.append(f"{head}: {len(edges) - 1} bins need {len(edges) - 1} level names, got {len(names)}")
        if labels is not None:
            p.append(f"{head}: 'labels' apply to declared levels, not to bins")
    if labels is not None and bins is None:
        p += _level_label_problems(head, labels, names)
    return p


def _level_label_problems(head: str, labels: Any, names: list[str]) -> list[str]:
    """What is wrong with a label table (the log's texts -> levels) of declared ``names``."""
    if not isinstance(labels, Mapping):
        return [f"{head}: 'labels' must map the log's texts to levels, got {labels!r}"]
    return [
        f"{head}: label {theirs}={ours!r} is not one of the levels {names}"
        for theirs, ours in labels.items()
        if names and label_key(ours) not in names
    ]


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
    p += unknown_entries(head, entry, ("column", "levels", "labels"))
    col = entry.get("column", name)
    if not isinstance(col, str) or not col:
        p.append(f"{head}: 'column' must name the log's column, got {col!r}")
    levels = entry.get("levels")
    ok = isinstance(levels, list) and all(isinstance(v, (str, int, float, bool)) for v in levels)
    names = [label_key(v) for v in levels] if ok and isinstance(levels, list) else []
    if not names or len(set(names)) != len(names) or not all(n.strip() for n in names):
        p.append(f"{head}: 'levels' must list its distinct levels in their order, got {levels!r}")
    labels = entry.get("labels")
    if labels is not None:
        p += _level_label_problems(head, labels, names)
    return p


def _label_table(table: Mapping, conflicts: list[str] | None = None, head: str = "labels") -> dict[str, Any]:
    """A label table with its set entries (canonical -> [their labels]) turned into their -> canonical;
    a label of theirs given two canonical labels is added to ``conflicts``."""
    out: dict[str, Any] = {}

    def put(theirs: str, ours: Any) -> None:
        if theirs in out and out[theirs] != ours and conflicts is not None:
            conflicts.append(
                f"{head}: the label {shorten(theirs, 80)!r} is mapped to two categories, {out[theirs]!r} and {ours!r}"
            )
        out[theirs] = ours

    for k, v in table.items():
        if isinstance(v, list):
            for theirs in v:
                put(label_key(theirs), str(k))
        else:
            put(label_key(k), v)
    return out


def label_key(v: Any) -> str:
    """A label written in a mapping file as text (a TOML/JSON number or boolean as the reader's text)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    return str(v)


def as_mapping(mapping: ColumnMapping | Mapping | str | Path | None) -> ColumnMapping:
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
