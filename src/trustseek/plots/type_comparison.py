"""Supervisor types (Remark 1): reward per block of each policy per type, and the paired gain of
planning for types."""

from __future__ import annotations

from typing import Any

import numpy as np

from . import figure, finish

POLICY_COLORS = {
    "pooled trust-aware": "#1f5fa8",
    "type-aware (fitted types)": "#98df8a",
    "type-aware": "#2ca02c",
    "oracle (type known)": "#7f7f7f",
    "trust-agnostic": "#c8102e",
}


def _bars(ax, block: dict[str, Any], policies: list[str]) -> None:
    groups = block["groups"]
    width = 0.8 / len(policies)
    x = np.arange(len(groups))
    for j, p in enumerate(policies):
        vals = [g["reward"].get(p) for g in groups]
        means = np.array([v["mean"] if v else np.nan for v in vals])
        err = np.array([[v["mean"] - v["low"], v["high"] - v["mean"]] if v else [np.nan, np.nan] for v in vals]).T
        ax.bar(x + (j - (len(policies) - 1) / 2) * width, means, width, yerr=err, capsize=2, color=POLICY_COLORS.get(p), label=p,
               error_kw={"lw": 0.7})  # fmt: skip
    ax.set_xticks(x, [f"{g['group']}\n(n = {g['participants']})" for g in groups])
    ax.set_ylabel("cumulative reward per block")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_title(f"{block['population']}, {block['trials']} trials")


def plot_types_section(numbers: dict[str, Any], path=None):
    """The report section's figure (``numbers``: ``TypesSection.numbers``).  Left: mean reward
    per block of each policy, per type and overall, at the first block length on the mixture,
    with 95 % intervals.  Right: the paired differences from the pooled trust-aware policy of
    the type-aware policies (the true types, and the types fitted to the experiment-1 log), per
    type, population and block length.  Returns the figure (written to ``path``)."""
    pops = numbers["populations"]
    policies = list(POLICY_COLORS)
    with figure(1, 2, figsize=(7.4, 2.9), gridspec_kw={"width_ratios": [1.3, 1]}) as (fig, axes):
        _bars(axes[0], pops[0], policies)
        axes[0].legend(fontsize=6, loc="lower left", framealpha=0.9)
        ax = axes[1]
        labels = [f"{g['group']} · {b['population']} · {b['trials']}" for b in pops for g in b["groups"]]
        y = np.arange(len(labels))[::-1].astype(float)
        for policy, offset in (("type-aware", 0.15), ("type-aware (fitted types)", -0.15)):
            pts = []
            for block in pops:
                for g in block["groups"]:
                    pair = (policy, "pooled trust-aware")
                    d = next((d for d in g["differences"] if (d["policy"], d["against"]) == pair), None)
                    pts.append((d["mean"], d["low"], d["high"]) if d else (np.nan, np.nan, np.nan))
            m, lo, hi = (np.array(v) for v in zip(*pts, strict=True))
            ax.errorbar(m, y + offset, xerr=[m - lo, hi - m], fmt="o", color=POLICY_COLORS[policy], ms=3, capsize=2, lw=0.9,
                        label=policy)  # fmt: skip
        ax.legend(fontsize=6, loc="upper right")
        ax.axvline(0, color="k", lw=0.6)
        ax.set_yticks(y, labels, fontsize=6)
        ax.set_xlabel("difference from pooled trust-aware\n(reward per block, paired 95 % CI)")
        ax.set_title("gain of planning for types")
        return finish(fig, path)
