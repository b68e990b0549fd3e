"""A second file joined onto a log by participant (and block): the mapping's ``join``.

The second file (CSV, JSON or Parquet) is read as a log is; its columns are added to the log
as read (:class:`~.sources.RawLog`) before the canonical columns are checked, so a joined
column is mapped, rated or used as an input like any other.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from .cells import Column, DataError, Problems, value_ids
from .sources import RawLog, load_source


def _keys(raw: Any, on: list[str], tables: list[dict[str, int]]) -> np.ndarray:
    """Per row of ``raw`` the ids of its values in the ``on`` columns, (rows, len(on))."""
    return np.stack([value_ids(raw.col(c), t) for c, t in zip(on, tables, strict=True)], axis=1)


def join_file(raw: Any, spec: dict[str, Any], participant: str, missing: frozenset[str]) -> tuple[Any, list[str]]:
    """``raw`` with the columns of the second file ``spec["file"]`` joined on ``spec["on"]``
    (default: the participant column, and ``block`` when both files have it; a dict maps the
    log's key columns to the second file's).  Duplicate keys in
    the second file and its keys that match no row of the log are errors, by count and
    participant; rows of the log without a match get empty cells (counted in the notes returned)."""
    second = load_source(spec["file"], None, missing)
    sname = second.name
    given = spec.get("on") or [participant, *(["block"] if "block" in raw.columns and "block" in second.columns else [])]
    pairs = dict(given) if isinstance(given, dict) else {c: c for c in given}  # the log's column -> the second file's
    on, other = list(pairs), list(pairs.values())
    lines = [f"join: no column {c!r} in the log; its columns: {raw.columns}" for c in on if c not in raw.columns]
    lines += [f"join: no column {c!r} in {sname}; its columns: {second.columns}" for c in other if c not in second.columns]
    clash = [c for c in second.columns if c not in other and c in raw.columns]
    lines += [f"join: column {c!r} of {sname} is in the log too; rename one of them" for c in clash]
    if lines:
        raise DataError(lines, raw.name)
    tables: list[dict[str, int]] = [{} for _ in on]
    theirs = _keys(second, other, tables)
    ours = _keys(raw, on, tables)
    texts = [{v: k for k, v in t.items()} for t in tables]
    pi = on.index(participant) if participant in on else 0

    def who(key: np.ndarray) -> str:
        return " / ".join(repr(texts[i].get(int(k), "")) for i, k in enumerate(key))

    p = Problems()
    empty = np.flatnonzero((theirs < 0).any(axis=1))
    p.rows(f"join: empty {' / '.join(other)} in {sname}", empty)
    uniq, inverse, counts = np.unique(theirs, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    dup = np.flatnonzero(counts > 1)
    p.add(
        f"join: {sname} has more than one row for a {' / '.join(other)}",
        [f"{who(uniq[d])} ({counts[d]} rows)" for d in dup],
        len(dup),
        unit="keys",
    )
    # each log row's row of the second file (-1: none), by one integer per key
    radix = np.cumprod([1, *(len(t) + 1 for t in tables[:-1])]).astype(np.int64)
    k2, k1 = (theirs + 1) @ radix, (ours + 1) @ radix
    by = np.argsort(k2, kind="stable")
    at = np.minimum(np.searchsorted(k2[by], k1), max(len(k2) - 1, 0))
    found = (k2[by][at] == k1) & (ours >= 0).all(axis=1) if len(k2) else np.zeros(raw.n, dtype=bool)
    match = np.where(found, by[at] if len(k2) else 0, -1)
    hit = np.zeros(len(uniq), dtype=bool)  # per distinct key of the second file: some log row has it
    hit[inverse[match[match >= 0]]] = True
    unmatched = np.flatnonzero(~hit[inverse] & (theirs >= 0).all(axis=1))
    if len(unmatched):
        per = _by_participant(theirs[unmatched, pi], texts[pi])
        p.lines.append(f"join: rows that match no trial of {raw.name} by {' / '.join(on)}: {len(unmatched)} ({per})")
    if p.lines:
        raise DataError(p.lines, sname)
    notes = []
    lost = np.flatnonzero(match < 0)
    if len(lost):
        per = _by_participant(ours[lost, pi], texts[pi])
        notes.append(f"{len(lost)} trials have no row in {sname} (their joined cells are empty): {per}")
    added = [c for c in second.columns if c not in other]

    def col(c: str) -> Column:
        if c not in added:
            return raw.col(c)
        sc = second.col(c)
        return Column(np.where(match >= 0, sc.codes[np.maximum(match, 0)], len(sc.texts)).astype(np.int32), [*sc.texts, None])

    def extras(cs: list[str]) -> pd.DataFrame:
        mine = [c for c in cs if c not in added]
        frame = raw.extras(mine) if mine else pd.DataFrame(index=pd.RangeIndex(raw.n))
        more = [c for c in cs if c in added]
        if more:
            other = second.extras(more).reindex(match).reset_index(drop=True)
            for c in more:
                frame[c] = other[c].to_numpy()
        return frame[cs]

    release = raw.release and (lambda cs: raw.release([c for c in cs if c not in added]))
    return RawLog(raw.name, raw.n, [*raw.columns, *added], col, extras, release), notes


def _by_participant(codes: np.ndarray, texts: dict[int, str]) -> str:
    who, count = np.unique(codes, return_counts=True)
    shown = ", ".join(f"{texts.get(int(w), '')!r} {c}" for w, c in zip(who[:20], count[:20], strict=True))
    more = f", ... ({len(who) - 20} more participants)" if len(who) > 20 else ""
    return f"by participant, {len(who)}: {shown}{more}"
