"""The HTML reports: the reproduction's (one self-contained HTML file, the PNG figures,
summary.json and the data) and the design study's (the targets and the smallest design that
meets them, the power and regret tables, the data-collection search and the figures).

Each page embeds its figures as base64 PNG and its styles inline, so it reads offline and can be
mailed as a single file; both format their numbers with the same functions (:func:`fmt`,
:func:`pct`, :func:`iv`, :func:`stat`).
"""

from __future__ import annotations

import base64
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from jinja2 import Environment, FileSystemLoader, StrictUndefined

from .data.trials import write_csv
from .design.sweep import participants_needed
from .model.presets import paper_model, paper_task
from .reproduction import AGNOSTIC, AWARE, PAPER, Reproduction, write_summary
from .reproduction.comparison import floored
from .version import __version__

__all__ = ["FIGURES", "fmt", "iv", "pct", "render_html", "stat", "write_design_report", "write_report"]

TEMPLATES = Path(__file__).resolve().parent / "templates"

FIGURES = [
    # file, section, caption
    ("fig4_emissions.png", "fit", "Fig. 4 equivalent: fitted P(o | T, C, a), with the paper's values as markers."),
    ("fig5_6_transitions.png", "fit", "Figs. 5–6 equivalent: fitted P(T' | T, E', C, a), with the paper's values as markers."),
    ("fig7_q.png", "plan", "Fig. 7 equivalent: Q(b, C, a) of the fitted model's belief MDP; the dotted line is the threshold."),
    (
        "fig8_rewards.png",
        "experiment2",
        "Fig. 8 equivalent: cumulative reward per block and policy; (a) the paper-sized experiment, lines join each "
        "participant's two blocks; (b) the large-N experiment. Diamonds: the paper's medians.",
    ),
    (
        "replicates.png",
        "replicates",
        "Distributions over replicate experiments of the estimated threshold and of the aware − agnostic reward difference.",
    ),
    (
        "sensitivity_tornado.png",
        "sensitivity",
        "The threshold in high complexity when each printed parameter moves alone by ± half a unit of its last "
        "printed decimal (bars, the 12 largest effects), and jointly (grey band); the dashed line is the paper's ≈ 0.75.",
    ),
    (
        "scheduling.png",
        "scheduling",
        "Trial scheduling under the paper's model: which item the optimal schedule collects at each trial and when it "
        "asks, against the belief, compared with the paper's random order and its trust-aware policy.",
    ),
    (
        "types.png",
        "types",
        "Remark 1 with supervisor types: mean cumulative reward per block of each policy per type on the same simulated "
        "people (left, 95 % intervals), and the paired gain of the type-aware policy over the pooled trust-aware one per "
        "type, population and block length (right).",
    ),
    ("policies.png", "costs", "Mean cumulative reward per block of each policy on the same simulated participants."),
    (
        "remark1.png",
        "remark1",
        "Remark 1: heterogeneous supervisors by quartile of conservativeness, under the pooled trust-aware and "
        "trust-agnostic policies.",
    ),
]


def fmt(v: Any) -> str:
    """Numbers for tables: integers plainly, others with 3 significant decimals; the numerical
    floor of a probability (1e-12) shows as 0, and one minus it as 1."""
    if v is None:
        return "–"
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, (int, np.integer)):
        return f"{v:,}"
    if isinstance(v, (float, np.floating)):
        x = floored(float(v))
        if not np.isfinite(x):
            return "–"
        if x.is_integer() and abs(x) < 1e6:
            return f"{int(x)}"
        if abs(x) >= 100:
            return f"{x:.1f}"
        return f"{x:.3g}" if abs(x) < 0.01 else f"{x:.3f}".rstrip("0").rstrip(".") if abs(x) < 1 else f"{x:.2f}"
    return str(v)


def pct(v: Any) -> str:
    """A share as a percentage, its number as :func:`fmt` writes it: 0.6 as "60 %", 0.0123 as "1.23 %"
    (– for none or a non-finite share)."""
    text = fmt(None if v is None else 100 * float(v))
    return text if text == "–" else f"{text} %"


def iv(d: dict[str, Any], spec: str = ".3f", scale: float = 1.0, unit: str = "") -> str:
    """``mean [lo, hi]`` (the mean alone without an interval, – without a mean), each ``scale`` times, as ``spec``."""
    if d.get("mean") is None:
        return "–"
    mean = f"{scale * d['mean']:{spec}}{unit}"
    return mean if d.get("lo") is None else f"{mean} [{scale * d['lo']:{spec}}, {scale * d['hi']:{spec}}]"


def stat(v: Any) -> str:
    """One format for every test statistic and p-value: 3 significant digits."""
    return "–" if v is None else f"{float(v):.3g}"


def make_figures(rep: Reproduction, out: Path) -> list[Path]:
    """Write the PNG figures into ``out``; returns their paths."""
    from .plots.model import plot_emissions, plot_transitions
    from .plots.q import plot_q
    from .plots.rewards import plot_heterogeneity, plot_policy_values, plot_replicates, plot_rewards
    from .plots.scheduling import plot_scheduling_section
    from .plots.sensitivity import plot_tornado
    from .plots.type_comparison import plot_types_section

    paths: list[Path] = []

    def draw(file: str, plot: Callable[..., Any], *args: Any, **kwargs: Any) -> None:
        paths.append(out / file)
        plot(*args, path=paths[-1], **kwargs)

    s = rep.summary
    paper = paper_model()
    ci = getattr(rep.fit, "ci", None)
    draw("fig4_emissions.png", plot_emissions, rep.fitted, ci=ci, reference=paper)
    asked = paper_task().ask_experience
    draw("fig5_6_transitions.png", plot_transitions, rep.fitted, ci=ci, reference=paper, ask_experience=asked)
    title = f"Action-value functions of the fitted model (belief update: {rep.aware.belief_update})"
    draw("fig7_q.png", plot_q, rep.aware, title=title)
    medians = {AWARE: PAPER["median_aware"], AGNOSTIC: PAPER["median_agnostic"]}
    draw("fig8_rewards.png", plot_rewards, rep.experiment2.by_policy(), rep.experiment2_large.by_policy(), paper_medians=medians)
    r = s["replicates"]
    draw(
        "replicates.png",
        plot_replicates,
        [np.nan if v is None else v for v in r["threshold"]["values"]],
        r["median_diff_small"]["values"],
        r["mean_diff_large"]["values"],
        paper_threshold=PAPER["threshold_high"],
        true_threshold=s["plan"]["true_model"]["thresholds"]["high"],
        paper_difference=PAPER["median_aware"] - PAPER["median_agnostic"],
        design=f"{s['config']['participants_1']} × {sum(s['config']['counts_1'])}",
    )
    if rep.sensitivity is not None:
        title = "Threshold in high complexity within the printed precision of the paper's parameters"
        quantity = s["threshold_sensitivity"]["quantity"]
        draw("sensitivity_tornado.png", plot_tornado, rep.sensitivity, quantity, paper_value=PAPER["threshold_high"], title=title)
    if rep.scheduling is not None:
        draw("scheduling.png", plot_scheduling_section, rep.scheduling)
    if rep.types is not None:
        draw("types.png", plot_types_section, rep.types.numbers)
    costs = s["costs"]
    title = f"{costs['participants']:,} simulated participants, one block of {costs['trials_per_block']} trials"
    draw("policies.png", plot_policy_values, costs["rows"], title=title)
    draw("remark1.png", plot_heterogeneity, s["heterogeneity"]["quartiles"])
    return paths


def _page(template: str, **context: Any) -> str:
    """``template`` rendered with ``context`` and the number formats every report shares."""
    env = Environment(loader=FileSystemLoader(str(TEMPLATES)), autoescape=True, undefined=StrictUndefined)
    return env.get_template(template).render(fmt=fmt, pct=pct, iv=iv, stat=stat, version=__version__, **context)


def _embedded(path: Path) -> str:
    return base64.b64encode(path.read_bytes()).decode("ascii")


def render_html(summary: dict, figure_dir: Path) -> str:
    """The report as one HTML string with every figure embedded."""
    figures = [
        {"file": file, "section": section, "caption": caption, "alt": caption.split(":")[0], "data": _embedded(figure_dir / file)}
        for file, section, caption in FIGURES
        if (figure_dir / file).exists()
    ]
    return _page("report.html.j2", s=summary, figures=figures)


def write_report(rep: Reproduction, out: str | Path) -> dict[str, Path]:
    """Write the report folder: report.html, the PNGs, summary.json, data and policies."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    make_figures(rep, out)
    write_summary(rep.summary, out / "summary.json")
    write_csv(rep.experiment1, out / "experiment1.csv")
    write_csv(rep.experiment2.trials(), out / "experiment2.csv")
    rep.fitted.save(out / "fitted_model.json")
    rep.aware.save(out / "policy_trust_aware.json")
    rep.agnostic.save(out / "policy_trust_agnostic.json")
    html = out / "report.html"
    html.write_text(render_html(rep.summary, out), encoding="utf-8")
    return {"html": html, "summary": out / "summary.json", "dir": out}


def write_design_report(summary: dict[str, Any], out: str | Path, search: dict[str, Any] | None = None) -> dict[str, Path]:
    """Write ``out``/design.html (figures embedded), the PNGs and design.json."""
    from .plots.design import plot_ask_search, plot_power, plot_regret

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    figures: list[tuple[str, Callable[..., Any], dict[str, Any], str]] = [
        (
            "power.png",
            plot_power,
            summary,
            "Power of experiment 2 against its participants (bands: exact 95 % intervals, Wilcoxon)",
        ),
        ("regret.png", plot_regret, summary, "Regret of the policy estimated from each experiment-1 design (95 % intervals)"),
    ]
    if search is not None:
        figures.append(("ask_search.png", plot_ask_search, search, "Mean regret by experiment 1's ask probabilities"))
    embedded = []
    for name, fn, data, caption in figures:
        fn(data, out / name)
        embedded.append({"caption": caption, "data": _embedded(out / name)})
    doc = {"design": summary, "ask_search": search}
    (out / "design.json").write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    html = _page("design.html.j2", s=summary, search=search, figures=embedded, needed=participants_needed)
    (out / "design.html").write_text(html, encoding="utf-8")
    return {"html": out / "design.html", "json": out / "design.json", "dir": out}
