"""Fig. 7: the action-value functions Q(b, C, a) of the belief MDP."""

from __future__ import annotations

import numpy as np

from . import COLORS, figure, finish, legend_below


def plot_q(policy, path=None, title: str | None = None):
    """Q(b, C, a) for both actions, one panel per complexity, with the threshold marked.

    ``policy`` is a :class:`~trustseek.policy.TrustAwarePolicy`.  Returns the figure
    (closed and written to ``path`` when one is given).
    """
    thresholds = policy.thresholds()
    N = len(policy.complexities)
    with figure(1, N, figsize=(3.3 * N, 2.6), sharey=False, squeeze=False) as (fig, axes):
        for c, cn in enumerate(policy.complexities):
            ax = axes[0, c]
            ax.plot(policy.grid, policy.q[:, c, 0], color=COLORS["autonomous"], label="autonomous ($a^-$)")
            ax.plot(policy.grid, policy.q[:, c, 1], color=COLORS["ask"], ls="--", label="ask ($a^+$)")
            th = thresholds[cn]
            if th is not None and np.isfinite(th) and 0 < th < 1:
                ax.axvline(th, color="0.3", lw=0.8, ls=":")
                right = th > 0.6
                ax.annotate(
                    f"threshold {th:.3f}",
                    xy=(th, 0.04),
                    xycoords=("data", "axes fraction"),
                    xytext=(-4 if right else 4, 0),
                    textcoords="offset points",
                    ha="right" if right else "left",
                    fontsize=7,
                    color="0.25",
                )
            ax.set_xlim(0, 1)
            ax.set_xlabel(r"belief $b^T = P(T = \mathrm{high})$")
            ax.set_ylabel(r"$Q(b^T, C, a)$")
            ax.set_title(f"complexity {cn}")
        legend_below(fig, axes[0, 0], fontsize=8, y=-0.02)
        title = title or f"Action-value functions (belief update: {policy.belief_update})"
        return finish(fig, path, title, rect=(0, 0.07, 1, 1))
