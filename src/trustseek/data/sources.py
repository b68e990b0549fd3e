"""The sources a log is read from: CSV (delimiter sniffed; gzip, bzip2 or zstd compressed too),
Parquet, JSON lines, JSON, Excel workbooks (:mod:`.workbooks`), SPSS, Stata and SAS data files
(:mod:`.statfiles`) and data frames.

Each source becomes a :class:`RawLog`: its columns as :class:`~.cells.Column` codes, read
column by column (pyarrow where it can), with the rows numbered as in the file.
"""

from __future__ import annotations

import collections
import csv
import io
import itertools
import json
import mmap
import os
import re
import sys
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..model.jsonfile import special_file
from .cells import SHOWN, Column, DataError, Problems, RawLog, column_from_arrow, column_from_pandas, shorten
from .folders import stacked
from .suffixes import (
    COMPRESSED,
    CSV_SUFFIXES,
    FOLDER_SUFFIXES,
    JSON_SUFFIXES,
    JSONL_SUFFIXES,
    OTHER_SHEET_SUFFIXES,
    PACKED_SUFFIXES,
    PARQUET_SUFFIXES,
    STAT_SUFFIXES,
    WORKBOOK_SUFFIXES,
    kind_suffix,
    object_arrays,
    table_records,
)

DELIMITERS = (",", ";", "\t", "|")
MAX_COLUMNS = 10_000  # a CSV's columns: parsing takes ~6 s at this width and grows with its square
HEADER_BYTES = 1 << 26  # the longest header line read (64 MB: millions of columns)
#: a CSV is parsed in blocks of this size (16 MB), each with its own dictionaries; a smaller file in one
#: block of its own size (a block's buffer is allocated whole)
BLOCK_BYTES = 1 << 24
SPLIT_BYTES = 1 << 26  # a CSV from this size (64 MB) is parsed in parts on two threads
PART_BYTES = 1 << 25  # the size of those parts (32 MB)
SPLIT_SEARCH = 1 << 20  # how far past a part's end a line end is looked for


def _input(path: Path) -> Any:
    """What pyarrow reads a whole file from: its path, or a stream that decompresses it by its
    suffix in any case (pyarrow's own detection knows ``.gz``, not ``.GZ``)."""
    codec = COMPRESSED.get(path.suffix.lower())
    if codec is None:
        return str(path)
    import pyarrow as pa

    return pa.input_stream(str(path), compression=codec)


def _not_decompressed(path: Path, name: str, why: Exception) -> DataError:
    return DataError([f"cannot decompress the file ({COMPRESSED[path.suffix.lower()]}, by its suffix): {why}"], name)


def _sniff(path: Path, sep: str | None, name: str) -> tuple[str, list[str], int]:
    """The delimiter (given, by the file's first line ``sep=;`` as Excel writes and reads it, by
    suffix, or the most frequent candidate in the header outside quoted names), the header names,
    and the lines before the data (the header, after a ``sep=`` line); the whole header line is
    read, however long.  UTF-16 text (Excel's "Unicode Text") is refused here: its ASCII would
    pass as UTF-8 with a NUL byte between every two characters."""
    try:
        with io.BufferedReader(_input(path)) if path.suffix.lower() in COMPRESSED else path.open("rb") as fh:
            head = fh.readline(HEADER_BYTES)
            declared = re.fullmatch(rb"(?:\xef\xbb\xbf)?sep=(.)\r?\n?", head)
            if declared:
                sep = sep or declared.group(1).decode("utf-8", "replace")
                head = fh.readline(HEADER_BYTES)
    except OSError as exc:
        if path.suffix.lower() in COMPRESSED:  # a compressed file that is not what its suffix says
            raise _not_decompressed(path, name, exc) from None
        raise DataError([f"cannot read the file: {exc.strerror or exc}"], name) from None  # (no permission to read it)
    if head[:2] in (b"\xff\xfe", b"\xfe\xff"):
        fix = f"save it as 'CSV UTF-8' or iconv -f UTF-16 -t UTF-8 {shorten(path.name, 80)} > log.csv"
        raise DataError([f"the file is UTF-16 text (as Excel's 'Unicode Text'), not UTF-8: {fix}"], name)
    if b"\x00" in head:
        raise DataError(["the header holds NUL bytes: the file is not UTF-8 text (UTF-16 without its mark, or no text)"], name)
    text = head.decode("utf-8", "replace").lstrip("\ufeff")
    first = text.splitlines()[0] if text.strip() else ""
    if sep is None:
        if kind_suffix(path) == ".tsv":
            sep = "\t"
        else:
            unquoted = re.sub(r'"[^"]*"', "", first)
            counts = {d: unquoted.count(d) for d in DELIMITERS}
            best = max(counts, key=lambda d: counts[d])
            sep = best if counts[best] > 0 else ","
    names = [n.strip() for n in next(csv.reader(io.StringIO(first), delimiter=sep), [])] if first else []
    # a header cell left empty (a spreadsheet's formatted but unused columns: ``a;b;;``) names its column by place
    return sep, [n or f"(column {i})" for i, n in enumerate(names, 1)], 2 if declared else 1


def load_source(
    source: Any, sep: str | None, missing: frozenset[str], explode: dict[str, Any] | None = None, sheet: str | None = None
) -> RawLog:
    """A log as read, one row per trial: ``explode`` (a mapping's entry) turns the per-trial
    lists of a record per participant or block into rows (JSON, JSON lines, Parquet, a data frame);
    ``sheet`` names a workbook's sheet."""
    if isinstance(source, pd.DataFrame):
        if explode is not None:
            return _exploded_frame(source, missing, explode)
        frame = source

        def col(c: str) -> Column:
            return column_from_pandas(frame[c], missing)

        return RawLog("<table>", len(frame), [str(c) for c in frame.columns], col, lambda cs: frame[cs].reset_index(drop=True))
    if isinstance(source, (list, tuple)):  # several files, as one log
        if len(source) == 1:
            return load_source(source[0], sep, missing, explode, sheet)
        if not source:
            raise DataError(["no trial log given"], "<no files>")
        files = [Path(p) for p in source]
        return _load_files(files, os.path.commonpath([p.absolute() for p in files]), sep, missing, explode, sheet)
    path = Path(source)
    name = str(path)
    if not path.exists():
        raise DataError(["file not found"], name)
    if path.is_dir():
        return _load_folder(path, name, sep, missing, explode, sheet)
    special = special_file(path)
    if special:
        raise DataError([f"is {special}; expected a trial log file"], name)
    suffix = path.suffix.lower()
    if suffix in PARQUET_SUFFIXES:
        from .layouts import explode_table

        table = _parquet_table(path, name)
        return _arrow_raw(table if explode is None else explode_table(table, explode, name, "row"), name, missing, True)
    flat = {**dict.fromkeys(CSV_SUFFIXES, "a CSV cell is text"), **dict.fromkeys(WORKBOOK_SUFFIXES, "a sheet's cell is a value"),
            **dict.fromkeys(STAT_SUFFIXES, "a variable's value is one value")}  # fmt: skip
    if explode is not None and kind_suffix(path) in flat:
        raise DataError([f"explode: {flat[kind_suffix(path)]}, not a list; per-trial lists are read from JSON or Parquet"], name)
    if kind_suffix(path) in CSV_SUFFIXES:
        return _load_csv(path, name, sep, missing)
    if suffix in JSONL_SUFFIXES + JSON_SUFFIXES:
        return _load_json(path, name, _json_lines(path, suffix in JSONL_SUFFIXES), missing, explode)
    if suffix in WORKBOOK_SUFFIXES:
        from .workbooks import load_workbook

        return load_workbook(path, name, sheet, missing)
    if suffix in STAT_SUFFIXES:
        from .statfiles import load_statfile

        return load_statfile(path, name, missing)
    how = {**dict.fromkeys(OTHER_SHEET_SUFFIXES, "a spreadsheet: save it as an Excel workbook (.xlsx) or 'CSV UTF-8'"),
           **dict.fromkeys(PACKED_SUFFIXES, "a compressed file: decompress it first, e.g. with gunzip or unzip")}  # fmt: skip
    hint = f" ({how[suffix]})" if suffix in how else ""
    raise DataError(
        [f"unknown file type {suffix!r}{hint}: use .csv, .tsv, .parquet, .jsonl, .json, .xlsx, .sav, .dta or .sas7bdat (a CSV "
         "may be compressed: .csv.gz, .csv.bz2, .csv.zst)"],
        name,
    )  # fmt: skip


def _load_folder(
    path: Path, name: str, sep: str | None, missing: frozenset[str], explode: dict[str, Any] | None, sheet: str | None
) -> RawLog:
    """The logs of a folder as one (one file per participant or session, as PsychoPy and most
    experiment software write them): its files of the kind most of them are (``.csv``, ``.parquet``,
    ...; hidden files and others left out), in name order (:func:`_load_files`)."""
    kinds = collections.defaultdict(list)
    for p in sorted(path.iterdir()):
        if p.is_file() and not p.name.startswith(".") and kind_suffix(p) in FOLDER_SUFFIXES:
            kinds[kind_suffix(p)].append(p)
    if not kinds:
        raise DataError([f"the folder holds no trial log (files ending in {', '.join(FOLDER_SUFFIXES)})"], name)
    files = max(kinds.values(), key=len)
    if [k for k, v in kinds.items() if len(v) == len(files)] != [kind_suffix(files[0])]:
        counts = {k: len(v) for k, v in kinds.items()}
        raise DataError([f"the folder holds as many logs of two kinds ({counts}): keep one kind"], name)
    return _load_files(files, name, sep, missing, explode, sheet)


def _load_files(
    files: list[Path], name: str, sep: str | None, missing: frozenset[str], explode: dict[str, Any] | None, sheet: str | None
) -> RawLog:
    """Several logs as one, in the order given (:func:`.folders.stacked`).  A file goes by its name,
    or by its path from the files' common folder where two names are alike."""
    seen = collections.Counter(p.resolve() for p in files)
    twice = sorted(str(p) for p, k in seen.items() if k > 1)
    if twice:
        raise DataError([f"a file is given twice: {twice[:SHOWN]}"], name)
    labels = [p.name for p in files]
    if len(set(labels)) < len(labels):
        labels = [str(p.absolute().relative_to(name)) for p in files]
    raws = [load_source(p, sep, missing, explode, sheet) for p in files]  # each file's own errors name it
    suffixes = [p.suffixes[-2:] if p.suffix.lower() in COMPRESSED else p.suffixes[-1:] for p in files]
    stems = [t.removesuffix("".join(x)) for t, x in zip(labels, suffixes, strict=True)]
    return stacked(raws, labels, stems, name)


def _exploded_frame(source: pd.DataFrame, missing: frozenset[str], explode: dict[str, Any]) -> RawLog:
    """A data frame of records with per-trial lists, exploded into one row per item."""
    import pyarrow as pa

    from .layouts import explode_table

    try:
        table = pa.Table.from_pandas(source, preserve_index=False)
    except (pa.ArrowInvalid, pa.ArrowTypeError) as exc:
        raise DataError([f"explode: the table's columns cannot be read as lists: {exc}"], "<table>") from None
    return _arrow_raw(explode_table(table, explode, "<table>", "row"), "<table>", missing, True)


def _arrow_raw(table: Any, name: str, missing: frozenset[str], null_is_nan: bool = False) -> RawLog:
    """A pyarrow table as a log: refused when a column holds lists or objects or a name repeats;
    its columns read as codes on demand, and let go of when no longer needed.  A null is an empty
    cell, or with ``null_is_nan`` in a numeric column a NaN (a table from pandas)."""
    import pyarrow as pa

    from .layouts import refuse_nested

    refuse_nested(table, name)
    names = [str(c) for c in table.column_names]
    counts = collections.Counter(names)
    dupes = sorted(c for c, k in counts.items() if k > 1)
    if dupes:
        raise DataError([f"column {c!r} appears {counts[c]} times" for c in dupes], name)
    held = {"table": table}

    def release(cs: list[str]) -> None:
        held["table"] = held["table"].drop_columns([c for c in cs if c in held["table"].column_names])
        pa.default_memory_pool().release_unused()

    return RawLog(
        name,
        table.num_rows,
        names,
        lambda c: column_from_arrow(held["table"].column(c), missing, null_is_nan),
        lambda cs: held["table"].select(cs).to_pandas(),
        release,
    )


def _parquet_table(path: Path, name: str) -> Any:
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        schema = pq.read_schema(path)
        texts = [f.name for f in schema if pa.types.is_string(f.type) or pa.types.is_large_string(f.type)]
        # text columns come as codes into their distinct values (no string per row)
        return pq.read_table(path, read_dictionary=texts)
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise DataError([f"cannot read the file as Parquet: {exc}"], name) from None


def _json_lines(path: Path, by_suffix: bool) -> bool:
    """Whether a JSON log is JSON lines, by its content: an array starts with ``[``; records one
    per line start with ``{`` and their first line is a whole JSON value (whatever the suffix;
    a ``.json`` file of a single object is no log of lines: the array reader says so)."""
    try:
        with path.open("rb") as fh:
            first = fh.readline(HEADER_BYTES).decode("utf-8", "replace").lstrip("\ufeff").strip()
            more = any(line.strip() for line in itertools.islice(fh, 100))
    except OSError:
        return by_suffix  # the reader says what is wrong
    if first.startswith("["):
        return False
    if first.startswith("{"):
        try:
            json.loads(first)
        except json.JSONDecodeError:
            return False  # one object over several lines: the array reader names what is wrong
        return by_suffix or more
    return by_suffix


def _load_json(path: Path, name: str, lines: bool, missing: frozenset[str], explode: dict[str, Any] | None = None) -> RawLog:
    """JSON lines (one object per line) or a JSON array of objects; row N is the N-th record
    (the N-th trial, when ``explode`` turns each record's lists into trials)."""
    import pyarrow as pa

    from .layouts import explode_table, nested_columns, table_from_records

    lists = set(explode["columns"]) if explode is not None else set()
    if lines:
        import pyarrow.json as pjson

        try:
            table = pjson.read_json(path)
            if not nested_columns(table):
                return _arrow_raw(table, name, missing)
            if lists and not set(nested_columns(table)) - lists:
                return _arrow_raw(explode_table(table, explode or {}, name), name, missing)
        except (pa.ArrowException, OSError):
            pass  # mixed types in a column, a bad line or nested values: read record by record to say where
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise DataError(["the file is not UTF-8 text"], name) from None
    except OSError as exc:
        raise DataError([f"cannot read the file: {exc.strerror or exc}"], name) from None
    p = Problems()
    records: list[Any] = []
    where: list[str] = []
    if lines:
        bad: list[str] = []
        for i, line in enumerate(text.splitlines(), 1):
            if not line.strip():
                continue
            try:
                records.append(json.loads(line))
                where.append(f"line {i}")
            except json.JSONDecodeError as exc:
                bad.append(f"line {i}: {exc.msg}")
        p.add("lines that are not JSON", bad, unit="lines")
    else:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise DataError([f"invalid JSON: {exc}"], name) from None
        records = _json_records(data, name)
        where = [f"record {i}" for i in range(1, len(records) + 1)]
    p.add("records that are not objects", [w for w, r in zip(where, records, strict=True) if not isinstance(r, dict)])
    if p.lines:
        raise DataError(p.lines, name)
    _nested_values(records, where, name, lists)
    table = table_from_records(records, lists)
    if explode is not None:
        table = explode_table(table, explode, name)
    return _arrow_raw(table, name, missing)


def _json_records(data: Any, name: str) -> list[Any]:
    """The records of a JSON log (:func:`.suffixes.table_records`), or what it holds instead."""
    records = table_records(data)
    if records is not None:
        return records
    expected = "a JSON trial log must be an array of records (objects), one per trial"
    if not isinstance(data, dict):
        raise DataError([expected], name)
    arrays = object_arrays(data)
    if arrays:
        raise DataError([f"{expected}; this object holds {len(arrays)}: {arrays[:SHOWN]}: keep the one of the trials"], name)
    keys = [shorten(k, 40) for k in list(data)[:SHOWN]]
    raise DataError([f"{expected}, or an object holding one (this object's keys: {keys})"], name)


def _items(values: list[Any]) -> bool:
    """Whether a list holds per-trial items: texts and numbers, or objects of them (a trial each)."""
    if all(isinstance(x, dict) for x in values):
        return not any(isinstance(y, (dict, list)) for x in values for y in x.values())
    return not any(isinstance(x, (dict, list)) for x in values)


def _nested_values(records: list[dict[str, Any]], where: list[str], name: str, lists: set[str]) -> None:
    """Refuse cells that are objects or lists (a cell is a text, number or boolean; a list in a
    column the mapping explodes), by column."""
    from .layouts import explode_hint

    bad: dict[str, list[str]] = {}
    scalar: dict[str, list[str]] = {}
    found: set[str] = set()  # columns holding lists
    for w, r in zip(where, records, strict=True):
        for k, v in r.items():
            if isinstance(v, dict) or (isinstance(v, list) and k not in lists):
                bad.setdefault(k, []).append(f"{w} {json.dumps(v)[:40]}")
                if isinstance(v, list):
                    found.add(k)
            elif k in lists and v is not None and (not isinstance(v, list) or not _items(v)):
                scalar.setdefault(k, []).append(f"{w} {json.dumps(v)[:40]}")
    p = Problems()
    for k, items in bad.items():
        p.add(f"column {shorten(k, 80)!r}: an object or a list where a text or number was expected", items, unit="records")
    if found:
        p.lines.append(explode_hint([k for k in bad if k in found]))
    for k, items in scalar.items():
        what = "not a list of per-trial texts or numbers, or of objects of them"
        p.add(f"explode: column {shorten(k, 80)!r}: {what}", items, unit="records")
    if p.lines:
        raise DataError(p.lines, name)


def _load_csv(path: Path, name: str, sep: str | None, missing: frozenset[str]) -> RawLog:
    import pyarrow as pa
    import pyarrow.csv as pcsv

    sep, header, skip = _sniff(path, sep, name)
    if not header:
        raise DataError(["the file is empty (expected a header line naming the columns)"], name)
    if len(header) > MAX_COLUMNS:
        raise DataError(
            [f"the header names {len(header):,} columns (delimiter {sep!r}); at most {MAX_COLUMNS:,} are read: keep the columns "
             "the analysis uses"],
            name,
        )  # fmt: skip
    counts = collections.Counter(header)
    dupes = sorted(c for c, k in counts.items() if k > 1)
    if dupes:
        raise DataError([f"column {shorten(c, 80)!r} appears {counts[c]} times in the header" for c in dupes[:SHOWN]], name)
    # every column as codes into its distinct texts: no Python string per cell
    dictionary = pa.dictionary(pa.int32(), pa.string())
    types = dict.fromkeys(header, dictionary)
    parts, quoted = _csv_parts(path)
    bad_rows: list[list[tuple[int | None, int, str]]] = [[] for _ in parts]
    block = BLOCK_BYTES if len(parts) > 1 or path.suffix.lower() in COMPRESSED else min(BLOCK_BYTES, path.stat().st_size + 1)

    def parse(i: int) -> Any:
        if len(parts) > 1 and quoted(i):
            raise _Quoted

        def invalid(row: Any) -> str:
            try:
                text = str(row.text)
            except UnicodeDecodeError:
                text = "(not UTF-8 text)"
            bad_rows[i].append((row.number, row.actual_columns, text))
            return "skip"

        def read(handler: Any) -> Any:
            # on the calling thread (pyarrow's own pool is not used): a process that has read a CSV on
            # pyarrow's thread pool can abort at exit ("terminate called without an active exception")
            # under load, instead of exiting with its status
            return pcsv.read_csv(
                pa.BufferReader(parts[i]) if len(parts) > 1 else _input(path),
                read_options=pcsv.ReadOptions(
                    column_names=header, skip_rows=skip if i == 0 else 0, block_size=block, use_threads=False
                ),
                parse_options=pcsv.ParseOptions(
                    delimiter=sep,
                    invalid_row_handler=handler,
                    newlines_in_values=True,  # a quoted value may span lines
                ),
                convert_options=pcsv.ConvertOptions(
                    column_types=types,
                    null_values=[],
                    strings_can_be_null=False,
                    quoted_strings_can_be_null=False,
                    check_utf8=False,  # checked once per distinct value below, not once per cell
                ),
            )

        try:  # every row as wide as the header (the usual case): parsed without a handler, 15 % less work
            table = read(None)
        except (pa.ArrowException, OSError):  # a row of another width, or a failure: parsed again to say where
            table = read(invalid)
        _check_utf8(table)
        return table

    # pyarrow decodes a malformed row's text for the handler; a row that is not UTF-8 fails there,
    # outside any caller, so such failures are collected here instead of being printed
    undecodable: list[Any] = []
    hook = sys.unraisablehook
    sys.unraisablehook = undecodable.append
    try:
        try:
            table = parse(0) if len(parts) == 1 else pa.concat_tables(_on_two_threads(parse, len(parts)))
        except _Quoted:  # a quoted value may hold a line end: the file in one pass
            parts, bad_rows = [path], [[]]
            table = parse(0)
    except (pa.ArrowException, OSError) as exc:
        msg = str(exc)
        if "UTF8" in msg or "UTF-8" in msg:
            raise DataError(["the file is not UTF-8 text (save it as UTF-8 CSV)"], name) from None
        if path.suffix.lower() in COMPRESSED and isinstance(exc, OSError):  # zlib's and the others' failures
            raise _not_decompressed(path, name, exc) from None
        raise DataError([f"cannot read the file as CSV (delimiter {sep!r}): {msg}"], name) from None
    finally:
        sys.unraisablehook = hook
    if undecodable:
        raise DataError(["the file is not UTF-8 text (save it as UTF-8 CSV)"], name)
    if any(bad_rows):
        before = 0
        for i in range(1, len(parts)):  # a later part's line numbers count from its start
            before += _line_ends(parts[i - 1])
            bad_rows[i] = [(None if n is None else n + before, got, text) for n, got, text in bad_rows[i]]
        p = Problems()
        p.add(
            f"rows whose number of fields differs from the header's {len(header)} (delimiter {sep!r})",
            [_bad_row(number, got, text, skip) for part in bad_rows for number, got, text in part],
        )
        raise DataError(p.lines, name)
    return _arrow_raw(table, name, missing)


def _check_utf8(table: Any) -> None:
    """Raise pyarrow's error for text that is not UTF-8 in a table of dictionary columns (each
    distinct value of a block is checked: 0.3 s less than each cell of 7.1 M rows)."""
    for column in table.columns:
        for chunk in column.chunks:
            chunk.dictionary.validate(full=True)


def _on_two_threads(parse: Any, count: int) -> list[Any]:
    """``parse(i)`` of every part ``i``, in order, on two threads, each part taken by whichever is
    free: the two end together however the cores are shared.  From the first failure on no part
    is begun, and the error of the first part that fails is raised."""
    with ThreadPoolExecutor(2, thread_name_prefix="trustseek-csv") as pool:
        futures = [pool.submit(parse, i) for i in range(count)]
        wait(futures, return_when=FIRST_EXCEPTION)
        for f in futures:
            f.cancel()  # the parts not begun (they come after every part begun)
    return [f.result() for f in futures]


class _Quoted(Exception):
    """A part of a CSV holds a quote: the file is parsed in one pass instead."""


def _csv_parts(path: Path) -> tuple[list[Any], Any]:
    """The file whole (one part), or from :data:`SPLIT_BYTES` on a machine with two cores or more
    its parts of about :data:`PART_BYTES` (buffers of the memory-mapped file), each split after the
    first line end past its size; and whether part ``i`` holds a quote.  Only an uncompressed file
    without a quote is read in parts (the first part is looked at here, each other one on the
    thread that parses it): a quoted value may hold a line end, and a row never spans lines
    outside one, so the parts hold the rows of the whole, in order.  They are parsed on two
    threads, one per core: 7.1 M rows in about half the time of one pass
    (``benchmarks/bench_read.py``)."""
    import pyarrow as pa

    whole_file: tuple[list[Any], Any] = ([path], lambda i: False)
    size = path.stat().st_size
    if size < SPLIT_BYTES or len(os.sched_getaffinity(0)) < 2 or path.suffix.lower() in COMPRESSED:
        return whole_file
    with path.open("rb") as fh:
        whole = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    count = max(2, size // PART_BYTES)
    starts = [0]
    for j in range(1, count):
        at = max(j * size // count, starts[-1])
        end = whole.find(b"\n", at, at + SPLIT_SEARCH)
        if end < 0:
            return whole_file
        if end + 1 >= size:
            break
        starts.append(end + 1)
    ends = [*starts[1:], size]

    def quoted(i: int) -> bool:
        return whole.find(b'"', starts[i], ends[i]) >= 0

    if len(starts) < 2 or quoted(0):  # a file that quotes its header or first rows: no part parsed in vain
        return whole_file
    buffer = pa.py_buffer(whole)
    return [buffer.slice(a, b - a) for a, b in zip(starts, ends, strict=True)], quoted


def _line_ends(part: Any) -> int:
    """The line ends in a part of the file (the lines before the next part)."""
    return int(np.count_nonzero(np.frombuffer(part, dtype=np.uint8) == ord("\n")))


def _bad_row(number: int | None, got: int, text: str, skip: int = 1) -> str:
    """A row whose field count is wrong: its data row (the file's line less the ``skip`` lines
    before the data), the fields found, the start of its text, and an unterminated quote when it
    has one."""
    where = f"row {number - skip}" if number is not None else "a row"
    quote = ", an unterminated quote" if text.count('"') % 2 else ""
    return f"{where} ({got} fields{quote}): {text[:60]!r}"
