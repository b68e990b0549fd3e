"""The design command: JSON output, the HTML page and its figures, refused options."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from trustseek.cli import app

SMALL = ["-r", "2", "--participants-1", "6", "--trials-1", "40", "--participants-2", "4,8", "--trials-2", "20", "--restarts", "1"]


def test_design_json_and_report(tmp_path):
    out = tmp_path / "study"
    res = CliRunner().invoke(
        app, ["design", *SMALL, "--json", "-q", "-o", str(out), "--search-ask-low", "0.1,0.3", "--search-ask-high", "0.4"]
    )
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    point = doc["design"]["points"][0]
    assert point["experiment1"] == {"participants": 6, "trials": 40, "counts": [23, 17], "ask_low": 0.1, "ask_high": 0.4}
    assert [c["participants"] for c in point["experiment2"][0]["curve"]] == [4, 8]
    assert {(r["ask_low"], r["ask_high"]) for r in doc["ask_search"]["rows"]} == {(0.1, 0.4), (0.3, 0.4)}
    html = (out / "design.html").read_text(encoding="utf-8")
    assert html.count("data:image/png;base64,") == 3
    assert "Experiment 2: power" in html and "ask probabilities" in html
    assert json.loads((out / "design.json").read_text())["design"] == doc["design"]


def test_design_tables(tmp_path):
    res = CliRunner().invoke(app, ["design", *SMALL, "-q"])
    assert res.exit_code == 0, res.output
    assert "participants for power 0.8" in res.stdout and "V* = " in res.stdout


def test_design_refuses_bad_grids():
    from trustseek.errors import TrustseekError

    res = CliRunner().invoke(app, ["design", "--participants-2", "1,x"])
    assert isinstance(res.exception, TrustseekError)
    assert "--participants-2" in " ".join(res.exception.lines())
    res = CliRunner().invoke(app, ["design", "--alpha", "2", "--replicates", "1"])
    assert isinstance(res.exception, TrustseekError)
    text = " ".join(res.exception.lines())
    assert "--alpha" in text and "--replicates" in text
