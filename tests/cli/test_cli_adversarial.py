"""The CLI under corrupted input files and bad output paths, run in-process.

Every command that reads a model, task, policy, mapping or .pomdp file is given a file
corrupted in one way (random bytes, another encoding, truncated JSON, NaN/Infinity/null,
out-of-range numbers, wrong types, a missing key, a folder); every command that writes
is given an output path in a missing folder or that is a folder.  Each run must end with
exit code 2, no traceback, a message naming the file, and no file left behind.
"""

from __future__ import annotations

import json
import random
import shutil
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cli_runner import run_cli
from trustseek.data.trials import example_path
from trustseek.model.presets import paper_model, paper_task
from trustseek.pomdp.problem import AssistancePOMDP
from trustseek.solvers import make_solver

LOG = str(example_path("paper_trials.csv"))

VALID = {
    "model": paper_model().to_dict(),
    "task": paper_task().to_dict(),
    "policy": make_solver("grid", grid=51).solve(AssistancePOMDP(paper_model(), paper_task())).to_dict(),
    "mapping": {"columns": {"participant": "participant"}},
}

#: command lines reading a file of each kind; {f} is the corrupted file, {o} a fresh output path
READERS = {
    "model": [
        ["check", "{f}"],
        ["solve", "-m", "{f}", "--grid", "11", "-o", "{o}.json"],
        ["simulate", "-m", "{f}", "-n", "1", "-o", "{o}.csv"],
        ["decode", LOG, "--model", "{f}", "-o", "{o}.csv"],
        ["export-pomdp", "{o}.pomdp", "-m", "{f}"],
    ],
    "task": [
        ["check", "{f}"],
        ["solve", "-t", "{f}", "--grid", "11", "-o", "{o}.json"],
        ["agnostic", "-t", "{f}", "-o", "{o}.json"],
        ["simulate", "-t", "{f}", "-n", "1", "--summary-out", "{o}.csv"],
    ],
    "policy": [
        ["check", "{f}"],
        ["simulate", "--policy", "{f}", "-n", "1", "-o", "{o}.csv"],
        ["plot-q", "--policy", "{f}", "-o", "{o}.png"],
    ],
    "mapping": [
        ["fit", LOG, "--mapping", "{f}", "-r", "1", "-o", "{o}.json"],
        ["decode", LOG, "--model", "{model}", "--mapping", "{f}", "-o", "{o}.csv"],
        ["agnostic", "--data", LOG, "--mapping", "{f}", "-o", "{o}.json"],
    ],
}

#: command lines writing to {o}, which is made a bad path
WRITERS = [
    ["fit", LOG, "-r", "1", "--max-iter", "2", "-o", "{o}"],
    ["fit", LOG, "-r", "1", "--max-iter", "2", "--posteriors", "{o}"],
    ["decode", LOG, "--model", "{model}", "-o", "{o}"],
    ["solve", "--grid", "11", "-o", "{o}"],
    ["agnostic", "-o", "{o}"],
    ["simulate", "-n", "1", "--grid", "11", "-o", "{o}"],
    ["simulate", "-n", "1", "--grid", "11", "--summary-out", "{o}"],
    ["plot-q", "--grid", "11", "-o", "{o}"],
    ["preset", "--model-out", "{o}"],
    ["preset", "--task-out", "{o}"],
    ["export-pomdp", "{o}"],
    ["reproduce", "--out", "{o}"],
]


def _leaves(obj, path=()):
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _leaves(v, (*path, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _leaves(v, (*path, i))
    elif isinstance(obj, (int, float)) and not isinstance(obj, bool):
        yield path


def _set(obj, path, value):
    obj = json.loads(json.dumps(obj))
    node = obj
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    return obj


#: numeric leaves whose corruption the loaders must refuse: every number of a model; the
#: probabilities and discount of a task; the Q values and model of a policy
def _checked_leaves(kind: str) -> list[tuple]:
    leaves = list(_leaves(VALID[kind]))
    if kind == "task":
        return [p for p in leaves if p[0] in ("complexities", "discount")]
    if kind == "policy":
        return [p for p in leaves if p[0] in ("q", "model")]
    return leaves


SENTINEL = "__BAD__"
BAD_VALUES = {"NaN": "NaN", "Infinity": "Infinity", "-Infinity": "-Infinity", "null": "null", "text": '"x"', "list": "[]"}
REQUIRED_KEY = {"model": "emission", "task": "discount", "policy": "q"}


@st.composite
def corrupted(draw, kind: str) -> tuple[str, bytes | None]:
    """(how, content) of a corrupted file of ``kind``; content None means a folder."""
    text = json.dumps(VALID[kind], indent=2)
    options = ["bytes", "latin-1", "utf-16", "truncated", "top-level", "folder", "empty"]
    if kind != "mapping":
        options += ["value", "missing-key"]
        if kind == "model":
            options.append("out-of-range")
    how = draw(st.sampled_from(options))
    if how == "bytes":
        return how, b"\xff\x00" + draw(st.binary(max_size=64))
    if how == "latin-1":
        return how, text.replace('"', '"\u00e9', 1).encode("latin-1")
    if how == "utf-16":
        return how, text.encode("utf-16")
    if how == "truncated":
        return how, text[: draw(st.integers(0, text.rindex("}") - 1))].encode()
    if how == "top-level":
        return how, draw(st.sampled_from(["[]", "1", '"model"', "null", "[{}]"])).encode()
    if how == "folder":
        return how, None
    if how == "empty":
        return how, draw(st.sampled_from([b"", b"  \n"]))
    if how == "missing-key":
        d = dict(VALID[kind])
        del d[REQUIRED_KEY[kind]]
        return how, json.dumps(d).encode()
    leaf = draw(st.sampled_from(_checked_leaves(kind)))
    if how == "out-of-range":
        value = draw(st.sampled_from([1.5, -0.25, 1e308]))
        return how, json.dumps(_set(VALID[kind], leaf, value)).encode()
    bad = draw(st.sampled_from(sorted(BAD_VALUES)))
    return how, json.dumps(_set(VALID[kind], leaf, SENTINEL)).replace(f'"{SENTINEL}"', BAD_VALUES[bad]).encode()


def _listing(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def _assert_clean_refusal(code: int, output: str, name: str, before: set[str], folder: Path, args: list[str]) -> None:
    assert code == 2, f"{args}: exit {code}\n{output}"
    assert "Traceback" not in output, f"{args}:\n{output}"
    assert name in output, f"{args}: the message does not name {name}:\n{output}"
    assert _listing(folder) == before, f"{args}: left {sorted(_listing(folder) - before)}"


CASES = [(kind, i) for kind, lines in READERS.items() for i in range(len(lines))]


@pytest.mark.parametrize(("kind", "index"), CASES, ids=[f"{k}-{' '.join(READERS[k][i][:1])}-{i}" for k, i in CASES])
@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)
@given(data=st.data())
def test_a_corrupted_input_file_is_refused_cleanly(kind, index, data):
    _how, content = data.draw(corrupted(kind), label="corruption")
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        f = folder / f"input-{kind}.json"
        if content is None:
            f.mkdir()
        else:
            f.write_bytes(content)
        model = folder / "model.json"
        model.write_text(json.dumps(VALID["model"]))
        before = _listing(folder)
        args = [a.format(f=f, o=folder / "out", model=model) for a in READERS[kind][index]]
        code, output = run_cli(args)
        _assert_clean_refusal(code, output, f.name, before, folder, args)


SUFFIX = {"fit": ".json", "decode": ".csv", "solve": ".json", "agnostic": ".json", "simulate": ".csv"}
SUFFIX.update({"plot-q": ".png", "preset": ".json", "export-pomdp": ".pomdp", "reproduce": ""})


@pytest.mark.parametrize("index", range(len(WRITERS)), ids=[" ".join(w[:1] + w[-2:-1]) for w in WRITERS])
@settings(max_examples=4, deadline=None, derandomize=True)
@given(bad=st.sampled_from(["missing-folder", "folder", "nested-missing"]), name=st.sampled_from(["out", "résultat", "a b"]))
def test_a_bad_output_path_is_refused_before_any_work(index, bad, name):
    args = WRITERS[index]
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        model = folder / "model.json"
        model.write_text(json.dumps(VALID["model"]))
        suffix = ".csv" if "--posteriors" in args or "--summary-out" in args else SUFFIX[args[0]]
        if bad == "folder":
            target = folder / f"{name}{suffix}"
            target.mkdir()
            (target / "keep").write_text("x")  # a non-empty folder, for reproduce
        elif bad == "missing-folder":
            target = folder / "missing" / f"{name}{suffix}"
        else:
            target = folder / "a" / "b" / f"{name}{suffix}"
        before = _listing(folder)
        line = [a.format(o=target, model=model) for a in args]
        code, output = run_cli(line)
        _assert_clean_refusal(code, output, target.name if bad == "folder" else target.parent.name, before, folder, line)


def test_the_corruptions_are_invalid_for_the_loaders():
    """The generator's corruptions are refused by the library too (a check of the test itself:
    a corruption that left a valid file would make the CLI test fail for the wrong reason)."""
    from trustseek.errors import TrustseekError
    from trustseek.model.core import TrustModel
    from trustseek.model.task import Task
    from trustseek.policies import load_policy

    loaders = {"model": TrustModel.load, "task": Task.load, "policy": load_policy}
    rng = random.Random(0)
    with tempfile.TemporaryDirectory() as d:
        for kind, load in loaders.items():
            f = Path(d) / f"{kind}.json"
            f.write_text(json.dumps(VALID[kind]))
            load(f)  # the valid file loads
            for leaf in rng.sample(_checked_leaves(kind), 5):
                f.write_text(json.dumps(_set(VALID[kind], leaf, None)))
                with pytest.raises(TrustseekError):
                    load(f)


@pytest.mark.parametrize(
    "args",
    [["solve", "--tol", "nan"], ["solve", "--tol", "-1"], ["select", LOG, "--tol", "0"]],
    ids=["nan", "negative", "zero"],
)
def test_a_tolerance_must_be_finite_and_positive(args):
    code, output = run_cli(args)
    assert code == 2 and "--tol" in output and "Traceback" not in output


def test_options_a_policy_file_would_ignore_are_refused(tmp_path):
    pol = tmp_path / "policy.json"
    pol.write_text(json.dumps(VALID["policy"]))
    for extra in (["-u", "paper"], ["--policy-model", "paper"]):
        code, output = run_cli(["simulate", "-n", "1", "--policy", str(pol), *extra])
        assert code == 2 and extra[0] in output and "policy.json" in output
    assert run_cli(["simulate", "-n", "1", "--policy", str(pol)])[0] == 0


def test_a_task_without_rewards_or_discount_is_refused(tmp_path):
    for key in ("rewards", "discount"):
        d = dict(VALID["task"])
        del d[key]
        f = tmp_path / f"no-{key}.json"
        f.write_text(json.dumps(d))
        code, output = run_cli(["check", str(f)])
        assert code == 2 and f"{key} is missing" in output and f.name in output


def test_export_refuses_a_missing_sqlite_file(tmp_path):
    db = tmp_path / "mistyped.sqlite"
    code, output = run_cli(["export", "s1", "--db", f"sqlite:///{db}", "-o", str(tmp_path / "t.csv")])
    assert code == 2 and "does not exist" in output
    assert not db.exists()


def test_a_database_that_accepts_and_never_answers_is_refused_after_the_connect_timeout(tmp_path, monkeypatch):
    import socket
    import threading

    import trustseek.server.db as db

    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(4)
    held = []
    stop = threading.Event()

    def accept() -> None:  # accepts every connection and never answers
        listener.settimeout(0.2)
        while not stop.is_set():
            try:
                held.append(listener.accept()[0])
            except TimeoutError:
                continue

    thread = threading.Thread(target=accept, daemon=True)
    thread.start()
    monkeypatch.setattr(db, "CONNECT_TIMEOUT", 2)
    try:
        port = listener.getsockname()[1]
        url = f"postgresql://someone@127.0.0.1:{port}/trustseek"
        code, output = run_cli(["export", "s1", "--db", url, "-o", str(tmp_path / "t.csv")])
    finally:
        stop.set()
        thread.join()
        for c in held:
            c.close()
        listener.close()
    assert code == 2 and "127.0.0.1" in output and "Traceback" not in output, output


def test_solve_pomdp_file_exits_3_above_its_target_gap(tmp_path):
    f = tmp_path / "assist.pomdp"
    assert run_cli(["export-pomdp", str(f)])[0] == 0
    code, output = run_cli(["solve-pomdp-file", str(f), "--gap", "1e-12", "--max-seconds", "0.05"])
    assert code == 3 and "above the target" in output


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, "file not found"),
        ("folder", "is a directory, expected a .pomdp file"),
        (b"discount: 0.9\x00", "is a binary file, expected .pomdp text"),
        ("discount: 0.9 # \u00e9".encode("latin-1"), f"is not UTF-8 text (byte {len('discount: 0.9 # ')})"),
    ],
)
def test_solve_pomdp_file_refuses_an_unreadable_file_naming_it(tmp_path, content, message):
    f = tmp_path / "problem.pomdp"
    if content == "folder":
        f.mkdir()
    elif content is not None:
        f.write_bytes(content)
    code, output = run_cli(["solve-pomdp-file", str(f)])
    assert code == 2 and "Traceback" not in output
    assert f"{f}: {message}" in " ".join(output.split()), output


def test_decode_needs_only_the_columns_the_model_uses(tmp_path):
    import pandas as pd

    log = tmp_path / "log.csv"
    pd.read_csv(LOG).drop(columns=["complexity", "robot_action"]).to_csv(log, index=False)
    model = tmp_path / "m.json"
    fit = ["fit", str(log), "--transitions-on", "experience", "--emissions-on", "none", "-r", "1", "-o", str(model)]
    assert run_cli(fit)[0] == 0
    code, output = run_cli(["decode", str(log), "-m", str(model), "-o", str(tmp_path / "p.csv")])
    assert code == 0, output
    assert len(pd.read_csv(tmp_path / "p.csv")) == len(pd.read_csv(log))


# --------------------------------------------------------------------------- hostile inputs


def _log_rows() -> list[str]:
    return Path(LOG).read_text().splitlines()


@pytest.mark.parametrize(
    "args",
    [
        ["fit", "{log}", "-r", "1", "--max-iter", "2", "--posteriors", "{log}"],
        ["fit", "{log}", "-r", "1", "--max-iter", "2", "--posteriors", "{dir}/./log.csv"],
        ["decode", "{log}", "--model", "{model}", "-o", "{log}"],
        ["predict", "{log}", "--model", "{model}", "-b", "0", "-o", "{log}"],
        ["fit-types", "{log}", "-r", "1", "--type-posteriors", "{log}"],
        ["solve", "-m", "{model}", "--grid", "11", "-o", "{model}"],
        ["agnostic", "-m", "{model}", "-o", "{model}"],
        ["decode", "{log}", "--model", "{model}", "-o", "{link}"],
        ["schedule", "-m", "{model}", "-n", "2,2", "-o", "{model}"],
        ["export", "s1", "--db", "sqlite:///{log}", "-o", "{log}"],
    ],
    ids=[
        "fit-posteriors",
        "fit-posteriors-dot",
        "decode",
        "predict",
        "fit-types",
        "solve",
        "agnostic",
        "decode-symlink",
        "schedule",
        "export",
    ],
)
def test_an_output_naming_an_input_is_refused_and_the_input_kept(tmp_path, args):
    log, model = tmp_path / "log.csv", tmp_path / "model.json"
    log.write_text(Path(LOG).read_text())
    model.write_text(json.dumps(VALID["model"]))
    (tmp_path / "link.csv").symlink_to(log)
    before = (log.read_bytes(), model.read_bytes())
    line = [a.format(log=log, model=model, dir=tmp_path, link=tmp_path / "link.csv") for a in args]
    code, output = run_cli(line)
    assert code == 2 and "would overwrite the input" in output and "Traceback" not in output, output
    assert (log.read_bytes(), model.read_bytes()) == before


#: the folder of the shipped examples, inside the package
SHIPPED = Path(LOG).parent


@pytest.mark.parametrize(
    "args",
    [
        ["simulate", "-n", "2", "-o", "{shipped}"],
        ["simulate", "-n", "2", "-o", "{new}.csv"],
        ["simulate", "-n", "2", "--summary-out", "{new}.json"],
        ["fit", LOG, "-r", "1", "-o", "{new}.json"],
        ["fit", LOG, "-r", "1", "--plots", "{new}"],
        ["fit", LOG, "-r", "1", "--plots", "{folder}"],
        ["fit-types", LOG, "-r", "1", "-o", "{new}.json"],
        ["solve", "--grid", "11", "-o", "{new}.json"],
        ["agnostic", "-o", "{new}.json"],
        ["preset", "--model-out", "{new}.json"],
        ["schedule", "-n", "2,2", "--figure", "{new}.png"],
        ["reproduce", "-o", "{new}"],
        ["export-pomdp", "{new}.pomdpx"],
    ],
)
def test_an_output_inside_the_package_is_refused(args):
    before = {p.name: p.read_bytes() if p.is_file() else None for p in SHIPPED.iterdir()}
    new = SHIPPED / "written-by-a-test"
    line = [a.format(shipped=SHIPPED / "paper_trials.csv", new=new, folder=SHIPPED) for a in args]
    try:
        code, output = run_cli(line)
        assert code == 2 and "is inside the trustseek package" in output and "Traceback" not in output, output
    finally:
        after = {p.name: p.read_bytes() if p.is_file() else None for p in SHIPPED.iterdir()}
        for name in set(after) - set(before):  # put the package back as it was, whatever the command did
            path = SHIPPED / name
            shutil.rmtree(path) if path.is_dir() else path.unlink()
        for name, data in before.items():
            if after.get(name) != data:
                (SHIPPED / name).write_bytes(data)
    assert after == before


@pytest.mark.parametrize(
    "args",
    [
        ["fit", LOG, "--restarts", "1000000000"],
        ["fit", LOG, "--bootstrap", "1000000000"],
        ["fit", LOG, "--seed=-1"],
        ["solve", "--grid", "1000000000"],
        ["simulate", "-n", "1000000000"],
        ["simulate", "--seed=-1"],
        ["simulate", "-n", "1000000", "--trials", "1000"],
        ["fit-types", LOG, "--bootstrap", "1000000000"],
        ["predict", LOG, "--restarts", "1000000000"],
    ],
    ids=["restarts", "bootstrap", "fit-seed", "grid", "simulate-n", "simulate-seed", "simulate-trials", "types", "predict"],
)
def test_a_size_beyond_the_machine_or_a_negative_seed_is_refused(args):
    code, output = run_cli(args)
    assert code == 2 and "Traceback" not in output, output
    flag = next(a for a in args[1:] if a.startswith("-")).split("=")[0]
    assert flag in output or "--participants" in output, output


def test_a_log_or_model_that_is_a_fifo_is_refused_without_waiting(tmp_path):
    import os

    for name, line in (("log.csv", ["fit", "{f}", "-r", "1"]), ("model.json", ["check", "{f}"])):
        fifo = tmp_path / name
        os.mkfifo(fifo)
        code, output = run_cli([a.format(f=fifo) for a in line])
        assert code == 2 and "named pipe (FIFO)" in output and name in output, output


def test_rewards_that_overflow_the_values_are_refused(tmp_path):
    task = json.loads(json.dumps(VALID["task"]))
    first, second = list(task["rewards"])[:2]
    task["rewards"][first], task["rewards"][second] = 1e308, -1e308
    f = tmp_path / "task.json"
    f.write_text(json.dumps(task))
    code, output = run_cli(["solve", "-t", str(f), "--grid", "11"])
    assert code == 2 and f"rewards[{first}] = 1e+308 is outside" in output and "never asks" not in output, output


def test_a_model_file_with_a_duplicated_key_is_refused(tmp_path):
    text = json.dumps(VALID["model"], indent=1)
    row = '"high": {'
    at = text.index(row)
    f = tmp_path / "model.json"
    f.write_text(text[:at] + '"high": {"rely": 0.5, "intervene": 0.5}, ' + text[at:])
    code, output = run_cli(["check", str(f)])
    assert code == 2 and "the key 'high' appears twice" in output, output


def test_nested_participant_ids_in_json_are_refused_by_record(tmp_path):
    import pandas as pd

    records = pd.read_csv(LOG).to_dict(orient="records")
    records[2]["participant"] = {"id": 1}
    records[4]["participant"] = [1, 2]
    for suffix, text in ((".json", json.dumps(records)), (".jsonl", "\n".join(json.dumps(r) for r in records))):
        f = tmp_path / f"log{suffix}"
        f.write_text(text)
        code, output = run_cli(["fit", str(f), "-r", "1"])
        assert code == 2 and "column 'participant': an object or a list" in output and "in 2 records" in output, output


def test_a_missing_marker_that_is_a_label_is_refused():
    code, output = run_cli(["fit", LOG, "-r", "1", "--missing", "rely"])
    assert code == 2 and "'rely' is also a label of human_action" in output, output


def test_a_label_mapped_to_two_categories_is_reported_as_such(tmp_path):
    code, output = run_cli(["fit", LOG, "-r", "1", "--label", "human_action:1=rely", "--label", "human_action:1=intervene"])
    assert code == 2 and "mapped to two categories, 'rely' and 'intervene'" in output, output
    m = tmp_path / "map.json"
    m.write_text(json.dumps({"labels": {"human_action": {"rely": ["1", "yes"], "intervene": ["1", "no"]}}}))
    code, output = run_cli(["fit", LOG, "-r", "1", "--mapping", str(m)])
    assert code == 2 and "the label '1' is mapped to two categories" in output and "experience rule" not in output, output


@pytest.mark.parametrize("width", [3_000, 20_000])
def test_a_wide_csv_header_is_counted_whole(tmp_path, width):
    rows = _log_rows()[:4]
    f = tmp_path / "wide.csv"
    extra = "," + ",".join(f"x{i}" for i in range(width))
    f.write_text(rows[0] + extra + "\n" + "\n".join(r + ",0" * width for r in rows[1:3]) + "\n" + rows[3] + "\n")
    code, output = run_cli(["fit", str(f), "-r", "1"])
    assert code == 2 and "Traceback" not in output
    if width > 10_000:
        assert f"the header names {width + 7:,} columns" in output, output
    else:
        assert f"differs from the header's {width + 7}" in output and "row 3 (7 fields)" in output, output


def test_a_quoted_header_name_with_semicolons_does_not_change_the_delimiter(tmp_path):
    rows = _log_rows()
    f = tmp_path / "semi.csv"
    f.write_text(rows[0] + ',"notes; a; b; c; d; e; f; g; h"\n' + "\n".join(r + ",x" for r in rows[1:]) + "\n")
    code, output = run_cli(["fit", str(f), "-r", "1", "--max-iter", "2"])
    assert code == 0, output


@pytest.mark.parametrize(
    ("edit", "expected"), [("quote", "row 10 (1 fields, an unterminated quote)"), ("extra", "row 20 (8 fields)")]
)
def test_a_malformed_csv_row_is_reported_with_its_row(tmp_path, edit, expected):
    rows = _log_rows()
    if edit == "quote":
        rows[10] = '"' + rows[10]
    else:
        rows[20] += ",extra"
    f = tmp_path / "bad.csv"
    f.write_text("\n".join(rows) + "\n")
    code, output = run_cli(["fit", str(f), "-r", "1"])
    assert code == 2 and expected in output, output


def test_a_huge_unknown_value_is_cut_in_the_error(tmp_path):
    rows = _log_rows()
    cells = rows[30].split(",")
    cells[2] = "z" * 1_000_000
    rows[30] = ",".join(cells)
    f = tmp_path / "huge.csv"
    f.write_text("\n".join(rows) + "\n")
    code, output = run_cli(["fit", str(f), "-r", "1"])
    assert code == 2 and "unknown category" in output and "more characters" in output and len(output) < 2000, output[:300]


def test_decode_and_predict_take_a_preset_name(tmp_path):
    for line in (["decode", LOG, "--model", "paper", "-o", str(tmp_path / "p.csv")], ["predict", LOG, "-m", "paper", "-b", "0"]):
        code, output = run_cli(line)
        assert code == 0, output


def test_a_log_where_everyone_always_relies_warns_that_trust_is_not_identified(tmp_path):
    import pandas as pd

    frame = pd.read_csv(LOG)
    frame = frame[frame.robot_action == "autonomous"].assign(human_action="rely")
    f = tmp_path / "rely.csv"
    frame.to_csv(f, index=False)
    code, output = run_cli(["fit", str(f), "-r", "1"])
    text = " ".join(output.split())
    assert code == 0 and "the initial distribution and the transitions are not identified" in text, output
    code, output = run_cli(["fit", LOG, "-r", "1"])
    assert "are not identified (any values" not in " ".join(output.split())


#: (command line, what the refusal says) of options out of bounds that a command refuses before
#: any work (each ran for seconds or without end, or failed with a traceback after its work)
REFUSED_UP_FRONT = [
    (["select-types", LOG, "--types", "1..1000000000"], "--types: numbers of types between 1 and 12"),
    (["select-types", LOG, "--types", "1,1"], "--types: a number of types is given twice"),
    (["schedule", "--compare", "--figure", "{dir}/log.csv"], "--figure {dir}/log.csv: expected a file ending in .png"),
    (["schedule", "--figure", "{dir}/missing/f.png"], "the folder {dir}/missing does not exist"),
    (["sensitivity", "--plot", "{dir}/log.csv"], "--plot {dir}/log.csv: expected a file ending in .png"),
    (["compare-types", "--plot", "{dir}/figure.csv"], "--plot {dir}/figure.csv: expected a file ending in .png"),
    (["design", "-r", "1000000000"], "--replicates must be between 2 and 10,000, got 1000000000"),
    (["design", "--participants-2", "1000000000"], "experiment 2 of 1,000,000,000 participants x 2 blocks x 34 trials"),
    (["design", "--grid", "1000000000"], "--grid must be between 3 and 1,000,001 belief points"),
    (["design", "--tol", "nan"], "--tol must be a finite number > 0, got nan"),
    (["design", "--search-ask-low", ""], "--search-ask-low: expected at least one value"),
    (["design", "--scheduler", ""], "--scheduler"),  # without dask: that it needs it
    (["design", "--jobs", "1000000000"], "1000000000 is not in the range 1<=x<=256"),
    (["reproduce", "--jobs", "1000000000", "-o", "{dir}/report"], "1000000000 is not in the range 1<=x<=256"),
    (["fit", LOG, "--jobs", "1000000000"], "1000000000 is not in the range 1<=x<=256"),
    (["select", LOG, "--jobs", "1000000000"], "1000000000 is not in the range 1<=x<=256"),
    (["predict", LOG, "--jobs", "0"], "0 is not in the range 1<=x<=256"),
    (["sensitivity", "--jobs", "1000000000"], "1000000000 is not in the range 1<=x<=256"),
    (["select", LOG, "--folds", "10"], "--folds 10 is more than the 9 participants of the log"),
    (["select-types", LOG, "--folds", "1000000000"], "--folds 1000000000 is more than the 9 participants"),
    (["fit", LOG, "--plots", "{dir}/missing/figures"], "--plots {dir}/missing/figures: the folder {dir}/missing does not exist"),
    (["fit-types", LOG, "--plots", "{dir}/log.csv"], "--plots {dir}/log.csv: exists and is not a folder"),
    (["select-types", LOG, "--types", "8..10"], "types (--types) must be at most the log's 9 participants (each participant"),
    (["fit-types", LOG, "--types", "10"], "types (--types) must be at most the log's 9 participants (each participant is"),
    (["fit", LOG, "--prior", "1e308"], "prior (--prior) must be a pseudo-count between 0 and 1e+12, got 1e+308"),
    (
        ["personalize", LOG, "-m", "paper", "-o", "{dir}/people", "--strength", "1e308"],
        "strength (--strength) must be a pseudo-count",
    ),
    (["simulate", "--counts", ""], "--counts '': 1 number for 2 complexities"),
    (["export", "s1", "--db", "sqlite:///", "-o", "{dir}/t.csv"], "--db sqlite:///: names no SQLite file"),
    (["sensitivity", "--samples", "1000000"], "--samples 1,000,000 x --grid 401 is 401,000,000 belief points"),
    (["sensitivity", "--starts", "1000"], "the ranges of 20 parameters from --starts 1,000 at --grid 401 take"),
    (["sensitivity", "--grid", "1000001", "--samples", "0"], "at --grid 1,000,001 take at least"),
    (["simulate", "-n", "1", "--concentration", "nan"], "(--concentration) must be a finite positive number, got nan"),
    (["compare-types", "--gap", "0"], "--gap must be a finite number > 0, got 0.0"),
    (["compare-types", "--max-seconds", "inf"], "--max-seconds must be a finite number > 0, got inf"),
    (["solve-pomdp-file", "{dir}/paper.pomdp", "--horizon", "8"], "--horizon 8: the exact value expands 2,532,289 belief nodes"),
]


@pytest.mark.parametrize(
    ("args", "expected"),
    REFUSED_UP_FRONT,
    ids=[f"{a[0]} {next(x for x in a[1:] if x.startswith('-'))}" for a, _ in REFUSED_UP_FRONT],
)
def test_an_option_beyond_its_bounds_is_refused_before_any_work(tmp_path, args, expected):
    (tmp_path / "log.csv").write_text(Path(LOG).read_text())
    if "solve-pomdp-file" in args:
        assert run_cli(["export-pomdp", str(tmp_path / "paper.pomdp")])[0] == 0
    before = _listing(tmp_path)
    code, output = run_cli([a.format(dir=tmp_path) for a in args])
    text = " ".join(output.split())
    assert code == 2 and "Traceback" not in output and expected.format(dir=tmp_path) in text, output
    assert _listing(tmp_path) == before


def test_a_figure_whose_writing_is_interrupted_leaves_no_partial_file(tmp_path, monkeypatch):
    """An output is replaced whole or not at all: sensitivity's --plot interrupted while the
    figure is written (Ctrl-C, or a full disk) leaves neither a half-written figure nor a temporary."""
    import trustseek.plots.sensitivity as figures

    def interrupted(res, quantity, path, **kwargs):
        Path(path).write_bytes(b"\x89PNG half a figure")
        raise KeyboardInterrupt

    monkeypatch.setattr(figures, "plot_tornado", interrupted)
    out = tmp_path / "tornado.png"
    code, _ = run_cli(["sensitivity", "--samples", "0", "--starts", "1", "--grid", "101", "--plot", str(out)])
    assert code != 0
    assert _listing(tmp_path) == set(), sorted(_listing(tmp_path))
