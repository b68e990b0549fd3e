"""Excel workbooks (``.xlsx``, ``.xlsm``) as trial logs, read with python-calamine.

One sheet is the log: the one named (``--sheet``, the mapping's ``"sheet"``), else the only
visible sheet that holds any value.  Its header is the first row with at least half as many values
as the fullest of its first :data:`LOOK` rows (a title above it is passed over); every row below
is a trial, numbered as the other formats number theirs (``row N``: the N-th data row) with the
row Excel shows beside it.  A cell is read as the value the spreadsheet program last computed for
it, a whole number as an integer, a date as its ISO text, a merged cell's value in each of its
cells (a participant's id merged over their rows).  An error cell (``#N/A``, ``#DIV/0!``)
is read as its error's text and a formula never computed (as Python libraries save them) as its
formula (``=B2*2``), so that the checks of the columns name them where the reader alone would
give an empty cell.
"""

from __future__ import annotations

import collections
import re
import xml.etree.ElementTree as ET
import zipfile
import zlib
from pathlib import Path, PurePosixPath
from typing import Any
from xml.sax.saxutils import unescape

import pandas as pd

from .cells import SHOWN, DataError, RawLog, column_from_pandas, shorten

LOOK = 50  # rows of a sheet looked at to tell whether it holds any value and where its header is
#: a cell of a sheet's XML (any namespace prefix): its attributes, and what it holds
_CELL = re.compile(rb"<((?:\w+:)?)c\b([^>]*?)(?:/>|>(.*?)</\1c>)", re.S)
_REF = re.compile(rb'\br="([A-Z]+)([0-9]+)"')
_VALUE = re.compile(rb"<(?:\w+:)?v>([^<]*)</(?:\w+:)?v>")
_FORMULA = re.compile(rb"<(?:\w+:)?f\b[^>]*?(?:/>|>([^<]*)</(?:\w+:)?f>)")


def load_workbook(path: Path, name: str, sheet: str | None, missing: frozenset[str]) -> RawLog:
    """The log one sheet of the workbook at ``path`` holds."""
    from python_calamine import CalamineError, CalamineWorkbook

    try:
        book = CalamineWorkbook.from_path(str(path))
        chosen, ws = _sheet(book, sheet, name)
        label = f"{name} (sheet {chosen!r})" if len(book.sheet_names) > 1 else name
        grid, merged = ws.to_python(skip_empty_area=False), ws.merged_cell_ranges or []
        marked = _marked_cells(path, chosen, label)
    except CalamineError as exc:
        raise DataError([f"cannot read the file as an Excel workbook (.xlsx): {shorten(str(exc), 200)}"], name) from None
    except OSError as exc:  # (before the clause below, which would take it)
        raise DataError([f"cannot read the file: {exc.strerror or exc}"], name) from None
    except BaseException as exc:  # the Rust reader's panic on a damaged file (pyo3's PanicException is no Exception)
        if type(exc).__name__ != "PanicException":
            raise
        raise DataError([f"cannot read the file as an Excel workbook (.xlsx): the reader stopped on it: {exc}"], name) from None
    every = grid  # the cells as read; each converted (:func:`_cell`) when its column is used
    for (r, c), text in marked.items():  # what the reader gives as empty: the error's text, the formula
        every += [[] for _ in range(r + 1 - len(every))]
        every[r] += [None] * (c + 1 - len(every[r]))
        every[r][c] = text
    for (r0, c0), (r1, c1) in merged:  # a merged cell (a participant's id over their rows): its value in each
        every += [[] for _ in range(r1 + 1 - len(every))]
        value = every[r0][c0] if c0 < len(every[r0]) else None
        for r in range(r0, r1 + 1):
            every[r] += [None] * (c1 + 1 - len(every[r]))
            every[r][c0 : c1 + 1] = [value] * (c1 + 1 - c0)
    fullest = max((_count(r) for r in every[:LOOK]), default=0)
    top = next((i for i, r in enumerate(every) if fullest and 2 * _count(r) >= fullest), None)
    if top is None:
        raise DataError(["the sheet is empty (expected a header row naming the columns)"], label)
    header, rows = [_cell(v) for v in every[top]], every[top + 1 :]
    while rows and not _count(rows[-1]):  # formatted but unused rows at the end
        rows.pop()

    def cells(i: int) -> list[Any]:
        return [_cell(r[i]) if i < len(r) else None for r in rows]

    width = max([len(header), *map(len, rows)])
    while width and header[width - 1 : width] in ([], [None]) and not any(v is not None for v in cells(width - 1)):
        width -= 1  # columns formatted but unused at the right
    names = [_name(header[i] if i < len(header) else None, i) for i in range(width)]
    counts = collections.Counter(names)
    dupes = sorted(c for c, k in counts.items() if k > 1)
    if dupes:
        lines = [f"column {shorten(c, 80)!r} appears {counts[c]} times in the header (row {top + 1})" for c in dupes[:SHOWN]]
        raise DataError(lines, label)
    index = {c: i for i, c in enumerate(names)}
    converted: dict[str, pd.Series] = {}

    def column(c: str) -> pd.Series:
        if c not in converted:
            converted[c] = pd.Series(cells(index[c]), dtype=object, index=pd.RangeIndex(len(rows)))
        return converted[c]

    return RawLog(
        label,
        len(rows),
        names,
        lambda c: column_from_pandas(column(c), missing),
        lambda cs: pd.DataFrame({c: column(c) for c in cs}, index=pd.RangeIndex(len(rows))).infer_objects(),
        place=lambda i: f"row {i + 1} (Excel row {top + i + 2})",
    )


def _sheet(book: Any, sheet: str | None, name: str) -> tuple[str, Any]:
    """The sheet to read, by name and loaded: ``sheet``, else the only visible one holding a value
    (each sheet is parsed whole when loaded: once)."""
    names = list(book.sheet_names)
    if sheet is not None:
        if sheet in names:
            return sheet, book.get_sheet_by_name(sheet)
        raise DataError([f"no sheet named {shorten(sheet, 80)!r}; the workbook's sheets are {names}"], name)
    visible = [m.name for m in book.sheets_metadata if str(m.visible).endswith("Visible") and m.name in names]
    loaded = {n: book.get_sheet_by_name(n) for n in visible}
    used = [n for n, ws in loaded.items() if any(_count(r) for r in ws.to_python(nrows=LOOK))]
    if len(used) == 1:
        return used[0], loaded[used[0]]
    if not used:
        raise DataError([f"no visible sheet holds a value (sheets: {names}); name one with --sheet"], name)
    raise DataError(
        [f"the workbook has {len(used)} sheets holding values, {used}: name the log's with --sheet NAME "
         f"(or the mapping's \"sheet\"), e.g. --sheet {used[0]!r}"],
        name,
    )  # fmt: skip


def _marked_cells(path: Path, sheet: str, label: str) -> dict[tuple[int, int], str]:
    """The cells of ``sheet`` that hold an error value (as its text, ``#N/A``) or a formula
    without a computed value (as ``=`` and the formula), by (row, column) from 0, read from the
    sheet's XML (python-calamine gives both as empty)."""
    try:
        with zipfile.ZipFile(path) as z:
            part = _sheet_part(z, sheet)
            data = z.read(part) if part is not None else b""
    except (zipfile.BadZipFile, KeyError, ET.ParseError, OSError, EOFError, NotImplementedError, RuntimeError, zlib.error) as exc:
        # a damaged package, or one zipfile cannot open (patched or encrypted data)
        raise DataError([f"cannot read the sheet: {shorten(str(exc), 200)}"], label) from None
    if b't="e"' not in data and b"<f" not in data and b":f" not in data:  # no error cell, no formula (a quick test)
        return {}
    out: dict[tuple[int, int], str] = {}
    for m in _CELL.finditer(data):
        attrs, body = m.group(2), m.group(3) or b""
        value = _VALUE.search(body)
        if b't="e"' in attrs:
            text = _text(value.group(1)) if value else "#ERROR"
        elif (value is None or not value.group(1)) and (f := _FORMULA.search(body)) is not None:
            text = "=" + _text(f.group(1)) if f.group(1) else "=(a shared formula)"
        else:
            continue  # a value, or a formula with its computed value: the reader has it
        ref = _REF.search(attrs)
        if ref is None:
            raise DataError([f"a cell holds {text} and names no place (no r attribute): correct it in the sheet"], label)
        out[(int(ref.group(2)) - 1, _column_index(ref.group(1).decode()))] = text
    return out


def _sheet_part(z: zipfile.ZipFile, sheet: str) -> str | None:
    """The path in the package of the XML of the sheet named ``sheet`` (transitional or strict
    Office Open XML: elements and the relationship id by their local names)."""
    book = ET.fromstring(z.read("xl/workbook.xml"))
    sheets = [e for e in book.iter() if e.tag.rsplit("}", 1)[-1] == "sheet" and e.get("name") == sheet]
    rid = next((v for e in sheets for k, v in e.attrib.items() if k.endswith("}id")), None)
    rels = ET.fromstring(z.read("xl/_rels/workbook.xml.rels"))
    target = next((r.get("Target") for r in rels if r.get("Id") == rid), None)
    if target is None:
        return None
    return target.lstrip("/") if target.startswith("/") else str(PurePosixPath("xl") / target)


def _text(raw: bytes) -> str:
    return unescape(raw.decode("utf-8", "replace"), {"&quot;": '"', "&apos;": "'"})


def _column_index(letters: str) -> int:
    n = 0
    for ch in letters:
        n = n * 26 + ord(ch) - ord("A") + 1
    return n - 1


def _cell(v: Any) -> Any:
    """A cell's value as the other formats give it: empty as None, a date or time as ISO text,
    a float that is a whole number as an integer (a sheet stores every number as a float)."""
    if isinstance(v, str):
        return v if v.strip() else None
    if isinstance(v, float) and v.is_integer() and abs(v) < 2**53:
        return int(v)
    if hasattr(v, "isoformat"):
        return v.isoformat(sep=" ") if hasattr(v, "date") else v.isoformat()
    return v


def _count(row: list[Any]) -> int:
    """The cells of ``row`` (as read) that hold a value."""
    return sum(_cell(v) is not None for v in row)


def _name(v: Any, i: int) -> str:
    """A header cell as a column name; an empty one by its place, as a CSV's: ``(column 7)``."""
    text = "" if v is None else str(v).strip()
    return text or f"(column {i + 1})"
