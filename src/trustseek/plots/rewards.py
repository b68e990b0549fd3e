"""Fig. 8 (cumulative reward per policy) and the distributions over replicate experiments."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from . import COLORS, figure, finish

POLICY_COLORS = {"trust-agnostic": "#7f7f7f", "trust-aware": COLORS["autonomous"]}
PAPER_MARK = {"facecolor": "none", "edgecolor": COLORS["ask"], "linewidth": 1.0}  # a value the paper reports


def _box(ax, data: Sequence[np.ndarray], labels: Sequence[str], colors: Sequence[str], fliers: bool = True):
    bp = ax.boxplot(
        data,
        widths=0.5,
        patch_artist=True,
        showfliers=fliers,
        medianprops={"color": "black", "lw": 1.2},
        whiskerprops={"lw": 0.8},
        capprops={"lw": 0.8},
        flierprops={"marker": ".", "markersize": 2, "alpha": 0.3, "markeredgecolor": "0.4"},
    )
    ax.set_xticks(range(1, len(labels) + 1), labels)
    for patch, col in zip(bp["boxes"], colors, strict=True):
        patch.set_facecolor(col)
        patch.set_alpha(0.35)
        patch.set_edgecolor(col)
    return bp


def plot_rewards(
    small: Mapping[str, np.ndarray],
    large: Mapping[str, np.ndarray] | None = None,
    path=None,
    paper_medians: Mapping[str, float] | None = None,
    order: Sequence[str] = ("trust-agnostic", "trust-aware"),
):
    """Fig. 8: cumulative reward per participant and policy.

    ``small`` maps policy label -> per-participant rewards of the paper-sized experiment
    (drawn as boxes with each participant's pair joined by a line); ``large`` the same for the
    large-N experiment; ``paper_medians`` are drawn as diamonds.
    """
    order = [k for k in order if k in small] + [k for k in small if k not in order]
    cols = [POLICY_COLORS.get(k, COLORS["ask"]) for k in order]
    n_pan = 2 if large is not None else 1
    with figure(1, n_pan, figsize=(3.4 * n_pan, 2.8), squeeze=False) as (fig, axes):
        panels = [(axes[0, 0], small, True)]
        if large is not None:
            panels.append((axes[0, 1], large, False))
        for ax, vals, paired in panels:
            data = [np.asarray(vals[k], dtype=float) for k in order]
            n = len(data[0])
            _box(ax, data, [k.replace("trust-", "trust-\n") for k in order], cols, fliers=not paired)
            if paired:
                jit = np.linspace(-0.08, 0.08, n) if n > 1 else np.zeros(1)
                for i in range(n):
                    ys = [d[i] for d in data]
                    ax.plot(np.arange(1, len(order) + 1) + jit[i], ys, color="0.55", lw=0.6, zorder=1)
                for j, d in enumerate(data):
                    ax.scatter(np.full(n, j + 1) + jit, d, s=12, color=cols[j], edgecolor="black", linewidth=0.4, zorder=3)
            for j, d in enumerate(data):
                med = float(np.median(d))
                ax.annotate(f"{med:g}", xy=(j + 1.27, med), fontsize=7, va="center", color="black")
            for j, k in enumerate(order):
                if paper_medians and k in paper_medians:
                    ax.scatter([j + 1], [paper_medians[k]], marker="D", s=22, zorder=4, **PAPER_MARK)
            ax.set_ylabel("cumulative reward per block")
            ax.set_xlim(0.5, len(order) + 0.7)
            ax.set_title(f"{'(a)' if paired else '(b)'} {n:,} simulated participants")
        if paper_medians:
            from matplotlib.lines import Line2D

            handle = Line2D([], [], marker="D", ls="none", markersize=5, markerfacecolor="none", markeredgecolor=COLORS["ask"])
            median_line = Line2D([], [], color="black", lw=1.2)
            labels = ["median (simulation)", "median reported in the paper"]
            where = {"loc": "lower center", "bbox_to_anchor": (0.5, 0.0)}
            fig.legend([median_line, handle], labels, ncols=2, frameon=False, fontsize=7, **where)
        title = "Cumulative reward, 17 low + 17 high trials per block (Fig. 8)"
        return finish(fig, path, title, rect=(0, 0.06, 1, 1) if paper_medians else None)


def plot_replicates(
    thresholds: Sequence[float],
    diff_small: Sequence[float],
    diff_large: Sequence[float],
    path=None,
    paper_threshold: float = 0.75,
    true_threshold: float | None = None,
    paper_difference: float = 6.0,
    design: str = "9 × 71",
):
    """Distributions over replicate experiments: (a) the estimated ask threshold in high
    complexity; (b) the aware - agnostic reward difference (median difference of a
    paper-sized experiment, and mean difference over a large N)."""
    th = np.asarray([t for t in thresholds if t is not None and np.isfinite(t)], dtype=float)
    with figure(1, 2, figsize=(6.8, 2.6)) as (fig, axes):
        ax = axes[0]
        if len(th):
            lo = max(0.0, min(th.min(), paper_threshold) - 0.02)
            hi = min(1.0, max(th.max(), paper_threshold) + 0.02)
            ax.hist(th, bins=np.linspace(lo, hi, 21), color=COLORS["autonomous"], alpha=0.55, edgecolor="white", linewidth=0.5)
            ax.set_xlim(lo, hi)
        else:
            _no_data(ax, "no replicate has a threshold" if len(thresholds) else "no replicates were run")
        ax.axvline(paper_threshold, color=COLORS["ask"], ls="--", lw=1.0, label=f"paper ≈ {paper_threshold:g}")
        if true_threshold is not None:
            ax.axvline(true_threshold, color="black", ls=":", lw=1.0, label=f"true model {true_threshold:.3f}")
        ax.set_xlabel(r"threshold on $b^T$ in high complexity")
        ax.set_ylabel("replicates")
        missing = len(thresholds) - len(th)
        ax.set_title("(a) estimated threshold" + (f" ({missing} without one)" if missing else ""))
        ax.set_ylim(0, ax.get_ylim()[1] * 1.45)
        ax.legend(frameon=False, loc="upper left", ncols=2, fontsize=7)
        ax.yaxis.get_major_locator().set_params(integer=True)
        ax = axes[1]
        ds, dl = np.asarray(diff_small, dtype=float), np.asarray(diff_large, dtype=float)  # None: NaN
        if not (np.isfinite(ds).any() or np.isfinite(dl).any()):
            _no_data(ax, "no replicates were run")
        rows = [("large N:\nmean diff.", dl, COLORS["autonomous"]), ("5 participants:\nmedian diff.", ds, "0.45")]
        for y, (_, v, col) in enumerate(rows):
            v = v[np.isfinite(v)]
            if not len(v):
                continue
            ax.boxplot(
                [v],
                positions=[y],
                orientation="horizontal",
                widths=0.5,
                showfliers=False,
                patch_artist=True,
                boxprops={"facecolor": col, "alpha": 0.25, "edgecolor": col},
                medianprops={"color": "black"},
                whiskerprops={"lw": 0.8},
                capprops={"lw": 0.8},
            )
            jit = np.random.default_rng(0).uniform(-0.12, 0.12, len(v))
            ax.scatter(v, y + jit, s=10, color=col, edgecolor="black", linewidth=0.3, zorder=3)
        ax.axvline(paper_difference, color=COLORS["ask"], ls="--", lw=1.0, label=f"paper: {paper_difference:g} (57 − 51)")
        ax.axvline(0.0, color="black", lw=0.6)
        ax.set_yticks(range(len(rows)), [r[0] for r in rows])
        ax.set_ylim(-0.6, len(rows) - 0.4)
        ax.set_xlabel("aware − agnostic cumulative reward per block")
        ax.set_title("(b) reward difference")
        ax.grid(axis="y", visible=False)
        ax.legend(frameon=False, loc="lower left", fontsize=7)
        return finish(fig, path, f"{len(thresholds)} replicate experiments ({design} data collection, fit, plan, evaluation)")


def _no_data(ax, text: str) -> None:
    """Say in the panel why it has nothing to show."""
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", fontsize=8, color="0.3")


def plot_policy_values(rows: Sequence[Mapping], path=None, title: str | None = None):
    """Mean cumulative reward per block with 95% intervals, one bar per policy variant.

    ``rows``: dicts with ``label``, ``mean``, ``lo``, ``hi`` and optionally ``group``."""
    with figure(figsize=(5.6, 0.32 * len(rows) + 0.9)) as (fig, ax):
        y = np.arange(len(rows))[::-1]
        groups = sorted({r.get("group", "") for r in rows})
        palette = [COLORS["autonomous"], "#7f7f7f", COLORS["ask"], "#2a9d8f"]
        gcol = {g: palette[i % len(palette)] for i, g in enumerate(groups)}
        for yi, r in zip(y, rows, strict=True):
            col = gcol[r.get("group", "")]
            ax.barh(yi, r["mean"], color=col, alpha=0.45, height=0.62, edgecolor=col)
            ax.errorbar(r["mean"], yi, xerr=[[r["mean"] - r["lo"]], [r["hi"] - r["mean"]]], color="black", lw=0.8, capsize=2)
            ax.annotate(f"{r['mean']:.2f}", xy=(r["hi"], yi), xytext=(4, 0), textcoords="offset points", va="center", fontsize=7)
        ax.set_yticks(y, [r["label"] for r in rows])
        lo = min(r["lo"] for r in rows)
        hi = max(r["hi"] for r in rows)
        ax.set_xlim(min(0.0, lo - 0.08 * (hi - lo) - 1), hi + 0.15 * (hi - lo) + 1)
        ax.axvline(0.0, color="black", lw=0.6)
        ax.set_xlabel("mean cumulative reward per block (t 95% interval)")
        ax.grid(axis="y", visible=False)
        ax.set_title(title or "Policies evaluated on the same simulated participants")
        return finish(fig, path)


def plot_heterogeneity(quartiles: Sequence[Mapping], path=None):
    """Remark 1: mean reward and interventions per policy, by quartile of how conservative the
    simulated individuals are (1 = least)."""
    x = np.arange(len(quartiles))
    w = 0.36
    aware, agnostic = POLICY_COLORS["trust-aware"], POLICY_COLORS["trust-agnostic"]
    with figure(1, 2, figsize=(6.8, 2.5)) as (fig, (rewards, interventions)):
        # the rewards' levels lie close together: points, not bars on a cut axis
        va, vg = [r["mean_aware"] for r in quartiles], [r["mean_agnostic"] for r in quartiles]
        rewards.plot(x, vg, marker="s", ms=4, color=agnostic, label="trust-agnostic")
        rewards.plot(x, va, marker="o", ms=4, color=aware, label="trust-aware")
        pad = max(0.3, 0.3 * (max(va + vg) - min(va + vg)))
        rewards.set_ylim(min(va + vg) - pad, max(va + vg) + pad)
        rewards.legend(frameon=False, loc="upper right", fontsize=7)
        interventions.bar(x - w / 2, [r["interventions_agnostic"] for r in quartiles], w, color=agnostic, alpha=0.6)
        interventions.bar(x + w / 2, [r["interventions_aware"] for r in quartiles], w, color=aware, alpha=0.7)
        for ax, ylabel in ((rewards, "mean cumulative reward per block"), (interventions, "interventions per block")):
            ax.set_xticks(x, [f"Q{r['quartile']}" for r in quartiles])
            ax.set_xlabel("conservativeness quartile (Q4 = most)")
            ax.set_ylabel(ylabel)
            ax.grid(axis="x", visible=False)
        return finish(fig, path, "Heterogeneous supervisors under the pooled policies (Remark 1)")
