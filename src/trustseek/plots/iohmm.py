"""A general model's tables (a :class:`~trustseek.model.TrustModel` with named inputs) by input combination.

Emissions: P(output = its last category | level, emission inputs), one group of bars per
combination of the emission inputs' levels, one bar per level.  Transitions: P(next level
= the highest | level, transition inputs), one group per combination of the transition
inputs' levels.  The inputs' levels keep their declared order; rows the data never
reached are drawn as the fit left them (the model file holds them too).
"""

from __future__ import annotations

import numpy as np

from ..model.core import TrustModel
from . import figure, finish
from .model import _bars


def _labels(model: TrustModel, table: str, n: int) -> list[str]:
    return ["\n".join(f"{c}={v}" for c, v in model.combination(table, u).items()) or "(all trials)" for u in range(n)]


def plot_iohmm_emissions(model: TrustModel, path=None):
    """P(output = last category | level, emission inputs), by combination of the inputs."""
    return _plot_table(model, "emission", path)


def plot_iohmm_transitions(model: TrustModel, path=None):
    """P(next level = the highest | level, transition inputs), by combination of the inputs."""
    return _plot_table(model, "transition", path)


def _plot_table(model: TrustModel, table: str, path):
    """Bars of one probability per (combination of the table's inputs, level)."""
    if table == "emission":
        cat, inputs = model.output_categories[-1], model.emission_inputs
        vals = model.emission_rows[:, :, -1]
        ylabel, title = f"P({model.output} = {cat} | S, inputs)", f"Estimated P({cat})"
    else:
        top, inputs = model.levels[-1], model.transition_inputs
        vals = np.asarray(model.transition_rows[:, :, -1])
        ylabel, title = f"P(S' = {top} | S, inputs)", f"Estimated P(S' = {top})"
    title += f" by {', '.join(inputs) or 'level only'}"
    with figure(figsize=(max(4.6, 1.3 * len(vals) + 1.5), 2.8)) as (fig, ax):
        _bars(ax, vals, None, None, None, _labels(model, table, len(vals)), [f"S={k}" for k in model.levels])
        ax.set_ylabel(ylabel)
        ax.set_title(title)
        ax.set_ylim(0, 1.25)  # room for the legend above the bars
        ax.legend(loc="upper left", frameon=False, ncol=model.n_levels)
        return finish(fig, path)
