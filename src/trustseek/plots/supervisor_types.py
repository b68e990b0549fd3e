"""Supervisor types: the fitted types' trust models side by side, in the style of Figs. 4-6.

:func:`plot_type_emissions` draws P(rely | T, C, a = autonomous) with one bar per (type,
level); :func:`plot_types` writes that overview and, per type, the emission and
transition figures of :mod:`.model` (with the bootstrap intervals of each type when given).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..vocab import AUTONOMOUS, RELY
from . import figure, finish, legend_below
from .model import _bars, plot_emissions, plot_transitions


def plot_type_emissions(mixture, path=None, ci=None):
    """P(rely | T, C, autonomous) per complexity and trust level, one bar per type (legend: weight)."""
    m0 = mixture.models[0]
    C, T = m0.complexities, m0.trust_levels
    groups = [(c, t) for c in range(len(C)) for t in range(len(T))]
    vals = np.array([[m.emission[c, AUTONOMOUS, t, RELY] for m in mixture.models] for c, t in groups])
    lo = hi = None
    if ci is not None:
        lo = np.array([[ci[n]["emission"][0][c, AUTONOMOUS, t, RELY] for n in mixture.names] for c, t in groups])
        hi = np.array([[ci[n]["emission"][1][c, AUTONOMOUS, t, RELY] for n in mixture.names] for c, t in groups])
    series = [f"{n} ({w:.0%})" for n, w in zip(mixture.names, mixture.weights, strict=True)]
    with figure(figsize=(4.8, 2.6)) as (fig, ax):
        _bars(ax, vals, lo, hi, None, [f"C={C[c]}\nT={T[t]}" for c, t in groups], series)
        ax.set_ylabel(r"$P(o = \mathrm{rely} \mid T, C, a = \mathrm{autonomous})$")
        ax.set_title("Supervisor types: probability of relying" + (" (95% CI)" if ci is not None else ""))
        legend_below(fig, ax)
        return finish(fig, path, rect=(0, 0.07, 1, 1))


def plot_types(mixture, folder, ci=None) -> list[Path]:
    """``types.png`` and ``emissions_<type>.png``, ``transitions_<type>.png`` per type into ``folder``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    written = [folder / "types.png"]
    plot_type_emissions(mixture, written[0], ci)
    for name, model in zip(mixture.names, mixture.models, strict=True):
        c = None if ci is None else ci[name]
        for kind, draw in (("emissions", plot_emissions), ("transitions", plot_transitions)):
            path = folder / f"{kind}_{name}.png"
            draw(model, path, ci=c)
            written.append(path)
    return written
