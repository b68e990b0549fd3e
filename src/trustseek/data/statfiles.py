"""SPSS, Stata and SAS data files as trial logs, read with pyreadstat.

A variable with value labels is read as its labels (what SPSS shows with value labels on: ``rely``
where the file holds ``1``), a code without a label as the code; a missing value (system-missing,
or one the file declares missing) is an empty cell; a date as its ISO text.  ``row N`` is the N-th
case, as the data view numbers them.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from .cells import DataError, RawLog, column_from_pandas, shorten

#: the readers of pyreadstat, by suffix
READERS = {
    ".sav": "read_sav",
    ".zsav": "read_sav",
    ".por": "read_por",
    ".dta": "read_dta",
    ".sas7bdat": "read_sas7bdat",
    ".xpt": "read_xport",
}


def load_statfile(path: Path, name: str, missing: frozenset[str]) -> RawLog:
    """The log a statistics package's data file holds."""
    import pyreadstat

    read = getattr(pyreadstat, READERS[path.suffix.lower()])
    try:
        frame, meta = read(str(path))  # the codes, with the labels in meta
    except pyreadstat.ReadstatError as exc:
        raise DataError([f"cannot read the file as {_kind(path)} data: {shorten(str(exc), 200)}"], name) from None
    except OSError as exc:
        raise DataError([f"cannot read the file: {exc.strerror or exc}"], name) from None
    labels = getattr(meta, "variable_value_labels", {}) or {}
    columns = {c: _cells(frame[c], labels.get(c, {})) for c in frame.columns}
    frame = pd.DataFrame(columns, index=pd.RangeIndex(len(frame)))
    return RawLog(
        name,
        len(frame),
        [str(c) for c in frame.columns],
        lambda c: column_from_pandas(frame[c], missing),
        lambda cs: frame[cs].infer_objects().reset_index(drop=True),
    )


def _cells(values: pd.Series, labels: dict) -> pd.Series:
    """A variable's cells as Python values: a labelled code as its label, a missing value as None."""
    out = values.astype(object).where(values.notna(), None)
    if labels:
        out = out.map(lambda v: labels.get(v, v) if v is not None else None)
    return out


def _kind(path: Path) -> str:
    suffix = path.suffix.lower()
    return "SPSS" if suffix in (".sav", ".zsav", ".por") else "Stata" if suffix == ".dta" else "SAS"
