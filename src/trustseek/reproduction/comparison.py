"""The paper next to the reproduction: every number it reports, ours, an interval and a verdict.

:func:`param_specs` lists the trust-model cells of Figs. 4-6 with the paper's values;
:func:`comparison_rows` builds the table of the report from a summary; :func:`disagreements`
says in words where the two differ; :func:`judge` is the one rule every row's verdict follows
(:data:`RULES` in words, as the report states them).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from ..model.core import TrustModel
from ..vocab import ASK, AUTONOMOUS, FAULTY, INTERVENE, RELIABLE, RELY
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

    def interval(self, ci: dict[str, tuple[np.ndarray, np.ndarray]] | None) -> tuple[float, float] | None:
        """This cell's interval in a fit's bootstrap intervals ``ci`` (None without a bootstrap)."""
        if not ci:
            return None
        lo, hi = ci[self.table]
        return float(lo[self.cell]), float(hi[self.cell])


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


AGREES = "agrees"
DISAGREES = "disagrees"
NOT_TESTABLE = "not testable here"
DIRECTION_ONLY = "consistent only in direction"
#: every verdict, in the order the headline counts them
VERDICTS = (AGREES, DISAGREES, DIRECTION_ONLY, NOT_TESTABLE)
#: an interval of a probability wider than this says the design does not identify it
MAX_WIDTH = 0.5
#: the paper prints two decimals: a value within this of an interval's end counts as inside
TOLERANCE = 0.005

#: the rules of :func:`judge`, in words, as the report states them
RULES = (
    f"not testable here: the cell is fixed by design (not estimated), there is no interval, or a probability's "
    f"interval is wider than {MAX_WIDTH}, or its replicate experiments range more widely than that (the design does "
    "not identify it: a bootstrap interval of an estimate at 0 or 1 can collapse there however little the data say);",
    "disagrees: the paper's effect has one sign and ours the opposite one (whatever the interval), or the paper's "
    f"value lies outside the interval (by more than {TOLERANCE}, the paper's rounding) and ours is not on the same "
    "side of the reference;",
    "consistent only in direction: the paper's value lies outside the interval, but ours lies on the same side of "
    "the reference as the paper's (a difference of the same sign; a share on the same side of one half); or a "
    "qualitative claim holds for our estimate but the interval reaches the other side;",
    f"agrees: the paper's value lies inside the interval (within {TOLERANCE}), with the same sign as ours where a "
    "sign matters; or a qualitative claim holds over the whole interval.",
)


def _sign(x: float) -> int:
    return 1 if x > 0 else -1 if x < 0 else 0


def judge(
    paper: float | None,
    ours: float | None,
    interval: tuple[float | None, float | None] | list[float | None] | None,
    *,
    fixed: bool = False,
    max_width: float | None = None,
    reference: float | None = None,
    tol: float = TOLERANCE,
    replicates: tuple[float, float] | list[float] | None = None,
) -> tuple[str, str]:
    """The verdict of one row and the reason, by :data:`RULES`.

    ``paper`` is the paper's number, or None for a qualitative claim that the quantity lies
    above ``reference`` (such as "better for most participants": a share above one half);
    ``reference`` (e.g. 0 for a difference) gives the row a direction; ``max_width`` is the
    widest interval that still tests something (probabilities: :data:`MAX_WIDTH`); ``replicates``
    (min, max) of independent replicate experiments: wider than ``max_width``, the design does not
    identify the quantity whatever the interval (a bootstrap at a boundary estimate can collapse).
    """
    if fixed:
        return NOT_TESTABLE, "fixed by design, not estimated"
    if max_width is not None and replicates is not None and replicates[1] - replicates[0] > max_width:
        lo_r, hi_r = replicates
        return NOT_TESTABLE, f"not identified: the replicate experiments range over [{lo_r:.2f}, {hi_r:.2f}]"
    if interval is None or interval[0] is None or interval[1] is None:
        return NOT_TESTABLE, "no interval"
    lo, hi = float(interval[0]), float(interval[1])
    if max_width is not None and hi - lo > max_width:
        return NOT_TESTABLE, f"not identified: the interval is wider than {max_width:g}"
    if paper is None:
        if reference is None or ours is None:
            raise ValueError("a qualitative claim needs our value and a reference")
        if lo > reference:
            return AGREES, f"the whole interval lies above {reference:g}"
        if ours > reference:
            return DIRECTION_ONLY, f"our value lies above {reference:g}, the interval reaches below it"
        return DISAGREES, f"our value is not above {reference:g}"
    same_side = False
    if reference is not None and ours is not None:
        sp, so = _sign(paper - reference), _sign(ours - reference)
        if sp != 0 and so == -sp:
            return DISAGREES, "the sign is reversed"
        same_side = sp != 0 and so == sp
    if lo - tol <= paper <= hi + tol:
        return AGREES, "the paper's value lies inside the interval"
    if same_side:
        return DIRECTION_ONLY, "same sign as the paper's, but the paper's value lies outside the interval"
    return DISAGREES, "the paper's value lies outside the interval"


def _row(
    quantity: str,
    paper: Any,
    ours: Any,
    interval: tuple[float | None, float | None] | None,
    kind: str,
    note: str = "",
    verdict: tuple[str, str] | None = None,
    **rule: Any,
) -> dict[str, Any]:
    if verdict is None:
        verdict = judge(paper if isinstance(paper, (int, float)) else None, ours, interval, **rule)
    return {
        "quantity": quantity,
        "paper": paper,
        "ours": ours,
        "interval": list(interval) if interval else None,
        "interval_kind": kind,
        "verdict": verdict[0],
        "reason": verdict[1],
        "note": note,
    }


def _categorical(quantity: str, paper: str, ours: str, note: str) -> dict[str, Any]:
    v = (AGREES, "the same action") if ours == paper else (DISAGREES, "a different action")
    return _row(quantity, paper, ours, None, "", note, verdict=v)


def _replicate_range(d: dict[str, Any] | None) -> tuple[float | None, float | None] | None:
    return (d["min"], d["max"]) if d and d.get("n") else None


def _replicates_kind(summary: dict[str, Any]) -> str:
    """The kind of interval the replicate experiments give."""
    return f"range of {summary['replicates']['n']} replicates (min–max)"


def comparison_rows(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """Every number the paper reports, next to ours and an interval, with a verdict (:func:`judge`).

    The parameter rows test whether the estimator is consistent: the simulated supervisors
    *are* the paper's model, so the paper's values are the truth the fit should recover."""
    return [*_parameter_rows(summary), *_policy_rows(summary), *_experiment2_rows(summary)]


def _parameter_rows(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """The fitted model's cells against the paper's, with the bootstrap or the replicates' range."""
    rows = []
    fitted = summary["fit"]["values"]
    boot = summary["fit"].get("bootstrap_ci") or {}
    fixed = set(summary["fit"].get("fixed") or ())
    reps = summary["replicates"]["params"]
    rep_kind = _replicates_kind(summary)
    n_boot = summary["fit"].get("bootstrap", 0)
    for key, label, paper_val, _, _ in param_specs():
        rep_range = _replicate_range(reps.get(key))
        note = ""
        interval: tuple[float | None, float | None] | None
        if key in fixed:
            interval, kind = None, ""
        elif key in boot:
            interval, kind = tuple(boot[key]), f"bootstrap 95% ({n_boot} resamples)"
            if rep_range is not None:
                note = f"{rep_kind}: [{rep_range[0]:.3f}, {rep_range[1]:.3f}]"
        else:
            interval, kind = rep_range, rep_kind
        row = _row(
            label, paper_val, fitted[key], interval, kind, note, fixed=key in fixed, max_width=MAX_WIDTH, replicates=rep_range
        )
        row["replicate_range"] = list(rep_range) if rep_range is not None else None
        rows.append(row)
    return rows


def _policy_rows(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """The planned policies: the threshold, its sensitivity, where each policy asks."""
    rows = []
    rep_kind = _replicates_kind(summary)
    plan = summary["plan"]
    th = summary["replicates"]["threshold"]
    rows.append(
        _row(
            "Threshold on P(T=high), high complexity (ask below)",
            PAPER["threshold_high"],
            plan["fitted"]["thresholds"]["high"],
            _replicate_range(th),
            rep_kind,
            f"printed (true) model: {plan['true_model']['thresholds']['high']:.4f}",
            max_width=MAX_WIDTH,
        )
    )
    sens = summary.get("threshold_sensitivity")
    if sens:
        rows.append(
            _row(
                "Threshold of the printed parameters, high complexity",
                PAPER["threshold_high"],
                sens["nominal"],
                tuple(sens["range"]),
                "range under the printed precision (±0.005 each, jointly)",
                "see 'Why 0.78 and not 0.75'",
            )
        )
    share_low = summary["replicates"]["share_never_ask_low"]
    never = not plan["fitted"]["ask_intervals"]["low"]
    rows.append(
        _categorical(
            "Trust-aware policy never asks in low complexity",
            "never asks",
            "never asks" if never else "asks somewhere",
            f"{share_low:.0%} of replicates never ask",
        )
    )
    agn = plan["agnostic"]["action"]
    rep_agn = summary["replicates"]["agnostic_share_paper"]
    for cn, pv in (("low", "autonomous"), ("high", "ask")):
        rows.append(
            _categorical(f"Trust-agnostic policy, {cn} complexity", pv, agn[cn], f"{rep_agn[cn]:.0%} of replicates choose {pv}")
        )
    return rows


def _experiment2_rows(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """Experiment 2: the medians, their difference, the share better off, the autonomous collections."""
    rows = []
    rep_kind = _replicates_kind(summary)
    small, large = summary["experiment2"]["small"], summary["experiment2"]["large"]
    rr = summary["replicates"]
    rr_large = summary["config"]["replicate_large_n"]
    for key, lab in (("median_aware", "trust-aware"), ("median_agnostic", "trust-agnostic")):
        rows.append(
            _row(
                f"Median cumulative reward, {lab} ({small['participants']} participants)",
                PAPER[key],
                small[key],
                _replicate_range(rr[key]),
                rep_kind,
                f"{large['participants']:,} participants: {large[key]:g}",
            )
        )
    lo, hi = large["mean_difference_ci"]
    rows.append(
        _row(
            f"Median difference aware − agnostic ({small['participants']} participants)",
            PAPER["median_aware"] - PAPER["median_agnostic"],
            small["median_difference"],
            _replicate_range(rr["median_diff_small"]),
            rep_kind,
            f"{large['participants']:,} participants: mean difference {large['mean_difference']:.2f} [{lo:.2f}, {hi:.2f}]",
            reference=0.0,
        )
    )
    share_rep = _replicate_range(rr.get("share_better_large"))
    share_ci = large.get("share_aware_better_ci")
    share_iv: tuple[float | None, float | None] | None
    if share_rep is not None:
        share_iv, share_kind = share_rep, f"{rep_kind}, {rr_large:,} participants each"
        share_note = f"this run's exact binomial 95%: [{share_ci[0]:.3f}, {share_ci[1]:.3f}]; " if share_ci else ""
    else:
        share_iv, share_kind = ((share_ci[0], share_ci[1]) if share_ci else None), "exact binomial 95%"
        share_note = ""
    rows.append(
        _row(
            f"Trust-aware better for most participants ({large['participants']:,} participants)",
            "most (Fig. 8)",
            large["share_aware_better"],
            share_iv,
            share_kind,
            share_note + f"{large['share_tied']:.0%} tied; {small['share_aware_better']:.0%} of {small['participants']} "
            "in the paper-sized run",
            reference=0.5,
        )
    )
    aw = large["per_policy"][AWARE]["autonomous_collections"]["mean"]
    ag = large["per_policy"][AGNOSTIC]["autonomous_collections"]["mean"]
    dci = large.get("autonomous_difference_ci")
    rows.append(
        _row(
            "More autonomous collections with the trust-aware policy (difference per block)",
            "more",
            aw - ag,
            tuple(dci) if dci else None,
            f"t 95% ({large['participants']:,} participants)",
            f"{aw:.1f} vs {ag:.1f} per block",
            reference=0.0,
        )
    )
    return rows


def verdict_counts(rows: list[dict[str, Any]]) -> dict[str, int]:
    """How many rows carry each verdict, in the order of :data:`VERDICTS`."""
    return {v: sum(r["verdict"] == v for r in rows) for v in VERDICTS}


def disagreements(rows: list[dict[str, Any]]) -> list[str]:
    """One sentence per row whose verdict is "disagrees"."""
    out = []
    for r in rows:
        if r["verdict"] == DISAGREES:
            iv = r["interval"]
            ivs = f" ({r['interval_kind']}: [{_fmt(iv[0])}, {_fmt(iv[1])}])" if iv else ""
            ours = _fmt(r["ours"])
            out.append(f"{r['quantity']}: the paper reports {r['paper']}, the simulation gives {ours}{ivs}: {r['reason']}.")
    return out


#: a probability this close to 0 or 1 is the estimator's numerical floor (1e-12), not a value
FLOOR = 1e-9


def floored(x: float) -> float:
    """``x``, or 0 or 1 where it lies within :data:`FLOOR` of it."""
    if abs(x) < FLOOR:
        return 0.0
    if 0 < 1 - x < FLOOR:
        return 1.0
    return x


def _fmt(v: Any) -> str:
    return f"{floored(v):.3g}" if isinstance(v, float) else str(v)
