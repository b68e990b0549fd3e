"""Figures in the style of the paper (matplotlib, Agg backend, no display needed).

``figure()`` makes a figure in the shared look (serif fonts, thin axes, the paper's two colours).
Each family of figures lives in its own module: ``model`` (Figs. 4-6, the fitted trust
model), ``q`` (Fig. 7, the belief MDP's Q-values), ``rewards`` (Fig. 8 and the replicate,
policy-comparison and heterogeneity figures).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

if TYPE_CHECKING:
    from matplotlib.typing import RcKeyType

COLORS = {"autonomous": "#1f5fa8", "ask": "#c8102e", "low": "#c8102e", "high": "#1f5fa8"}

RC: dict[RcKeyType, Any] = {
    "font.family": "serif",
    "font.serif": ["DejaVu Serif"],
    "font.size": 9,
    "axes.titlesize": 9,
    "figure.titlesize": 9,
    "axes.labelsize": 9,
    "legend.fontsize": 8,
    "xtick.labelsize": 8,
    "ytick.labelsize": 8,
    "axes.linewidth": 0.7,
    "lines.linewidth": 1.4,
    "axes.grid": True,
    "grid.alpha": 0.25,
    "grid.linewidth": 0.5,
    "figure.dpi": 150,
    "savefig.bbox": "tight",
    "mathtext.fontset": "dejavuserif",
}


@contextlib.contextmanager
def figure(*args: Any, **kwargs: Any) -> Iterator[Any]:
    """``(fig, axes)`` of ``plt.subplots(*args, **kwargs)`` drawn with the paper's look (restored on exit)."""
    with plt.rc_context(RC):
        yield plt.subplots(*args, **kwargs)


def legend_below(fig, ax, fontsize: float = 7, y: float = -0.01) -> None:
    """The legend of ``ax`` in one row below the panels (the layout leaves it room: ``finish(..., rect=(0, 0.07, 1, 1))``)."""
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), frameon=False, fontsize=fontsize, bbox_to_anchor=(0.5, y))


def finish(fig, path=None, title: str | None = None, rect: tuple[float, float, float, float] | None = None, layout: bool = True):
    """A figure's common tail: its ``title`` (``suptitle``), the tight layout (within ``rect``;
    none when not ``layout``), saved to ``path`` when one is given; returns the figure."""
    if title:
        fig.suptitle(title)
    if layout:
        fig.tight_layout(rect=rect)
    if path is not None:
        fig.savefig(path)
        plt.close(fig)
    return fig
