"""Trial order: trial numbers, the order a mapping's ``order`` columns give, and duplicate trials.

Every check works on integer codes with array operations; problems go to
:class:`~.cells.Problems` (one line per kind, with counts and the first rows).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pandas as pd

from .cells import NAN_MARK, SHOWN, Column, Problems, level_lookup, report_kinds

MAX_TRIAL = 2**31 - 1
ALL = slice(None)  # the order of rows that are in trial order already
LISTED = 100  # participants listed by name in a duplicate-trial error


def trial_numbers(problems: Problems, tc: Column, column: str) -> tuple[np.ndarray, np.ndarray]:
    """Trial numbers (integers >= 0; the distinct values are parsed once) and where they are valid."""

    def number(t: str) -> int | None:
        try:
            f = float(t)
        except ValueError:
            return None
        return int(f) if f.is_integer() and 0 <= f <= MAX_TRIAL else None

    t_lookup, t_kind = level_lookup(tc, {}, number, np.int64)
    expect = "expected an integer: trials numbered in increasing order, e.g. 1, 2, ... or 0, 1, ..."
    heads = (
        f"{column}: empty trial index ({expect})",
        f"{column}: value is NaN ({expect})",
        f"{column}: value is not an integer between 0 and {MAX_TRIAL}",
    )
    tkind = report_kinds(problems, tc, t_kind, heads)
    return tc.per_row(t_lookup), np.ones(len(tc.codes), dtype=bool) if tkind is None else tkind == 0


def order_values(problems: Problems, cc: Column, name: str) -> tuple[np.ndarray, np.ndarray]:
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


def order_trials(
    problems: Problems, get: Any, order: list[str], pcode: np.ndarray, ids: list[str]
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Trials ordered by the ``order`` columns within each participant: numbered 1, 2, ...;
    rows with the same participant and order values are an error."""
    n = len(pcode)
    keys, valid = [], pcode >= 0
    for c in order:
        k, ok = order_values(problems, get(c), c)
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
            f"{problems.where(int(perm[d]))}: same {' / '.join(order)} as {problems.where(int(perm[d - 1]))} "
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


def check_trials(
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

        def at(i: int) -> str:
            return problems.where(int(order[i] if rows is None else rows[order[i]]))

        items = [
            f"{at(d)}: duplicate trial index {t[order[d]]} for participant {ids[p[order[d]]]!r} (first at {at(f)})"
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


def offenders(codes: np.ndarray, ids: list[str]) -> str:
    """Every participant among ``codes`` (one per offending row) with its count of rows."""
    n, per = by_participant(codes, ids.__getitem__, LISTED)
    return f"by participant, {n} ({per})"


def by_participant(codes: np.ndarray, name: Callable[[int], str], listed: int) -> tuple[int, str]:
    """The participants among ``codes`` (one per row): how many, and the first ``listed`` of them
    by ``name``, each with its count of rows (``'P1' 3, 'P2' 1, ... (7 more participants)``)."""
    who, count = np.unique(codes, return_counts=True)
    shown = ", ".join(f"{name(int(w))!r} {c}" for w, c in zip(who[:listed], count[:listed], strict=True))
    more = f", ... ({len(who) - listed} more participants)" if len(who) > listed else ""
    return len(who), shown + more
