"""The planning CLI: solve, agnostic, plot-q, preset, check, and clean errors."""

import json
import subprocess
import sys

import pandas as pd
import pytest

from cli_runner import run_cli
from trustseek import TrustModel, load_policy
from trustseek.vocab import TRIAL_COLUMNS


def run(*args, check=True):
    proc = subprocess.run([sys.executable, "-m", "trustseek", *args], capture_output=True, text=True, timeout=120)
    if check and proc.returncode != 0:
        raise AssertionError(f"exit {proc.returncode}\nstdout:\n{proc.stdout}\nstderr:\n{proc.stderr}")
    return proc


def test_solve_json_and_policy_file(tmp_path):
    out = tmp_path / "policy.json"
    proc = run("solve", "--belief-update", "paper", "--grid", "1001", "--json", "--out", str(out))
    d = json.loads(proc.stdout)
    assert d["belief_update"] == "paper"
    assert d["thresholds"]["low"] is None
    assert 0.72 <= d["thresholds"]["high"] <= 0.80
    assert d["trust_agnostic"] == {"low": 0.0, "high": 1.0}
    pol = load_policy(out)
    assert pol.thresholds()["high"] == pytest.approx(d["thresholds"]["high"])


def test_solve_table_says_which_update():
    proc = run("solve", "--grid", "501")
    assert "belief update: bayes" in proc.stdout
    assert "never asks" in proc.stdout


def test_bad_model_file_gives_one_line_per_problem(tmp_path, model):
    d = model.to_dict()
    d["transition"]["high"]["ask"]["reliable"]["low"] = {"low": 0.53, "high": 0.44}
    d["emission"]["low"]["autonomous"]["high"]["rely"] = 1.5
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(d))
    proc = run("solve", "--model", str(bad), check=False)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert lines == [
        f"error: {bad}: emission[C=low, a=autonomous][T=high][rely] = 1.5 is outside [0, 1]",
        f"error: {bad}: transition[C=high, a=ask, E=reliable][T=low] sums to 0.97",
    ]


def _taking(option: str) -> list[str]:
    """The commands that take ``option``."""
    import click
    import typer

    from trustseek.cli import app

    group = typer.main.get_command(app)
    ctx = click.Context(group)
    commands = [group.get_command(ctx, name) for name in group.list_commands(ctx)]
    return [c.name for c in commands if any(option in p.opts for p in c.params)]


def test_bad_option_values(tmp_path):
    assert {"solve", "simulate", "schedule", "reproduce", "design", "sensitivity"} <= set(_taking("--belief-update"))
    for command in _taking("--belief-update"):  # one check, one message
        proc = run(command, "--belief-update", "magic", check=False)
        assert proc.returncode == 2 and "Traceback" not in proc.stderr
        assert "--belief-update must be 'bayes' or 'paper', got 'magic'" in proc.stderr, command
    proc = run("solve", "--model", str(tmp_path / "missing.json"), check=False)
    assert proc.returncode == 2 and "file not found" in proc.stderr


def test_plot_q_writes_png(tmp_path):
    out = tmp_path / "q.png"
    run("plot-q", "--grid", "501", "--out", str(out))
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert out.stat().st_size > 10_000


def test_preset_export_and_check(tmp_path):
    run("preset", "paper", "--model-out", str(tmp_path / "m.json"), "--task-out", str(tmp_path / "t.json"))
    assert TrustModel.load(tmp_path / "m.json").trust_levels == ("low", "high")
    proc = run("check", str(tmp_path / "m.json"), str(tmp_path / "t.json"))
    assert proc.stdout.count(": ok") == 2
    proc = run("solve", "--model", str(tmp_path / "m.json"), "--task", str(tmp_path / "t.json"), "--json", "--grid", "501")
    assert json.loads(proc.stdout)["thresholds"]["low"] is None


def test_help_everywhere():
    for cmd in ([], ["solve"], ["agnostic"], ["plot-q"], ["preset"], ["check"]):
        proc = run(*cmd, "--help")
        assert "Usage" in proc.stdout


def test_solvers_come_from_the_registry_and_refuse_cleanly():
    from trustseek.data import example_path

    d = json.loads(run("solve", "--solver", "certified-grid", "-u", "paper", "--json").stdout)
    assert d["solver"] == "certified-grid" and d["certified_gap"] <= 1e-6
    proc = run(
        "solve",
        "--model",
        str(example_path("three_level_model.json")),
        "--task",
        str(example_path("three_level_task.json")),
        check=False,
    )
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.strip().splitlines() == [
        "error: the default grid solver needs two trust levels; this model has 3: use --solver point"
    ]


def test_check_reads_a_trial_log_as_the_fit_does_and_says_what_it_holds(tmp_path):
    """A researcher's first step: `trustseek check log.csv` said 'invalid JSON at line 1'."""
    from trustseek.data import example_path

    log = str(example_path())
    code, output = run_cli(["check", log])
    assert code == 0, output
    said = " ".join(output.split())
    raw = pd.read_csv(log)  # the counts the summary must give, counted here from the file

    def counts(c: str, order: list[str]) -> str:
        n = raw[c].value_counts()
        return f"{c}: " + ", ".join(f"{v} {n[v]}" for v in order)

    per = raw.groupby("participant").size()
    assert per.nunique() == 1
    assert f"{log}: ok: {len(raw)} trials of {len(per)} participants ({per.iloc[0]} each); " in said
    summary = "; ".join(
        counts(c, order)
        for c, order in (
            ("human_action", ["intervene", "rely"]),
            ("complexity", ["low", "high"]),
            ("robot_action", ["autonomous", "ask"]),
            ("experience", ["faulty", "reliable"]),
        )
    )
    assert summary in said, (summary, said)
    others = [c for c in raw.columns if c not in TRIAL_COLUMNS]
    assert others and f"other columns: {', '.join(others)}" in said
    # with the log options, as the fit reads it; a JSON array of records and a folder too
    frame = raw.rename(columns={"human_action": "response"})
    frame["response"] = frame.response.map({"rely": 1, "intervene": 0}).astype("Int64")
    frame.loc[3, "response"] = pd.NA
    frame.to_json(tmp_path / "log.json", orient="records")
    (tmp_path / "logs").mkdir()
    for pid, g in frame.groupby("participant"):
        g.to_csv(tmp_path / "logs" / f"{pid}.csv", index=False)
    flags = ["--column", "human_action=response", "--label", "human_action:1=rely", "--label", "human_action:0=intervene"]
    code, output = run_cli(["check", str(tmp_path / "log.json"), str(tmp_path / "logs"), *flags])
    said = " ".join(output.split())
    recorded = frame.response.drop(3).value_counts()
    expected = f"human_action: intervene {recorded[0]}, rely {recorded[1]}, not recorded 1"
    assert code == 0 and said.count(expected) == 2, output
    code, output = run_cli(["check", str(tmp_path / "log.json")])  # without the flags: located, exit 2
    assert code == 2 and "missing column 'human_action'" in output and "--column 'human_action=response'" not in output


def test_check_validates_a_mapping_file_and_still_a_model(tmp_path):
    from trustseek.data import example_path

    code, output = run_cli(["check", str(example_path("study_mapping.json")), str(example_path("three_level_model.json"))])
    assert code == 0 and output.count(": ok") == 2 and "a column mapping" in output, output
    (tmp_path / "m.json").write_text('{"columns": {"participant": 3}, "order": "block"}')
    code, output = run_cli(["check", str(tmp_path / "m.json")])
    assert code == 2 and "participant must map to a column name, got 3" in output, output
