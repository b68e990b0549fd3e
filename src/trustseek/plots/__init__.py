"""Figures in the style of the paper (matplotlib, Agg backend, no display needed).

``style()`` is the shared look: serif fonts, thin axes, the paper's two colours.
Each figure lives in its own module: ``q`` (Fig. 7).
"""

from __future__ import annotations

import contextlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

COLORS = {"autonomous": "#1f5fa8", "ask": "#c8102e", "low": "#c8102e", "high": "#1f5fa8"}

RC = {
    "font.family": "serif",
    "font.serif": ["DejaVu Serif"],
    "font.size": 9,
    "axes.titlesize": 9,
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
def style():
    with plt.rc_context(RC):
        yield plt


def save(fig, path) -> None:
    fig.savefig(path)
    plt.close(fig)
