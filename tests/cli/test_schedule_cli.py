"""The ``trustseek schedule`` command."""

import json
import subprocess
import sys

import pytest

from trustseek import load_policy


def run(*args, check=True):
    proc = subprocess.run([sys.executable, "-m", "trustseek", *args], capture_output=True, text=True, timeout=300)
    if check and proc.returncode != 0:
        raise AssertionError(f"exit {proc.returncode}\nstdout:\n{proc.stdout}\nstderr:\n{proc.stderr}")
    return proc


def test_schedule_json_policy_file_and_comparison(tmp_path):
    out, fig = tmp_path / "schedule.json", tmp_path / "schedule.png"
    proc = run(
        "schedule", "--counts", "low=4,high=3", "--json", "--out", str(out), "--compare", "--participants", "500",
        "--figure", str(fig),
    )  # fmt: skip
    d = json.loads(proc.stdout)
    assert d["problem"] == "4 low + 3 high items, full control"
    pol = load_policy(out)
    assert pol.kind == "schedule" and pol.counts == (4, 3)
    assert pol.start_value() == pytest.approx(d["value"], abs=1e-8)
    names = [r["schedule"] for r in d["comparison"]["schedules"]]
    assert "optimal" in names and "random + trust-aware" in names
    assert fig.stat().st_size > 0


def test_schedule_table_and_errors():
    proc = run("schedule", "--counts", "3,3", "--window", "2", "--representation", "alpha")
    assert "window 2" in proc.stdout and "expected discounted reward" in proc.stdout
    bad = run("schedule", "--counts", "3,x", check=False)
    assert bad.returncode == 2 and "--counts" in bad.stderr
    bad = run("schedule", "--counts", "3,3", "-u", "paper", "--representation", "alpha", check=False)
    assert bad.returncode == 2 and "grid representation" in bad.stderr


def test_the_comparison_says_what_it_does_while_it_runs(monkeypatch):
    """schedule --compare ran 18 s at its defaults (12 min at --participants 1000000) without a
    word on the terminal."""
    import io

    from rich.console import Console

    from cli_runner import run_cli
    from trustseek.cli import _progress

    screen = io.StringIO()
    monkeypatch.setattr(_progress, "err_console", Console(file=screen, force_terminal=True, width=100))
    code, out = run_cli(["schedule", "--counts", "3,3", "--compare", "--participants", "40"])
    assert code == 0, out
    assert "comparing the schedules on 40 simulated participants" in screen.getvalue()
