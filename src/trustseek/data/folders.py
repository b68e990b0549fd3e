"""Several trial logs read as one (a folder's files, or files given together): each file's rows in
turn, the same columns in each, a column naming each trial's file, and locations by file and row."""

from __future__ import annotations

import numpy as np
import pandas as pd

from .cells import SHOWN, Column, DataError, RawLog

#: the column a log of several files adds: the name of each trial's file, less its suffix
FILE_COLUMN = "file"


def stacked(raws: list[RawLog], labels: list[str], stems: list[str], name: str) -> RawLog:
    """The logs ``raws`` as one, each file named by its label in messages and by its stem in the
    :data:`FILE_COLUMN` column (unless the files have a column of that name); a file whose columns
    are not the first's is an error naming what it lacks and has."""
    columns = raws[0].columns
    lines = [
        f"{t}: its columns are not those of {labels[0]}: lacks {sorted(set(columns) - set(r.columns))}, "
        f"has {sorted(set(r.columns) - set(columns))} too"
        for t, r in zip(labels, raws, strict=True)
        if set(r.columns) != set(columns)
    ]
    if lines:
        raise DataError(lines[:SHOWN] + ([f"... ({len(lines) - SHOWN} more files)"] if len(lines) > SHOWN else []), name)
    sizes = np.array([r.n for r in raws])
    starts = np.cumsum(sizes) - sizes
    added = [FILE_COLUMN] if FILE_COLUMN not in columns else []

    def col(c: str) -> Column:
        if c == FILE_COLUMN and added:
            return Column(np.repeat(np.arange(len(raws), dtype=np.int32), sizes), [*stems, None], last_unused=True)
        merged: dict[str | None, int] = {}
        parts = []
        for r in raws:
            one = r.col(c)
            parts.append(np.array([merged.setdefault(t, len(merged)) for t in one.texts], dtype=np.int32)[one.codes])
        return Column(np.concatenate(parts), list(merged))

    def extras(cs: list[str]) -> pd.DataFrame:
        own = [c for c in cs if c not in added]
        frame = pd.concat([r.extras(own) for r in raws], ignore_index=True) if own else pd.DataFrame(index=range(sizes.sum()))
        if added and FILE_COLUMN in cs:
            frame[FILE_COLUMN] = np.repeat(np.array(stems, dtype=object), sizes)
        return frame[cs]

    def release(cs: list[str]) -> None:
        for r in raws:
            if r.release is not None:
                r.release([c for c in cs if c in r.columns])

    def place(i: int) -> str:
        k = int(np.searchsorted(starts, i, side="right")) - 1
        return f"{labels[k]} row {i - starts[k] + 1}"

    return RawLog(name, int(sizes.sum()), [*columns, *added], col, extras, release, place, True)
