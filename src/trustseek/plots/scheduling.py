"""What an optimal schedule does: item order and asks against the belief."""

from __future__ import annotations

import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.patches import Patch

from . import COLORS, figure, finish

DECISION_COLORS = ("#9ecae1", "#c8102e", "#1f5fa8", "#fd8d3c")  # low/auto, low/ask, high/auto, high/ask


def plot_schedule(policy, runs, name: str = "optimal", baseline: str | None = None, path=None, points: int = 201):
    """Two panels.  Left: the decision of the schedule ``policy`` (full control, two complexities)
    at every belief on each trial along the most common path of remaining items in ``runs``
    (its column ``name``; which item it collects and whether it asks), with the simulated mean belief on top.  Right:
    per trial, the share of high-complexity items and of asks under the policy and, when given,
    under the ``baseline`` schedule of ``runs``.  Returns the figure (written to ``path``)."""
    j = runs.names.index(name)
    cx, act, bel = runs.complexity[j], runs.action[j], runs.belief[j]
    T = cx.shape[1]
    counts = np.asarray(policy.counts)
    xs = np.linspace(0.0, 1.0, points)
    img = np.zeros((points, T))
    rem = counts.copy()
    for t in range(T):
        c, a = policy.choices(xs, np.tile(rem, (points, 1)))
        img[:, t] = c * 2 + a
        # follow the most common pick on this trial
        k = int(np.bincount(cx[:, t], minlength=len(counts)).argmax())
        rem[k] -= 1
    with figure(1, 2, figsize=(7.4, 2.8)) as (fig, axes):
        ax = axes[0]
        ax.imshow(
            img, origin="lower", aspect="auto", extent=(0.5, T + 0.5, 0, 1), cmap=ListedColormap(DECISION_COLORS),
            vmin=-0.5, vmax=3.5, interpolation="nearest",
        )  # fmt: skip
        ax.plot(np.arange(1, T + 1), bel.mean(axis=0), color="k", lw=1.0, label="mean belief")
        ax.set_xlabel("trial")
        ax.set_ylabel(r"belief $P(T = \mathrm{high})$")
        names = [f"{cn} item, {an}" for cn in policy.complexities for an in ("autonomous", "ask")]
        handles = [Patch(color=col, label=n) for col, n in zip(DECISION_COLORS, names, strict=True)]
        ax.legend(handles=handles, loc="lower left", fontsize=6, framealpha=0.9)
        ax.set_title("decision along the most common path")
        ax = axes[1]
        trials = np.arange(1, T + 1)
        ax.plot(trials, cx.mean(axis=0), color=COLORS["high"], label="high item (schedule)")
        ax.plot(trials, act.mean(axis=0), color=COLORS["ask"], ls="--", label="ask (schedule)")
        if baseline is not None:
            b = runs.names.index(baseline)
            ax.plot(trials, runs.complexity[b].mean(axis=0), color=COLORS["high"], alpha=0.4, label=f"high item ({baseline})")
            ax.plot(trials, runs.action[b].mean(axis=0), color=COLORS["ask"], ls="--", alpha=0.4, label=f"ask ({baseline})")
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlabel("trial")
        ax.set_ylabel("share of participants")
        ax.legend(fontsize=6, loc="center left")
        ax.set_title("item order and asks (simulated)")
        return finish(fig, path)


def plot_scheduling_section(section, path=None):
    """The report section's figure: :func:`plot_schedule` of its optimal policy against the
    paper's random order (``section``: a ``reproduction.scheduling.SchedulingSection``)."""
    from ..reproduction.scheduling import BASELINE

    return plot_schedule(section.optimal, section.runs, "optimal", BASELINE, path=path)
