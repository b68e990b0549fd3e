"""The HTML page of a design study: the targets and the smallest design that meets them, the
power and regret tables, the data-collection search and the figures, in one self-contained file."""

from __future__ import annotations

import base64
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from jinja2 import Environment, FileSystemLoader, StrictUndefined

from .design.sweep import participants_needed
from .version import __version__

__all__ = ["iv", "write_design_report"]

TEMPLATES = Path(__file__).parent / "templates"


def _fmt(v: Any) -> str:
    return "–" if v is None else (f"{v:.3f}" if isinstance(v, float) else str(v))


def _pct(v: Any) -> str:
    return "–" if v is None else f"{100 * v:.2f} %"


def iv(d: dict[str, Any], spec: str = ".3f", scale: float = 1.0, unit: str = "") -> str:
    """``mean [lo, hi]`` (the mean alone without an interval, – without a mean), each ``scale`` times, as ``spec``."""
    if d.get("mean") is None:
        return "–"
    mean = f"{scale * d['mean']:{spec}}{unit}"
    return mean if d.get("lo") is None else f"{mean} [{scale * d['lo']:{spec}}, {scale * d['hi']:{spec}}]"


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
        embedded.append({"caption": caption, "data": base64.b64encode((out / name).read_bytes()).decode("ascii")})
    doc = {"design": summary, "ask_search": search}
    (out / "design.json").write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    env = Environment(loader=FileSystemLoader(str(TEMPLATES)), autoescape=True, undefined=StrictUndefined)
    html = env.get_template("design.html.j2").render(
        s=summary, search=search, figures=embedded, fmt=_fmt, pct=_pct, iv=iv, needed=participants_needed, version=__version__
    )
    (out / "design.html").write_text(html, encoding="utf-8")
    return {"html": out / "design.html", "json": out / "design.json", "dir": out}
