"""The paper next to the reproduction: every number it reports, ours, an interval and a verdict.

:func:`param_specs` lists the trust-model cells of Figs. 4-6 with the paper's values;
:func:`comparison_rows` builds the table of the report from a summary; :func:`disagreements`
says in words where the two differ.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from ..model.core import ASK, AUTONOMOUS, FAULTY, INTERVENE, RELIABLE, RELY, TrustModel
from .config import AGNOSTIC, AWARE, HIGH, LOW, PAPER


class ParamSpec(NamedTuple):
    """One trust-model cell the paper reports: summary key, figure label, the paper's value,
    and where it lives in a :class:`TrustModel` (table name and cell index)."""

    key: str
    label: str
    paper: float
    table: str
    cell: tuple[int, ...]

    def value(self, model: TrustModel) -> float:
        """This cell of ``model``."""
        return float(getattr(model, self.table)[self.cell])


def param_specs() -> list[ParamSpec]:
    """The cells of Figs. 4-6 (initial trust, emissions, transitions), in the report's order."""
    A, K = AUTONOMOUS, ASK
    specs = [ParamSpec("initial_high", "P(T_1 = high)", 1.0, "initial", (1,))]
    for c, cn in ((LOW, "low"), (HIGH, "high")):
        for t, tn in ((0, "low"), (1, "high")):
            label = f"Fig. 4a  P(intervene | T={tn}, C={cn}, ask)"
            specs.append(ParamSpec(f"em_ask_{cn}_{tn}", label, 1.0, "emission", (c, K, t, INTERVENE)))
    for c, cn, fig, vals in ((LOW, "low", "4b", (0.98, 1.0)), (HIGH, "high", "4c", (0.46, 0.95))):
        for t, tn in ((0, "low"), (1, "high")):
            label = f"Fig. {fig}  P(rely | T={tn}, C={cn}, autonomous)"
            specs.append(ParamSpec(f"em_rely_{cn}_{tn}", label, vals[t], "emission", (c, A, t, RELY)))
    trans = [
        ("5a", LOW, A, RELIABLE, [("high", "high", 1.0), ("low", "low", 1.0)]),
        ("5b", LOW, A, FAULTY, [("high", "low", 0.39), ("low", "low", 0.99)]),
        ("5c", LOW, K, FAULTY, [("high", "high", 1.0), ("low", "low", 1.0)]),
        ("6a", HIGH, A, RELIABLE, [("high", "high", 1.0), ("low", "high", 1.0)]),
        ("6b", HIGH, A, FAULTY, [("high", "low", 1.0), ("low", "low", 0.7)]),
        ("6c", HIGH, K, RELIABLE, [("high", "high", 0.94), ("low", "high", 0.44)]),
    ]
    names = {"low": 0, "high": 1}
    an = {A: "autonomous", K: "ask"}
    en = {RELIABLE: "reliable", FAULTY: "faulty"}
    for fig, c, a, e, cells in trans:
        cn = "low" if c == LOW else "high"
        for fr, to, val in cells:
            label = f"Fig. {fig}  P(T'={to} | T={fr}, E'={en[e]}, C={cn}, {an[a]})"
            specs.append(ParamSpec(f"tr_{fig}_{fr}_{to}", label, val, "transition", (c, a, e, names[fr], names[to])))
    return specs


def param_values(model: TrustModel) -> dict[str, float]:
    """Every reported cell of ``model``, by summary key."""
    return {spec.key: spec.value(model) for spec in param_specs()}


def bootstrap_interval(fit: Any, spec: ParamSpec) -> tuple[float, float] | None:
    """The fit's bootstrap interval of one cell, or None when the fit has none."""
    ci = getattr(fit, "ci", None)
    if not ci:
        return None
    try:
        lo, hi = ci[spec.table]
        return float(np.asarray(lo)[spec.cell]), float(np.asarray(hi)[spec.cell])
    except (KeyError, IndexError, TypeError, ValueError):
        return None


def _inside(v: float, lo: float | None, hi: float | None, tol: float = 0.005) -> bool:
    return lo is not None and hi is not None and lo - tol <= v <= hi + tol


def _row(
    quantity: str,
    paper: float,
    ours: Any,
    interval: tuple[float | None, float | None] | None,
    kind: str,
    note: str = "",
) -> dict[str, Any]:
    if interval is None or interval[0] is None:
        verdict = "no interval"
    elif _inside(paper, *interval):
        verdict = "agrees"
    else:
        verdict = "DISAGREES"
    return {
        "quantity": quantity,
        "paper": paper,
        "ours": ours,
        "interval": list(interval) if interval else None,
        "interval_kind": kind,
        "verdict": verdict,
        "note": note,
    }


def comparison_rows(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """Every number the paper reports, next to ours and an interval, with a verdict."""
    rows = []
    fitted = summary["fit"]["values"]
    boot = summary["fit"].get("bootstrap_ci") or {}
    reps = summary["replicates"]["params"]
    cfg = summary["config"]
    design = f"{cfg['participants_1']} × {sum(cfg['counts_1'])}"
    for key, label, paper_val, _, _ in param_specs():
        rep = reps.get(key)
        interval = (rep["p2.5"], rep["p97.5"]) if rep and rep["n"] else None
        kind = "replicates 95%"
        if interval is None and key in boot:
            interval, kind = tuple(boot[key]), "bootstrap 95%"
        notes = []
        if interval is not None and interval[1] - interval[0] > 0.8:
            notes.append(f"not identified by a {design} sample (the range spans most of [0, 1])")
        if key in boot:
            notes.append(f"bootstrap 95% [{boot[key][0]:.3f}, {boot[key][1]:.3f}]")
        note = "; ".join(notes)
        rows.append(_row(label, paper_val, fitted[key], interval, kind, note))
    plan = summary["plan"]
    th = summary["replicates"]["threshold"]
    rows.append(
        _row(
            "Threshold on P(T=high), high complexity (ask below)",
            PAPER["threshold_high"],
            plan["fitted"]["thresholds"]["high"],
            (th["p2.5"], th["p97.5"]) if th["n"] else None,
            "replicates 95%",
            f"true model: {plan['true_model']['thresholds']['high']:.3f}",
        )
    )
    share_low = summary["replicates"]["share_never_ask_low"]
    rows.append(
        {
            "quantity": "Trust-aware policy never asks in low complexity",
            "paper": "never asks",
            "ours": "never asks" if not plan["fitted"]["ask_intervals"]["low"] else "asks somewhere",
            "interval": None,
            "interval_kind": "share of replicates",
            "note": f"{share_low:.0%} of replicates",
            "verdict": "agrees" if not plan["fitted"]["ask_intervals"]["low"] else "DISAGREES",
        }
    )
    agn = plan["agnostic"]["action"]
    rep_agn = summary["replicates"]["agnostic_share_paper"]
    for cn, pv in (("low", "autonomous"), ("high", "ask")):
        rows.append(
            {
                "quantity": f"Trust-agnostic policy, {cn} complexity",
                "paper": pv,
                "ours": agn[cn],
                "interval": None,
                "interval_kind": "share of replicates",
                "note": f"{rep_agn[cn]:.0%} of replicates choose {pv}",
                "verdict": "agrees" if agn[cn] == pv else "DISAGREES",
            }
        )
    small, large = summary["experiment2"]["small"], summary["experiment2"]["large"]
    rr = summary["replicates"]
    for key, pk, lab in (
        ("median_aware", "median_aware", "trust-aware"),
        ("median_agnostic", "median_agnostic", "trust-agnostic"),
    ):
        d = rr[key]
        rows.append(
            _row(
                f"Median cumulative reward, {lab} ({small['participants']} participants)",
                PAPER[pk],
                small[key],
                (d["p2.5"], d["p97.5"]) if d["n"] else None,
                "replicates 95%",
                f"{large['participants']:,} participants: {large[key]:g}",
            )
        )
    d = rr["median_diff_small"]
    rows.append(
        _row(
            "Median difference aware − agnostic",
            PAPER["median_aware"] - PAPER["median_agnostic"],
            small["median_difference"],
            (d["p2.5"], d["p97.5"]) if d["n"] else None,
            "replicates 95%",
            f"large N mean difference {large['mean_difference']:.2f} "
            f"[{large['mean_difference_ci'][0]:.2f}, {large['mean_difference_ci'][1]:.2f}]",
        )
    )
    rows.append(
        {
            "quantity": "Trust-aware better for most participants",
            "paper": "most (Fig. 8)",
            "ours": f"{large['share_aware_better']:.0%} of {large['participants']:,}",
            "interval": None,
            "interval_kind": "",
            "note": f"{large['share_tied']:.0%} tied; "
            f"{small['share_aware_better']:.0%} of {small['participants']} in the paper-sized run",
            "verdict": "agrees" if large["share_aware_better"] > 0.5 else "DISAGREES",
        }
    )
    aw = large["per_policy"][AWARE]["autonomous_collections"]["mean"]
    ag = large["per_policy"][AGNOSTIC]["autonomous_collections"]["mean"]
    rows.append(
        {
            "quantity": "More autonomous collections with the trust-aware policy",
            "paper": "more",
            "ours": f"{aw:.1f} vs {ag:.1f} per block",
            "interval": None,
            "interval_kind": "",
            "note": f"{large['participants']:,} participants",
            "verdict": "agrees" if aw > ag else "DISAGREES",
        }
    )
    return rows


def disagreements(rows: list[dict[str, Any]]) -> list[str]:
    """One sentence per row whose verdict is DISAGREES."""
    out = []
    for r in rows:
        if r["verdict"] == "DISAGREES":
            iv = r["interval"]
            ivs = f" ({r['interval_kind']}: [{iv[0]:.3g}, {iv[1]:.3g}])" if iv else ""
            out.append(f"{r['quantity']}: the paper reports {r['paper']}, the simulation gives {_fmt(r['ours'])}{ivs}.")
    return out


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.3g}"
    return str(v)
