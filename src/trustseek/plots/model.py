"""Figs. 4-6: estimated emission and transition probabilities, with bootstrap CIs.

``ci`` is the ``FitResult.ci`` dict ('emission'/'transition' -> (lower, upper)
arrays of the TrustModel shapes); ``reference`` is a TrustModel (e.g. the paper
preset) drawn as open markers labelled ``reference_label`` ("paper" by default).
Rows the model marks as never estimated (``TrustModel.not_estimated``) are not drawn.
"""

from __future__ import annotations

import numpy as np

from ..vocab import ACTIONS, EXPERIENCES, RELY
from . import figure, finish, legend_below

_LEVEL_COLORS = ("#c8102e", "#1f5fa8", "#2a9d3f", "#7b3294", "#e08214", "#666666", "#000000", "#8c510a")


def _bars(ax, values, lower, upper, ref, labels, series, ref_label="paper"):
    n_groups, n_series = values.shape
    width = 0.8 / n_series
    x = np.arange(n_groups)
    for s in range(n_series):
        pos = x - 0.4 + width * (s + 0.5)
        color = _LEVEL_COLORS[s % len(_LEVEL_COLORS)]
        ax.bar(pos, values[:, s], width * 0.9, color=color, alpha=0.75, label=series[s])
        if lower is not None:
            err = np.vstack([values[:, s] - lower[:, s], upper[:, s] - values[:, s]])
            ax.errorbar(pos, values[:, s], yerr=np.clip(err, 0, None), fmt="none", ecolor="0.15", elinewidth=0.8, capsize=2)
        if ref is not None:
            ax.plot(pos, ref[:, s], ls="none", marker="o", mfc="white", mec="0.1", ms=4, label=ref_label if s == 0 else None)
    ax.set_xticks(x)
    ax.set_xticklabels(labels)
    ax.set_ylim(0, 1.05)


def _cells(model, table, ci, reference, groups, index):
    """``table`` at ``index(group, trust level)`` per group and level, shape (groups, levels): of the
    model, of the ends of its interval ``ci`` and of a ``reference`` of the same levels and
    complexities (None where there is none)."""
    same = reference is not None and (reference.trust_levels, reference.complexities) == (model.trust_levels, model.complexities)
    ends = ci[table] if ci is not None else (None, None)
    arrays = (getattr(model, table), *ends, getattr(reference, table) if same else None)
    levels = range(len(model.trust_levels))
    return [None if a is None else np.array([[a[index(g, t)] for t in levels] for g in groups]) for a in arrays]


def plot_emissions(model, path=None, ci=None, reference=None, reference_label="paper"):
    """P(rely | T, C, a) per complexity and robot action (Fig. 4), one bar per trust level."""
    T, C = model.trust_levels, model.complexities
    skip = set(getattr(model, "not_estimated", ()))
    groups = [(c, a) for a in range(2) for c in range(len(C)) if ("emission", (c, a)) not in skip]
    vals, lo, hi, ref = _cells(model, "emission", ci, reference, groups, lambda g, t: (*g, t, RELY))
    with figure(figsize=(4.6, 2.6)) as (fig, ax):
        _bars(ax, vals, lo, hi, ref, [f"C={C[c]}\na={ACTIONS[a]}" for c, a in groups], [f"T={t}" for t in T], reference_label)
        ax.set_ylabel(r"$P(o = \mathrm{rely} \mid T, C, a)$")
        ax.set_title("Estimated probability of relying on the robot" + (" (95% CI)" if ci is not None else ""))
        ax.legend(loc="upper right", frameon=False, ncol=1)
        return finish(fig, path)


def plot_transitions(model, path=None, ci=None, reference=None, reference_label="paper", ask_experience=None):
    """P(T' = highest | T, E', C, a) for each (C, a, E') (Figs. 5-6), one bar per current trust level.

    ``ask_experience`` (per complexity, the experience the design records after asking, as in
    ``Task.ask_experience``) leaves out the (ask, E') groups the design never produces."""
    T, C = model.trust_levels, model.complexities
    top = len(T) - 1
    skip = set(getattr(model, "not_estimated", ()))
    panels = []
    for c in range(len(C)):
        groups = [(a, e) for a in range(2) for e in range(2) if ("transition", (c, a, e)) not in skip]
        if ask_experience is not None:
            groups = [(a, e) for a, e in groups if ACTIONS[a] != "ask" or e == ask_experience[c]]
        if groups:
            panels.append((c, groups))
    with figure(1, max(len(panels), 1), figsize=(3.4 * max(len(panels), 1), 2.7), squeeze=False) as (fig, axes):
        for ax, (c, groups) in zip(axes[0], panels, strict=False):
            vals, lo, hi, ref = _cells(model, "transition", ci, reference, groups, lambda g, t, c=c: (c, *g, t, top))
            labels = [f"{ACTIONS[a]}\nE'={EXPERIENCES[e]}" for a, e in groups]
            _bars(ax, vals, lo, hi, ref, labels, [f"T={t}" for t in T], reference_label)
            ax.set_title(f"complexity {C[c]}")
            ax.set_ylabel(rf"$P(T' = \mathrm{{{T[top]}}} \mid T, E', C, a)$")
            ax.tick_params(axis="x", labelsize=6.5)
        legend_below(fig, axes[0, 0])
        title = "Estimated trust transitions" + (" (95% CI)" if ci is not None else "")
        return finish(fig, path, title, rect=(0, 0.07, 1, 1))
