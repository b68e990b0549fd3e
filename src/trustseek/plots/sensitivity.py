"""The tornado plot of a sensitivity analysis: each parameter's one-at-a-time swing of a quantity,
largest first, with the joint range over the whole box."""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.patches import Patch

from . import COLORS, figure, finish


def plot_tornado(res: Any, quantity: str, path=None, top: int = 12, paper_value: float | None = None, title: str | None = None):
    """One bar per parameter from ``quantity`` at the lower to ``quantity`` at the upper end of its box
    (``res`` is a :class:`~trustseek.solvers.sensitivity.Sensitivity`); the ``top`` largest swings,
    the printed-value line, the joint range as a shaded band and ``paper_value`` as a dashed line."""
    rows = [r for r in res.one_at_a_time if np.isfinite(r["at_lower"][quantity]) and np.isfinite(r["at_upper"][quantity])]
    rows = sorted(rows, key=lambda r: -abs(r["at_upper"][quantity] - r["at_lower"][quantity]))[:top][::-1]
    nominal = res.nominal[quantity]
    lo, hi = res.range_of(quantity)
    with figure(figsize=(6.4, 0.32 * len(rows) + 1.4)) as (fig, ax):
        ax.axvspan(lo, hi, color="0.85", alpha=0.6, lw=0, label=f"joint range [{lo:.3f}, {hi:.3f}]")
        for i, r in enumerate(rows):
            a, b = r["at_lower"][quantity], r["at_upper"][quantity]
            ax.barh(i, a - nominal, left=nominal, color=COLORS["low"], alpha=0.75, height=0.6)
            ax.barh(i, b - nominal, left=nominal, color=COLORS["high"], alpha=0.75, height=0.6)
        ax.set_yticks(range(len(rows)), [f"{r['name']}  ({r['value']:.3g})" for r in rows])
        ax.axvline(nominal, color="black", lw=0.9, label=f"printed values: {nominal:.4f}")
        if paper_value is not None:
            ax.axvline(paper_value, color="black", lw=1.0, ls="--", label=f"paper: {paper_value:g}")
        handles, _ = ax.get_legend_handles_labels()
        handles += [
            Patch(color=COLORS["low"], alpha=0.75, label="parameter at its lower end"),
            Patch(color=COLORS["high"], alpha=0.75, label="parameter at its upper end"),
        ]
        ax.set_xlabel(quantity)
        ax.grid(axis="y", visible=False)
        ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
        ax.set_title(title or f"{quantity}: each parameter within its printed precision, alone")
        return finish(fig, path, layout=False)
