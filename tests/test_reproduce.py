"""The reproduction pipeline on a reduced configuration, its determinism, the CLI, and the
round trip of simulated logs through ``trustseek fit``."""

import itertools
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from trustseek import paper_model
from trustseek.cli._app import app
from trustseek.report import FIGURES, write_report
from trustseek.reproduction import AGNOSTIC, AWARE, ReproduceConfig, reproduce
from trustseek.reproduction.statistics import wilcoxon

SMALL = {
    "replicates": 2,
    "large_n": 400,
    "bootstrap": 0,
    "restarts": 2,
    "replicate_restarts": 1,
    "replicate_large_n": 200,
    "grid": 201,
    "jobs": 1,
}


@pytest.fixture(scope="module")
def small_run():
    return reproduce(ReproduceConfig(seed=3, **SMALL))


def test_pipeline_follows_the_paper_design(small_run):
    s = small_run.summary
    f1 = small_run.experiment1
    assert len(f1) == 9 * 71 and f1["participant"].nunique() == 9
    assert (f1.groupby("participant")["complexity"].apply(lambda c: (c == "low").sum()) == 41).all()
    e2 = small_run.experiment2.trials()
    assert e2["participant"].nunique() == 5 and len(e2) == 5 * 68
    firsts = e2[e2["trial"] == 1]["policy"].tolist()
    assert sorted(firsts) == sorted([AWARE] * 3 + [AGNOSTIC] * 2)
    # the deployed agnostic policy is the one estimated from the experiment-1 log
    auto = f1[f1["robot_action"] == "autonomous"]
    p_int = (auto[auto["complexity"] == "high"]["human_action"] == "intervene").mean()
    assert s["plan"]["agnostic"]["p_intervene"]["high"] == pytest.approx(p_int)
    # summary numbers are the simulation's
    r = small_run.experiment2.by_policy()
    assert s["experiment2"]["small"]["median_aware"] == float(np.median(r[AWARE]))
    assert s["experiment2"]["small"]["rewards"][AGNOSTIC] == list(r[AGNOSTIC])
    assert s["experiment2"]["large"]["participants"] == 400
    assert s["replicates"]["n"] == 2 and len(s["replicates"]["threshold"]["values"]) == 2
    # the trust-aware policy rows of the cost study use the same participants: the true-model
    # policy's paired difference with itself is exactly zero
    assert s["costs"]["rows"][0]["vs_true_policy"]["mean"] == 0.0


def test_comparison_lists_every_paper_number(small_run):
    rows = small_run.summary["comparison"]
    paper = [r["paper"] for r in rows]
    for v in (0.98, 0.46, 0.95, 0.39, 0.99, 0.7, 0.94, 0.44, 0.75, 57.0, 51.0):
        assert v in paper, v
    assert sum(1 for r in rows if r["quantity"].startswith("Fig. 4")) == 8
    assert sum(1 for r in rows if r["quantity"].startswith(("Fig. 5", "Fig. 6"))) == 12
    for r in rows:
        assert r["verdict"] in ("agrees", "DISAGREES", "no interval")
        if r["interval"] and r["verdict"] != "no interval":
            lo, hi = r["interval"]
            inside = lo - 0.005 <= r["paper"] <= hi + 0.005
            assert (r["verdict"] == "agrees") == inside
    dis = small_run.summary["disagreements"]
    assert len(dis) == sum(r["verdict"] == "DISAGREES" for r in rows)


def test_same_seed_same_summary(small_run, tmp_path):
    again = reproduce(ReproduceConfig(seed=3, **SMALL))
    assert json.dumps(again.summary, sort_keys=True) == json.dumps(small_run.summary, sort_keys=True)
    other = reproduce(ReproduceConfig(seed=4, **SMALL))
    assert other.summary["experiment1"] != small_run.summary["experiment1"]


def _exact_signed_rank_p(d):
    """Two-sided exact p-value of the signed-rank statistic by enumerating all sign flips."""
    d = np.asarray([x for x in d if x != 0], dtype=float)
    ranks = pd.Series(np.abs(d)).rank().to_numpy()
    w_plus = ranks[d > 0].sum()
    total = ranks.sum()
    stats = [sum(r for r, s in zip(ranks, signs, strict=True) if s) for signs in itertools.product([0, 1], repeat=len(d))]
    stats = np.array(stats)
    lo = min(w_plus, total - w_plus)
    return np.mean((stats <= lo + 1e-9) | (stats >= total - lo - 1e-9))


def test_wilcoxon_against_enumeration():
    aware = np.array([57.0, 61, 49, 55, 60, 52])
    agn = np.array([51.0, 51, 51, 48, 50, 53])
    res = wilcoxon(aware, agn)
    assert res["p_value"] == pytest.approx(_exact_signed_rank_p(aware - agn))
    assert wilcoxon(agn, agn)["p_value"] is None


def test_report_folder(small_run, tmp_path):
    paths = write_report(small_run, tmp_path / "rep")
    out = paths["dir"]
    for file, *_ in FIGURES:
        assert (out / file).stat().st_size > 5000
    assert json.loads((out / "summary.json").read_text()) == small_run.summary
    html = paths["html"].read_text()
    assert html.count("data:image/png;base64,") == len(FIGURES)
    assert "Paper vs reproduction" in html and 'src="http' not in html
    f = pd.read_csv(out / "experiment2.csv")
    assert list(f.columns[:6]) == ["participant", "trial", "complexity", "robot_action", "human_action", "experience"]


def test_reproduce_command(tmp_path):
    res = CliRunner().invoke(
        app,
        [
            "reproduce",
            "--out",
            str(tmp_path / "r"),
            "--replicates",
            "1",
            "--large-n",
            "200",
            "--bootstrap",
            "0",
            "--restarts",
            "1",
            "--replicate-restarts",
            "1",
            "--replicate-large-n",
            "100",
            "--jobs",
            "1",
        ],
    )
    assert res.exit_code == 0, res.output
    assert "Paper vs reproduction" in res.output and "report:" in res.output
    assert (tmp_path / "r" / "report.html").exists()


def test_bad_options_give_one_line_errors(tmp_path):
    exe = Path(sys.executable).parent / "trustseek"
    r = subprocess.run(
        [str(exe), "reproduce", "--out", str(tmp_path), "--belief-update", "magic"], capture_output=True, text=True
    )
    assert r.returncode == 2 and "belief-update" in r.stderr and "Traceback" not in r.stderr
    r = subprocess.run([str(exe), "simulate", "--counts", "4,x"], capture_output=True, text=True)
    assert r.returncode == 2 and "--counts" in r.stderr and "Traceback" not in r.stderr


def test_simulated_log_round_trips_through_fit(tmp_path):
    """A large simulated log, written by ``simulate`` and read back by ``fit``, gives back
    the supervisors' model in the cells the design identifies."""
    log = tmp_path / "trials.parquet"
    runner = CliRunner()
    res = runner.invoke(app, ["simulate", "--policy", "randomized", "-n", "150", "--seed", "2", "--out", str(log), "--json"])
    assert res.exit_code == 0, res.output
    frame = pd.read_parquet(log)
    assert len(frame) == 150 * 71 and "true_trust" in frame.columns
    res = runner.invoke(app, ["fit", str(log), "--restarts", "3", "--seed", "1", "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.output[res.output.index("{") :])
    fitted = out["model"]
    truth = paper_model()
    em = fitted["emission"]
    assert em["high"]["autonomous"]["high"]["rely"] == pytest.approx(truth.emission[1, 0, 1, 1], abs=0.03)
    assert em["low"]["autonomous"]["high"]["rely"] == pytest.approx(1.0, abs=0.01)
    tr = fitted["transition"]
    assert tr["low"]["autonomous"]["reliable"]["high"]["high"] == pytest.approx(1.0, abs=0.02)
    assert fitted["initial"]["high"] == pytest.approx(1.0, abs=0.05)
    # maximum likelihood: the fitted model explains the log at least as well as the truth
    # (cells such as P(rely | low trust, high complexity) are weakly identified, so the
    # likelihood, not each cell, is the sharp check)
    from trustseek.estimation import encode, loglik
    from trustseek.estimation.fit import from_trust_model

    spec, params = from_trust_model(truth)
    ll_truth = loglik(encode(frame[frame.columns[:6]], spec), spec, params)
    assert out["loglik"] >= ll_truth - 1e-6
    assert out["loglik"] - ll_truth < 0.5 * out["n_params"] + 10  # not absurdly better: no overfitting bug
