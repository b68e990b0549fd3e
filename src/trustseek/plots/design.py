"""Figures of a design study: power curves of experiment 2, the regret of the policy estimated
from each experiment-1 design, and the data-collection design search."""

from __future__ import annotations

from typing import Any

import matplotlib
import numpy as np

from . import COLORS, figure, finish

TEST_LABELS = {"wilcoxon": "paired Wilcoxon", "t": "paired t-test"}


def _label(point: dict[str, Any]) -> str:
    e = point["experiment1"]
    return f"{e['participants']} × {e['trials']} (ask {e['ask_low']:.2f}/{e['ask_high']:.2f})"


def plot_power(summary: dict[str, Any], path=None):
    """Power of experiment 2 against its participants, one line per test and experiment-1 design
    and block length, with the exact 95 % intervals as bands and the target power as a line."""
    target = summary["targets"]["power"]
    with figure(figsize=(5.6, 3.4)) as (fig, ax):
        colors = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
        designs = [(point, e2) for point in summary["points"] for e2 in point["experiment2"]]
        for k, (point, e2) in enumerate(designs):
            color, curve = colors[k % len(colors)], e2["curve"]
            n = [c["participants"] for c in curve]
            for test, ls in (("wilcoxon", "-"), ("t", "--")):
                lab = f"{TEST_LABELS[test]}, exp. 1 {_label(point)}, {e2['trials_per_block']} trials/block"
                ax.plot(n, [c[test]["power"] for c in curve], ls=ls, marker="o", ms=3, color=color, label=lab)
                if test == "wilcoxon":  # the band of its exact interval
                    lo, hi = [c[test]["lo"] for c in curve], [c[test]["hi"] for c in curve]
                    ax.fill_between(n, lo, hi, color=color, alpha=0.15, lw=0)
        ax.axhline(target, color="black", lw=0.8, ls=":", label=f"target power {target:g}")
        ns = [c["participants"] for p in summary["points"] for e in p["experiment2"] for c in e["curve"]]
        if ns and max(ns) > 20 * min(ns):
            ax.set_xscale("log")
        ax.set_xlabel("participants in experiment 2")
        ax.set_ylabel(f"power (α = {summary['targets']['alpha']:g})")
        ax.set_ylim(0, 1)
        ax.set_title("Experiment 2: power to detect the trust-aware advantage")
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
        return finish(fig, path, layout=False)


def plot_regret(summary: dict[str, Any], path=None):
    """Mean regret of the estimated policy (share of V*) per experiment-1 design, with its 95 %
    interval, and the regret target."""
    pts = summary["points"]
    target = summary["targets"]["relative_regret"]
    with figure(figsize=(5.6, 0.35 * len(pts) + 1.5)) as (fig, ax):
        for i, p in enumerate(pts):
            r = p["relative_regret"]
            if r["mean"] is None:
                continue
            lo = r["lo"] if r["lo"] is not None else r["mean"]
            hi = r["hi"] if r["hi"] is not None else r["mean"]
            err = [[100 * (r["mean"] - lo)], [100 * (hi - r["mean"])]]
            ax.errorbar(100 * r["mean"], i, xerr=err, fmt="o", color=COLORS["high"], capsize=3)
        ax.axvline(100 * target, color="black", lw=0.8, ls=":", label=f"target {100 * target:g} % of V*")
        ax.set_yticks(range(len(pts)), [_label(p) for p in pts])
        ax.set_xlabel("regret of the estimated policy (% of V*, exact evaluation under the true model)")
        ax.set_title("Experiment 1: how close the estimated policy is to the optimal one")
        ax.legend(loc="lower right", frameon=False)
        return finish(fig, path, layout=False)


def plot_ask_search(search: dict[str, Any], path=None):
    """Mean regret (share of V*) of every (ask_low, ask_high) of the search, as a heat map, with
    the best and the paper's choice marked."""
    rows = search["rows"]
    lows = sorted({r["ask_low"] for r in rows})
    highs = sorted({r["ask_high"] for r in rows})
    grid = np.full((len(highs), len(lows)), np.nan)
    for r in rows:
        if r["relative_regret"] is not None:
            grid[highs.index(r["ask_high"]), lows.index(r["ask_low"])] = 100 * r["relative_regret"]
    with figure(figsize=(4.8, 3.6)) as (fig, ax):
        im = ax.imshow(grid, origin="lower", cmap="viridis_r", aspect="auto")
        ax.set_xticks(range(len(lows)), [f"{v:.2f}" for v in lows])
        ax.set_yticks(range(len(highs)), [f"{v:.2f}" for v in highs])
        ax.set_xlabel("P(ask | low complexity) in experiment 1")
        ax.set_ylabel("P(ask | high complexity)")
        for key, marker, lab in (("best", "*", "best"), ("paper", "s", "paper (0.10 / 0.40)")):
            x, y = lows.index(search[key]["ask_low"]), highs.index(search[key]["ask_high"])
            ax.plot(x, y, marker=marker, color="white", mec="black", ms=11, ls="", label=lab)
        fig.colorbar(im, ax=ax, label="mean regret (% of V*)")
        ax.grid(False)
        ax.legend(loc="upper left", bbox_to_anchor=(1.35, 1.0), frameon=False)
        b = search["budget"]
        ax.set_title(f"Data collection: {b['participants']} × {b['trials']} trials")
        return finish(fig, path, layout=False)
