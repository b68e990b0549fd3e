"""Trial logs: read, map, validate and write the canonical one-row-per-trial table
(``docs/data-format.md``): ``participant  trial  complexity  robot_action  human_action  experience``,
``human_action`` empty where not recorded, extra columns kept.

Reading is column-wise: every column becomes integer codes into its few distinct values
(:mod:`.cells`), each distinct value is checked once, and the problems are found with array
operations, reported one line per kind (file, column, how many rows and the first few; ``row N``
is the N-th data row in every format).  :func:`read_trials` is one step per function: columns,
drop rules, participants, trials, derived columns, labels, rating, experience.
"""

from __future__ import annotations

import re
import shlex
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..vocab import ACTIONS, CATEGORICAL_COLUMNS, EXPERIENCES, HUMAN_ACTIONS
from .cells import NAN_MARK, Column, DataError, Problems, RawLog, shorten, spellings, value_ids
from .folders import FILE_COLUMN
from .layouts import join_file, unpivot
from .levels import category_codes, input_codes, one_rating_per_block, rating_codes
from .mapping import CANONICAL, RATING, ColumnMapping, as_mapping, label_key
from .order import check_trials, order_trials, trial_numbers
from .sources import DELIMITERS, PARQUET_SUFFIXES, load_source


def read_trials(
    source: Any,
    mapping: ColumnMapping | Mapping | str | Path | None = None,
    *,
    required: Sequence[str] | None = None,
    delimiter: str | None = None,
    sheet: str | None = None,
    check_experience: bool = True,
) -> pd.DataFrame:
    """Read, map and validate a trial log (CSV/TSV, Parquet, JSON lines, a JSON array, an Excel
    workbook, an SPSS, Stata or SAS file, or a DataFrame).

    Returns the canonical columns in order (``participant`` and the categorical
    columns as pandas categoricals with the canonical labels, ``trial`` as int64,
    an unrecorded ``human_action`` as missing), followed by every extra column.
    Rows keep the file's order, less the rows a drop rule of the mapping leaves out
    (their counts are in ``frame.attrs["dropped"]``: one ``(rule, rows)`` pair per rule);
    the mapping's ``wide`` and ``explode`` make one row per trial of a row or record first
    (a record's trials in order), its ``join`` adds a second file's columns (trials without a
    row there are counted in ``frame.attrs["joined"]``).
    ``required`` names the canonical columns that must be present (default: all
    six; participant, trial and human_action for a mapping that declares ``inputs``); an
    absent optional column comes back empty.  Each of the mapping's ``inputs`` becomes a
    column named by the input (a categorical of its declared levels; ``frame.attrs["inputs"]``
    holds every input's levels).  A CSV's delimiter is taken
    from ``delimiter`` (or the mapping's), else ``.tsv`` means tab, else the most
    frequent of ``, ; TAB |`` in the header.  ``sheet`` (or the mapping's) names an Excel
    workbook's sheet (default: its only visible sheet holding values).  ``check_experience`` checks the
    experience rule of the data format where the columns it needs are present.
    Raises :class:`DataError` listing every kind of problem at once.
    """
    mapping = as_mapping(mapping)
    required = _required(mapping, required)
    theirs = {c: mapping.columns.get(c, c) for c in CANONICAL}
    markers = frozenset(m.strip().lower() for m in (mapping.missing or ()))
    raw = load_source(source, delimiter or mapping.delimiter, markers, mapping.explode, sheet or mapping.sheet)
    name = raw.name
    if raw.from_files and theirs["participant"] not in raw.columns and "participant" not in mapping.columns:
        theirs["participant"] = FILE_COLUMN  # a folder of logs without participant ids: one participant per file
    if mapping.wide is not None:
        raw = unpivot(raw, mapping.wide)
    joined: list[str] = []
    if mapping.join is not None:
        raw, joined = join_file(
            raw,
            load_source(mapping.join["file"], None, markers, sheet=mapping.join.get("sheet")),
            mapping.join,
            theirs["participant"],
        )
    known = _check_columns(raw, mapping, theirs, required, delimiter)
    get = _Columns(raw)  # the file's columns as codes, each converted once
    rowid, dropped = _drop_rows(raw, mapping, markers, get)
    get.keep(rowid)
    present = [c for c in CANONICAL if theirs[c] in known]
    canonical = [theirs[c] for c in present if theirs[c] in raw.columns]
    if raw.release is not None:  # the canonical columns as codes; the file's copy of them goes
        for c in canonical:
            get(c)
        raw.release(canonical)
    problems = Problems(rowid, raw.place)

    def column(c: str) -> str:
        return f"column {theirs[c]!r}"

    pcode, ids = _participants(problems, get(theirs["participant"]), column("participant"))
    trial, perm = _trials(problems, get, mapping, pcode, ids, column("trial"))
    _derive(get, mapping, pcode, perm)
    codes = _categories(problems, get, mapping, present, column)
    nothing_recorded = "human_action" in present and not (codes["human_action"] >= 0).any()
    if "human_action" in required and nothing_recorded and not any(column("human_action") in x for x in problems.lines):
        problems.lines.append(
            f"{column('human_action')}: no trial has a recorded human action (every cell is empty): nothing to fit"
        )
    rated = _ratings(problems, get, mapping, pcode, perm)
    by_input = {inp: input_codes(problems, get(mapping.input_column(inp)), mapping, inp) for inp in mapping.inputs}
    if check_experience and mapping.experience_rule is not False:
        _check_experience(problems, codes, mapping, present, column)
    if problems.lines:
        raise DataError(problems.lines, name)
    frame = _frame(pcode, ids, trial, codes, rated, by_input, mapping)
    del codes
    used = {theirs[c] for c in present} | {mapping.input_column(inp) for inp in mapping.inputs}
    if mapping.order is None:
        used.add(theirs["trial"])
    if rated is not None:
        used.add(mapping.rating["column"])  # type: ignore[index]
    extras = [c for c in raw.columns if c not in used and c not in frame.columns]
    if extras:
        more = raw.extras(extras)
        for c in extras:
            values = more[c] if rowid is None else more[c].iloc[rowid]
            frame[c] = values.to_numpy() if isinstance(source, pd.DataFrame) else values.values
    frame.attrs["dropped"] = dropped
    frame.attrs["joined"] = joined
    return frame


def _required(mapping: ColumnMapping, required: Sequence[str] | None) -> tuple[str, ...]:
    """The canonical columns the log must have: participant and trial always (trial unless the
    mapping orders the trials by its own columns)."""
    if required is None:  # a mapping that declares inputs is for a model of those: the canonical inputs are optional
        required = ("participant", "trial", "human_action") if mapping.inputs else CANONICAL
    required = (*[c for c in ("participant", "trial") if c not in required], *required)
    return tuple(c for c in required if c != "trial" or mapping.order is None)


def _check_columns(
    raw: RawLog, mapping: ColumnMapping, theirs: dict[str, str], required: tuple[str, ...], delimiter: str | None
) -> set[str]:
    """Every column the mapping names must exist, in the log or derived from earlier columns;
    returns the columns known (the log's and the derived ones)."""
    present = f"; columns present: {raw.columns}"
    lines = []
    known = set(raw.columns)
    for new, d in mapping.derived.items():
        lines += [f"derived column {new!r}: no column {s!r}{present}" for s in d.get("equal", [d.get("shift")]) if s not in known]
        known.add(new)
    lines += [f"drop rule: no column {r['column']!r}{present}" for r in mapping.drop if r["column"] not in raw.columns]
    lines += [f"order: no column {c!r}{present}" for c in mapping.order or () if c not in raw.columns]
    rating = mapping.rating or {}
    for c, what in (
        (rating.get("column"), "the mapping's rating column"),
        (rating.get("per"), "the block of the mapping's rating, 'per'"),
    ):
        if c is not None and c not in known:
            lines.append(f"missing column {c!r} ({what}){present}")
    for inp in mapping.inputs:
        src = mapping.input_column(inp)
        if src not in known:
            lines.append(f"missing column {src!r} (the mapping's input {inp!r}){present}")
        elif inp != src and inp in raw.columns:
            lines.append(f"input {inp!r}: the log has a column {inp!r} too; give the input another name")
    absent = [c for c in required if theirs[c] not in known]
    lines += [
        f"missing column {theirs[c]!r}{f' (mapped from canonical {c!r})' if theirs[c] != c else ''}{present}" for c in absent
    ]
    if lines:
        hints = _missing_column_hint(absent, raw.columns, delimiter or mapping.delimiter, theirs) if absent else []
        raise DataError(lines + hints, raw.name)
    if raw.n == 0:
        raise DataError(["the log has no trials (only a header)"], raw.name)
    return known


class _Columns:
    """The log's columns as codes, each read on first use (of the kept rows only, once :meth:`keep`
    has named them), and the derived columns."""

    def __init__(self, raw: RawLog) -> None:
        self.raw, self.n = raw, raw.n
        self.rowid: np.ndarray | None = None
        self.read: dict[str, Column] = {}  # columns read of every row, before some rows were dropped
        self.cols: dict[str, Column] = {}

    def keep(self, rowid: np.ndarray | None) -> None:
        """From now on the rows ``rowid`` only (None: every row)."""
        if rowid is not None:
            self.read, self.cols = self.cols, {}
            self.rowid, self.n = rowid, len(rowid)

    def __call__(self, c: str) -> Column:
        if c not in self.cols:
            col = self.read.pop(c, None)
            col = self.raw.col(c) if col is None else col
            self.cols[c] = col if self.rowid is None else col.take(self.rowid)
        return self.cols[c]


def _drop_rows(
    raw: RawLog, mapping: ColumnMapping, markers: frozenset[str], column: _Columns
) -> tuple[np.ndarray | None, list[tuple[str, int]]]:
    """The rows kept (None: every row) and per drop rule the rows it drops, each rule counted on
    the rows the rules before it left.  Rows with every cell empty (a spreadsheet's formatted but
    unused rows: ``,,,,``; null or NaN in Parquet and JSON) go first, as blank lines do, counted
    as a rule of their own."""
    empty = np.ones(raw.n, dtype=bool)
    for c in raw.columns:  # usually one column tells: no row is empty in the participant's
        cc = column(c)
        empty &= cc.mask([t is None or t == NAN_MARK or not t.strip() for t in cc.texts])
        if not empty.any():
            break
    keep = ~empty
    if not keep.any():
        raise DataError([f"the log has no trials: every cell of its {raw.n:,} rows is empty"], raw.name)
    dropped: list[tuple[str, int]] = [] if keep.all() else [("every cell empty", int((~keep).sum()))]
    for rule in mapping.drop:
        cc = column(rule["column"])
        wanted = {s for v in rule["values"] for s in spellings(label_key(v))}
        blank = "" in wanted or any(str(v).strip().lower() in markers for v in rule["values"])
        hit = cc.mask([t in wanted if t is not None else blank for t in cc.texts]) & keep
        count = int(hit.sum())
        keep &= ~hit
        dropped.append((f"{rule['column']} in {rule['values']}", count))
    if keep.all():
        return None, dropped
    if not keep.any():
        raise DataError([f"every row is dropped by the drop rules ({'; '.join(f'{r}: {k}' for r, k in dropped)})"], raw.name)
    return np.flatnonzero(keep), dropped


def _trials(
    problems: Problems, get: _Columns, mapping: ColumnMapping, pcode: np.ndarray, ids: list[str], head: str
) -> tuple[np.ndarray, np.ndarray | slice | None]:
    """Trial numbers (from the trial column, or counted along the mapping's order columns) and the
    order of the rows by participant and trial (None where the order is broken)."""
    if mapping.order is not None:
        trial, _, perm = order_trials(problems, get, list(mapping.order), pcode, ids)
        return trial, perm
    trial, valid = trial_numbers(problems, get(mapping.columns.get("trial", "trial")), head)
    valid &= pcode >= 0
    if valid.all():  # the usual case: no copies of the columns
        return trial, check_trials(problems, pcode, trial, None, ids, head)
    if valid.any():
        ok = np.flatnonzero(valid)
        check_trials(problems, pcode[ok], trial[ok], ok, ids, head)
    return trial, None


def _derive(get: _Columns, mapping: ColumnMapping, pcode: np.ndarray, perm: np.ndarray | slice | None) -> None:
    """The mapping's derived columns, in the order they are defined."""
    for new, d in mapping.derived.items():
        if "equal" in d:
            a, b = (get(s) for s in d["equal"])
            get.cols[new] = _equal(a, b)
        elif perm is not None:
            fill = None if d.get("fill") is None else label_key(d["fill"])
            get.cols[new] = _shift(get(d["shift"]), pcode, perm, int(d.get("by", 1)), fill)
        else:  # the trial order is broken (reported already): nothing to shift by
            get.cols[new] = Column(np.zeros(get.n, np.int32), [None])


def _categories(
    problems: Problems, get: _Columns, mapping: ColumnMapping, present: list[str], column: Any
) -> dict[str, np.ndarray]:
    """Per categorical column the codes into its canonical labels (-1 = none)."""
    return {
        c: category_codes(problems, get(mapping.columns.get(c, c)), mapping, c, column(c))
        if c in present
        else np.full(get.n, -1, dtype=np.int8)
        for c in CATEGORICAL_COLUMNS
    }


def _ratings(
    problems: Problems, get: _Columns, mapping: ColumnMapping, pcode: np.ndarray, perm: np.ndarray | slice | None
) -> np.ndarray | None:
    """Per row the code of the rating's level (None: the mapping has no rating), kept once per block
    when the rating is given ``per`` block."""
    if mapping.rating is None:
        return None
    rating_col, per = mapping.rating["column"], mapping.rating.get("per")
    rated = rating_codes(problems, get(rating_col), mapping, rating_col)
    if per is not None and perm is not None:
        order = np.arange(get.n) if isinstance(perm, slice) else perm
        rated = one_rating_per_block(problems, rated, pcode, get(per), order, per, rating_col)
    return rated


def _frame(
    pcode: np.ndarray,
    ids: list[str],
    trial: np.ndarray,
    codes: dict[str, np.ndarray],
    rated: np.ndarray | None,
    by_input: dict[str, np.ndarray],
    mapping: ColumnMapping,
) -> pd.DataFrame:
    """The canonical columns as a frame (categoricals with the canonical labels), then the rating and the inputs."""
    frame = pd.DataFrame(
        {
            "participant": pd.Categorical.from_codes(pcode, categories=pd.Index(ids, dtype=object)),
            "trial": trial,
        }
    )
    for c in CATEGORICAL_COLUMNS:
        frame[c] = pd.Categorical.from_codes(codes[c], categories=pd.Index(list(mapping.categories(c)), dtype=object))
    if rated is not None and mapping.rating is not None:
        levels = pd.Index(list(mapping.rating_levels()), dtype=object)
        frame[RATING] = pd.Categorical.from_codes(rated, categories=levels, ordered=True)
        frame.attrs["rating_levels"] = tuple(levels)
        frame.attrs["rating_column"] = mapping.rating["column"]
        frame.attrs["rating_per"] = mapping.rating.get("per")
    for inp, levels in mapping.input_levels().items():
        frame[inp] = pd.Categorical.from_codes(by_input[inp], categories=pd.Index(list(levels), dtype=object))
    if mapping.inputs:
        frame.attrs["inputs"] = mapping.input_levels()
    return frame


def _participants(problems: Problems, pc_: Column, head: str) -> tuple[np.ndarray, list[str]]:
    """Per row the participant's index (-1 = no id), the ids in order of first appearance; empty
    ids and NaNs reported."""
    valid = np.array([t is not None and t != NAN_MARK for t in pc_.texts], dtype=bool)
    # the first row of every distinct value: rows where the code changes are enough
    c = pc_.codes
    first = np.full(len(pc_.texts), len(c), dtype=np.int64)
    change = np.flatnonzero(np.r_[True, c[1:] != c[:-1]]) if len(c) else np.zeros(0, dtype=np.int64)
    np.minimum.at(first, c[change], change)
    seen = np.flatnonzero(valid & (first < len(c)))  # the valid values a row holds, by first row
    seen = seen[np.argsort(first[seen], kind="stable")]
    lookup = np.full(len(pc_.texts), -1, dtype=np.int32)
    named = [str(pc_.texts[j]) for j in seen]
    ids = dict.fromkeys(named)
    if len(ids) == len(named):  # the usual case: one text per distinct value
        lookup[seen] = np.arange(len(seen), dtype=np.int32)
    else:  # values that read as the same id (' P1' and 'P1'): the first one's index
        index = {t: i for i, t in enumerate(ids)}
        lookup[seen] = [index[t] for t in named]
    used = int(c.max()) + 1 if len(c) else 0
    # the codes are the ids' indices already where a file's distinct values are in order
    pcode = c if c.dtype == np.int32 and np.array_equal(lookup[:used], np.arange(used)) else pc_.per_row(lookup)
    empty = pc_.mask([t is None for t in pc_.texts])
    problems.rows(f"{head}: empty participant id", np.flatnonzero(empty))
    problems.rows(f"{head}: value is NaN", np.flatnonzero((pcode < 0) & ~empty))
    return pcode, list(ids)


def _equal(a: Column, b: Column) -> Column:
    """``true`` where two columns hold the same value (numbers by value); empty where either is
    empty, NaN where either is NaN (an error where the column needs a value)."""
    keys: dict[str, int] = {}
    va, vb = value_ids(a, keys, nan=-2), value_ids(b, keys, nan=-2)
    codes = (va == vb).astype(np.int32)
    codes[(va == -1) | (vb == -1)] = 2
    codes[(va == -2) | (vb == -2)] = 3
    return Column(codes, ["false", "true", None, NAN_MARK])


def _shift(col: Column, pcode: np.ndarray, perm: np.ndarray | slice, by: int, fill: str | None = None) -> Column:
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
    return Column(codes, [*col.texts, fill])


def _check_experience(
    problems: Problems, codes: dict[str, np.ndarray], mapping: ColumnMapping, present: list[str], column: Any
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


def write_trials(frame: pd.DataFrame, path: str | Path) -> None:
    """Write a trial table as CSV or Parquet, chosen by the suffix of ``path``."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in PARQUET_SUFFIXES:
        frame.to_parquet(path, index=False)
    elif suffix == ".csv":
        write_csv(frame, path)
    else:
        raise DataError([f"unknown file type {suffix!r}: use .csv or .parquet"], str(path))


QUOTED = re.compile(r'[,"\r\n]')  # a field with one of these is quoted in a CSV


def write_csv(frame: pd.DataFrame, path: str | Path) -> None:
    """``frame.to_csv(path, index=False)``, byte for byte, written by Arrow's CSV writer when every
    column is text, whole numbers, float64 or true/false and no field needs quotes (each column's
    distinct values formatted once: ``trustseek simulate`` of 100,000 participants, 7.1 million
    trials, writes its file in 12-14 s instead of 48 s); by pandas otherwise."""
    import pyarrow as pa
    import pyarrow.csv as pcsv

    names = [str(c) for c in frame.columns]
    # pandas' cases: a name to quote, or a single column (its empty field is quoted, as a row)
    plain = frame.shape[1] > 1 and not any(QUOTED.search(n) for n in names)
    columns = [_csv_column(frame.iloc[:, j]) for j in range(frame.shape[1])] if plain else []
    if not plain or any(c is None for c in columns):
        frame.to_csv(path, index=False)
        return
    with open(path, "wb") as fh:
        fh.write((",".join(names) + "\n").encode())
        table = pa.table(dict(zip(map(str, range(len(names))), columns, strict=True)))
        pcsv.write_csv(table, fh, write_options=pcsv.WriteOptions(include_header=False, quoting_style="none"))


def _csv_column(col: pd.Series) -> Any:
    """``col`` as an Arrow array whose CSV text is pandas' (codes into its distinct values, formatted
    as pandas formats them, missing values empty), or None where pandas' own writer is needed."""
    import pyarrow as pa

    dtype = col.dtype
    if dtype.kind in "iu" and isinstance(dtype, np.dtype):
        return pa.array(col.to_numpy())
    if dtype == np.float64 or dtype == np.bool_:
        # distinct bit patterns (-0.0 is not 0.0), each formatted once as pandas does; NaN empty
        codes, bits = pd.factorize(col.to_numpy().view(np.uint64 if dtype == np.float64 else np.uint8))
        values = np.asarray(bits).view(dtype)
        text = values.astype(str).astype(object)
        if dtype == np.float64:
            text[np.isnan(values)] = ""
        return _dictionary(codes, list(text))
    if isinstance(dtype, pd.CategoricalDtype) or dtype.kind == "O" or pd.api.types.is_string_dtype(dtype):
        codes, uniques = pd.factorize(col)
        values = list(uniques)
        if not all(type(v) is str and not QUOTED.search(v) for v in values):
            return None
        return _dictionary(codes, values)
    return None


def _dictionary(codes: np.ndarray, values: list[str]) -> Any:
    """Arrow's dictionary array of ``codes`` into ``values`` (a negative code: missing)."""
    import pyarrow as pa

    return pa.DictionaryArray.from_arrays(pa.array(codes, mask=codes < 0, type=pa.int32()), pa.array(values, type=pa.string()))


def example_path(name: str = "paper_trials.csv") -> Path:
    """Path of an example file shipped in ``trustseek/examples``."""
    return Path(__file__).resolve().parent.parent / "examples" / name


def _plain(name: str) -> str:
    """A column name without case, spacing and word style: ``Robot Action``, ``robot-action``,
    ``ROBOT_ACTION`` and ``robotAction`` read ``robotaction``."""
    return re.sub(r"[\s_\-.]+", "", name).lower()


def _missing_column_hint(
    missing: list[str], present: list[str], sep: str | None, sought: dict[str, str] | None = None
) -> list[str]:
    """Hints for the canonical columns ``missing`` (``sought`` under the names a mapping gave them):
    the flags naming a column of the log written in another style, and what else may help."""
    sought = sought or {}
    alike = {c: [p for p in present if _plain(p) in (_plain(c), _plain(sought.get(c, c)))] for c in missing}
    named = " ".join(f"--column {shlex.quote(f'{c}={shorten(found[0], 80)}')}" for c, found in alike.items() if len(found) == 1)
    hints = [f"columns named in another style: {named}"] if named else []
    hints.append("name another column with --column canonical=theirs or a --mapping file (Python: ColumnMapping)")
    if "trial" in missing and not alike["trial"]:
        times = [p for p in present if re.search("time|stamp|date|onset|start", p, re.IGNORECASE)]
        order = shlex.quote(times[0]) if times else "COLUMN"
        hints.append(f"trials without numbers are put in order by a column of times or numbers: --order {order}")
    if any(c in missing and not alike[c] for c in ("complexity", "robot_action")):
        hints.append(
            "a log without complexity/robot_action can be fitted by a model that does not use them: "
            "--transitions-on experience --emissions-on none"
        )
    if len(present) == 1 and any(d in present[0] for d in DELIMITERS if d != sep):
        hints.append(f"the header has a single column {present[0]!r}: is the file separated by another delimiter?")
    return [f"hint: {h}" for h in hints]
