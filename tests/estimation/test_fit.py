"""Fitting trust models: parameter recovery, labels, bootstrap, other studies' logs, decode, select, CLI."""

import json
import logging
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trustseek import TrustModel, paper_model
from trustseek.data.trials import ColumnMapping, example_path, read_trials
from trustseek.estimation import decode, fit_trust_model, paper_spec, select_levels
from trustseek.estimation.fit import never_estimated
from trustseek.estimation.options import FitOptions
from trustseek.simulation.designs import simulate_design


def free_cells(result):
    """Estimated cells (the free parameters): P(T1=high), P(rely | ...), P(T'=high | ...)."""
    m, est = result.model, result.estimated
    pairs = [(m.initial[1:], est["initial"][1:])]
    pairs.append((m.emission[..., 1], est["emission"][..., 1]))
    pairs.append((m.transition[..., 1], est["transition"][..., 1]))
    return pairs


@pytest.fixture(scope="module")
def big_fit():
    # seed 0, the default, not a seed picked for a good result: over 20 synthetic data sets
    # (seeds 0-19, benchmarks/bench_fit.py --recovery 20) the MAE is 0.004-0.062, median 0.015,
    # above 0.03 on 2 of 20 (docs/fitting.md)
    df = simulate_design(paper_model(), 1000, seed=0)
    return df, fit_trust_model(df, options=FitOptions(restarts=4, seed=1))


def test_parameter_recovery_at_1000_participants(big_fit):
    df, res = big_fit
    truth = paper_model()
    errors = []
    for name in ("initial", "emission", "transition"):
        mask = res.estimated[name]
        errors.append(np.abs(getattr(res.model, name) - getattr(truth, name))[mask])
    err = np.concatenate(errors)
    assert len(err) > 0
    assert err.mean() <= 0.03, err
    # the labelling rule: "high" relies more in high complexity
    assert res.model.emission[1, 0, 1, 1] > res.model.emission[1, 0, 0, 1]
    # never-observed cells follow the paper preset's convention (identity)
    np.testing.assert_array_equal(res.model.transition[0, 1, 1], np.eye(2))
    np.testing.assert_array_equal(res.model.transition[1, 1, 0], np.eye(2))
    # P(intervene | ask) = 1 stays fixed
    np.testing.assert_array_equal(res.model.emission[:, 1, :, 0], 1.0)
    assert res.n_params == 17
    assert res.bic == pytest.approx(17 * np.log(len(df)) - 2 * res.loglik)
    assert res.aic == pytest.approx(34 - 2 * res.loglik)
    assert len(res.restart_logliks) == 4 and max(res.restart_logliks) == pytest.approx(res.loglik)


WELL_IDENTIFIED_EVENTS = 5000  # expected events behind a cell for the check on several data sets


@pytest.mark.parametrize("seed", [100, 101, 102])
def test_recovery_of_well_identified_cells_on_other_data_sets(seed):
    """On data sets not looked at beforehand: the fit reaches at least the likelihood of the
    true parameters (the optimizer finds the maximum, whatever the sampling error), and the
    cells with many expected events are within 0.03 of the truth.  (Event counts are only a
    partial guide: the weakly identified cells -- P(rely | T=low, C=high) and the transitions
    after a failure -- also have thousands of events; see docs/fitting.md.)"""
    from trustseek.estimation import from_model, loglik

    truth = paper_model()
    df = simulate_design(truth, 1000, seed=seed)
    res = fit_trust_model(df, options=FitOptions(restarts=4, seed=0))
    spec, ptrue = from_model(truth)
    assert res.loglik >= loglik(res.seqs, spec, ptrue) - 1e-6
    checked = 0
    for c in res.cells():
        if c["events"] >= WELL_IDENTIFIED_EVENTS:
            t = float(getattr(truth, c["table"])[tuple(c["index"])])
            assert abs(c["estimate"] - t) <= 0.03, c
            checked += 1
    assert checked >= 5


def test_decode_with_the_true_model_tracks_the_hidden_trust(big_fit):
    df, _ = big_fit
    part = df[df["participant"].isin(df["participant"].unique()[:100])]
    post = decode(part, paper_model())
    assert len(post) == len(part)
    np.testing.assert_allclose(post["p_trust_low"] + post["p_trust_high"], 1.0)
    agree = (post["viterbi_trust"].to_numpy() == part["true_trust"].to_numpy()).mean()
    assert agree > 0.85
    # smoothed posteriors are calibrated: mean P(high) ~ share of trials in high trust
    assert post["p_trust_high"].mean() == pytest.approx((part["true_trust"] == "high").mean(), abs=0.03)


def test_result_json_and_counts(big_fit):
    _, res = big_fit
    d = json.loads(json.dumps(res.to_dict()))
    assert TrustModel.from_dict(d["model"]) == res.model
    assert d["n_params"] == 17 and len(d["restart_logliks"]) == 4
    assert d["ended"] == ["stationary"] * 4 and d["converged"] == [True] * 4  # how each restart ended
    # events behind the emission rows of autonomous trials add up to the number of such trials
    assert res.counts["emission"][:, 0, :, 0].sum() == pytest.approx(sum_autonomous(big_fit[0]), rel=1e-9)
    for name in ("initial", "emission", "transition"):
        assert res.counts[name].shape == getattr(res.model, name).shape


def sum_autonomous(df):
    return float(((df["robot_action"] == "autonomous") & df["human_action"].notna()).sum())


def test_nine_participants_bootstrap_is_deterministic_across_processes():
    df = read_trials(example_path())
    one = fit_trust_model(df, options=FitOptions(restarts=1, seed=3, tol=1e-6, n_jobs=1), bootstrap=3)
    two = fit_trust_model(df, options=FitOptions(restarts=1, seed=3, tol=1e-6, n_jobs=2), bootstrap=3)
    assert one.ci is not None
    for name in ("initial", "emission", "transition"):
        lo, hi = one.ci[name]
        assert lo.shape == getattr(one.model, name).shape
        assert np.all(lo <= hi + 1e-12)
        np.testing.assert_array_equal(lo, two.ci[name][0])
        np.testing.assert_array_equal(hi, two.ci[name][1])
    # fixed cells have degenerate intervals
    assert np.all(one.ci["emission"][0][:, 1, :, 0] == 1.0)
    # few participants: some cells are flagged as not identified
    assert any("not identified" in w for w in one.warnings)
    cells = one.cells()
    assert all("lower" in c and "upper" in c for c in cells)


def test_fit_logs_each_start_and_bootstrap_replicate_and_prints_nothing(caplog, capsys):
    df = read_trials(example_path())
    with caplog.at_level(logging.DEBUG, logger="trustseek.estimation"):
        fit_trust_model(df, options=FitOptions(restarts=2, seed=0, tol=1e-5, n_jobs=1), bootstrap=2)
    messages = [r.getMessage() for r in caplog.records if r.name.startswith("trustseek.estimation")]
    for start in (0, 1):  # every start reports how it ended
        assert any(m.startswith(f"start {start}: log-likelihood") and ("converged" in m or "cap" in m) for m in messages), (
            messages
        )
    assert any(m.startswith("best of 2 starts") for m in messages)
    for replicate in (0, 1):
        assert any(m.startswith(f"bootstrap replicate {replicate} done") for m in messages), messages
    assert capsys.readouterr().out == ""


def test_another_studys_log_fits_by_column_mapping_alone(tmp_path):
    """participant, trial, automation_correct (0/1), rely (0/1): a 2-level model, transitions on
    automation_correct, emissions on nothing."""
    rng = np.random.default_rng(5)
    N, T = 300, 60
    p_correct = 0.8
    rely = np.array([0.35, 0.95])  # P(rely | level)
    up = np.array([[0.7, 0.3], [0.1, 0.9]])  # after a correct trial: rows = current level
    down = np.array([[0.95, 0.05], [0.4, 0.6]])  # after an error
    level = (rng.random(N) < 0.8).astype(int)
    rows = []
    for t in range(T):
        r = (rng.random(N) < rely[level]).astype(int)
        c = (rng.random(N) < p_correct).astype(int)
        pr = np.where(c == 1, up[level, 1], down[level, 1])
        rows.append(pd.DataFrame({"subject": [f"s{i}" for i in range(N)], "trial_no": t + 1, "automation_correct": c, "rely": r}))
        level = (rng.random(N) < pr).astype(int)
    log = pd.concat(rows).sort_values(["subject", "trial_no"])
    path = tmp_path / "study.csv"
    log.to_csv(path, index=False)
    mapping = ColumnMapping.load(example_path("other_study_mapping.json"))
    frame = read_trials(path, mapping, required=("experience", "human_action"))
    res = fit_trust_model(frame, options=FitOptions(restarts=4, seed=0), transition_inputs=("experience",), emission_inputs=())
    m = res.model
    # emissions depend on nothing: identical across complexity and robot action
    assert np.allclose(m.emission, m.emission[0, 0])
    assert m.emission[0, 0, :, 1] == pytest.approx(rely, abs=0.04)
    assert m.transition[0, 0, 1, :, 1] == pytest.approx(up[:, 1], abs=0.06)
    assert m.transition[0, 0, 0, :, 1] == pytest.approx(down[:, 1], abs=0.08)
    assert res.n_params == 1 + 2 + 4


def test_select_levels_prefers_two_levels_on_paper_data(caplog):
    df = simulate_design(paper_model(), 100, seed=9)
    with caplog.at_level(logging.INFO, logger="trustseek.estimation"):
        rows = select_levels(df, levels=(1, 2, 3), folds=2, options=FitOptions(restarts=2, seed=0, tol=1e-5, n_jobs=1))
    progress = [r for r in caplog.records if r.name == "trustseek.estimation.selection" and r.levelno == logging.INFO]
    assert [r.getMessage().split(":")[0] for r in progress] == [
        "1 levels",
        "2 levels",
        "3 levels",
    ]
    by = {r["levels"]: r for r in rows}
    assert by[2]["loglik"] > by[1]["loglik"] + 50
    assert by[3]["loglik"] >= by[2]["loglik"] - 1.0  # nested: more levels fit at least about as well
    assert by[2]["best_bic"]
    assert by[2]["heldout_loglik"] > by[1]["heldout_loglik"]
    assert by[1]["n_params"] < by[2]["n_params"] < by[3]["n_params"]


# --------------------------------------------------------------------------- CLI


def run(*args, check=True):
    proc = subprocess.run([sys.executable, "-m", "trustseek", *args], capture_output=True, text=True, timeout=300)
    if check and proc.returncode != 0:
        raise AssertionError(f"exit {proc.returncode}\nstdout:\n{proc.stdout}\nstderr:\n{proc.stderr}")
    return proc


def invoke(*args):
    from typer.testing import CliRunner

    from trustseek.cli import app

    res = CliRunner().invoke(app, [str(a) for a in args])
    if res.exit_code != 0:
        raise AssertionError(f"exit {res.exit_code}\n{res.output}\n{res.exception!r}")
    return res.stdout


def test_cli_fit_decode_select(tmp_path):
    log = str(example_path())
    out = tmp_path / "model.json"
    d = json.loads(
        invoke("fit", log, "--preset", "paper", "--restarts", "2", "--seed", "1", "--tol", "1e-6", "--out", out, "--json")
    )
    m = TrustModel.load(out)
    assert TrustModel.from_dict(d["model"]) == m
    assert len(d["restart_logliks"]) == 2 and d["n_params"] == 17
    text = invoke("fit", log, "--restarts", "1", "--tol", "1e-5", "--plots", tmp_path / "figs")
    assert "log-likelihood" in text and "events" in text and "1 of 1 within 0.01 of the best" in text
    assert (tmp_path / "figs" / "emissions.png").stat().st_size > 0
    assert (tmp_path / "figs" / "transitions.png").stat().st_size > 0
    post = tmp_path / "post.csv"
    invoke("decode", log, "--model", out, "--out", post)
    p = pd.read_csv(post)
    assert len(p) == 9 * 71 and set(p["viterbi_trust"]) <= {"low", "high"}
    d = json.loads(invoke("select", log, "--max-levels", "2", "--folds", "2", "--restarts", "1", "--json"))
    rows = d["levels"]
    assert [r["levels"] for r in rows] == [1, 2]
    assert all(1 <= r["reached_best"] <= r["starts"] for r in rows) and rows[1]["starts"] == 1 + 2
    assert d["warnings"] == _warnings_of(rows)
    text = invoke("select", log, "--max-levels", "2", "--folds", "2", "--restarts", "1")
    assert "reached best" in text and f"{rows[1]['reached_best']} of 3" in text


def _warnings_of(rows):
    from trustseek.estimation import selection_warnings

    return selection_warnings(rows)


def test_cli_reports_bad_logs_cleanly(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("participant,trial,complexity,robot_action,human_action\nA,1,low,autonomous,rely\n")
    proc = run("fit", str(bad), check=False)
    assert proc.returncode == 2
    assert "missing column 'experience'" in proc.stderr and "Traceback" not in proc.stderr
    proc = run("fit", str(bad), "--transitions-on", "weather", check=False)
    assert proc.returncode == 2 and "'weather'" in proc.stderr


def test_small_coverage_study():
    """The coverage report, cell by cell (the full study is in benchmarks/bench_fit.py): on data
    sets large enough to pin a well-identified cell down, its intervals cover the truth; scored
    against a model whose cell is 0.2 away (a negative control), they never do."""
    from trustseek.reproduction.coverage import coverage_study

    truth = paper_model()
    cell = "P(rely | T=high, C=high, a=autonomous)"
    kw = {"n_participants": 60, "datasets": 2, "bootstrap": 20, "restarts": 1, "n_jobs": 1, "seed": 4}
    rows = {r["cell"]: r for r in coverage_study(truth, **kw)}
    assert len(rows) >= 12
    for r in rows.values():
        assert r["datasets"] == 2 and 0.0 <= r["truth"] <= 1.0 and r["mean_width"] >= 0
    assert rows["P(T1=high)"]["truth"] == truth.initial[1]
    assert rows[cell]["truth"] == pytest.approx(0.95)
    assert rows[cell]["coverage"] == 1.0 and rows[cell]["mean_width"] < 0.15
    # cells estimated at 0 or 1 are counted apart: how often, their coverage, how many likelihood-ratio intervals
    edge = [r for r in rows.values() if r["at_boundary"]]
    assert edge and all(0 <= r["likelihood"] <= r["at_boundary"] <= 2 and 0 <= r["boundary_coverage"] <= 1 for r in edge)
    emission = truth.emission.copy()
    emission[1, 0, 1] = [0.25, 0.75]  # P(rely | T=high, C=high, autonomous) = 0.75 instead of 0.95
    wrong = truth.replace(emission=emission)
    shifted = {r["cell"]: r for r in coverage_study(truth, truth=wrong, **kw)}
    assert shifted[cell]["truth"] == pytest.approx(0.75) and shifted[cell]["coverage"] == 0.0


def test_decode_names_participants_the_model_rules_out():
    from trustseek.estimation import FitError

    df = read_trials(example_path())
    i = df.index[(df["participant"] == "P004") & (df["robot_action"] == "ask")][0]
    df.loc[i, "human_action"] = "rely"  # the paper model says the human always teleoperates when asked
    with pytest.raises(FitError, match="participant 'P004': the trials have probability zero"):
        decode(df, paper_model())


def test_select_heldout_stays_finite_when_a_training_fold_never_saw_an_event():
    """One participant relies in high complexity, nobody else ever does: the training fold
    without them puts that cell at 0, yet the held-out score (smoothed) stays finite and
    the JSON valid."""
    n, T = 6, 20
    frames = []
    for i in range(n):
        cx = np.where(np.arange(T) % 2, "high", "low")
        ha = np.where(cx == "low", "rely", "intervene")
        if i == 0:
            ha = np.full(T, "rely")
        frames.append(
            pd.DataFrame(
                {
                    "participant": f"p{i}",
                    "trial": np.arange(1, T + 1),
                    "complexity": cx,
                    "robot_action": "autonomous",
                    "human_action": ha,
                    "experience": np.where(ha == "rely", "reliable", "faulty"),
                }
            )
        )
    df = pd.concat(frames, ignore_index=True)
    rows = select_levels(df, levels=(1, 2), folds=3, options=FitOptions(restarts=2, seed=0, tol=1e-6, n_jobs=1))
    for r in rows:
        assert np.isfinite(r["heldout_loglik"]) and all(np.isfinite(r["heldout_per_fold"]))
    json.dumps(rows, allow_nan=False)
    # a fold that contains participant p0 scores lower than under the unsmoothed model's -inf, but finite
    assert min(min(r["heldout_per_fold"]) for r in rows) < -5


def test_simulate_design_needs_one_ask_probability_per_complexity():
    from trustseek.errors import TrustseekError

    with pytest.raises(TrustseekError, match="one probability per complexity"):
        simulate_design(paper_model(), 2, p_ask=(0.1,))


def test_cli_fit_says_how_many_resamples_an_interval_rests_on():
    log = str(example_path())
    args = ("fit", log, "--restarts", "2", "--tol", "1e-6", "--jobs", "1")
    text = " ".join(invoke(*args, "--bootstrap", "3").split())  # the table wraps long lines
    assert "95% CI (3 resamples)" in text
    assert "bootstrap over 3 resamples" in text
    assert "3 resamples are too few for 95% intervals (at least 200" in text
    d = json.loads(invoke(*args, "--bootstrap", "3", "--json"))
    assert d["bootstrap"] == 3 and d["ci_level"] == 0.95 and "percentile" in d["ci_method"]
    assert all(c["lower"] <= c["estimate"] <= c["upper"] for c in d["cells"])


def test_cli_model_of_a_study_without_asking_is_marked_checked_refused_and_filled(tmp_path):
    """fit marks the ask rows a study without asking never estimated; check warns; solve refuses
    naming them; fit --fill-from paper supplies them, and solve then plans; the figures leave
    them out (before the marker, solve planned on identity ask transitions silently)."""
    from typer.testing import CliRunner

    from trustseek import ModelError
    from trustseek.cli import app
    from trustseek.data.trials import write_trials

    log = tmp_path / "no_ask.csv"
    write_trials(simulate_design(paper_model(), 30, seed=2, p_ask=(0.0, 0.0)).drop(columns="true_trust"), log)
    model = tmp_path / "m.json"
    invoke("fit", log, "--restarts", "1", "--tol", "1e-5", "--out", model)
    d = json.loads(model.read_text())
    assert {(r["a"], r.get("E")) for r in d["not_estimated"]} == {("ask", "faulty"), ("ask", "reliable")}
    out = invoke("check", model)
    assert "warning:" in out and "transition[C=high, a=ask, E=reliable]" in out and "ok" in out
    res = CliRunner().invoke(app, ["solve", "--model", str(model)])
    assert isinstance(res.exception, ModelError)  # main() prints each line on stderr and exits with 2
    lines = res.exception.lines()
    assert any("transition[C=low, a=ask, E=faulty] was never estimated" in ln for ln in lines)
    assert any("transition[C=high, a=ask, E=reliable] was never estimated" in ln for ln in lines)
    assert "--fill-from paper" in lines[-1]
    filled = tmp_path / "filled.json"
    text = invoke(
        "fit", log, "--restarts", "1", "--tol", "1e-5", "--out", filled, "--fill-from", "paper", "--plots", tmp_path / "f"
    )
    assert "taken from paper" in text
    m = TrustModel.load(filled)
    assert m.not_estimated == ()
    np.testing.assert_array_equal(m.transition[:, 1], paper_model().transition[:, 1])
    invoke("solve", "--model", filled, "--json")
    assert (tmp_path / "f" / "transitions.png").stat().st_size > 0


@settings(max_examples=40, deadline=None)
@given(
    rows=st.lists(
        st.tuples(
            st.integers(0, 3),  # participant
            st.sampled_from(["low", "high", None]),
            st.sampled_from(["autonomous", "ask"]),
            st.sampled_from(["rely", "intervene", None]),
            st.sampled_from(["faulty", "reliable", None]),
        ),
        max_size=30,
    ),
    categorical=st.booleans(),
)
def test_never_estimated_rows_are_those_no_trial_informs(rows, categorical):
    """Against a trial-by-trial count: an emission row (c, a) needs an observed human action, a
    transition row (c, a, e) a trial of the same participant after it (and e known)."""
    frame = pd.DataFrame(rows, columns=["participant", "complexity", "robot_action", "human_action", "experience"])
    frame["trial"] = frame.groupby("participant").cumcount() * 2 + 1  # gaps: 'next' is any later trial
    frame = frame.sample(frac=1, random_state=0)  # in any order
    if categorical:
        frame = frame.astype(dict.fromkeys(("participant", "complexity", "robot_action", "experience"), "category"))
    spec = paper_spec()
    got = set(never_estimated(frame, spec))
    if frame["complexity"].isna().any():
        assert got == set()  # a trial without its complexity: nothing to say per row
        return
    last = frame.groupby("participant", observed=True)["trial"].transform("max")
    em, tr = set(), set()
    for (_, t), lst in zip(frame.iterrows(), last, strict=True):
        c, a = ["low", "high"].index(t["complexity"]), ["autonomous", "ask"].index(t["robot_action"])
        if pd.notna(t["human_action"]):
            em.add((c, a))
        if t["trial"] < lst and pd.notna(t["experience"]):
            tr.add((c, a, ["faulty", "reliable"].index(t["experience"])))
    want = {("emission", (c, a)) for c in range(2) for a in range(2) if (c, a) not in em and a == 0}
    want |= {("transition", (c, a, e)) for c in range(2) for a in range(2) for e in range(2) if (c, a, e) not in tr}
    assert got == want


def test_a_best_restart_stopped_at_the_cap_is_a_warning():
    """A fit whose best restart hit --max-iter said nothing: its estimates looked final."""
    frame = read_trials(example_path())
    capped = fit_trust_model(frame, options=FitOptions(restarts=2, max_iter=3, seed=0))
    assert not capped.runs[capped.best].converged
    assert any(w.startswith("the best restart stopped at the cap on E-steps") for w in capped.warnings)
    done = fit_trust_model(frame, options=FitOptions(restarts=2, seed=0))
    assert done.runs[done.best].converged
    assert not any("cap on E-steps" in w for w in done.warnings)


def test_a_general_fit_names_the_rows_no_trial_reaches():
    """A general model's rows that no trial reaches (a declared level without trials) hold defaults,
    not data: the fit says which (a row the structure fixes whole, e.g. P(intervene | ask) = 1, is
    not news and is not named)."""
    import pandas as pd

    from trustseek.data import example_path, read_trials
    from trustseek.estimation.fit import fit_model
    from trustseek.estimation.options import FitOptions

    frame = read_trials(example_path("paper_trials.csv"))
    frame["condition"] = pd.Categorical(
        np.where(frame["participant"].astype(str).str[-1].isin(list("02468")), "a", "b"), categories=["a", "b", "unused"]
    )
    result = fit_model(frame, ("complexity", "robot_action"), ("condition",), options=FitOptions(restarts=1, max_iter=30))
    (note,) = [w for w in result.warnings if w.startswith("never estimated")]
    assert "condition=unused" in note and "condition=a" not in note and "robot_action=ask" not in note, note
    full = fit_model(frame, ("complexity", "robot_action"), ("experience",), options=FitOptions(restarts=1, max_iter=30))
    assert not [w for w in full.warnings if w.startswith("never estimated")], full.warnings
