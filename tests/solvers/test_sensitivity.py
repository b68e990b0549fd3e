"""The sensitivity analysis of the threshold and V to the printed precision of the parameters."""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from importlib.resources import files

import numpy as np
import pytest
from typer.testing import CliRunner

from trustseek.cli import main
from trustseek.cli._app import app
from trustseek.model.core import TrustModel
from trustseek.model.presets import paper_model, paper_task
from trustseek.model.task import Task
from trustseek.solvers.sensitivity import SensitivityError, apply, evaluate, free_parameters, sensitivity

THRESHOLD = "threshold[high]"


@pytest.fixture(scope="module")
def paper_run():
    return sensitivity(paper_model(), paper_task(), starts=1, samples=96, grid=201)


def test_the_extremes_over_processes_are_the_extremes_in_one():
    """The joint extremes run side by side in processes: the same ranges, points and number of
    evaluations as one after another (the random starts drawn in the same order)."""
    model, task = paper_model(), paper_task()
    some = free_parameters(model, task, 2, include_task=False)[:6]
    runs = [sensitivity(model, task, starts=3, samples=8, grid=101, parameters=some, jobs=jobs).to_dict() for jobs in (1, 2)]
    assert json.dumps(runs[0], sort_keys=True) == json.dumps(runs[1], sort_keys=True)


def test_free_parameters_of_the_paper_preset():
    params = free_parameters(paper_model(), paper_task())
    names = [p.name for p in params]
    # one probability per row: initial, 4 autonomous emissions, 8 autonomous + 4 ask transitions, 2 successes, discount
    assert len(params) == 1 + 4 + 8 + 4 + 2 + 1
    assert not any("ask)" in n and n.startswith("P(rely") for n in names)  # ask emissions are fixed by design
    # the rows the design never produces are left out: reliable after asking in low, faulty after asking in high
    assert not any("E'=reliable, C=low, ask" in n or "E'=faulty, C=high, ask" in n for n in names)
    for p in params:
        assert 0.0 <= p.lower <= p.value <= p.upper <= 1.0
        assert p.upper - p.lower <= (0.001 if p.name == "discount" else 0.01) + 1e-12
    high = next(p for p in params if p.name == "p_suc(C=high)")
    assert (high.lower, high.upper) == pytest.approx((0.825, 0.835))


def test_apply_keeps_rows_normalised_and_moves_only_its_cell():
    m, t = paper_model(), paper_task()
    params = free_parameters(m, t)
    x = [p.upper for p in params]
    m2, t2 = apply(m, t, params, x)
    assert np.allclose(m2.emission.sum(axis=-1), 1) and np.allclose(m2.transition.sum(axis=-1), 1)
    assert t2.success[1] == pytest.approx(0.835) and t2.discount == pytest.approx(0.9875)
    m3, t3 = apply(m, t, params, [p.value for p in params])
    assert np.allclose(m3.emission, m.emission) and np.allclose(m3.transition, m.transition)
    assert np.array_equal(t3.success, t.success) and t3.discount == t.discount


def test_rounding_of_p_suc_high_moves_the_threshold():
    """25 of 30 high-complexity successes print as 0.83 but give a different threshold."""
    m, t = paper_model(), paper_task()
    printed = evaluate(m, t)[THRESHOLD]
    exact = evaluate(m, replace(t, success=np.array([0.97, 25 / 30])))[THRESHOLD]
    assert printed == pytest.approx(0.7812, abs=5e-4)
    assert abs(exact - printed) > 0.01


def test_one_at_a_time_and_joint_ranges(paper_run):
    res = paper_run
    assert res.quantities == [THRESHOLD, "V"]
    lo, hi = res.range_of(THRESHOLD)
    # the paper's 0.75 lies inside the range its printed precision allows; the printed values' 0.78 too
    assert lo < 0.75 < res.nominal[THRESHOLD] < hi
    # every one-at-a-time end is a point of the box: the joint range contains it
    for r in res.one_at_a_time:
        for end in ("at_lower", "at_upper"):
            for q in res.quantities:
                jl, jh = res.range_of(q)
                assert jl - 1e-9 <= r[end][q] <= jh + 1e-9
    # the largest single effect is the robot's success probability in high complexity
    top = max(res.one_at_a_time, key=lambda r: abs(r["at_upper"][THRESHOLD] - r["at_lower"][THRESHOLD]))
    assert top["name"] == "p_suc(C=high)"


def test_optimised_extremes_bound_the_sample_and_are_reached(paper_run):
    """The optimiser is checked against the Latin-hypercube sample: no sampled point lies beyond
    its extremes, and its extremes are values the model really takes at the reported arguments."""
    res = paper_run
    m, t = paper_model(), paper_task()
    params = res.parameters
    for q in res.quantities:
        j, s = res.joint[q], res.sampled[q]
        assert s["n"] == 96
        assert j["min"] <= s["min"] + 1e-9 and s["max"] <= j["max"] + 1e-9
        # strictly wider than the sample: the extremes are corners the sample does not reach
        assert j["max"] - j["min"] > s["max"] - s["min"]
        for sense in ("min", "max"):
            x = [j[f"{sense}_at"][p.name] for p in params]
            assert all(p.lower - 1e-12 <= v <= p.upper + 1e-12 for p, v in zip(params, x, strict=True))
            again = evaluate(*apply(m, t, params, x), grid=201)[q]
            assert again == pytest.approx(j[sense], rel=1e-9)


def test_a_start_at_the_printed_values_finds_no_wider_range_than_the_corner():
    model_only = free_parameters(paper_model(), paper_task(), include_task=False)
    res1 = sensitivity(paper_model(), paper_task(), starts=1, samples=0, grid=101, parameters=model_only)
    res3 = sensitivity(paper_model(), paper_task(), starts=2, samples=0, grid=101, parameters=model_only)
    for q in res1.quantities:
        assert res3.joint[q]["min"] == pytest.approx(res1.joint[q]["min"], abs=1e-6)
        assert res3.joint[q]["max"] == pytest.approx(res1.joint[q]["max"], abs=1e-6)


def test_three_level_models_are_refused():
    ex = files("trustseek") / "examples"
    m = TrustModel.load(ex / "three_level_model.json")
    t = Task.load(ex / "three_level_task.json")
    with pytest.raises(SensitivityError, match="two trust levels"):
        sensitivity(m, t)


def test_cli_json_and_refusal(tmp_path):
    runner = CliRunner()
    png = tmp_path / "tornado.png"
    res = runner.invoke(app, ["sensitivity", "--json", "--starts", "1", "--samples", "16", "--grid", "101", "--plot", str(png)])
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    lo, hi = out["joint"][THRESHOLD]["range"]
    assert lo < 0.75 < hi and png.stat().st_size > 10_000
    model = tmp_path / "m.json"
    model.write_text((files("trustseek") / "examples" / "three_level_model.json").read_text())
    task = files("trustseek") / "examples" / "three_level_task.json"
    argv = sys.argv
    sys.argv = ["trustseek", "sensitivity", "-m", str(model), "-t", str(task)]
    try:
        with pytest.raises(SystemExit) as exc:
            main()
    finally:
        sys.argv = argv
    assert exc.value.code == 2
