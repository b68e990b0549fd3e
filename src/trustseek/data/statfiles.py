"""SPSS, Stata and SAS data files as trial logs, read with pyreadstat.

A variable with value labels is read as its labels (what SPSS shows with value labels on: ``rely``
where the file holds ``1``), a code without a label as the code; a missing value (system-missing,
or one the file declares missing) is an empty cell; a date as its ISO text.  ``row N`` is the N-th
case, as the data view numbers them.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import pandas as pd

from .cells import DataError, RawLog, column_from_pandas, shorten

READ_SECONDS = 60  # the longest a file is read (a second more per MB) before its reader is stopped
#: by suffix, the reader of pyreadstat and the statistics package whose data the file holds
READERS = {
    ".sav": ("read_sav", "SPSS"),
    ".zsav": ("read_sav", "SPSS"),
    ".por": ("read_por", "SPSS"),
    ".dta": ("read_dta", "Stata"),
    ".sas7bdat": ("read_sas7bdat", "SAS"),
    ".xpt": ("read_xport", "SAS"),
}


def load_statfile(path: Path, name: str, missing: frozenset[str]) -> RawLog:
    """The log a statistics package's data file holds."""
    frame, labels = _read_apart(path, name)
    columns = {c: _cells(frame[c], labels.get(c, {})) for c in frame.columns}
    frame = pd.DataFrame(columns, index=pd.RangeIndex(len(frame)))
    return RawLog(
        name,
        len(frame),
        [str(c) for c in frame.columns],
        lambda c: column_from_pandas(frame[c], missing),
        lambda cs: frame[cs].infer_objects().reset_index(drop=True),
    )


def _read(path: str, suffix: str) -> tuple[pd.DataFrame, dict] | str:
    """The file's data and value labels, or what is wrong with it."""
    import pyreadstat

    try:
        frame, meta = getattr(pyreadstat, READERS[suffix][0])(path)  # the codes, with the labels in meta
    except pyreadstat.ReadstatError as exc:
        return f"cannot read the file as {READERS[suffix][1]} data: {shorten(str(exc), 200)}"
    except OSError as exc:
        return f"cannot read the file: {exc.strerror or exc}"
    return frame, dict(getattr(meta, "variable_value_labels", {}) or {})


def _child(path: str, suffix: str, conn: Any) -> None:
    import faulthandler

    faulthandler.disable()  # a crash here is the parent's to say (pytest's handler would print a trace)
    try:
        conn.send(_read(path, suffix))
    except Exception as exc:  # whatever the reader raises is said, not raised, in the parent
        conn.send(f"cannot read the file as {READERS[suffix][1]} data: {type(exc).__name__}: {shorten(str(exc), 200)}")
    conn.close()


def _read_apart(path: Path, name: str) -> tuple[pd.DataFrame, dict]:
    """:func:`_read` in a forked process: readstat's C parser can crash on a damaged file (a
    segmentation fault on a damaged .sav), which would end the command without a word."""
    import multiprocessing as mp

    import pyreadstat  # noqa: F401  (here, once: each forked reader has it without importing it, 0.2 s)

    suffix = path.suffix.lower()
    if "fork" not in mp.get_all_start_methods():  # no fork (Windows): read here
        got = _read(str(path), suffix)
    else:
        ctx = mp.get_context("fork")
        receive, send = ctx.Pipe(duplex=False)
        child = ctx.Process(target=_child, args=(str(path), suffix, send), daemon=True)
        child.start()
        send.close()
        seconds = READ_SECONDS + path.stat().st_size / 1e6  # and a second more per MB
        deadline = time.monotonic() + seconds
        while not receive.poll(0.05) and child.is_alive() and time.monotonic() < deadline:
            pass
        kind = f"cannot read the file as {READERS[suffix][1]} data"
        try:
            got = receive.recv() if receive.poll() else f"{kind}: the reader did not finish in {seconds:.0f} s"
        except EOFError:  # the reader died without an answer
            child.join()
            got = f"{kind}: the reader stopped on it (exit code {child.exitcode}): the file is damaged"
        if child.is_alive() and not isinstance(got, tuple):
            child.kill()
        child.join()
    if isinstance(got, str):
        raise DataError([got], name)
    return got


def _cells(values: pd.Series, labels: dict) -> pd.Series:
    """A variable's cells as Python values: a labelled code as its label, a missing value as None."""
    out = values.astype(object).where(values.notna(), None)
    if labels:
        out = out.map(lambda v: labels.get(v, v) if v is not None else None)
    return out
