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
