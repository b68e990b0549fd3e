"""General inputs: named discrete variables of the mapping, on transitions and emissions, in their
declared level order; the paper's trust model is the preset of this general model."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cli_runner import run_cli
from trustseek.data import ColumnMapping, DataError, example_path, read_trials
from trustseek.estimation.options import FitOptions

RENAME = {"low": "simple", "high": "complex"}  # "complex" sorts before "simple": the declared order must win


def renamed_log(tmp_path: Path) -> Path:
    log = pd.read_csv(example_path()).drop(columns=["true_trust"])
    log["complexity"] = log["complexity"].map(RENAME)
    path = tmp_path / "log.csv"
    log.to_csv(path, index=False)
    return path


def test_declared_complexity_order_is_kept_from_the_mapping_to_solve(tmp_path):
    """Fails before: the fit sorted complexities other than low/high alphabetically, so the model
    said [complex, simple] and solve refused a task written in the declared order."""
    path = renamed_log(tmp_path)
    mapping = tmp_path / "m.json"
    mapping.write_text(json.dumps({"complexities": ["simple", "complex"]}))
    assert list(read_trials(path, mapping)["complexity"].cat.categories) == ["simple", "complex"]
    model = tmp_path / "model.json"
    code, out = run_cli(["fit", str(path), "--mapping", str(mapping), "-r", "1", "--max-iter", "30", "-o", str(model), "--quiet"])
    assert code == 0, out
    assert json.loads(model.read_text())["complexities"] == ["simple", "complex"]
    task = json.loads(json.dumps(_paper_task_dict()).replace('"low"', '"simple"').replace('"high"', '"complex"'))
    (tmp_path / "task.json").write_text(json.dumps(task))
    code, out = run_cli(["solve", "--model", str(model), "--task", str(tmp_path / "task.json"), "--json"])
    assert code == 0, out
    assert list(json.loads(out)["ask_intervals"]) == ["simple", "complex"]


def _paper_task_dict() -> dict:
    from trustseek.model import paper_task

    return paper_task().to_dict()


# --------------------------------------------------------------------------- a model with named inputs against an independent EM

CONDITIONS = ("control", "aid")  # declared order: not alphabetical
ADVICE = ("disagree", "agree")
DIFFICULTY = ("easy", "medium", "hard")
TRUE_INITIAL = np.array([0.4, 0.6])
# P(rely | level, advice, difficulty): [advice, difficulty, level]
TRUE_RELY = np.array([[[0.30, 0.80], [0.20, 0.70], [0.10, 0.55]], [[0.45, 0.95], [0.35, 0.90], [0.25, 0.75]]])
# P(next level | level, condition): [condition, level, next]
TRUE_TRANSITION = np.array([[[0.85, 0.15], [0.25, 0.75]], [[0.60, 0.40], [0.05, 0.95]]])
MAPPING = {
    "columns": {"participant": "subject", "human_action": "relied"},
    "labels": {"human_action": {"yes": "rely", "no": "intervene"}},
    "inputs": {
        "condition": {"column": "cond", "levels": list(CONDITIONS), "labels": {"C": "control", "A": "aid"}},
        "advice": {"column": "aid_says", "levels": list(ADVICE)},
        "difficulty": {"column": "img", "levels": list(DIFFICULTY), "labels": {"easy": ["1"], "medium": ["2"], "hard": ["3"]}},
    },
    "missing": ["NA"],
}


def study_log(n: int = 50, trials: int = 24, seed: int = 5) -> tuple[pd.DataFrame, dict[str, np.ndarray]]:
    """A study's log drawn from the IOHMM above (0-based trials, a few unrecorded decisions), and
    its codes per participant for the reference EM."""
    rng = np.random.default_rng(seed)
    cond = rng.integers(0, 2, n)
    adv = rng.integers(0, 2, (n, trials))
    dif = rng.integers(0, 3, (n, trials))
    s = np.zeros((n, trials), dtype=int)
    s[:, 0] = rng.random(n) < TRUE_INITIAL[1]
    for t in range(1, trials):
        p_high = TRUE_TRANSITION[cond, s[:, t - 1], 1]
        s[:, t] = rng.random(n) < p_high
    y = (rng.random((n, trials)) < TRUE_RELY[adv, dif, s]).astype(int)
    y_obs = np.where(rng.random((n, trials)) < 0.04, -1, y)
    rows = [
        {
            "subject": f"S{i:02d}",
            "trial": t,
            "cond": "CA"[cond[i]],
            "aid_says": ADVICE[adv[i, t]],
            "img": dif[i, t] + 1,
            "relied": "NA" if y_obs[i, t] < 0 else ("yes" if y_obs[i, t] else "no"),
        }
        for i in range(n)
        for t in range(trials)
    ]
    return pd.DataFrame(rows), {"cond": cond, "adv": adv, "dif": dif, "y": y_obs}


def reference_em(cond, adv, dif, y, iterations: int = 4000, tol: float = 1e-13):
    """Plain Baum-Welch for this IOHMM, written out here: scaled forward-backward over all
    participants at once, then the M-step as normalised expected counts."""
    n, T = y.shape
    pi, rely, A = TRUE_INITIAL.copy(), TRUE_RELY.copy(), TRUE_TRANSITION.copy()
    prev = -np.inf
    for _ in range(iterations):
        p_rely = rely[adv, dif]  # (n, T, K)
        B = np.where((y == 1)[..., None], p_rely, np.where((y == 0)[..., None], 1 - p_rely, 1.0))
        At = A[cond]  # (n, K, K): the condition is the participant's
        alpha = np.zeros((n, T, 2))
        c = np.zeros((n, T))
        a = pi[None] * B[:, 0]
        c[:, 0] = a.sum(1)
        alpha[:, 0] = a / c[:, :1]
        for t in range(1, T):
            a = np.einsum("nk,nkj->nj", alpha[:, t - 1], At) * B[:, t]
            c[:, t] = a.sum(1)
            alpha[:, t] = a / c[:, t : t + 1]
        beta = np.ones((n, T, 2))
        for t in range(T - 2, -1, -1):
            beta[:, t] = np.einsum("nkj,nj->nk", At, B[:, t + 1] * beta[:, t + 1]) / c[:, t + 1 : t + 2]
        ll = float(np.log(c).sum())
        gamma = alpha * beta
        xi = alpha[:, :-1, :, None] * At[:, None] * (B[:, 1:] * beta[:, 1:])[:, :, None, :] / c[:, 1:, None, None]
        pi = gamma[:, 0].mean(0)
        A = np.stack([xi[cond == k].sum((0, 1)) for k in range(2)])
        A /= A.sum(-1, keepdims=True)
        num = np.zeros((2, 3, 2))
        den = np.zeros((2, 3, 2))
        seen = y >= 0
        np.add.at(num, (adv[seen], dif[seen]), gamma[seen] * y[seen][:, None])
        np.add.at(den, (adv[seen], dif[seen]), gamma[seen])
        rely = num / den
        if abs(ll - prev) < tol * abs(ll):
            break
        prev = ll
    return ll, pi, rely, A


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("study")
    log, codes = study_log()
    path = tmp / "study.csv"
    log.to_csv(path, index=False)
    mapping = tmp / "mapping.json"
    mapping.write_text(json.dumps(MAPPING))
    return path, mapping, codes


def test_named_inputs_fit_equals_an_independent_em(study, tmp_path):
    """Two named inputs on the emissions and one on the transitions, from a mapping file alone,
    through the command line: the model file's log-likelihood and tables equal plain EM's."""
    path, mapping, codes = study
    out = tmp_path / "model.json"
    code, text = run_cli(
        ["fit", str(path), "--mapping", str(mapping), "--emissions-on", "advice,difficulty", "--transitions-on", "condition"]
        + ["-r", "3", "--tol", "1e-12", "-o", str(out), "--json", "--quiet"]
    )
    assert code == 0, text
    result = json.loads(text)
    d = json.loads(out.read_text())
    assert d["format"] == "trustseek.iohmm/1"
    assert d["inputs"] == {"advice": list(ADVICE), "difficulty": list(DIFFICULTY), "condition": list(CONDITIONS)}
    ll, pi, rely, A = reference_em(codes["cond"], codes["adv"], codes["dif"], codes["y"])
    assert result["loglik"] == pytest.approx(ll, abs=1e-6)
    # the named axes: emission[advice][difficulty][level][category], transition[condition][level][next level]
    levels = d["levels"]
    ours_rely = np.array([[[d["emission"][a][f][k]["rely"] for k in levels] for f in DIFFICULTY] for a in ADVICE])
    ours_A = np.array([[[d["transition"][c][k][j] for j in levels] for k in levels] for c in CONDITIONS])
    perm = [0, 1] if abs(ours_rely[..., 0] - rely[..., 0]).max() < abs(ours_rely[..., 0] - rely[..., 1]).max() else [1, 0]
    np.testing.assert_allclose(ours_rely, rely[..., perm], atol=5e-5)
    np.testing.assert_allclose(ours_A, A[:, perm][:, :, perm], atol=5e-5)
    np.testing.assert_allclose([d["initial"][k] for k in levels], pi[perm], atol=5e-5)


# --------------------------------------------------------------------------- the general model file


def test_general_model_file_round_trip_and_problems(study, tmp_path):
    from trustseek.estimation.fit import fit_model
    from trustseek.model.core import TrustModel, load_any_model
    from trustseek.model.jsonfile import ModelError

    path, mapping, _ = study
    frame = read_trials(path, mapping)
    result = fit_model(frame, ("advice", "difficulty"), ("condition",), options=FitOptions(restarts=1, max_iter=40))
    model = result.model
    f = tmp_path / "g.json"
    model.save(f)
    again = load_any_model(f)
    assert isinstance(again, TrustModel) and again.general
    assert again == model
    assert again.inputs == {"advice": ADVICE, "difficulty": DIFFICULTY, "condition": CONDITIONS}
    d = json.loads(f.read_text())
    row = d["emission"]["agree"]["hard"]["high"]
    row["rely"] = row["intervene"] = 0.75
    d["transition"]["aid"].pop("low")
    d["inputs"]["condition"] = ["control", "control"]
    with pytest.raises(ModelError) as err:
        TrustModel.from_dict(d, "bad.json", general=True)
    lines = err.value.lines()
    assert any("inputs.condition has duplicate names" in x for x in lines), lines
    d["inputs"]["condition"] = list(CONDITIONS)
    with pytest.raises(ModelError) as err:
        TrustModel.from_dict(d, "bad.json", general=True)
    text = "\n".join(err.value.lines())
    assert "emission[advice=agree, difficulty=hard][level=high] sums to" in text
    assert "transition[condition=aid][level=low] is missing" in text


def test_existing_trust_model_files_still_load_and_the_paper_model_is_the_preset(tmp_path):
    """A trust model file loads as before, through the general loader too; the paper's structure is
    the general model's preset: the same spec, and a trust model decodes like its general form."""
    from trustseek.estimation import PAPER_EMISSION_INPUTS, PAPER_TRANSITION_INPUTS, decode, paper_spec
    from trustseek.estimation.trust_iohmm import from_model, general_spec, spec_of, to_model
    from trustseek.model import TrustModel, paper_model
    from trustseek.model.core import load_any_model

    shipped = example_path("three_level_model.json")
    assert load_any_model(shipped) == TrustModel.load(shipped)
    paper = paper_model()
    paper.save(tmp_path / "paper.json")
    assert load_any_model(tmp_path / "paper.json") == paper
    frame = read_trials(example_path())
    assert general_spec(frame, PAPER_EMISSION_INPUTS, PAPER_TRANSITION_INPUTS) == paper_spec()
    general = to_model(*from_model(paper), general=True)
    general.save(tmp_path / "general.json")
    again = load_any_model(tmp_path / "general.json")
    assert again == general  # the fixed row P(intervene | ask) = 1 and the level-naming rule kept
    assert spec_of(again) == paper_spec()
    pd.testing.assert_frame_equal(decode(frame, again), decode(frame, paper))


def test_planning_commands_refuse_a_general_model_in_one_line(study, tmp_path):
    from trustseek.estimation.fit import fit_model

    path, mapping, _ = study
    result = fit_model(read_trials(path, mapping), ("advice",), ("condition",), options=FitOptions(restarts=1, max_iter=20))
    f = tmp_path / "g.json"
    result.model.save(f)
    for argv in (["solve", "--model", str(f)], ["simulate", "--model", str(f), "--participants", "2"]):
        code, err = run_cli(argv, stdout=False)
        assert code == 2, err
        lines = [x for x in err.splitlines() if x.strip()]
        assert len(lines) == 1 and "needs a trust model" in lines[0] and "complexity, robot_action, experience" in lines[0], err
    code, out = run_cli(
        ["fit", str(path), "--mapping", str(mapping), "--emissions-on", "advice", "--transitions-on", "condition"]
        + ["-r", "1", "--max-iter", "20", "--plots", str(tmp_path / "figs"), "--quiet"]
    )
    assert code == 0 and "the tables by combination of the inputs" in out, out
    assert {p.name for p in (tmp_path / "figs").iterdir()} == {"emissions.png", "transitions.png"}
    code, out = run_cli(["check", str(f)])
    assert code == 0 and "a general model, inputs: advice, condition" in out, out
    code, _ = run_cli(["decode", str(path), "--model", str(f), "--mapping", str(mapping), "-o", str(tmp_path / "p.csv")])
    assert code == 0
    post = pd.read_csv(tmp_path / "p.csv")
    expected = result.posteriors()
    np.testing.assert_allclose(post["p_trust_high"], expected["p_trust_high"], atol=1e-12)
    code, out = run_cli(["predict", str(path), "--model", str(f), "--mapping", str(mapping), "-b", "0", "--json"])
    assert code == 0, out
    assert json.loads(out)["n_scored"] == int((study_log()[1]["y"] >= 0).sum())


# --------------------------------------------------------------------------- the mapping's inputs

LEVEL_NAMES = st.text(alphabet="abcdefgh", min_size=1, max_size=3)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    levels=st.lists(LEVEL_NAMES, min_size=1, max_size=4, unique=True),
    values=st.lists(st.one_of(LEVEL_NAMES, st.just("")), min_size=1, max_size=30),
)
def test_input_values_outside_the_levels_are_reported_by_row(levels, values):
    """Any cells against any declared levels: the values outside them are one line with their count,
    first rows and values; empty cells another; otherwise the column holds the levels in the declared order."""
    n = len(values)
    frame = pd.DataFrame(
        {
            "participant": ["p"] * n,
            "trial": range(1, n + 1),
            "human_action": ["rely"] * n,
            "grp": values,
        }
    )
    mapping = {"inputs": {"group": {"column": "grp", "levels": levels}}}
    outside = [i for i, v in enumerate(values) if v and v not in levels]
    empty = [i for i, v in enumerate(values) if not v]
    if not outside and not empty:
        got = read_trials(frame, mapping)["group"]
        assert list(got.cat.categories) == levels
        assert got.astype(str).tolist() == values
        return
    with pytest.raises(DataError) as err:
        read_trials(frame, mapping)
    lines = err.value.lines()
    assert len(lines) == bool(outside) + bool(empty), lines
    if outside:
        (line,) = [x for x in lines if "outside the declared levels" in x]
        assert line.startswith("<table>: column 'grp' (input 'group')")
        assert f"the levels {levels}" in line
        first = outside[0]
        shown = f"row {first + 1} {values[first]!r}"
        assert (f"in {len(outside)} rows: " if len(outside) > 1 else ": ") + shown in line
    if empty:
        (line,) = [x for x in lines if "empty" in x]
        assert f"row {empty[0] + 1}" in line


def test_input_mapping_problems_are_named(tmp_path):
    bad = {
        "inputs": {
            "complexity": {"column": "c", "levels": ["a", "b"]},
            "advice": {"column": "a", "levels": ["x", "x"]},
            "cond": {"levels": ["a"], "labels": {"z": "b"}, "colour": 1},
            "grp": "g",
        }
    }
    with pytest.raises(DataError) as err:
        ColumnMapping.from_dict(bad)
    text = "\n".join(err.value.lines())
    assert "input 'complexity': the name is taken" in text
    assert "input 'advice': 'levels' must list its distinct levels in their order" in text
    assert "input 'cond': unknown entries ['colour']" in text
    assert "input 'cond': label z='b' is not one of the levels ['a']" in text
    assert "input 'grp': expected" in text
    path = tmp_path / "log.csv"
    path.write_text("participant,trial,human_action,g\np,1,rely,x\n")
    with pytest.raises(DataError) as err:
        read_trials(path, {"inputs": {"cond": {"column": "condition", "levels": ["a"]}}})
    assert "missing column 'condition' (the mapping's input 'cond')" in str(err.value)
    assert ColumnMapping.from_dict({"inputs": {"cond": {"column": "g", "levels": ["x"]}}}).to_dict()["inputs"] == {
        "cond": {"column": "g", "levels": ["x"]}
    }


# --------------------------------------------------------------------------- a study's log with a condition as an input


def test_study_log_with_a_condition_input_fits_like_the_canonical_log(tmp_path):
    """Block-wise trial order, decision/advice/truth columns, JSON lines with nulls, NA cells, practice
    rows to drop, per-trial ratings and a between-subject condition declared as an input: read by a
    mapping file alone, it encodes and fits as the canonical log with the condition column does."""
    from test_data_studies import BASE_MAPPING, study_columns

    from trustseek.estimation import PAPER_EMISSION_INPUTS, PAPER_TRANSITION_INPUTS
    from trustseek.estimation.fit import fit_model

    canonical = read_trials(example_path())
    log = study_columns(canonical)
    canonical = canonical.assign(
        condition=pd.Categorical(log["condition"], categories=["transparent", "opaque"]),
        rating=pd.Categorical(log["rating"].astype(str), categories=[str(i) for i in range(1, 8)], ordered=True),
    )
    log["block"] = (log["trial"] - 1) // 10
    log["trial_in_block"] = (log["trial"] - 1) % 10
    practice = log.groupby("subject", sort=False).head(2).assign(practice="yes", block=-1)
    log = pd.concat([practice, log.assign(practice="no")]).drop(columns="trial").sample(frac=1.0, random_state=3)
    log["condition"] = log["condition"].map({"transparent": "T", "opaque": "O"})
    path = tmp_path / "study.jsonl"
    with path.open("w") as fh:
        for rec in log.to_dict(orient="records"):
            rec = {k: (v.item() if hasattr(v, "item") else v) for k, v in rec.items()}
            fh.write(json.dumps({**rec, "decision": None if rec["decision"] == "NA" else rec["decision"]}) + "\n")
    mapping = {
        **BASE_MAPPING,
        "order": ["block", "trial_in_block"],
        "drop": [{"column": "practice", "values": ["yes"]}],
        "inputs": {
            "group": {"column": "condition", "levels": ["transparent", "opaque"], "labels": {"T": "transparent", "O": "opaque"}}
        },
        "rating": {"column": "rating", "levels": [1, 2, 3, 4, 5, 6, 7]},
    }
    mfile = tmp_path / "mapping.json"
    mfile.write_text(json.dumps(mapping))
    frame = read_trials(path, mfile)
    assert list(frame["group"].cat.categories) == ["transparent", "opaque"]
    tr = (*PAPER_TRANSITION_INPUTS, "group")
    fits = []
    for f, group in ((frame, "group"), (canonical, "condition")):
        f = f.rename(columns={group: "group"}) if group != "group" else f
        fits.append(fit_model(f, PAPER_EMISSION_INPUTS, tr, options=FitOptions(restarts=1, seed=3, max_iter=40), rating="rating"))
    mapped, reference = fits
    assert mapped.model.inputs["group"] == ("transparent", "opaque")
    assert mapped.seqs.n_trials == reference.seqs.n_trials == len(canonical)
    assert mapped.loglik == pytest.approx(reference.loglik, rel=1e-9, abs=1e-9)


def test_select_compares_levels_of_a_model_of_named_inputs(study):
    """select on named inputs compares the general model: its one-level row is the independent
    count-based maximum (a single level: P(rely | advice) = the share of relying per advice)."""
    path, mapping, codes = study
    code, out = run_cli(
        ["select", str(path), "--mapping", str(mapping), "--emissions-on", "advice", "--transitions-on", "condition"]
        + ["--max-levels", "2", "--folds", "2", "-r", "2", "--json", "--quiet", "--no-widen"]
    )
    assert code == 0, out
    rows = json.loads(out)["levels"]
    assert [r["levels"] for r in rows] == [1, 2]
    y, adv = codes["y"], codes["adv"]
    seen = y >= 0
    ll = 0.0
    for a in np.unique(adv[seen]):
        yy = y[seen & (adv == a)]
        p = yy.mean()
        ll += float(np.sum(yy * np.log(p) + (1 - yy) * np.log(1 - p)))
    assert rows[0]["loglik"] == pytest.approx(ll, abs=1e-6)
    assert rows[1]["loglik"] >= rows[0]["loglik"] - 1e-6


def test_bootstrap_intervals_for_a_model_of_named_inputs(study):
    """--bootstrap on named inputs: every estimated cell gets an interval that holds its estimate,
    the same resamples give the same intervals, and the table shows them."""
    path, mapping, _ = study
    argv = ["fit", str(path), "--mapping", str(mapping), "--emissions-on", "advice", "--transitions-on", "condition"]
    argv += ["-r", "2", "--bootstrap", "6", "--jobs", "1", "--quiet"]
    code, text = run_cli([*argv, "--json"])
    assert code == 0, text
    d = json.loads(text)
    assert d["bootstrap"] == 6 and d["ci_level"] == 0.95
    cells = d["cells"]
    assert {c["table"] for c in cells} == {"initial", "emission", "transition"}
    for c in cells:
        assert c["lower"] <= c["estimate"] <= c["upper"], c
    assert any(c["upper"] - c["lower"] > 1e-3 for c in cells)  # resampling moves the estimates
    code, again = run_cli([*argv, "--json"])
    assert json.loads(again)["cells"] == cells
    code, table = run_cli(argv)
    assert code == 0 and "95% CI (6 resamples)" in table, table
