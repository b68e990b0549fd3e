"""Trial logs: read, map, validate and write the canonical one-row-per-trial table.

Canonical columns, in order (see ``docs/data-format.md``)::

    participant  trial  complexity  robot_action  human_action  experience

``human_action`` may be empty (not recorded: unobserved).  Extra columns are kept.
A log from another study is read through a :class:`ColumnMapping`: its column
names (``columns``: canonical -> theirs) and category labels (``labels``:
canonical column -> {their label: canonical label}).

Reading is column-wise: every column becomes integer codes into its few distinct
values (:mod:`.cells`), each distinct value is checked once, and the problems are found
with array operations.  Problems are reported through :class:`~.cells.DataError`, one
line per kind of problem with the file, the column, how many rows and the first few of
them (``row N`` is the N-th data row, the header not counted, in every format).  The
mapping lives in :mod:`.mapping`, the file formats in :mod:`.sources`; this module reads
(:func:`read_trials`: columns, labels, order, trial numbers, experience) and writes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..vocab import ACTIONS, EXPERIENCES, HUMAN_ACTIONS
from .cells import NAN_MARK, SHOWN, Column, DataError, Problems, same_value_key, spellings
from .joins import join_file
from .levels import input_codes, one_rating_per_block, rating_codes
from .mapping import CANONICAL, CATEGORICAL, RATING, ColumnMapping, as_mapping, label_key
from .sources import load_source, missing_column_hint
from .wide import unpivot

MAX_TRIAL = 2**31 - 1
ALL = slice(None)  # the order of rows that are in trial order already


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
    frequent of ``, ; TAB |`` in the header.  ``check_experience`` checks the
    experience rule of the data format where the columns it needs are present.
    Raises :class:`DataError` listing every kind of problem at once.
    """
    mapping = as_mapping(mapping)
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
    raw = load_source(source, delimiter or mapping.delimiter, markers, mapping.explode)
    name = raw.name
    if mapping.wide is not None:
        raw = unpivot(raw, mapping.wide)
    joined: list[str] = []
    if mapping.join is not None:
        raw, joined = join_file(raw, mapping.join, theirs["participant"], markers)
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
    per = mapping.rating.get("per") if mapping.rating is not None else None
    if per is not None and per not in known:
        lines.append(f"missing column {per!r} (the block of the mapping's rating, 'per'); columns present: {raw.columns}")
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
        hints = missing_column_hint(absent, raw.columns, delimiter or mapping.delimiter) if absent else []
        raise DataError(lines + hints, name)
    if raw.n == 0:
        raise DataError(["the log has no trials (only a header)"], name)

    # rows to drop, each rule counted on the rows the rules before it left
    rowid: np.ndarray | None = None
    keep = np.ones(raw.n, dtype=bool)
    dropped: list[tuple[str, int]] = []
    for rule in mapping.drop:
        cc = raw.col(rule["column"])
        wanted = {s for v in rule["values"] for s in spellings(label_key(v))}
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
    cols: dict[str, Column] = {}

    def get(c: str) -> Column:
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
    problems = Problems(rowid)

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
            cols[new] = _shift(get(d["shift"]), pcode, perm, int(d.get("by", 1)), None if fill is None else label_key(fill))
        else:  # the trial order is broken (reported above): nothing to shift by
            cols[new] = Column(np.zeros(n, np.int32), [None])

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
            if t == NAN_MARK:
                kind[j] = 2
                continue
            label = next((table[s] for s in spellings(t) if s in table), t)
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
        near = {
            t: a
            for j, t in enumerate(cc.texts)
            if kind[j] == 3 and t is not None
            for a in allowed
            if t.strip().lower() == a.lower()
        }
        if near and (k == 3).any():
            flags = " ".join(f"--label {c}:{t.strip()}={a}" for t, a in list(near.items())[:SHOWN])
            one = len(near) == 1
            problems.lines.append(
                f"hint: {', '.join(repr(t) for t in list(near)[:SHOWN])} {'is a label' if one else 'are labels'} written "
                f"in another case or with spaces: map {'it' if one else 'them'} with {flags} (or a mapping file's labels)"
            )
        del k
    nothing_recorded = "human_action" in present and not (codes["human_action"] >= 0).any()
    if "human_action" in required and nothing_recorded and not any(column("human_action") in x for x in problems.lines):
        problems.lines.append(
            f"{column('human_action')}: no trial has a recorded human action (every cell is empty): nothing to fit"
        )

    rated = None
    if rating_col is not None:
        rc = cols[rating_col] if rating_col in cols else get(rating_col)
        rated = rating_codes(problems, rc, mapping, rating_col)
        if per is not None and perm is not None:
            order = np.arange(n) if isinstance(perm, slice) else perm
            rated = one_rating_per_block(problems, rated, pcode, cols[per] if per in cols else get(per), order, per, rating_col)
    by_input = {
        inp: input_codes(problems, cols[src] if src in cols else get(src), mapping, inp, src)
        for inp in mapping.inputs
        for src in (mapping.input_column(inp),)
    }
    if check_experience and mapping.experience_rule is not False:
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
    if rated is not None and rating_col is not None:
        levels = pd.Index(list(mapping.rating_levels()), dtype=object)
        frame[RATING] = pd.Categorical.from_codes(rated, categories=levels, ordered=True)
        frame.attrs["rating_levels"] = tuple(levels)
        frame.attrs["rating_column"] = rating_col
        frame.attrs["rating_per"] = per
        used.add(rating_col)
    for inp, levels in mapping.input_levels().items():
        frame[inp] = pd.Categorical.from_codes(by_input[inp], categories=pd.Index(list(levels), dtype=object))
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
    frame.attrs["joined"] = joined
    return frame


def _participant_codes(pc_: Column) -> tuple[np.ndarray, list[str]]:
    """Per row the participant's index (-1 = no id), the ids in order of first appearance."""
    valid = np.array([t is not None and t != NAN_MARK for t in pc_.texts], dtype=bool)
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


def _trial_numbers(problems: Problems, tc: Column, column: str) -> tuple[np.ndarray, np.ndarray]:
    """Trial numbers (integers >= 0; the distinct values are parsed once) and where they are valid."""
    t_lookup = np.zeros(len(tc.texts), dtype=np.int64)
    t_kind = np.zeros(len(tc.texts), dtype=np.int8)  # 0 ok, 1 empty, 2 NaN, 3 not an integer >= 0
    for j, t in enumerate(tc.texts):
        if t is None:
            t_kind[j] = 1
        elif t == NAN_MARK:
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


def _order_values(problems: Problems, cc: Column, name: str) -> tuple[np.ndarray, np.ndarray]:
    """An order column's sort key per row (numbers, else timestamps) and where it is valid."""
    texts = [t for t in cc.texts if t is not None and t != NAN_MARK]
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
    problems: Problems, get: Any, order: list[str], pcode: np.ndarray, ids: list[str]
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
        problems.lines[-1] += f'; {offenders(ps[dup], ids)}: add a column to --order or the mapping\'s "order"'
        return trial, valid, None
    lengths = np.bincount(pcode, minlength=len(ids))
    offsets = np.cumsum(lengths) - lengths
    trial[perm] = np.arange(n) - offsets[ps] + 1
    return trial, valid, perm


def _equal(a: Column, b: Column) -> Column:
    """``true`` where two columns hold the same value (numbers by value); empty where either is
    empty, NaN where either is NaN (an error where the column needs a value)."""
    keys: dict[str, int] = {}

    def ids(col: Column) -> np.ndarray:
        out = np.full(len(col.texts), -1, dtype=np.int64)  # -1 empty, -2 NaN
        for j, t in enumerate(col.texts):
            if t == NAN_MARK:
                out[j] = -2
            elif t is not None:
                out[j] = keys.setdefault(same_value_key(t), len(keys))
        return out

    va, vb = ids(a)[a.codes], ids(b)[b.codes]
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


def _check_trials(
    problems: Problems, p: np.ndarray, t: np.ndarray, rows: np.ndarray | None, ids: list[str], column: str
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
        problems.lines[-1] += (
            f"; {offenders(p[order[dup]], ids)}: a trial number that restarts in every block or session needs "
            '--order block,trial or the mapping\'s "order" (e.g. "order": ["block", "trial"]); a participant '
            "who took the study twice needs an id per session"
        )
        return None
    return order if rows is None else rows[order]


LISTED = 100  # participants listed by name in a duplicate-trial error


def offenders(codes: np.ndarray, ids: list[str]) -> str:
    """Every participant among ``codes`` (one per offending row) with its count of rows."""
    who, count = np.unique(codes, return_counts=True)
    per = ", ".join(f"{ids[w]!r} {c}" for w, c in zip(who[:LISTED], count[:LISTED], strict=True))
    more = f", ... ({len(who) - LISTED} more participants)" if len(who) > LISTED else ""
    return f"by participant, {len(who)} ({per}{more})"


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
