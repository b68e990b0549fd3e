"""Layouts read by a mapping alone: per-trial lists exploded from a record per participant or
block, a second file joined by participant (and block), a rating given once per block, and
the trial order given by columns (``order``, ``--order``)."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from test_write_csv import frames

from trustseek.data import ColumnMapping, DataError, example_path, read_trials
from trustseek.data.suffixes import file_kind

FIELDS = ["trial", "complexity", "robot_action", "human_action", "experience"]


@pytest.fixture(scope="module")
def small() -> pd.DataFrame:
    """Three participants' first 20 trials of the shipped log, in blocks of 5, as text."""
    frame = pd.read_csv(example_path(), dtype=str)
    frame = frame[frame.participant.isin(["P001", "P002", "P003"]) & (frame.trial.astype(int) <= 20)]
    frame = frame.reset_index(drop=True)
    frame["block"] = ((frame.trial.astype(int) - 1) // 5 + 1).astype(str)
    return frame


def records(frame: pd.DataFrame, by: list[str], fields: list[str]) -> list[dict]:
    return [
        {**dict(zip(by, key if isinstance(key, tuple) else (key,), strict=True)), **{f: g[f].tolist() for f in fields}}
        for key, g in frame.groupby(by, sort=False)
    ]


def same_trials(frame: pd.DataFrame, canonical: pd.DataFrame) -> None:
    got = frame.assign(participant=frame.participant.astype(str)).sort_values(["participant", "trial"])
    want = canonical.assign(participant=canonical.participant.astype(str)).sort_values(["participant", "trial"])
    for c in ["participant", *FIELDS[1:]]:
        assert got[c].astype(str).tolist() == want[c].astype(str).tolist(), c


# --------------------------------------------------------------------------- explode


@pytest.mark.parametrize("suffix", [".json", ".jsonl", ".parquet", "frame"])
def test_a_record_per_participant_is_exploded_into_its_trials(small, tmp_path, suffix):
    recs = records(small.rename(columns={"participant": "pid"}), ["pid"], FIELDS)
    path = tmp_path / f"people{suffix}"
    if suffix == ".json":
        path.write_text(json.dumps(recs))
    elif suffix == ".jsonl":
        path.write_text("".join(json.dumps(r) + "\n" for r in recs))
    elif suffix == ".parquet":
        pd.DataFrame(recs).to_parquet(path)
    source = pd.DataFrame(recs) if suffix == "frame" else path
    frame = read_trials(source, {"columns": {"participant": "pid"}, "explode": FIELDS})
    same_trials(frame, read_trials(small))


@pytest.mark.parametrize("suffix", [".json", ".jsonl", ".parquet"])
def test_a_record_per_participant_with_a_list_of_trial_objects_is_exploded(small, tmp_path, suffix):
    trials = [{"pid": pid, "trials": g[FIELDS].to_dict("records")} for pid, g in small.groupby("participant")]
    path = tmp_path / f"people{suffix}"
    if suffix == ".json":
        path.write_text(json.dumps({"study": "s1", "participants": trials}))  # the array inside an object
    elif suffix == ".jsonl":
        path.write_text("".join(json.dumps(r) + "\n" for r in trials))
    else:
        pd.DataFrame(trials).to_parquet(path)
    frame = read_trials(path, {"columns": {"participant": "pid"}, "explode": ["trials"]})
    same_trials(frame, read_trials(small))
    trials[1]["trials"][0]["pid"] = "X"  # a trial's field that is a field of its record too
    path = tmp_path / "clash.json"
    path.write_text(json.dumps(trials))
    with pytest.raises(DataError) as exc:
        read_trials(path, {"columns": {"participant": "pid"}, "explode": ["trials"]})
    assert "explode: column 'trials': its objects' field 'pid' is a column of the record too" in exc.value.problems


@pytest.mark.parametrize("orient", ["records", "columns", "index", "split", "table"])
def test_a_frame_written_by_pandas_to_json_is_read_in_every_orientation(small, tmp_path, orient):
    path = tmp_path / f"{orient}.json"
    small.to_json(path, orient=orient)
    assert file_kind(path) == "log"  # what `trustseek check` reads it as: the same rule as the reader's
    frame = read_trials(path)
    if orient == "table":  # the table's records carry the frame's index as a column of their own
        frame = frame.drop(columns="index")
    pd.testing.assert_frame_equal(frame, read_trials(small))


def test_a_json_object_of_several_arrays_or_none_says_what_it_holds(tmp_path):
    path = tmp_path / "two.json"
    path.write_text(json.dumps({"practice": [{"trial": 1}], "main": [{"trial": 1}]}))
    assert file_kind(path) == "log"  # checked as a log, which says the same
    with pytest.raises(DataError, match=r"this object holds 2: \['practice', 'main'\]: keep the one of the trials"):
        read_trials(path)
    path.write_text(json.dumps({"study": "s1", "n": 3}))
    with pytest.raises(DataError, match=r"or an object holding one \(this object's keys: \['study', 'n'\]\)"):
        read_trials(path)


def test_a_record_per_block_numbers_its_items_for_the_order(small, tmp_path):
    recs = records(small, ["participant", "block"], FIELDS[1:])
    path = tmp_path / "blocks.json"
    path.write_text(json.dumps(recs))
    mapping = {"explode": {"columns": FIELDS[1:], "position": "item"}, "order": ["block", "item"]}
    frame = read_trials(path, mapping)
    same_trials(frame, read_trials(small))
    assert frame["item"].astype(int).max() == 5


def test_lists_in_a_column_the_mapping_does_not_explode_are_refused_naming_explode(small, tmp_path):
    recs = records(small, ["participant"], FIELDS)
    for suffix in (".json", ".parquet"):
        path = tmp_path / f"people{suffix}"
        path.write_text(json.dumps(recs)) if suffix == ".json" else pd.DataFrame(recs).to_parquet(path)
        with pytest.raises(DataError) as exc:
            read_trials(path)
        text = "\n".join(exc.value.problems)
        entry = '"explode": ["trial", "complexity", "robot_action", "human_action", "experience"]'
        assert "'complexity'" in text and entry in text, text
        with pytest.raises(DataError) as exc:  # only some columns listed: the others are named
            read_trials(path, {"explode": ["trial", "complexity"]})
        assert any("'human_action'" in p for p in exc.value.problems), exc.value.problems


def test_lists_of_different_lengths_name_the_record_and_the_lengths(small, tmp_path):
    recs = records(small, ["participant"], FIELDS)
    recs[1]["human_action"] = recs[1]["human_action"][:-2]
    path = tmp_path / "people.json"
    path.write_text(json.dumps(recs))
    with pytest.raises(DataError) as exc:
        read_trials(path, {"explode": FIELDS})
    (line,) = exc.value.problems
    assert "record 2 (trial 20, complexity 20, robot_action 20, human_action 18, experience 20)" in line, line


@pytest.mark.parametrize(
    ("cell", "expected"),
    [("low", 'record 2 "low"'), (None, "is empty (expected a list): record 2"), ([["low"]], 'record 2 [["low"]]')],
)
def test_a_cell_of_an_exploded_column_that_is_not_a_list_of_values_is_an_error(small, tmp_path, cell, expected):
    recs = records(small, ["participant"], FIELDS)
    recs[1]["complexity"] = cell
    path = tmp_path / "people.json"
    path.write_text(json.dumps(recs))
    with pytest.raises(DataError) as exc:
        read_trials(path, {"explode": FIELDS})
    assert any(expected in p and "'complexity'" in p for p in exc.value.problems), exc.value.problems


def test_explode_is_refused_for_a_csv_and_checked_in_the_mapping(small, tmp_path):
    path = tmp_path / "log.csv"
    small.to_csv(path, index=False)
    with pytest.raises(DataError, match="a CSV cell is text"):
        read_trials(path, {"explode": ["trial"]})
    for bad in ([], [1], {"columns": ["a"], "where": 1}, {"columns": ["a", "a"]}, {"columns": ["a"], "position": 3}):
        with pytest.raises(DataError, match="explode"):
            ColumnMapping.from_dict({"explode": bad})


# --------------------------------------------------------------------------- join


def test_a_ratings_file_per_block_is_joined_and_counts_once_per_block(small, tmp_path):
    log = small.drop(columns=[]).copy()
    blocks = log[["participant", "block"]].drop_duplicates().reset_index(drop=True)
    blocks["trust"] = (np.arange(len(blocks)) % 7 + 1).astype(str)
    log.to_csv(tmp_path / "log.csv", index=False)
    blocks.to_json(tmp_path / "ratings.json", orient="records")
    mapping = {"join": {"file": "ratings.json"}, "rating": {"column": "trust", "levels": list(range(1, 8)), "per": "block"}}
    (tmp_path / "m.json").write_text(json.dumps(mapping))
    frame = read_trials(tmp_path / "log.csv", tmp_path / "m.json")  # the file is found beside the mapping
    rated = frame[frame.rating.notna()]
    assert len(rated) == len(blocks) == 12
    last = frame.groupby(["participant", "block"], observed=True).trial.transform("max") == frame.trial
    assert rated.index.equals(frame.index[last]), "the rating sits on the block's last trial"
    got = rated.set_index([rated.participant.astype(str), rated.block.astype(str)]).rating.astype(str)
    want = blocks.set_index(["participant", "block"]).trust
    assert got.sort_index().tolist() == want.sort_index().tolist()
    # without 'per' every trial carries the copy
    del mapping["rating"]["per"]
    (tmp_path / "m.json").write_text(json.dumps(mapping))
    assert read_trials(tmp_path / "log.csv", tmp_path / "m.json").rating.notna().sum() == len(small)


def test_a_file_per_participant_is_joined_and_unmatched_log_rows_are_counted(small, tmp_path):
    people = pd.DataFrame({"participant": ["P001", "P002"], "age": [31, 44]})
    people.to_csv(tmp_path / "people.csv", index=False)
    frame = read_trials(small, {"join": {"file": str(tmp_path / "people.csv")}})
    assert frame.loc[frame.participant == "P002", "age"].astype(int).eq(44).all()
    assert frame.loc[frame.participant == "P003", "age"].isna().all()
    assert frame.attrs["joined"] == [
        f"20 trials have no row in {tmp_path / 'people.csv'} (their joined cells are empty): by participant, 1: 'P003' 20"
    ]


def test_duplicate_and_unmatched_keys_of_the_second_file_are_counted_by_participant(small, tmp_path):
    blocks = small[["participant", "block"]].drop_duplicates()
    extra = pd.DataFrame({"participant": ["P009", "P009", "P001"], "block": ["1", "2", "1"]})
    pd.concat([blocks, extra]).assign(trust=3).to_csv(tmp_path / "r.csv", index=False)
    with pytest.raises(DataError) as exc:
        read_trials(small, {"join": {"file": str(tmp_path / "r.csv"), "on": ["participant", "block"]}})
    dup, unmatched = exc.value.problems
    assert "more than one row for a participant / block: 'P001' / '1' (2 rows)" in dup, dup
    assert "match no trial of <table> by participant / block: 2 (by participant, 1: 'P009' 2)" in unmatched, unmatched


def test_join_errors_name_the_columns(small, tmp_path):
    small[["participant", "block"]].drop_duplicates().assign(trial=1).to_csv(tmp_path / "r.csv", index=False)
    with pytest.raises(DataError) as exc:
        read_trials(small, {"join": {"file": str(tmp_path / "r.csv"), "on": ["pid"]}})
    assert any("no column 'pid' in the log" in p for p in exc.value.problems), exc.value.problems
    with pytest.raises(DataError, match=r"column 'trial' of .* is in the log too"):
        read_trials(small, {"join": {"file": str(tmp_path / "r.csv")}})
    with pytest.raises(DataError, match="file not found"):
        read_trials(small, {"join": {"file": str(tmp_path / "none.csv")}})
    with pytest.raises(DataError, match="join: 'file'"):
        ColumnMapping.from_dict({"join": {"on": "participant"}})


# --------------------------------------------------------------------------- a rating per block


def test_different_ratings_within_a_block_are_an_error(small):
    log = small.assign(trust="4")
    log.loc[3, "trust"] = "5"
    with pytest.raises(DataError) as exc:
        read_trials(log, {"rating": {"column": "trust", "levels": [1, 2, 3, 4, 5], "per": "block"}})
    (line,) = exc.value.problems
    assert "different ratings within one block" in line and "row 4" in line, line


def test_a_rating_on_the_first_trial_of_a_block_moves_to_its_last(small):
    log = small.assign(trust=np.where(small.trial.astype(int) % 5 == 1, "2", ""))
    frame = read_trials(log, {"rating": {"column": "trust", "levels": [1, 2, 3], "per": "block"}})
    rated = frame[frame.rating.notna()]
    assert (rated.trial % 5 == 0).all() and len(rated) == 12


# --------------------------------------------------------------------------- order


def test_duplicate_trials_list_every_participant_and_name_the_order_flag(small):
    log = pd.concat([small, small]).reset_index(drop=True)
    with pytest.raises(DataError) as exc:
        read_trials(log)
    line = exc.value.problems[-1]
    assert "by participant, 3 ('P001' 20, 'P002' 20, 'P003' 20)" in line and "--order block,trial" in line, line
    with pytest.raises(DataError) as exc:  # an order that still leaves ties names the participants too
        read_trials(small, {"order": ["block"]})
    line = exc.value.problems[-1]
    assert "by participant, 3 ('P001' 16, 'P002' 16, 'P003' 16)" in line and "--order" in line, line


def test_the_order_flag_replaces_the_files_trial_column(small, tmp_path):
    log = small.assign(within=((small.trial.astype(int) - 1) % 5 + 1).astype(str)).drop(columns="trial")
    log = log.rename(columns={"participant": "pid"}).sample(frac=1, random_state=0)
    (tmp_path / "m.json").write_text(json.dumps({"columns": {"participant": "pid", "trial": "within"}}))
    mapping = ColumnMapping.from_flags([], [], tmp_path / "m.json", order=["block, within"])
    assert mapping.order == ("block", "within") and "trial" not in mapping.columns
    same_trials(read_trials(log, mapping), read_trials(small))
    with pytest.raises(DataError, match="--order"):
        ColumnMapping.from_flags([], [], order=["block,,trial"])


# --------------------------------------------------------------------------- wide


def test_a_wide_log_has_a_row_per_trial_and_fewer_trials_where_cells_are_empty(small, tmp_path):
    fields = FIELDS[1:]
    wide = small.pivot(index="participant", columns="trial", values=fields)
    wide.columns = [f"{f}.{t}" for f, t in wide.columns]
    wide = wide.reset_index()
    wide.loc[wide.participant == "P002", [f"{f}.20" for f in fields]] = None  # P002 has 19 trials
    wide.to_csv(tmp_path / "wide.csv", index=False)
    frame = read_trials(tmp_path / "wide.csv", {"wide": {"columns": fields, "separator": ".", "position": "trial"}})
    want = read_trials(small[~((small.participant == "P002") & (small.trial == "20"))])
    same_trials(frame, want)
    assert frame.groupby("participant", observed=True).size().tolist() == [20, 19, 20]


def test_wide_errors_name_the_fields_and_the_mapping_entries(small, tmp_path):
    small.to_csv(tmp_path / "log.csv", index=False)
    with pytest.raises(DataError, match=r"wide: no columns named choice_1, choice_2"):
        read_trials(tmp_path / "log.csv", {"wide": ["choice"]})
    with pytest.raises(DataError, match="either 'wide'"):
        ColumnMapping.from_dict({"wide": ["a"], "explode": ["b"]})
    with pytest.raises(DataError, match="wide: 'separator'"):
        ColumnMapping.from_dict({"wide": {"columns": ["a"], "separator": 1}})


def test_a_second_files_own_problems_name_it(small, tmp_path):
    (tmp_path / "r.csv").write_text("participant,block,trust\nP001,1,3\nP001,2\n")
    with pytest.raises(DataError) as exc:
        read_trials(small, {"join": {"file": str(tmp_path / "r.csv")}})
    assert exc.value.source == str(tmp_path / "r.csv") and "row 2 (2 fields)" in exc.value.problems[0], exc.value


def test_a_position_that_names_a_column_of_the_log_is_an_error(small, tmp_path):
    recs = records(small, ["participant"], FIELDS)
    (tmp_path / "people.json").write_text(json.dumps(recs))
    with pytest.raises(DataError, match="has a column 'participant' already"):
        read_trials(tmp_path / "people.json", {"explode": {"columns": FIELDS, "position": "participant"}})


def test_a_second_file_with_its_own_names_is_joined_by_a_map_of_the_keys(small, tmp_path):
    people = pd.DataFrame({"pid": ["P001", "P002", "P003"], "group": ["a", "b", "a"]})
    people.to_json(tmp_path / "people.jsonl", orient="records", lines=True)
    frame = read_trials(small, {"join": {"file": str(tmp_path / "people.jsonl"), "on": {"participant": "pid"}}})
    assert frame.groupby("participant", observed=True).group.first().tolist() == ["a", "b", "a"]
    with pytest.raises(DataError, match="no column 'id' in"):
        read_trials(small, {"join": {"file": str(tmp_path / "people.jsonl"), "on": {"participant": "id"}}})


def test_the_new_entries_survive_a_round_trip_and_a_toml_file(tmp_path):
    d = {
        "explode": {"columns": ["choice"], "position": "item"},
        "join": {"file": "/data/ratings.csv", "on": {"subject": "pid"}},
        "rating": {"column": "trust", "levels": [1, 2, 3], "per": "block"},
        "order": ["block", "item"],
    }
    m = ColumnMapping.from_dict(d)
    assert ColumnMapping.from_dict(m.to_dict()) == m
    (tmp_path / "m.toml").write_text(
        'order = ["block", "item"]\nexplode = ["choice"]\n[join]\nfile = "ratings.csv"\n[wide]\ncolumns = ["x"]\n'
    )
    with pytest.raises(DataError, match="either 'wide'"):
        ColumnMapping.load(tmp_path / "m.toml")
    (tmp_path / "m.toml").write_text('explode = ["choice"]\n[join]\nfile = "ratings.csv"\n')
    m = ColumnMapping.load(tmp_path / "m.toml")
    assert m.explode == {"columns": ["choice"], "position": None} and m.join == {"file": str(tmp_path / "ratings.csv")}


# --------------------------------------------------------------------------- a folder of logs


def test_a_folder_of_logs_one_per_participant_reads_as_one_log(small, tmp_path):
    for pid, g in small.groupby("participant"):  # as PsychoPy writes them: no participant column
        g.drop(columns="participant").to_csv(tmp_path / f"{pid}.csv", index=False)
    (tmp_path / ".hidden.csv").write_text("junk\n")
    (tmp_path / "mapping.json").write_text("{}")  # files of another kind than most are left out
    (tmp_path / "notes.txt").write_text("notes")
    frame = read_trials(tmp_path)
    same_trials(frame, read_trials(small))
    assert "file" not in frame.columns  # it gave the participants


def test_a_folder_s_files_with_participant_ids_keep_their_file_names(small, tmp_path):
    for i, (_, g) in enumerate(small.groupby("participant")):
        g.to_parquet(tmp_path / f"session{i}.parquet")
    frame = read_trials(tmp_path)
    same_trials(frame, read_trials(small))
    assert frame.groupby("participant", observed=True)["file"].first().to_dict() == {
        "P001": "session0",
        "P002": "session1",
        "P003": "session2",
    }


def test_a_folder_s_problems_name_the_file_and_its_row(small, tmp_path):
    for pid, g in small.groupby("participant"):
        g.drop(columns="participant").to_csv(tmp_path / f"{pid}.csv", index=False)
    text = (tmp_path / "P002.csv").read_text().splitlines()
    text[3] = text[3].replace(",low,", ",medium,").replace(",high,", ",medium,")
    (tmp_path / "P002.csv").write_text("\n".join(text) + "\n")
    with pytest.raises(DataError) as exc:
        read_trials(tmp_path)
    assert exc.value.problems == [
        "column 'complexity': unknown category (expected one of ['low', 'high']): P002.csv row 3 'medium'"
    ]
    (tmp_path / "P002.csv").write_text((tmp_path / "P001.csv").read_text().replace("experience", "exp"))
    with pytest.raises(DataError) as exc:
        read_trials(tmp_path)
    assert exc.value.problems == ["P002.csv: its columns are not those of P001.csv: lacks ['experience'], has ['exp'] too"]


def test_several_files_read_as_one_log_named_by_their_paths_where_names_are_alike(small, tmp_path):
    paths = []
    for site, pids in (("siteA", ["P001", "P002"]), ("siteB", ["P003"])):
        (tmp_path / site).mkdir()
        for i, pid in enumerate(pids):  # each site numbers its sessions from 1
            paths.append(tmp_path / site / f"session{i + 1}.csv")
            small[small.participant == pid].to_csv(paths[-1], index=False)
    frame = read_trials(paths)
    same_trials(frame, read_trials(small))
    assert sorted(set(frame["file"])) == ["siteA/session1", "siteA/session2", "siteB/session1"]
    text = paths[2].read_text().splitlines()
    text[2] = text[2].replace(",low,", ",medium,").replace(",high,", ",medium,")
    paths[2].write_text("\n".join(text) + "\n")
    with pytest.raises(DataError) as exc:
        read_trials(paths)
    assert exc.value.problems == [
        "column 'complexity': unknown category (expected one of ['low', 'high']): siteB/session1.csv row 2 'medium'"
    ]
    with pytest.raises(DataError, match="a file is given twice"):
        read_trials([paths[0], tmp_path / "siteA" / ".." / "siteA" / "session1.csv"])
    with pytest.raises(DataError, match="no trial log given"):
        read_trials([])


def test_a_folder_without_logs_or_with_two_kinds_alike_is_refused(small, tmp_path):
    with pytest.raises(DataError, match="the folder holds no trial log"):
        read_trials(tmp_path)
    small.to_csv(tmp_path / "a.csv", index=False)
    small.to_parquet(tmp_path / "b.parquet")
    with pytest.raises(DataError, match=r"as many logs of two kinds \(\{'.csv': 1, '.parquet': 1\}\): keep one kind"):
        read_trials(tmp_path)


def test_a_folder_of_wide_files_names_the_file_and_the_record_of_a_bad_trial(small, tmp_path):
    for pid, g in small.groupby("participant"):  # a row per participant, a column per trial of each field
        row = {
            f"{c}_{t}": v for t, r in zip(g["trial"], g.to_dict("records"), strict=True) for c, v in r.items() if c in FIELDS[1:]
        }
        pd.DataFrame([row]).to_csv(tmp_path / f"{pid}.csv", index=False)
    mapping = {"wide": {"columns": FIELDS[1:], "position": "trial"}}
    same_trials(read_trials(tmp_path, mapping), read_trials(small))
    text = (tmp_path / "P003.csv").read_text().replace(",low,", ",medium,", 1)
    (tmp_path / "P003.csv").write_text(text)
    with pytest.raises(DataError) as exc:
        read_trials(tmp_path, mapping)
    assert exc.value.problems == [
        "column 'complexity': unknown category (expected one of ['low', 'high']): P003.csv row 1 'medium'"
    ]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(frame=frames(), cuts=st.lists(st.integers(0, 12), max_size=3), suffix=st.sampled_from([".csv", ".parquet"]))
def test_a_log_cut_into_a_folder_of_files_reads_cell_for_cell_as_the_whole(tmp_path_factory, frame, cuts, suffix):
    from trustseek.data.sources import load_source

    texts = [str(v) for c in frame.columns for v in frame[c] if isinstance(v, str)]
    assume(
        suffix == ".parquet" or not any("\r" in t for t in texts)
    )  # a bare CR is a line end in a CSV (pandas does not quote it)
    folder = tmp_path_factory.mktemp("folder")
    bounds = [0, *sorted(min(c, len(frame)) for c in cuts), len(frame)]
    for i, (a, b) in enumerate(itertools.pairwise(bounds)):
        part = frame.iloc[a:b]
        part.to_csv(folder / f"part{i}.csv", index=False) if suffix == ".csv" else part.to_parquet(folder / f"part{i}.parquet")
    whole = folder.parent / f"{folder.name}-whole{suffix}"
    frame.to_csv(whole, index=False) if suffix == ".csv" else frame.to_parquet(whole)
    one, many = load_source(whole, None, frozenset()), load_source(folder, None, frozenset())
    assert many.n == one.n and many.columns == [*one.columns, "file"]
    for c in one.columns:
        a, b = one.col(c), many.col(c)
        assert [a.texts[k] for k in a.codes] == [b.texts[k] for k in b.codes], c
    assert [many.place(i) for i in range(many.n)] == [
        f"part{i}{suffix} row {r + 1}" for i, (a, b) in enumerate(itertools.pairwise(bounds)) for r in range(b - a)
    ]
