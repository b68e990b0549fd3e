"""Trial logs: reading, column/label mapping, validation messages, writing."""

import json

import numpy as np
import pandas as pd
import pytest

from trustseek.data.trials import CANONICAL, ColumnMapping, DataError, example_path, read_trials, write_trials

GOOD = """participant,trial,complexity,robot_action,human_action,experience,block
A,1,low,autonomous,rely,reliable,1
A,2,high,ask,intervene,reliable,1
A,3,high,autonomous,,faulty,1
B,1,high,autonomous,intervene,faulty,2
B,2,low,autonomous,rely,reliable,2
"""


def write(tmp_path, text, name="log.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def problems(exc):
    return "\n".join(exc.value.lines())


def test_reads_canonical_log_and_keeps_extra_columns(tmp_path):
    df = read_trials(write(tmp_path, GOOD))
    assert list(df.columns[:6]) == list(CANONICAL)
    assert "block" in df.columns
    assert df["trial"].dtype == np.int64
    assert df["trial"].tolist() == [1, 2, 3, 1, 2]
    # an empty human action is "not recorded": missing, not an error
    assert pd.isna(df.loc[2, "human_action"])
    assert df["human_action"].notna().sum() == 4


def test_example_file_is_shipped_and_valid():
    df = read_trials(example_path())
    assert df["participant"].nunique() == 9
    assert (df.groupby("participant").size() == 71).all()
    assert (df["complexity"] == "low").sum() == 9 * 41


@pytest.mark.parametrize(
    "edit, expected",
    [
        (lambda t: t.replace("complexity,", "cx,", 1), ["log.csv", "missing column 'complexity'"]),
        (lambda t: t.replace("B,1,high,autonomous", "B,1,medium,autonomous"), ["row 4", "column 'complexity'", "'medium'"]),
        (lambda t: t.replace("B,2,low", "B,1,low"), ["row 5", "duplicate trial index 1", "'B'", "first at row 4"]),
        (lambda t: t.replace("B,1,high", ",1,high"), ["row 4", "column 'participant'", "empty participant"]),
        (lambda t: t.replace("A,2,high,ask,intervene", "A,2,high,ask,NaN"), ["row 2", "column 'human_action'", "NaN"]),
        (
            lambda t: t.replace("A,1,low,autonomous,rely,reliable", "A,1,low,autonomous,rely,"),
            ["row 1", "column 'experience'", "empty value"],
        ),
        (lambda t: t.replace("B,2,low", "B,two,low"), ["row 5", "column 'trial'", "'two'"]),
    ],
)
def test_validation_names_file_row_column_value(tmp_path, edit, expected):
    path = write(tmp_path, edit(GOOD))
    with pytest.raises(DataError) as exc:
        read_trials(path)
    text = problems(exc)
    for piece in expected:
        assert piece in text, text
    assert str(path) in text


def test_every_problem_is_reported_at_once(tmp_path):
    bad = GOOD.replace("B,1,high,autonomous", "B,1,medium,autonomous").replace(
        "A,1,low,autonomous,rely", "A,1,low,autopilot,rely"
    )
    with pytest.raises(DataError) as exc:
        read_trials(write(tmp_path, bad))
    assert len(exc.value.problems) == 2


OTHER = """subject,trial_no,automation_correct,rely
s1,1,1,1
s1,2,0,1
s1,3,1,0
s2,1,1,1
"""


def test_column_and_label_mapping_by_flags_and_files(tmp_path):
    path = write(tmp_path, OTHER, "other.csv")
    flags = ColumnMapping.from_flags(
        ["participant=subject", "trial=trial_no", "experience=automation_correct", "human_action=rely"],
        ["experience:0=faulty", "experience:1=reliable", "human_action:0=intervene", "human_action:1=rely"],
    )
    need = ("participant", "trial", "experience", "human_action")
    df = read_trials(path, flags, required=need)
    assert df["experience"].tolist() == ["reliable", "faulty", "reliable", "reliable"]
    assert df["human_action"].tolist() == ["rely", "rely", "intervene", "rely"]
    assert df["complexity"].isna().all()  # absent optional column comes back empty
    # the same mapping as a JSON and a TOML file
    js = tmp_path / "map.json"
    js.write_text(json.dumps(flags.to_dict()))
    pd.testing.assert_frame_equal(read_trials(path, js, required=need), df)
    toml = tmp_path / "map.toml"
    toml.write_text(
        '[columns]\nparticipant = "subject"\ntrial = "trial_no"\nexperience = "automation_correct"\nhuman_action = "rely"\n'
        '[labels.experience]\n"0" = "faulty"\n"1" = "reliable"\n[labels.human_action]\n"0" = "intervene"\n"1" = "rely"\n'
    )
    pd.testing.assert_frame_equal(read_trials(path, toml, required=need), df)
    # the shipped example mapping works the same way
    pd.testing.assert_frame_equal(
        read_trials(
            path,
            example_path("other_study_mapping.json").read_text() and ColumnMapping.load(example_path("other_study_mapping.json")),
            required=need,
        ),
        df,
    )


def test_unmapped_label_is_an_unknown_category(tmp_path):
    path = write(tmp_path, OTHER, "other.csv")
    m = ColumnMapping.from_flags(
        ["participant=subject", "trial=trial_no", "experience=automation_correct", "human_action=rely"], ["experience:1=reliable"]
    )
    with pytest.raises(DataError) as exc:
        read_trials(path, m, required=("experience", "human_action"))
    text = problems(exc)
    assert "row 2" in text and "'automation_correct'" in text and "'0'" in text


def test_bad_mapping_flags_are_reported():
    with pytest.raises(DataError, match="canonical=theirs"):
        ColumnMapping.from_flags(["human_action"], [])
    with pytest.raises(DataError, match="not one of"):
        ColumnMapping.from_flags([], ["human_action:1=trusts"])
    with pytest.raises(DataError, match="not a canonical column"):
        ColumnMapping.from_flags(["reliance=rely"], [])


def test_parquet_roundtrip_with_unobserved_actions(tmp_path):
    df = read_trials(write(tmp_path, GOOD))
    pq = tmp_path / "log.parquet"
    write_trials(df, pq)
    back = read_trials(pq)
    pd.testing.assert_frame_equal(back[list(CANONICAL)], df[list(CANONICAL)])
    csv = tmp_path / "again.csv"
    write_trials(df, csv)
    pd.testing.assert_frame_equal(read_trials(csv)[list(CANONICAL)], df[list(CANONICAL)])
    with pytest.raises(DataError, match="unknown file type"):
        write_trials(df, tmp_path / "log.xlsx")


def test_parquet_nan_and_float_labels(tmp_path):
    raw = pd.DataFrame(
        {"participant": ["a", "a"], "trial": [1.0, 2.0], "experience": [1.0, np.nan], "human_action": ["rely", None]}
    )
    pq = tmp_path / "x.parquet"
    raw.to_parquet(pq)
    m = ColumnMapping(labels={"experience": {"1": "reliable", "0": "faulty"}})
    with pytest.raises(DataError) as exc:
        read_trials(pq, m, required=("experience", "human_action"))
    assert "column 'experience': value is NaN (expected one of ['faulty', 'reliable']): row 2" in problems(exc)


def test_missing_file_and_dataframe_source(tmp_path):
    with pytest.raises(DataError, match="file not found"):
        read_trials(tmp_path / "nope.csv")
    df = pd.read_csv(pd.io.common.StringIO(GOOD), dtype=str, keep_default_na=False)
    assert len(read_trials(df)) == 5


@pytest.mark.parametrize(
    ("suffix", "layout"), [(".json", "lines"), (".jsonl", "array"), (".ndjson", "array"), (".json", "array")]
)
def test_json_lines_and_arrays_are_told_apart_by_content(tmp_path, suffix, layout):
    canonical = read_trials(example_path("paper_trials.csv"))
    records = pd.read_csv(example_path("paper_trials.csv")).to_dict(orient="records")
    f = tmp_path / f"log{suffix}"
    f.write_text("\n".join(json.dumps(r) for r in records) if layout == "lines" else json.dumps(records, indent=1))
    frame = read_trials(f)
    cols = ["participant", "trial", "complexity", "robot_action", "human_action", "experience"]
    assert frame[cols].astype(str).equals(canonical[cols].astype(str))


def test_each_column_of_a_file_is_turned_into_codes_once(monkeypatch):
    """The participant column was converted twice (the check for empty rows, then the reading):
    on 7.1 M rows with 100,000 participants, 0.12 s each time."""
    from collections import Counter

    from trustseek.data import sources

    seen: Counter[str] = Counter()
    convert = sources.column_from_arrow

    def counted(chunked, missing, *how):
        seen[str(chunked.type)] += 1
        return convert(chunked, missing, *how)

    monkeypatch.setattr(sources, "column_from_arrow", counted)
    frame = read_trials(example_path())
    # the six canonical columns as codes (true_trust, an extra column, is carried as it is)
    assert len(frame) == 639 and sum(seen.values()) == 6, seen
