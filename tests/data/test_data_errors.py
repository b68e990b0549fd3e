"""Trial logs that are wrong in a way the reader must refuse, and logs it must accept."""

from __future__ import annotations

import json
import re
import shlex
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cli_runner import run_cli
from trustseek.data.trials import ColumnMapping, DataError, example_path, read_trials
from trustseek.estimation import decode, encode, paper_spec
from trustseek.model.presets import paper_model

HEADER = "participant,trial,complexity,robot_action,human_action,experience"
ROWS = [
    "A,1,low,autonomous,rely,reliable",
    "A,2,high,ask,intervene,reliable",
    "A,3,low,ask,intervene,faulty",
    "A,4,high,autonomous,intervene,faulty",
    "B,1,high,autonomous,rely,faulty",
    "B,2,low,autonomous,,reliable",
    "B,3,high,autonomous,rely,reliable",
]
GOOD = "\n".join([HEADER, *ROWS]) + "\n"


def write(tmp_path: Path, text: str, name: str = "log.csv") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def lines_of(exc: pytest.ExceptionInfo) -> list[str]:
    return exc.value.lines()


def test_the_good_log_is_accepted(tmp_path):
    assert len(read_trials(write(tmp_path, GOOD))) == len(ROWS)


@pytest.mark.parametrize(
    "row, expected",
    [
        ("B,1,low,ask,intervene,reliable", "'reliable' after an ask in low complexity"),
        ("B,1,high,ask,intervene,faulty", "'faulty' after an ask in high complexity"),
        ("B,1,high,autonomous,intervene,reliable", "'reliable' after an intervention"),
    ],
)
def test_a_row_contradicting_the_experience_rule_is_an_error(tmp_path, row, expected):
    path = write(tmp_path, GOOD.replace("B,1,high,autonomous,rely,faulty", row))
    with pytest.raises(DataError) as exc:
        read_trials(path)
    text = "\n".join(lines_of(exc))
    assert expected in text and "column 'experience'" in text and "row 5" in text and str(path) in text
    assert len(read_trials(path, check_experience=False)) == len(ROWS)


def test_an_entirely_empty_human_action_column_is_an_error(tmp_path):
    text = "\n".join([HEADER, *[",".join(r.split(",")[:4] + ["", r.split(",")[5]]) for r in ROWS]]) + "\n"
    path = write(tmp_path, text)
    with pytest.raises(DataError, match="no trial has a recorded human action"):
        read_trials(path)
    # some cells empty: "not recorded", as the format allows
    assert read_trials(write(tmp_path, GOOD))["human_action"].isna().sum() == 1


def test_trials_counted_from_zero_are_accepted_and_keep_their_numbers(tmp_path):
    shifted = [",".join([r.split(",")[0], str(int(r.split(",")[1]) - 1), *r.split(",")[2:]]) for r in ROWS]
    zero = read_trials(write(tmp_path, "\n".join([HEADER, *shifted]) + "\n", "zero.csv"))
    one = read_trials(write(tmp_path, GOOD))
    assert zero["trial"].tolist() == [t - 1 for t in one["trial"]]
    a, b = encode(zero, paper_spec()), encode(one, paper_spec())
    np.testing.assert_array_equal(a.y, b.y)
    np.testing.assert_array_equal(a.ut, b.ut)
    post = decode(zero, paper_model())
    assert post["trial"].tolist() == zero["trial"].tolist()
    np.testing.assert_allclose(post["p_trust_high"], decode(one, paper_model())["p_trust_high"])


def test_a_gap_in_a_zero_based_log_is_accepted_and_closed(tmp_path):
    """Trial numbers with gaps (trials removed from the log) are accepted: consecutive rows of a
    participant in trial order are consecutive trials, so the fit equals the renumbered log's."""
    shifted = [",".join([r.split(",")[0], str(int(r.split(",")[1]) - 1), *r.split(",")[2:]]) for r in ROWS]
    renumber = {"A,1,": "A,3,", "A,2,": "A,4,", "A,3,": "A,9,"}  # A: 0, 3, 4, 9
    gapped = [renumber[r[:4]] + r[4:] if r[:4] in renumber else r for r in shifted]
    assert gapped != shifted
    frame = read_trials(write(tmp_path, "\n".join([HEADER, *gapped]) + "\n"))
    plain = read_trials(write(tmp_path, "\n".join([HEADER, *shifted]) + "\n", "plain.csv"))
    a, b = encode(frame, paper_spec()), encode(plain, paper_spec())
    np.testing.assert_array_equal(a.y, b.y)
    np.testing.assert_array_equal(a.ue, b.ue)
    np.testing.assert_array_equal(a.ut, b.ut)
    post = decode(frame, paper_model())
    assert post["trial"].tolist() == frame["trial"].tolist()  # the log's own numbers come back
    np.testing.assert_allclose(post["p_trust_high"], decode(plain, paper_model())["p_trust_high"])


@pytest.mark.parametrize("sep, name", [(";", "log.csv"), ("\t", "log.tsv"), ("\t", "log.csv"), ("|", "log.txt")])
def test_the_delimiter_is_found(tmp_path, sep, name):
    df = read_trials(write(tmp_path, GOOD.replace(",", sep), name))
    pd.testing.assert_frame_equal(df, read_trials(write(tmp_path, GOOD)))


def test_a_missing_column_says_how_to_map_it_and_which_model_needs_none(tmp_path):
    path = write(tmp_path, GOOD.replace("complexity,", "cx,", 1))
    with pytest.raises(DataError) as exc:
        read_trials(path)
    text = "\n".join(lines_of(exc))
    assert "missing column 'complexity'" in text
    assert "--column" in text and "--mapping" in text
    assert "--transitions-on" in text and "--emissions-on" in text


def test_columns_named_in_another_style_get_the_flags_that_map_them(tmp_path):
    header = "Participant,TRIAL,complexity,Robot Action,human-action,Experience"
    path = write(tmp_path, GOOD.replace(HEADER, header, 1))
    with pytest.raises(DataError) as exc:
        read_trials(path)
    flags = "--column participant=Participant --column trial=TRIAL --column 'robot_action=Robot Action' "
    flags += "--column human_action=human-action --column experience=Experience"
    assert any(line.endswith(f"hint: columns named in another style: {flags}") for line in lines_of(exc))
    code, output = run_cli(
        ["decode", str(path), "-m", "paper", "-o", str(tmp_path / "p.csv"), *shlex.split(flags)]
    )  # the hint, followed, reads the log
    assert code == 0, output


def test_a_mapped_name_found_in_another_style_gets_its_flag(tmp_path):
    """A mapping's 'pid' for a log whose columns an SPSS portable file wrote in capitals ('PID'): the
    hint named only the canonical names, and the model hint called present columns absent."""
    header = "PID,trial,CX,robot_action,human_action,experience"
    path = write(tmp_path, GOOD.replace(HEADER, header, 1))
    with pytest.raises(DataError) as exc:
        read_trials(path, {"columns": {"participant": "pid", "complexity": "cx"}})
    lines = lines_of(exc)
    assert any(
        line.endswith("hint: columns named in another style: --column participant=PID --column complexity=CX") for line in lines
    )
    assert not any("--transitions-on" in line for line in lines)


def test_a_log_without_trial_numbers_is_pointed_to_its_time_column(tmp_path):
    lines = [HEADER.replace("trial,", "", 1) + ",started at"]
    lines += [",".join(r.split(",")[:1] + r.split(",")[2:]) + f",2026-01-01T10:{i:02d}:00" for i, r in enumerate(ROWS)]
    path = write(tmp_path, "\n".join(lines) + "\n")
    with pytest.raises(DataError) as exc:
        read_trials(path)
    hint = "hint: trials without numbers are put in order by a column of times or numbers: --order 'started at'"
    assert any(line.endswith(hint) for line in lines_of(exc))
    df = read_trials(path, mapping=ColumnMapping(order=["started at"]))  # the hint, followed, reads the log
    assert list(df["trial"]) == [1, 2, 3, 4, 1, 2, 3]


def test_labels_coded_as_numbers_get_the_flags_to_say_which_is_which(tmp_path):
    path = write(tmp_path, GOOD.replace(",rely,", ",0,").replace(",intervene,", ",1,"))
    with pytest.raises(DataError) as exc:
        read_trials(path)
    hint = (
        "hint: if '0', '1' code the labels of human_action, say which label each is: --label human_action:0=LABEL "
        "--label human_action:1=LABEL, LABEL one of ['intervene', 'rely'] (or a mapping file's labels)"
    )
    assert any(line.endswith(hint) for line in lines_of(exc))
    good = read_trials(write(tmp_path, GOOD, "good.csv"))
    pd.testing.assert_frame_equal(
        read_trials(path, ColumnMapping(labels={"human_action": {"0": "rely", "1": "intervene"}})), good
    )


def test_a_spreadsheet_s_empty_header_cells_name_their_columns_by_place(tmp_path):
    text = "\n".join(line + ";;" for line in [HEADER, *ROWS]).replace(",", ";")
    df, good = read_trials(write(tmp_path, text)), read_trials(write(tmp_path, GOOD, "good.csv"))
    assert list(df.columns) == [*good.columns, "(column 7)", "(column 8)"]
    pd.testing.assert_frame_equal(df[good.columns], good)
    with pytest.raises(DataError) as exc:
        read_trials(write(tmp_path, text.replace("experience;", "exp;", 1)))
    assert (
        "columns present: ['participant', 'trial', 'complexity', 'robot_action', 'human_action', 'exp', '(column 7)', '(column 8)']"
        in lines_of(exc)[0]
    )


@pytest.mark.parametrize("folder", [False, True])
def test_a_log_without_permission_to_read_it_is_refused_by_name(tmp_path, monkeypatch, folder):
    path = write(tmp_path, GOOD)
    opened = Path.open

    def denied(self: Path, *args, **kwargs):  # as a file of another user, which root (the tests' user here) could read
        if self.name == path.name:
            raise PermissionError(13, "Permission denied", str(self))
        return opened(self, *args, **kwargs)

    monkeypatch.setattr(Path, "open", denied)
    with pytest.raises(DataError) as exc:
        read_trials(tmp_path if folder else path)
    assert str(exc.value) == f"{path}: cannot read the file: Permission denied"


def test_an_unknown_delimiter_gets_a_hint(tmp_path):
    with pytest.raises(DataError) as exc:
        read_trials(write(tmp_path, GOOD.replace(",", ";")), delimiter=",")
    text = "\n".join(lines_of(exc))
    assert "single column" in text and "delimiter" in text
    assert sum("missing column" in line for line in lines_of(exc)) == 6


def test_labels_in_another_case_get_the_flags_that_map_them(tmp_path):
    text = GOOD.replace("A,1,low,", "A,1,Low,").replace("B,1,high,autonomous,rely,", "B,1,high,autonomous, RELY ,")
    with pytest.raises(DataError) as exc:
        read_trials(write(tmp_path, text))
    lines = lines_of(exc)
    assert any("unknown category" in x and "'Low'" in x for x in lines)
    hints = [x for x in lines if "hint:" in x]
    assert len(hints) == 2
    assert any("--label complexity:Low=low" in x for x in hints)
    assert any("--label human_action:RELY=rely" in x for x in hints)
    # the flags the hint gives read the log
    m = ColumnMapping.from_flags([], ["complexity:Low=low", "human_action:RELY=rely"])
    df = read_trials(write(tmp_path, text), m)
    assert df["complexity"].iloc[0] == "low" and df["human_action"].iloc[4] == "rely"


def test_an_unknown_label_unlike_any_label_gets_no_hint(tmp_path):
    with pytest.raises(DataError) as exc:
        read_trials(write(tmp_path, GOOD.replace("A,1,low,", "A,1,easy,")))
    assert not any("hint:" in x for x in lines_of(exc))


def test_several_kinds_of_problem_one_line_each_with_a_count(tmp_path):
    rows = list(ROWS)
    rows[0] = "A,1,medium,autonomous,rely,reliable"
    rows[4] = "B,1,medium,autonomous,rely,faulty"
    rows[5] = "B,2,mid,autonomous,,reliable"
    rows[1] = "A,2,high,ask,trusts,reliable"
    rows[6] = "B,2,high,autonomous,rely,reliable"
    with pytest.raises(DataError) as exc:
        read_trials(write(tmp_path, "\n".join([HEADER, *rows]) + "\n"))
    got = lines_of(exc)
    assert len(got) == 3, got
    cx = next(line for line in got if "column 'complexity'" in line)
    assert "in 3 rows" in cx and "row 1 'medium'" in cx and "row 6 'mid'" in cx
    assert any("column 'human_action'" in line and "row 2 'trusts'" in line for line in got)
    assert any("duplicate trial index 2 for participant 'B'" in line and "first at row 6" in line for line in got)


def test_many_problems_of_one_kind_are_one_line(tmp_path):
    rows = [f"P{i},1,medium,autonomous,rely,reliable" for i in range(500)]
    with pytest.raises(DataError) as exc:
        read_trials(write(tmp_path, "\n".join([HEADER, *rows]) + "\n"))
    (line,) = lines_of(exc)
    assert "in 500 rows" in line and "row 1 'medium'" in line and "(495 more)" in line


def test_numbers_and_booleans_match_labels_in_every_format(tmp_path):
    raw = pd.DataFrame(
        {
            "subject": ["s1", "s1", "s2"],
            "trial_no": [1, 2, 1],
            "automation_correct": [True, False, True],
            "rely": [1.0, 0.0, 1.0],
        }
    )
    pq = tmp_path / "other.parquet"
    raw.to_parquet(pq)
    csv = write(tmp_path, "subject,trial_no,automation_correct,rely\ns1,1.0,TRUE,1.0\ns1,2,false,0\ns2,1,True,\n")
    need = ("experience", "human_action")
    for labels in (("0", "1"), ("false", "true")):
        m = ColumnMapping.from_flags(
            ["participant=subject", "trial=trial_no", "experience=automation_correct", "human_action=rely"],
            [
                f"experience:{labels[0]}=faulty",
                f"experience:{labels[1]}=reliable",
                "human_action:0=intervene",
                "human_action:1=rely",
            ],
        )
        a = read_trials(pq, m, required=need)
        assert a["experience"].tolist() == ["reliable", "faulty", "reliable"]
        assert a["human_action"].tolist() == ["rely", "intervene", "rely"]
        b = read_trials(csv, m, required=need)
        pd.testing.assert_frame_equal(a[["participant", "trial", "experience"]], b[["participant", "trial", "experience"]])
        assert pd.isna(b["human_action"].iloc[2])


def test_the_shipped_mapping_names_the_complexities_as_the_docs_show():
    d = json.loads(example_path("other_study_mapping.json").read_text())
    assert d["complexities"] == ["low", "high"]
    assert ColumnMapping.load(example_path("other_study_mapping.json")).complexities == ("low", "high")


def test_rows_are_data_rows_in_every_format(tmp_path):
    bad = GOOD.replace("B,2,low", "B,2,medium")
    csv = write(tmp_path, bad)
    pq = tmp_path / "log.parquet"
    pd.read_csv(csv, dtype=str, keep_default_na=False).to_parquet(pq)
    for path in (csv, pq):
        with pytest.raises(DataError) as exc:
            read_trials(path)
        assert "row 6 'medium'" in "\n".join(lines_of(exc))
    with pytest.raises(DataError) as exc:
        read_trials(pd.read_csv(csv, dtype=str, keep_default_na=False))
    assert "row 6 'medium'" in "\n".join(lines_of(exc))


@pytest.mark.parametrize(
    "text, expected",
    [
        (GOOD.replace("A,2,", "A,99999999999999999999,"), "not an integer"),
        (GOOD.replace("A,2,", "A,-1,"), "not an integer"),
        (GOOD.replace("A,2,", "A,2.5,"), "'2.5'"),
        (GOOD.replace("A,2,", "A,nan,"), "value is NaN"),
        (HEADER + "\n", "no trials"),
        ("", "empty"),
        (GOOD.replace("participant,trial", "participant,participant"), "appears 2 times"),
        (GOOD + "C,1,low,autonomous,rely,reliable,extra\n", "number of fields"),
    ],
)
def test_malformed_files_are_refused_with_a_located_message(tmp_path, text, expected):
    path = write(tmp_path, text)
    with pytest.raises(DataError) as exc:
        read_trials(path)
    text = "\n".join(lines_of(exc))
    assert expected in text and str(path) in text


def test_a_file_that_is_not_utf8_is_named(tmp_path):
    path = tmp_path / "log.csv"
    path.write_bytes(GOOD.replace("B,2,low", "B,2,l\xf6w").encode("latin-1"))
    with pytest.raises(DataError, match="UTF-8") as exc:
        read_trials(path)
    assert str(path) in str(exc.value)


# --------------------------------------------------------------------------- adversarial: every command that reads a log


def _corrupt(kind: str, rng: np.random.Generator) -> bytes:
    rows = [r.split(",") for r in ROWS]
    header = HEADER.split(",")
    i = int(rng.integers(len(rows)))
    col = int(rng.integers(len(header)))
    if kind == "bytes":
        return bytes(rng.integers(0, 256, size=int(rng.integers(1, 200)), dtype=np.uint8))
    if kind == "utf16":
        return GOOD.encode("utf-16")
    if kind == "delimiter":
        return GOOD.replace(",", " ").encode()
    if kind == "missing_column":
        col = col % 5  # a column every command needs (agnostic does without experience)
        keep = [j for j in range(len(header)) if j != col]
        return ("\n".join(",".join(r[j] for j in keep) for r in [header, *rows]) + "\n").encode()
    if kind == "duplicate_column":
        return ("\n".join(",".join([*r, r[col]]) for r in [header, *rows]) + "\n").encode()
    if kind == "extra_field":
        rows[i].append("x")
    elif kind == "bad_label":
        col = int(rng.integers(2, 6))
        rows[i][col] = str(rng.choice(["medium", "Rely", "yes", "2", "-", "NaN", "null"]))
    elif kind == "trial":
        rows[i][1] = str(rng.choice(["0.5", "-3", "1e30", "99999999999999999999", "NaN", "", "x", "inf"]))
    elif kind == "duplicate_row":
        rows.insert(i, list(rows[i]))
    elif kind == "participant":
        rows[i][0] = str(rng.choice(["", "NaN", "null"]))
    elif kind == "no_human_action":
        for r in rows:
            r[4] = ""
    elif kind == "experience_rule":
        rows[1][5] = "faulty"  # an ask in high complexity ends reliable
    elif kind == "header_only":
        rows = []
    return ("\n".join(",".join(r) for r in [header, *rows]) + "\n").encode()


KINDS = [
    "bytes",
    "utf16",
    "delimiter",
    "missing_column",
    "duplicate_column",
    "extra_field",
    "bad_label",
    "trial",
    "duplicate_row",
    "participant",
    "no_human_action",
    "experience_rule",
    "header_only",
]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kind=st.sampled_from(KINDS), seed=st.integers(0, 2**32 - 1), suffix=st.sampled_from([".csv", ".tsv", ".parquet"]))
def test_every_command_refuses_a_corrupted_log(kind, seed, suffix):
    rng = np.random.default_rng(seed)
    data = _corrupt(kind, rng)
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        log = folder / f"log{suffix}"
        log.write_bytes(data.replace(b",", b"\t") if suffix == ".tsv" and kind != "delimiter" else data)
        if suffix == ".parquet":
            log.write_bytes(data)  # bytes that are no Parquet file at all
        model = folder / "model.json"
        paper_model().save(model)
        with pytest.raises(DataError) as exc:
            read_trials(log)
        assert str(log) in str(exc.value)
        for argv, out in (
            (["fit", str(log), "--restarts", "1", "--out", str(folder / "fitted.json")], folder / "fitted.json"),
            (["decode", str(log), "--model", str(model), "--out", str(folder / "post.csv")], folder / "post.csv"),
            (["select", str(log), "--max-levels", "1", "--restarts", "1", "--folds", "2"], None),
            (["agnostic", "--data", str(log), "--out", str(folder / "policy.json")], folder / "policy.json"),
        ):
            code, err = run_cli(argv, stdout=False)
            assert code == 2, (argv, err)
            assert "Traceback" not in err
            assert str(log) in err.replace("\n", ""), err
            if out is not None:
                assert not out.exists()


def test_csv_is_parsed_on_the_calling_thread(tmp_path, monkeypatch):
    """pyarrow's threaded CSV parse left pool threads that aborted the process at exit under
    load (exit -6 instead of 2 for a log with a missing column, about 1 run in 10 with three
    runs at once); the reader parses on the calling thread."""
    import pyarrow.csv as pcsv

    seen = []
    real = pcsv.read_csv

    def spy(path, read_options=None, **kw):
        seen.append(read_options)
        return real(path, read_options=read_options, **kw)

    monkeypatch.setattr(pcsv, "read_csv", spy)
    read_trials(write(tmp_path, GOOD))
    assert len(seen) == 1 and seen[0] is not None and seen[0].use_threads is False


def _read_split_and_whole(path: Path, monkeypatch) -> list:
    """``read_trials(path)`` parsed whole and in two halves (the frame, or the error's text)."""
    from trustseek.data import sources

    out = []
    for split in (1 << 62, 0):
        monkeypatch.setattr(sources, "SPLIT_BYTES", split)
        try:
            out.append(read_trials(path))
        except DataError as exc:
            out.append(str(exc))
    return out


def test_a_large_csv_parsed_in_two_halves_reads_as_whole(tmp_path, monkeypatch):
    """A large CSV is parsed in two halves at once (two cores); the frame is the one-pass frame."""
    import pyarrow.csv as pcsv

    seen = []
    real = pcsv.read_csv

    def spy(source, read_options=None, **kw):
        seen.append(read_options.use_threads)
        return real(source, read_options=read_options, **kw)

    monkeypatch.setattr(pcsv, "read_csv", spy)
    whole, halves = _read_split_and_whole(example_path(), monkeypatch)
    pd.testing.assert_frame_equal(whole, halves)
    assert seen == [False, False, False]  # one pass, then two halves: never pyarrow's pool


def test_bad_rows_in_either_half_are_numbered_as_in_the_file(tmp_path, monkeypatch):
    lines = example_path().read_text().splitlines()
    lines[3] += ",x"  # first half
    lines[-5] += ",y"  # second half, after an empty line below
    lines.insert(len(lines) // 2 + 10, "")
    lines[-2] = lines[-2].rsplit(",", 1)[0]
    whole, halves = _read_split_and_whole(write(tmp_path, "\n".join(lines) + "\n"), monkeypatch)
    assert whole == halves
    assert "row 3 (8 fields)" in whole and "row 635 (8 fields)" in whole and "row 638 (6 fields)" in whole


def test_a_csv_with_quotes_is_never_cut_inside_a_quoted_line_end(tmp_path, monkeypatch):
    """A quoted value may hold a line end (pyarrow reads it as one value): a file with a quote is
    parsed in one pass, so a cut never falls inside one (here the line end past the middle)."""
    lines = example_path().read_text().splitlines()
    middle = len(lines) // 2 - 1
    lines[middle] = lines[middle].replace(",low,", ',"lo\nw",', 1).replace(",high,", ',"hi\ngh",', 1)
    whole, halves = _read_split_and_whole(write(tmp_path, "\r\n".join(lines) + "\r\n"), monkeypatch)
    assert whole == halves
    assert "unknown category" in whole and f"row {middle}" in whole


def test_duplicate_trials_are_counted_by_participant_naming_the_order(tmp_path):
    frame = pd.read_csv(example_path("paper_trials.csv"))
    again = pd.concat([frame, frame[frame.participant.isin(["P001", "P002"])]])
    f = tmp_path / "retaken.csv"
    again.to_csv(f, index=False)
    with pytest.raises(DataError) as exc:
        read_trials(f)
    line = exc.value.problems[-1]
    n1, n2 = (frame.participant == "P001").sum(), (frame.participant == "P002").sum()
    assert f"by participant, 2 ('P001' {n1}, 'P002' {n2})" in line and '"order"' in line, line


@pytest.mark.parametrize(("encoding", "bom", "expected"), [("utf-16", True, "UTF-16 text"), ("utf-16-le", False, "NUL bytes")])
def test_a_utf16_csv_is_named_with_its_fix(tmp_path, encoding, bom, expected):
    """Excel's 'Unicode Text' (UTF-16) passed as UTF-8 with a NUL between characters, and was refused
    for a row of '\\x00' at its end: the header's encoding is named, with the way to UTF-8."""
    path = tmp_path / "log.csv"
    path.write_bytes(GOOD.encode(encoding))
    assert path.read_bytes()[:2] in (b"\xff\xfe", b"\xfe\xff") or not bom
    with pytest.raises(DataError, match=expected) as exc:
        read_trials(path)
    assert str(path) in str(exc.value) and "UTF-8" in str(exc.value)


def test_excels_sep_line_names_the_delimiter_and_rows_count_from_the_header(tmp_path, monkeypatch):
    """Excel writes (and reads) a first line 'sep=;' naming the delimiter; it was taken for a header
    of two columns and every row refused. It names the delimiter, the header follows it, and a bad
    row is numbered as a data row, in one pass and in two halves alike."""
    lines = example_path().read_text().replace(",", ";").splitlines()
    plain = read_trials(write(tmp_path, "\n".join(lines) + "\n", "plain.csv"))
    declared = write(tmp_path, "\ufeffsep=;\r\n" + "\r\n".join(lines) + "\r\n", "declared.csv")
    pd.testing.assert_frame_equal(read_trials(declared), plain, check_like=True)
    lines[3] += ";x"
    lines[-5] += ";y"
    whole, halves = _read_split_and_whole(write(tmp_path, "sep=;\n" + "\n".join(lines) + "\n"), monkeypatch)
    assert whole == halves
    assert "row 3 (8 fields)" in whole and f"row {len(lines) - 5} (8 fields)" in whole and "delimiter ';'" in whole


def test_rows_with_every_cell_empty_are_dropped_and_counted(tmp_path):
    """A spreadsheet's formatted but unused rows (',,,,,') were refused as trials with an empty id,
    index and labels in every column: they are dropped as blank lines are, and counted; a row with
    some cells empty is a trial (its empty human action a missing one), and the other rows keep
    their numbers."""
    blank = ",,,,,"
    rows = [*ROWS[:3], blank, *ROWS[3:], blank, " , ,,\t,,"]
    frame = read_trials(write(tmp_path, "\n".join([HEADER, *rows]) + "\n"))
    assert frame.attrs["dropped"] == [("every cell empty", 3)]
    clean = read_trials(write(tmp_path, GOOD, "clean.csv"))
    pd.testing.assert_frame_equal(frame.reset_index(drop=True), clean.reset_index(drop=True), check_like=True)
    assert frame["human_action"].isna().sum() == 1  # B,2's empty human action: a trial, kept
    with pytest.raises(DataError, match=r"row 11: duplicate trial index 3 for participant .B. \(first at row 8\)"):
        read_trials(write(tmp_path, "\n".join([HEADER, *rows, "B,3,high,autonomous,rely,reliable"]) + "\n", "dup.csv"))
    records = pd.read_csv(write(tmp_path, GOOD, "records.csv"))
    records.loc[len(records)] = [None] * len(records.columns)  # pandas writes NaN in the trial column
    records.to_parquet(tmp_path / "nulls.parquet")
    assert read_trials(tmp_path / "nulls.parquet").attrs["dropped"] == [("every cell empty", 1)]
    with pytest.raises(DataError, match="every cell of its 2 rows is empty"):
        read_trials(write(tmp_path, "\n".join([HEADER, blank, blank]) + "\n", "none.csv"))
    code, out = run_cli(
        ["decode", str(tmp_path / "log.csv"), "-m", "paper", "-o", str(tmp_path / "posteriors.csv")], stdout=False
    )
    said = " ".join(out.split())
    assert code == 0 and "dropped 3 rows of" in said and "(every cell empty)" in said, out


@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("log.ods", "a spreadsheet: save it as an Excel workbook"),
        ("log.json.gz", "decompress it first"),
        ("log.zip", "decompress it first"),
    ],
)
def test_a_workbook_or_a_packed_log_gets_the_way_to_a_readable_one(tmp_path, name, expected):
    path = tmp_path / name
    path.write_bytes(b"PK\x03\x04")
    with pytest.raises(DataError, match=expected) as exc:
        read_trials(path)
    assert str(path) in str(exc.value) and ".csv, .tsv, .parquet" in str(exc.value) and ".csv.gz" in str(exc.value)


def _compress(data: bytes, codec: str) -> bytes:
    import bz2
    import gzip

    import pyarrow as pa

    if codec == "gzip":
        return gzip.compress(data)
    if codec == "bz2":
        return bz2.compress(data)
    return pa.compress(data, codec, asbytes=True)  # zstd: a raw frame, as the zstd tool writes it


@pytest.mark.parametrize(
    ("suffix", "codec"),
    [(".csv.gz", "gzip"), (".csv.bz2", "bz2"), (".csv.zst", "zstd"), (".tsv.gz", "gzip"), (".CSV.GZ", "gzip")],
)
def test_a_compressed_csv_reads_as_the_plain_file(tmp_path, suffix, codec):
    """A log compressed as a lab's tools keep it (log.csv.gz) was refused with 'decompress it first'."""
    plain = example_path()
    text = plain.read_bytes()
    if suffix.startswith(".tsv"):
        text = text.replace(b",", b"\t")
    path = tmp_path / f"log{suffix}"
    path.write_bytes(_compress(text, codec))
    pd.testing.assert_frame_equal(read_trials(path), read_trials(plain))


def test_a_compressed_csv_keeps_its_delimiter_line_and_row_numbers(tmp_path):
    body = "sep=;\n" + "\n".join([HEADER, *ROWS[:3], "A;4;high", *ROWS[4:]]).replace(",", ";") + "\n"
    path = tmp_path / "log.csv.gz"
    path.write_bytes(_compress(body.encode(), "gzip"))
    with pytest.raises(DataError, match=r"row 4 \(3 fields\)"):
        read_trials(path)


@pytest.mark.parametrize("damage", ["not gzip", "truncated"])
def test_a_damaged_compressed_csv_is_refused_by_name(tmp_path, damage):
    whole = _compress(example_path().read_bytes(), "gzip")
    path = tmp_path / "log.csv.gz"
    path.write_bytes(b"participant,trial\n" if damage == "not gzip" else whole[: len(whole) // 2])
    with pytest.raises(DataError, match=r"cannot decompress the file \(gzip, by its suffix\)") as exc:
        read_trials(path)
    assert str(path) in str(exc.value)


def test_a_json_null_among_numbers_is_an_empty_cell_and_a_nan_a_nan(tmp_path):
    """A JSON null in a column of codes (human_action 0/1) was read as a NaN, refused with 'leave
    the cell empty for not recorded' although it was empty; Parquet's null stays a NaN (pandas
    writes its NaN as null)."""
    frame = pd.read_csv(example_path()).head(6)
    frame["human_action"] = (frame.human_action == "rely").astype(float)
    frame.loc[3, "human_action"] = np.nan
    records = [{k: None if isinstance(v, float) and np.isnan(v) else v for k, v in r.items()} for r in frame.to_dict("records")]
    (tmp_path / "log.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    (tmp_path / "log.json").write_text(json.dumps(records))
    frame.to_parquet(tmp_path / "log.parquet")
    codes = {"labels": {"human_action": {"1": "rely", "0": "intervene"}}}
    for name in ("log.jsonl", "log.json"):
        assert read_trials(tmp_path / name, codes).human_action.isna().tolist() == [False, False, False, True, False, False]
    nan = (
        "value is NaN (expected one of ['intervene', 'rely']; an empty cell, or a NaN with --missing nan, is not recorded): row 4"
    )
    with pytest.raises(DataError, match=re.escape(nan)):
        read_trials(tmp_path / "log.parquet", codes)
    (tmp_path / "nan.jsonl").write_text(
        (tmp_path / "log.jsonl").read_text().replace('"human_action": null', '"human_action": NaN')
    )
    with pytest.raises(DataError, match=re.escape(nan)):
        read_trials(tmp_path / "nan.jsonl", codes)
