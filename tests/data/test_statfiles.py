"""data/statfiles: SPSS, Stata and SAS data files read as trial logs, as the same table in CSV;
value labels read as their labels, missing values as empty cells, damaged files refused by name."""

from __future__ import annotations

import contextlib
from pathlib import Path

import pandas as pd
import pyreadstat
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cli_runner import run_cli
from trustseek.data import DataError, example_path, read_trials

SHORT = {"participant": "pid", "human_action": "human", "robot_action": "robot", "complexity": "cx", "experience": "exp"}


@pytest.fixture(scope="module")
def log() -> pd.DataFrame:
    return pd.read_csv(example_path())


@pytest.mark.parametrize(
    ("suffix", "write"),
    [
        (".sav", pyreadstat.write_sav),
        (".zsav", lambda f, p: pyreadstat.write_sav(f, p, compress=True)),
        (".dta", pyreadstat.write_dta),
        (".xpt", pyreadstat.write_xport),  # SAS transport: names of at most 8 characters
        (".por", pyreadstat.write_por),
    ],
)
def test_each_format_reads_as_the_same_log_in_csv(log, tmp_path, suffix, write):
    frame = log.drop(columns="true_trust").rename(columns=SHORT)
    write(frame, str(tmp_path / f"log{suffix}"))
    case = str.upper if suffix == ".por" else str  # SPSS portable files keep names in capitals
    mapping = {"columns": {canon: case(short) for canon, short in SHORT.items()} | {"trial": case("trial")}}
    got = read_trials(tmp_path / f"log{suffix}", mapping)
    pd.testing.assert_frame_equal(got, read_trials(log.drop(columns="true_trust")), check_categorical=False)


def test_value_labels_are_read_as_labels_and_missing_values_as_empty(log, tmp_path):
    """A human action coded 0/1 with value labels reads as its labels; SPSS's system-missing and a
    value the file declares missing (9) are not recorded."""
    frame = log.drop(columns="true_trust").copy()
    frame["human_action"] = (frame.human_action == "rely").astype(float)
    frame.loc[3, "human_action"] = float("nan")
    frame.loc[5, "human_action"] = 9.0
    pyreadstat.write_sav(
        frame,
        str(tmp_path / "log.sav"),
        variable_value_labels={"human_action": {0.0: "intervene", 1.0: "rely", 9.0: "no answer"}},
        missing_ranges={"human_action": [9.0]},
    )
    got = read_trials(tmp_path / "log.sav")
    assert got.human_action.isna().tolist()[:7] == [False, False, False, True, False, True, False]
    assert got.human_action.dropna().tolist() == log.human_action.drop([3, 5]).tolist()
    pyreadstat.write_sav(frame.fillna(9.0).replace(9.0, 2.0), str(tmp_path / "coded.sav"),
                         variable_value_labels={"human_action": {0.0: "intervene", 1.0: "rely"}})  # fmt: skip
    with pytest.raises(DataError, match=r"column 'human_action': unknown category .* row 4 '2'"):
        read_trials(tmp_path / "coded.sav")


def test_a_folder_of_spss_files_one_per_participant_reads_as_one_log(log, tmp_path):
    small = log[log.participant.isin(["P001", "P002"])]
    for pid, g in small.groupby("participant"):
        pyreadstat.write_sav(g.drop(columns="participant"), str(tmp_path / f"{pid}.sav"))
    assert read_trials(tmp_path).equals(read_trials(small))


@pytest.mark.parametrize("suffix", [".sav", ".dta", ".sas7bdat", ".xpt", ".por"])
def test_a_damaged_file_is_refused_by_name(tmp_path, suffix):
    path = tmp_path / f"log{suffix}"
    path.write_bytes(b"participant,trial\nP1,1\n")
    code, output = run_cli(["fit", str(path)])
    assert code == 2 and f"{path}: cannot read the file as " in output and "Traceback" not in output, output


@pytest.mark.parametrize(
    ("suffix", "what"), [(".csv", "a CSV cell is text"), (".xlsx", "a sheet's cell is a value"), (".sav", "a variable's value")]
)
def test_explode_is_refused_for_a_file_of_single_values(log, tmp_path, suffix, what):
    path = tmp_path / f"log{suffix}"
    path.write_bytes(b"")  # refused before the file is read
    with pytest.raises(DataError, match=f"explode: {what}.*, not a list; per-trial lists are read from JSON or Parquet"):
        read_trials(path, {"explode": ["human_action"]})


def test_a_file_that_crashes_the_reader_is_refused_and_the_command_goes_on(tmp_path):
    """files/damaged.sav (an SPSS file with a few bytes changed) makes readstat's C parser end its
    process with a segmentation fault: read in this process, the command died without a word."""
    damaged = Path(__file__).parent / "files" / "damaged.sav"
    with pytest.raises(DataError, match=r"cannot read the file as SPSS data: the reader stopped on it \(exit code -\d+\)"):
        read_trials(damaged)
    code, output = run_cli(["check", str(damaged), str(example_path())])
    assert code == 2 and "the file is damaged" in output and f"{example_path()}: ok" in output, output


@pytest.fixture(scope="module")
def valid_files(tmp_path_factory, log) -> dict[str, bytes]:
    folder = tmp_path_factory.mktemp("valid")
    frame = log.head(40).assign(human_action=lambda f: (f.human_action == "rely").astype(float))
    pyreadstat.write_sav(frame, str(folder / "log.sav"), variable_value_labels={"human_action": {0.0: "intervene", 1.0: "rely"}})
    pyreadstat.write_dta(log.head(40), str(folder / "log.dta"))
    return {s: (folder / f"log{s}").read_bytes() for s in (".sav", ".dta")}


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data(), suffix=st.sampled_from([".sav", ".dta"]))
def test_a_corrupted_file_is_refused_or_read_never_a_crash(tmp_path_factory, valid_files, data, suffix):
    raw = bytearray(valid_files[suffix])
    for _ in range(data.draw(st.integers(1, 6))):
        raw[data.draw(st.integers(0, len(raw) - 1))] = data.draw(st.integers(0, 255))
    path = tmp_path_factory.mktemp("bad") / f"log{suffix}"
    path.write_bytes(bytes(raw[: data.draw(st.one_of(st.none(), st.integers(0, len(raw))))]))
    with contextlib.suppress(DataError):  # refused by name, or read: anything else fails the test
        read_trials(path)


def test_a_reader_that_never_ends_is_stopped_and_the_file_refused(log, tmp_path, monkeypatch):
    from trustseek.data import statfiles

    pyreadstat.write_dta(log.head(5), str(tmp_path / "log.dta"))
    monkeypatch.setattr(statfiles, "READ_SECONDS", 0.5)
    monkeypatch.setattr(statfiles, "_read", lambda path, suffix: __import__("time").sleep(60))  # in the forked reader
    with pytest.raises(DataError, match=r"log.dta: cannot read the file as Stata data: the reader did not finish in 1 s"):
        read_trials(tmp_path / "log.dta")
