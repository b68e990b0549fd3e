"""The fast paths of reading a large log give what the general ones give: a CSV read in blocks and
halves against the same table given as a data frame, ids checked at once against cell by cell."""

import io

import pandas as pd
import pytest

from trustseek.data.trials import CANONICAL, DataError, read_trials

HEADER = "participant,trial,complexity,robot_action,human_action,experience,block\n"


def rows(ids, trials=(1, 2)):
    """A valid log: a row for each id and trial (ask in low complexity, so the experience is faulty)."""
    return "".join(f"{p},{t},low,ask,rely,faulty,{t}\n" for p in ids for t in trials)


def as_table(text):
    return pd.read_csv(io.StringIO(text), dtype=str, keep_default_na=False)


def same_read(tmp_path, text, **kw):
    """The log read from a CSV file and from the same cells as a data frame (the general path;
    an extra column is carried as the source holds it)."""
    path = tmp_path / "log.csv"
    path.write_text(text)
    frame = read_trials(path, **kw)
    same(frame, read_trials(as_table(text), **kw))
    return frame


def same(frame, other):
    cols = list(CANONICAL)
    pd.testing.assert_frame_equal(frame[cols], other[cols])
    assert frame.attrs == other.attrs


def same_error(tmp_path, text, **kw):
    path = tmp_path / "log.csv"
    path.write_text(text)
    with pytest.raises(DataError) as from_file:
        read_trials(path, **kw)
    with pytest.raises(DataError) as from_table:
        read_trials(as_table(text), **kw)
    assert from_file.value.problems == from_table.value.problems
    return "\n".join(from_file.value.problems)


IDS = [f"P{i:03d}" for i in range(80)]  # more ids than are cleaned one by one


@pytest.mark.parametrize(
    "odd",
    [
        [],  # every id as it is: checked at once
        [" P001", "P002 "],  # spaces around an id: the same participant as without
        ["Zoë"],  # not ASCII
        ["P\x1c"],  # a separator str.strip() takes off: the same participant as 'P'
    ],
)
def test_many_ids_read_as_the_same_table_given_as_a_frame(tmp_path, odd):
    frame = same_read(tmp_path, HEADER + rows(IDS) + rows(odd, trials=(3,)))
    stripped = [o.strip() for o in odd]
    assert list(frame["participant"].cat.categories) == list(dict.fromkeys([*IDS, *stripped]))
    counts = frame.groupby("participant", observed=True).size()
    assert counts.to_dict() == {p: (2 if p in IDS else 0) + stripped.count(p) for p in dict.fromkeys([*IDS, *stripped])}


@pytest.mark.parametrize(("cell", "told"), [("nan", "value is NaN"), ("  ", "empty participant id"), ("N/A", "value is NaN")])
def test_a_bad_id_among_many_is_told_at_its_row(tmp_path, cell, told):
    text = HEADER + rows(IDS[:70]) + rows([cell]) + rows(IDS[70:])
    lines = same_error(tmp_path, text)
    assert f"column 'participant': {told} in 2 rows: row 141; row 142" in lines


def test_a_missing_value_marker_among_many_ids_is_an_empty_id(tmp_path):
    text = HEADER + rows(IDS[:70]) + rows(["gone"]) + rows(IDS[70:])
    assert "column 'participant': empty participant id in 2 rows: row 141; row 142" in same_error(
        tmp_path, text, mapping={"missing": ["GONE"]}
    )
    same_read(tmp_path, HEADER + rows(IDS), mapping={"missing": ["GONE"]})


def test_parquet_nulls_are_empty_cells_and_a_column_without_them_reads_whole(tmp_path):
    table = as_table(HEADER + rows(IDS[:3]))
    good = tmp_path / "good.parquet"
    table.to_parquet(good)
    same(read_trials(good), read_trials(table))
    table.loc[[1, 4], "trial"] = None
    table.loc[2, "complexity"] = None
    bad = tmp_path / "bad.parquet"
    table.to_parquet(bad)
    with pytest.raises(DataError) as exc:
        read_trials(bad)
    lines = "\n".join(exc.value.problems)
    assert "column 'trial': empty trial index" in lines and "in 2 rows: row 2; row 5" in lines
    assert "column 'complexity': empty value (expected one of ['low', 'high']): row 3" in lines


@pytest.fixture
def small_blocks(monkeypatch):
    """CSV parsed in blocks of 256 bytes (each with its own dictionaries) and, from 1 kB, in parts
    of 1 kB on two threads."""
    from trustseek.data import sources

    monkeypatch.setattr(sources, "BLOCK_BYTES", 256)
    monkeypatch.setattr(sources, "SPLIT_BYTES", 1024)
    monkeypatch.setattr(sources, "PART_BYTES", 1024)


def test_blocks_with_their_own_dictionaries_read_as_one_table(tmp_path, small_blocks):
    import pyarrow.csv as pcsv

    from trustseek.data import sources

    # later blocks meet the labels in another order, and the ids and empty actions anew
    text = HEADER + rows(IDS[:40]) + rows(IDS[40:]).replace("low,ask,rely,faulty", "high,autonomous,,reliable")
    frame = same_read(tmp_path, text)
    assert len(sources._csv_parts(tmp_path / "log.csv")[0]) == 5
    chunks = pcsv.read_csv(tmp_path / "log.csv", read_options=pcsv.ReadOptions(block_size=256)).column(0).num_chunks
    assert chunks > 20 and len(frame) == 160 and frame["human_action"].isna().sum() == 80
    assert list(frame["complexity"].iloc[[0, 79, 80, 159]]) == ["low", "low", "high", "high"]


@pytest.mark.parametrize("at", [5, 150])  # a first block; a late block of the second half
def test_text_that_is_not_utf8_in_any_block_is_refused(tmp_path, small_blocks, at):
    lines = (HEADER + rows(IDS)).splitlines(keepends=True)
    lines[at] = lines[at].replace("rely", "r\xe9ly")
    path = tmp_path / "log.csv"
    path.write_bytes("".join(lines).encode("latin-1"))
    with pytest.raises(DataError) as exc:
        read_trials(path)
    assert exc.value.problems == ["the file is not UTF-8 text (save it as UTF-8 CSV)"]


def test_rows_of_another_width_in_any_block_are_found_by_a_second_pass(tmp_path, small_blocks, monkeypatch):
    """A log whose rows are all as wide as the header is parsed once, without a handler for bad
    rows; a bad row anywhere makes its half parsed again with it, to number every bad row."""
    import pyarrow.csv as pcsv

    handlers = []
    real = pcsv.read_csv

    def spy(source, parse_options=None, **kw):
        handlers.append(parse_options.invalid_row_handler is not None)
        return real(source, parse_options=parse_options, **kw)

    monkeypatch.setattr(pcsv, "read_csv", spy)
    lines = (HEADER + rows(IDS)).splitlines(keepends=True)
    path = tmp_path / "log.csv"
    path.write_text("".join(lines))
    read_trials(path)
    parts = path.stat().st_size // 1024
    assert handlers == [False] * parts  # one pass each
    lines[7] = lines[7].replace(",1\n", ",1,x\n")
    lines[150] = lines[150].replace("rely,", "")
    path.write_text("".join(lines))
    handlers.clear()
    with pytest.raises(DataError) as exc:
        read_trials(path)
    assert sorted(handlers) == [False] * parts + [True, True]  # the two parts with a bad row again
    assert exc.value.problems == [
        "rows whose number of fields differs from the header's 7 (delimiter ',') in 2 rows: "
        "row 7 (8 fields): 'P003,1,low,ask,rely,faulty,1,x'; row 150 (6 fields): 'P074,2,low,ask,faulty,2'"
    ]


@pytest.mark.parametrize("at", [36, 77])  # a cell of 40 lines over the end of the first part; of another
def test_a_quoted_value_over_line_ends_makes_the_file_read_in_one_pass(tmp_path, small_blocks, monkeypatch, at):
    from trustseek.data import sources

    monkeypatch.setattr(sources, "BLOCK_BYTES", 1 << 20)  # the cell in one block (blocks split at line ends)
    cell = '"' + "\n".join(["note"] * 40) + '"'
    lines = (HEADER + rows(IDS)).splitlines(keepends=True)
    lines[at] = lines[at].rsplit(",", 1)[0] + "," + cell + "\n"
    text = "".join(lines)
    start, count = text.index(cell), len(text) // 1024
    assert any(start < j * len(text) // count < start + len(cell) for j in range(1, count))  # a split in the cell
    frame = same_read(tmp_path, text)
    assert len(frame) == 160 and frame["block"].iloc[at - 1] == cell.strip('"')


def test_a_file_that_quotes_its_header_is_read_in_one_pass_from_the_start(tmp_path, small_blocks):
    from trustseek.data import sources

    text = HEADER.replace("participant", '"participant"') + rows(IDS)
    same_read(tmp_path, text)
    assert sources._csv_parts(tmp_path / "log.csv")[0] == [tmp_path / "log.csv"]


def test_a_quoted_value_over_line_ends_at_a_block_end_is_one_value(tmp_path, monkeypatch):
    """pyarrow's reader ends a block at its last line end; without newlines in values allowed, a
    line end inside a quoted value there cut the row in two, and a valid file was refused with
    rows of the wrong width (a log over 16 MB with a free-text column of several lines)."""
    from trustseek.data import sources

    monkeypatch.setattr(sources, "BLOCK_BYTES", 256)
    lines = (HEADER + rows(IDS)).splitlines(keepends=True)
    cell = '"' + "\n".join(["note"] * 40) + '"'
    at = next(i for i in range(1, len(lines)) if len("".join(lines[:i])) > 200)
    lines[at] = lines[at].rsplit(",", 1)[0] + "," + cell + "\n"
    frame = same_read(tmp_path, "".join(lines))
    assert len(frame) == 160 and frame["block"].iloc[at - 1] == cell.strip('"')
