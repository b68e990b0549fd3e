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

from small_runs import SMALL, small_reproduction
from trustseek import paper_model
from trustseek.cli._app import app
from trustseek.report import FIGURES, write_report
from trustseek.reproduction import AGNOSTIC, AWARE, ReproduceConfig, reproduce
from trustseek.reproduction.comparison import (
    AGREES,
    DIRECTION_ONLY,
    DISAGREES,
    MAX_WIDTH,
    NOT_TESTABLE,
    VERDICTS,
    comparison_rows,
    judge,
)
from trustseek.statistics import mean_ci, share_ci, wilcoxon


@pytest.fixture(scope="module")
def small_run():
    return small_reproduction()


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
        assert r["verdict"] in VERDICTS and r["reason"]
    # every numeric row's verdict is the rule's
    for r in rows:
        if isinstance(r["paper"], float) and r["quantity"].startswith("Fig."):
            fixed = r["reason"].startswith("fixed")
            rule = judge(r["paper"], r["ours"], r["interval"], fixed=fixed, max_width=MAX_WIDTH, replicates=r["replicate_range"])
            assert (r["verdict"], r["reason"]) == rule
    # the Fig. 4a cells are fixed by the model's structure, not estimated
    fig4a = [r for r in rows if r["quantity"].startswith("Fig. 4a")]
    assert [r["verdict"] for r in fig4a] == [NOT_TESTABLE] * 4 and all(r["interval"] is None for r in fig4a)
    counts = small_run.summary["verdict_counts"]
    assert list(counts) == list(VERDICTS) and sum(counts.values()) == len(rows)
    dis = small_run.summary["disagreements"]
    assert len(dis) == counts[DISAGREES]
    assert not any("e-12" in d for d in dis)


@pytest.mark.parametrize(
    ("args", "verdict"),
    [
        # a probability inside its interval, within the paper's rounding of an end, outside, fixed, unidentified
        ((0.46, 0.40, (0.30, 0.50)), AGREES),
        ((0.505, 0.40, (0.30, 0.50)), AGREES),
        ((0.39, 1e-12, (1e-12, 1e-12)), DISAGREES),
        ((1.0, 1.0, (1.0, 1.0), {"fixed": True}), NOT_TESTABLE),
        ((0.7, 0.47, (1e-12, 1.0), {"max_width": MAX_WIDTH}), NOT_TESTABLE),
        ((0.7, 0.47, None), NOT_TESTABLE),
        # a collapsed bootstrap interval at the boundary, while the replicate experiments range over [0, 1]
        ((0.39, 1e-12, (1e-12, 1e-12), {"max_width": MAX_WIDTH, "replicates": (0.0, 1.0)}), NOT_TESTABLE),
        ((0.39, 0.35, (0.30, 0.45), {"max_width": MAX_WIDTH, "replicates": (0.2, 0.6)}), AGREES),
        # a difference: the sign reversed disagrees even inside the interval; the same sign outside it is direction only
        ((6.0, -4.0, (-7.0, 9.0), {"reference": 0.0}), DISAGREES),
        ((6.0, 2.0, (-7.0, 9.0), {"reference": 0.0}), AGREES),
        ((6.0, 2.0, (0.5, 3.0), {"reference": 0.0}), DIRECTION_ONLY),
        ((6.0, 0.0, (-1.0, 1.0), {"reference": 0.0}), DISAGREES),
        # a qualitative claim (a share above one half)
        ((None, 0.6, (0.55, 0.65), {"reference": 0.5}), AGREES),
        ((None, 0.52, (0.40, 0.52), {"reference": 0.5}), DIRECTION_ONLY),
        ((None, 0.45, (0.40, 0.52), {"reference": 0.5}), DISAGREES),
    ],
)
def test_verdict_rules_on_constructed_rows(args, verdict):
    kw = args[3] if len(args) > 3 else {}
    assert judge(*args[:3], **kw)[0] == verdict


def test_seed_0_shows_the_sign_reversed_and_untestable_rows():
    """The rows of the default seed-0 run that the old single rule called "agrees" (the summary of
    that run is rebuilt here from its inputs: the comparison reads nothing else)."""
    rows = comparison_rows(_seed0_like_summary())
    by = {r["quantity"].split(" (")[0]: r for r in rows}
    assert by["Median difference aware − agnostic"]["verdict"] == DISAGREES
    assert by["Median difference aware − agnostic"]["reason"] == "the sign is reversed"
    assert by["Trust-aware better for most participants"]["verdict"] == DIRECTION_ONLY
    assert sum(r["verdict"] == NOT_TESTABLE for r in rows) >= 5


def test_intervals_for_five_participants_are_t_intervals():
    d = np.array([6.0, -4.0, 2.0, 0.0, 9.0])
    m, lo, hi = mean_ci(d)
    half = 2.7764451051977987 * d.std(ddof=1) / np.sqrt(5)  # t(0.975, 4), not 1.96
    assert (m, lo, hi) == pytest.approx((d.mean(), d.mean() - half, d.mean() + half))
    lo, hi = share_ci(3, 5)
    # exact binomial: P(X >= 3 | p = lo) = 0.025 and P(X <= 3 | p = hi) = 0.025
    from scipy.stats import binom

    assert binom.sf(2, 5, lo) == pytest.approx(0.025) and binom.cdf(3, 5, hi) == pytest.approx(0.025)


def _seed0_like_summary():
    from trustseek.reproduction.comparison import param_specs, param_values

    truth = paper_model()
    values = param_values(truth)
    keys = [s.key for s in param_specs()]
    dist = {"n": 20, "min": 0.0, "max": 1.0, "median": 0.5}
    fixed = [k for k in keys if k.startswith("em_ask")]
    return {
        "config": {"participants_1": 9, "counts_1": [41, 30], "replicate_large_n": 2000},
        "fit": {
            "values": values,
            "bootstrap": 200,
            "bootstrap_ci": {k: [1e-12, 1.0] for k in keys},
            "fixed": fixed,
        },
        "replicates": {
            "n": 20,
            "params": dict.fromkeys(keys, dist),
            "threshold": {"n": 20, "min": 0.47, "max": 0.99},
            "share_never_ask_low": 1.0,
            "agnostic_share_paper": {"low": 1.0, "high": 1.0},
            "median_aware": {"n": 20, "min": 43.0, "max": 59.0},
            "median_agnostic": {"n": 20, "min": 43.0, "max": 56.0},
            "median_diff_small": {"n": 20, "min": -7.0, "max": 9.0},
            "share_better_large": {"n": 20, "min": 0.40, "max": 0.52},
        },
        "plan": {
            "fitted": {"thresholds": {"high": 0.66}, "ask_intervals": {"low": []}},
            "true_model": {"thresholds": {"high": 0.7812}},
            "agnostic": {"action": {"low": "autonomous", "high": "ask"}},
        },
        "experiment2": {
            "small": {
                "participants": 5,
                "median_aware": 47.0,
                "median_agnostic": 51.0,
                "median_difference": -4.0,
                "share_aware_better": 0.4,
            },
            "large": {
                "participants": 10_000,
                "median_aware": 49.0,
                "median_agnostic": 51.0,
                "mean_difference": 0.57,
                "mean_difference_ci": [0.42, 0.73],
                "share_aware_better": 0.517,
                "share_aware_better_ci": [0.507, 0.527],
                "share_tied": 0.1,
                "per_policy": {
                    AWARE: {"autonomous_collections": {"mean": 20.0}},
                    AGNOSTIC: {"autonomous_collections": {"mean": 12.0}},
                },
                "autonomous_difference_ci": [7.9, 8.1],
            },
        },
    }


def test_another_seed_gives_other_data(small_run):
    """(The same seed gives the same summary byte for byte, also over two processes:
    test_the_steps_run_beside_the_fit_give_the_same_summary.)"""
    # the costly sections, off here, do not change that
    lean = {**SMALL, "schedule_participants": 0, "types_participants": 0, "sensitivity_samples": 0}
    other = reproduce(ReproduceConfig(seed=4, **lean))
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
    assert "Remark 1 with supervisor types" in html
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
            "--schedule-participants",
            "0",
            "--types-participants",
            "0",
        ],
    )
    assert res.exit_code == 0, res.output
    assert "Paper vs reproduction" in res.output and "report:" in res.output
    assert (tmp_path / "r" / "report.html").exists()
    # the scheduling section left out on request: no numbers, no figure, no heading
    assert "scheduling" not in json.loads((tmp_path / "r" / "summary.json").read_text())
    assert not (tmp_path / "r" / "scheduling.png").exists()
    assert "Future work: scheduling the items" not in (tmp_path / "r" / "report.html").read_text()
    assert "types" not in json.loads((tmp_path / "r" / "summary.json").read_text())
    assert "supervisor types" not in (tmp_path / "r" / "report.html").read_text()


def test_types_section_of_the_report(small_run):
    """The report's supervisor-types section (Remark 1): both populations, every policy per type,
    a verdict per population and block length (the HTML and figure: test_report_folder)."""
    ty = small_run.summary["types"]
    assert [t["name"] for t in ty["types"]] == ["paper", "conservative"] and ty["participants"] == 300
    pops = ty["populations"]
    assert [p["population"] for p in pops] == ["paper + conservative", "paper alone"] * 2
    assert [p["trials"] for p in pops] == [34, 34, 136, 136]
    assert [g["group"] for g in pops[0]["groups"]] == ["paper", "conservative", "all"]
    assert ty["verdicts"] and all("pooled" in v and "[" in v for v in ty["verdicts"])
    assert ty["fitted_types"]["paper alone"]["chosen"] >= 1


def test_scheduling_section_of_the_report(small_run):
    """The report's scheduling section: every schedule of the comparison, the optimal one worth at
    least the paper's random order (exactly), the gains paired against that order."""
    sc = small_run.summary["scheduling"]
    assert sc["counts"] == {"low": 17, "high": 17} and sc["participants"] == 500
    rows = {r["schedule"]: r for r in sc["schedules"]}
    assert {"random + trust-aware", "optimal", "easy first", "hard first"} <= set(rows)
    assert rows["optimal"]["exact_discounted"] >= rows["random + finite-horizon"]["exact_discounted"]
    base = rows["random + trust-aware"]["gain_discounted"]
    assert base["mean"] == base["low"] == base["high"] == 0.0
    assert rows["optimal"]["gain_discounted"]["low"] > 0  # full control is worth something here (discounting)
    assert sc["window_values"]["1"] <= sc["window_values"]["3"] <= sc["window_values"]["all"]


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
    from trustseek.estimation.fit import from_model

    spec, params = from_model(truth)
    ll_truth = loglik(encode(frame[frame.columns[:6]], spec), spec, params)
    assert out["loglik"] >= ll_truth - 1e-6
    assert out["loglik"] - ll_truth < 0.5 * out["n_params"] + 10  # not absurdly better: no overfitting bug


def test_the_steps_run_beside_the_fit_give_the_same_summary(small_run):
    """With two processes the sensitivity, scheduling and types steps run in other processes while
    the fit and the plan run in this one, and the replicates over both: the summary is the one of
    a run in this process alone, byte for byte."""
    beside = reproduce(ReproduceConfig(seed=3, **{**SMALL, "jobs": 2}))
    assert json.dumps(beside.summary) == json.dumps(small_run.summary)
    assert beside.sensitivity is not None and beside.scheduling is not None and beside.types is not None
