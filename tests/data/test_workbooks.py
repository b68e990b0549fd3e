"""data/workbooks: an Excel workbook read as a trial log, cell for cell as the same table in JSON
lines; the sheet chosen or named; error cells and formulas never computed named by row; damaged
files refused by name."""

from __future__ import annotations

import contextlib
import datetime as dt
import io
import json
import zipfile

import openpyxl
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cli_runner import run_cli
from trustseek.data import DataError, example_path, read_trials
from trustseek.data.sources import load_source

TEXTS = ["low", "high", " rely ", "1.0", "P01", "ü", "", "  ", "NA", "#N/A", "#DIV/0!", "=A1*2", "a,b", "x" * 40]


def workbook(path, sheets: dict[str, list[list]], hidden: tuple[str, ...] = ()) -> None:
    """A workbook of ``sheets`` (name -> rows of Python values), saved by openpyxl (which computes
    no formula: a text starting with '=' is a formula without a value, '#N/A' an error cell)."""
    book = openpyxl.Workbook()
    book.remove(book.active)
    for name, rows in sheets.items():
        ws = book.create_sheet(name)
        for row in rows:
            ws.append(row)
        if name in hidden:
            ws.sheet_state = "hidden"
    book.save(path)


def frame_rows(frame: pd.DataFrame) -> list[list]:
    return [list(frame.columns), *([None if pd.isna(v) else v for v in row] for row in frame.itertuples(index=False))]


def texts(raw, column: str) -> list:
    col = raw.col(column)
    return [col.texts[k] for k in col.codes]


@st.composite
def tables(draw) -> list[list]:
    """Rows of typed columns (text, whole numbers, finite floats, booleans; any cell empty), the
    last row with a value (a sheet's empty rows at the end are not rows of it)."""
    n, k = draw(st.integers(1, 8)), draw(st.integers(1, 4))
    kinds = [draw(st.sampled_from(["text", "int", "float", "bool"])) for _ in range(k)]
    values = {
        "text": st.sampled_from(TEXTS),
        "int": st.integers(-(2**53) + 1, 2**53 - 1),
        "float": st.floats(allow_nan=False, allow_infinity=False),
        "bool": st.booleans(),
    }
    rows = [[draw(st.one_of(st.none(), values[kinds[j]])) for j in range(k)] for _ in range(n)]
    rows[-1][0] = draw(values[kinds[0]].filter(lambda v: not (isinstance(v, str) and not v.strip())))
    return [[f"c{j}" for j in range(k)], *rows]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rows=tables())
def test_a_sheet_reads_cell_for_cell_as_the_same_table_in_json_lines(tmp_path_factory, rows):
    folder = tmp_path_factory.mktemp("book")
    workbook(folder / "log.xlsx", {"Trials": rows})
    header, *body = rows
    body = [[float(f"{v:.16g}") if isinstance(v, float) else v for v in r] for r in body]  # as openpyxl writes a float
    (folder / "log.jsonl").write_text("".join(json.dumps(dict(zip(header, r, strict=True))) + "\n" for r in body))
    sheet, lines = load_source(folder / "log.xlsx", None, frozenset()), load_source(folder / "log.jsonl", None, frozenset())
    assert sheet.n == lines.n and sheet.columns == header
    for c in header:
        assert texts(sheet, c) == texts(lines, c), c
    assert [sheet.place(i) for i in range(sheet.n)] == [f"row {i + 1} (Excel row {i + 2})" for i in range(sheet.n)]


def test_the_shipped_log_as_a_workbook_fits_to_the_same_model_file(tmp_path):
    frame = pd.read_csv(example_path())
    workbook(tmp_path / "log.xlsx", {"Trials": frame_rows(frame)})
    pd.testing.assert_frame_equal(
        read_trials(tmp_path / "log.xlsx").drop(columns="true_trust"), read_trials(example_path()).drop(columns="true_trust")
    )
    for log, out in ((tmp_path / "log.xlsx", "a.json"), (example_path(), "b.json")):
        code, output = run_cli(["fit", str(log), "--preset", "paper", "--restarts", "2", "--out", str(tmp_path / out)])
        assert code == 0, output
    assert (tmp_path / "a.json").read_bytes() == (tmp_path / "b.json").read_bytes()


@pytest.fixture
def small() -> pd.DataFrame:
    frame = pd.read_csv(example_path(), dtype=str)
    return frame[frame.participant.isin(["P001", "P002"]) & (frame.trial.astype(int) <= 10)].reset_index(drop=True)


def test_the_only_sheet_with_values_is_read_and_several_are_refused_naming_them(small, tmp_path):
    rows = frame_rows(small)
    workbook(tmp_path / "one.xlsx", {"Notes": [], "Trials": rows, "Lookup": [["a", 1]]}, hidden=("Lookup",))
    assert read_trials(tmp_path / "one.xlsx").equals(read_trials(small))  # an empty and a hidden sheet passed over
    workbook(tmp_path / "two.xlsx", {"Trials": rows, "Ratings": [["participant", "rating"], ["P001", 5]]})
    with pytest.raises(DataError) as exc:
        read_trials(tmp_path / "two.xlsx")
    assert exc.value.problems == [
        "the workbook has 2 sheets holding values, ['Trials', 'Ratings']: name the log's with --sheet NAME "
        "(or the mapping's \"sheet\"), e.g. --sheet 'Trials'"
    ]
    assert read_trials(tmp_path / "two.xlsx", {"sheet": "Trials"}).equals(read_trials(small))
    assert read_trials(tmp_path / "two.xlsx", sheet="Trials").equals(read_trials(small))
    with pytest.raises(DataError, match=r"no sheet named 'trials'; the workbook's sheets are \['Trials', 'Ratings'\]"):
        read_trials(tmp_path / "two.xlsx", sheet="trials")
    with pytest.raises(DataError) as exc:  # a name of any length is cut in the message (it was echoed whole)
        read_trials(tmp_path / "two.xlsx", sheet="x" * 100_000)
    assert len(str(exc.value)) < 300 and "more characters" in str(exc.value)
    code, output = run_cli(["fit", str(tmp_path / "two.xlsx"), "--sheet", "Trials", "--restarts", "1"])
    assert code == 0 and "Fitted trust model (2 participants, 20 trials)" in output
    code, output = run_cli(["fit", str(tmp_path / "two.xlsx"), "--restarts", "1"])
    assert code == 2 and "--sheet 'Trials'" in output and "Traceback" not in output


def test_a_second_sheet_of_the_same_workbook_is_joined(small, tmp_path):
    ratings = [["participant", "age"], ["P001", 31], ["P002", 45]]
    workbook(tmp_path / "study.xlsx", {"Trials": frame_rows(small), "People": ratings})
    mapping = {"sheet": "Trials", "join": {"file": str(tmp_path / "study.xlsx"), "sheet": "People"}}
    frame = read_trials(tmp_path / "study.xlsx", mapping)
    assert frame.groupby("participant", observed=True).age.first().tolist() == [31, 45]
    with pytest.raises(DataError, match="join: 'sheet' names the second file's sheet, got 3"):
        read_trials(tmp_path / "study.xlsx", {"join": {"file": "x.xlsx", "sheet": 3}})
    with pytest.raises(DataError, match="sheet: expected the name of a workbook's sheet, got ''"):
        read_trials(tmp_path / "study.xlsx", {"sheet": ""})


def test_a_title_above_the_header_and_bad_cells_are_located_by_excel_row(small, tmp_path):
    rows = frame_rows(small)
    rows[3][2] = "medium"  # data row 3: Excel row 5 below the title and the header
    rows[5][4] = "#N/A"  # an error cell (a lookup that found nothing), data row 5
    rows[6][4] = '=IF(B7>1,"rely","intervene")'  # a formula never computed, data row 6
    workbook(tmp_path / "log.xlsx", {"Trials": [["Study 3: trial log, exported 2026-11-01"], [], *rows]})
    with pytest.raises(DataError) as exc:
        read_trials(tmp_path / "log.xlsx")
    assert exc.value.problems == [
        "column 'complexity': unknown category (expected one of ['low', 'high']): row 3 (Excel row 6) 'medium'",
        "column 'human_action': unknown category (expected one of ['intervene', 'rely']) in 2 rows: "
        "row 5 (Excel row 8) '#N/A'; row 6 (Excel row 9) '=IF(B7>1,\"rely\",\"intervene\")'",
    ]
    rows[3][2], rows[6][4] = "low", "rely"
    workbook(tmp_path / "log.xlsx", {"Trials": [["Study 3"], *rows]})
    frame = read_trials(tmp_path / "log.xlsx", {"missing": ["#N/A"]})  # an error cell meant as not recorded
    assert frame.human_action.isna().sum() == 1 and len(frame) == 20


def test_dates_read_as_iso_text_and_order_the_trials(small, tmp_path):
    start = dt.datetime(2026, 3, 1, 9, 0)
    rows = frame_rows(small.drop(columns="trial").assign(at=[start + dt.timedelta(minutes=i) for i in range(len(small))]))
    rows = [rows[0], *reversed(rows[1:])]  # newest first: the order comes from the times
    workbook(tmp_path / "log.xlsx", {"Trials": rows})
    raw = load_source(tmp_path / "log.xlsx", None, frozenset())
    assert texts(raw, "at")[-1] == "2026-03-01 09:00:00"
    frame = read_trials(tmp_path / "log.xlsx", {"order": ["at"]})  # rows as in the sheet, numbered by time
    columns = ["participant", "trial", "complexity", "robot_action", "human_action", "experience"]
    ordered = frame.astype(dict.fromkeys(columns, str)).sort_values(["participant", "trial"], key=lambda c: c.str.zfill(9))
    assert ordered[columns].values.tolist() == read_trials(small).astype(str)[columns].values.tolist()
    assert ordered.groupby("participant")["at"].is_monotonic_increasing.all()


def test_a_folder_of_workbooks_one_per_participant_reads_as_one_log(small, tmp_path):
    for pid, g in small.groupby("participant"):
        workbook(tmp_path / f"{pid}.xlsx", {"Sheet1": frame_rows(g.drop(columns="participant"))})
    assert read_trials(tmp_path).equals(read_trials(small))
    (tmp_path / "P002.xlsx").write_bytes((tmp_path / "P002.xlsx").read_bytes()[:300])
    with pytest.raises(DataError, match=r"P002.xlsx: cannot read the file as an Excel workbook \(.xlsx\)"):
        read_trials(tmp_path)


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"", "cannot read the file as an Excel workbook"),
        (b"participant,trial\nP1,1\n", "cannot read the file as an Excel workbook"),
        ("zip", "cannot read the file as an Excel workbook"),
        ("truncated", "cannot read the file as an Excel workbook"),
        ("empty sheet", "no visible sheet holds a value (sheets: ['Sheet1']); name one with --sheet"),
    ],
    ids=["empty", "csv-text", "other-zip", "truncated", "empty-sheet"],
)
def test_a_damaged_or_empty_workbook_is_refused_by_name(tmp_path, content, message):
    path = tmp_path / "log.xlsx"
    if content == "zip":
        with zipfile.ZipFile(path, "w") as z:
            z.writestr("log.csv", "participant,trial\nP1,1\n")
    elif content == "truncated":
        workbook(path, {"Trials": frame_rows(pd.read_csv(example_path()))})
        path.write_bytes(path.read_bytes()[:-2000])
    elif content == "empty sheet":
        workbook(path, {"Sheet1": []})
    else:
        path.write_bytes(content)
    code, output = run_cli(["fit", str(path)])
    assert code == 2 and f"{path}: {message}" in output and "Traceback" not in output, output


@pytest.mark.parametrize("suffix", [".xls", ".ods", ".numbers"])
def test_other_spreadsheets_are_refused_with_the_way_to_save_them(tmp_path, suffix):
    path = tmp_path / f"log{suffix}"
    path.write_bytes(b"\xd0\xcf\x11\xe0")
    with pytest.raises(DataError, match=r"save it as an Excel workbook \(.xlsx\) or 'CSV UTF-8'"):
        read_trials(path)


def test_a_merged_cell_holds_its_value_in_each_of_its_rows(small, tmp_path):
    """A lab sheet merges a participant's id over their rows: the reader gives it in the first row
    only, so every other row was an empty participant id."""
    rows = frame_rows(small)  # P001's ten trials, then P002's
    for r in [*range(2, 11), *range(12, 21)]:
        rows[r][0] = None
    book = openpyxl.Workbook()
    ws = book.active
    for row in rows:
        ws.append(row)
    ws.merge_cells("A2:A11")  # P001's ten trials
    ws.merge_cells("A12:A21")  # P002's
    book.save(tmp_path / "log.xlsx")
    assert [r[0] for r in rows[1:]].count(None) == 18
    assert read_trials(tmp_path / "log.xlsx").equals(read_trials(small))


@pytest.fixture(scope="module")
def valid_book(tmp_path_factory) -> bytes:
    path = tmp_path_factory.mktemp("valid") / "log.xlsx"
    rows = frame_rows(pd.read_csv(example_path()).head(30))
    rows[3][4], rows[4][4] = "#N/A", "=B5*2"  # an error cell and a formula: the XML scan runs
    workbook(path, {"Trials": rows, "Notes": [["a"]]})
    return path.read_bytes()


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_a_corrupted_workbook_is_refused_or_read_never_a_crash(tmp_path_factory, valid_book, data):
    raw = bytearray(valid_book)
    for _ in range(data.draw(st.integers(1, 8))):
        raw[data.draw(st.integers(0, len(raw) - 1))] = data.draw(st.integers(0, 255))
    cut = data.draw(st.one_of(st.none(), st.integers(0, len(raw))))
    path = tmp_path_factory.mktemp("bad") / "log.xlsx"
    path.write_bytes(bytes(raw[:cut]))
    if data.draw(st.booleans()):  # a package intact as a zip, with damaged XML in it
        with zipfile.ZipFile(io.BytesIO(valid_book)) as z:
            parts = {n: z.read(n) for n in z.namelist()}
        part = data.draw(st.sampled_from(["xl/worksheets/sheet1.xml", "xl/workbook.xml", "xl/_rels/workbook.xml.rels"]))
        xml = bytearray(parts[part])
        for _ in range(data.draw(st.integers(1, 8))):
            xml[data.draw(st.integers(0, len(xml) - 1))] = data.draw(st.sampled_from(b'<>"=/ \x00\xff&;#ef1AZ'))
        parts[part] = bytes(xml[: data.draw(st.integers(0, len(xml)))])
        with zipfile.ZipFile(path, "w") as z:
            for n, content in parts.items():
                z.writestr(n, content)
    with contextlib.suppress(DataError):  # refused by name, or read: anything else fails the test
        read_trials(path, {"sheet": "Trials"})


def test_a_sheet_part_zipfile_cannot_open_is_refused_by_name(tmp_path, valid_book):
    """A damaged flag in the sheet's zip header (found by the test above): the reader took the sheet,
    and the scan for error cells failed with zipfile's NotImplementedError."""
    raw = bytearray(valid_book)
    at = raw.rfind(b"xl/worksheets/sheet1.xml") - 46  # the part's central directory entry: its name 46 bytes in
    assert raw[at : at + 4] == b"PK\x01\x02"
    raw[at + 8] |= 0x20  # its flags: "compressed patched data"
    (tmp_path / "log.xlsx").write_bytes(bytes(raw))
    code, output = run_cli(["check", str(tmp_path / "log.xlsx"), "--sheet", "Trials"])
    assert code == 2 and "log.xlsx (sheet 'Trials'): cannot read the sheet" in output and "Traceback" not in output, output


def test_a_workbook_the_system_cannot_read_is_refused_by_name(monkeypatch, tmp_path, valid_book):
    """The reader's OSError (a file without read permission, an I/O error on a network drive) is one
    located line, not a traceback."""
    import python_calamine

    class Unreadable:
        @staticmethod
        def from_path(path):
            raise PermissionError(13, "Permission denied", path)

    monkeypatch.setattr(python_calamine, "CalamineWorkbook", Unreadable)
    (tmp_path / "log.xlsx").write_bytes(valid_book)
    with pytest.raises(DataError, match=r"log\.xlsx: cannot read the file: Permission denied$"):
        read_trials(tmp_path / "log.xlsx")
