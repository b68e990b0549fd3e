"""The model figures (Figs. 4-7) draw the model's own numbers, its intervals and the reference."""

from __future__ import annotations

import numpy as np
import pytest

from trustseek.model.presets import conservative_model, paper_model, paper_task
from trustseek.plots.model import plot_emissions, plot_transitions
from trustseek.plots.q import plot_q
from trustseek.vocab import RELY


def bar_heights(ax) -> list[float]:
    return [p.get_height() for p in ax.patches]


def test_emission_bars_are_the_model_and_the_markers_the_reference():
    m, ref = paper_model(), conservative_model()
    fig = plot_emissions(m, reference=ref)
    ax = fig.axes[0]
    # one bar per (C, a) group and trust level, series by trust level: level t's bars first
    groups = [(c, a) for a in range(2) for c in range(len(m.complexities))]
    expected = [m.emission[c, a, t, RELY] for t in range(len(m.trust_levels)) for c, a in groups]
    np.testing.assert_allclose(bar_heights(ax), expected)
    markers = [line for line in ax.lines if line.get_marker() == "o"]
    drawn = np.concatenate([line.get_ydata() for line in markers])
    np.testing.assert_allclose(drawn, [ref.emission[c, a, t, RELY] for t in range(2) for c, a in groups])
    assert sorted(t.get_text() for t in ax.get_legend().get_texts()) == ["T=high", "T=low", "paper"]


def test_emission_interval_bars_span_the_interval():
    m = paper_model()
    lower, upper = m.emission * 0.5, np.minimum(m.emission * 1.5, 1.0)
    fig = plot_emissions(m, ci={"emission": (lower, upper)})
    ax = fig.axes[0]
    assert ax.get_title().endswith("(95% CI)")
    bars = [c for c in ax.collections if c.get_segments()]
    spans = sorted((seg[0][1], seg[1][1]) for bar in bars for seg in bar.get_segments())
    want = sorted(
        (lower[c, a, t, RELY], upper[c, a, t, RELY]) for t in range(2) for a in range(2) for c in range(len(m.complexities))
    )
    np.testing.assert_allclose(spans, want)


def test_a_reference_with_other_levels_is_not_drawn():
    m = paper_model()
    other = m.replace(complexities=("easy", "hard"))
    ax = plot_emissions(m, reference=other).axes[0]
    assert not [line for line in ax.lines if line.get_marker() == "o"]


def test_transition_figure_draws_the_top_level_and_leaves_out_what_the_design_never_records():
    m, task = paper_model(), paper_task()
    fig = plot_transitions(m, ask_experience=task.ask_experience)
    for c, ax in enumerate(fig.axes[: len(m.complexities)]):
        ticks = [t.get_text() for t in ax.get_xticklabels()]
        assert len(ticks) == 3 and sum("ask" in t for t in ticks) == 1
        assert ax.get_title() == f"complexity {m.complexities[c]}"
        heights = bar_heights(ax)
        groups = [(0, 0), (0, 1), (1, task.ask_experience[c])]
        np.testing.assert_allclose(heights, [m.transition[c, a, e, t, 1] for t in range(2) for a, e in groups])


def test_transition_figure_leaves_out_never_estimated_rows():
    m = paper_model()
    full = plot_transitions(m)
    marked = plot_transitions(m.replace(not_estimated=(("transition", (0, 1, 0)), ("transition", (0, 1, 1)))))
    ticks = [t.get_text() for t in marked.axes[0].get_xticklabels()]
    assert len(ticks) == 2 and not any("ask" in t for t in ticks)
    assert len(full.axes[0].get_xticklabels()) == 4


def test_q_figure_draws_both_actions_and_marks_the_threshold(tmp_path):
    from trustseek.pomdp.problem import AssistancePOMDP
    from trustseek.solvers.registry import make_solver

    policy = make_solver("grid").solve(AssistancePOMDP(paper_model(), paper_task()))
    path = tmp_path / "q.png"
    fig = plot_q(policy, path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    thresholds = policy.thresholds()
    for c, cn in enumerate(policy.complexities):
        ax = fig.axes[c]
        autonomous, ask = ax.lines[0], ax.lines[1]
        np.testing.assert_allclose(autonomous.get_ydata(), policy.q[:, c, 0])
        np.testing.assert_allclose(ask.get_ydata(), policy.q[:, c, 1])
        marks = [line for line in ax.lines[2:] if line.get_linestyle() == ":"]
        th = thresholds[cn]
        if th is not None and 0 < th < 1:
            assert marks and marks[0].get_xdata()[0] == pytest.approx(th)
            assert any(f"{th:.3f}" in t.get_text() for t in ax.texts)
        else:
            assert not marks
