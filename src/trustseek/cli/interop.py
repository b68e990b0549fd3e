"""Solver and file-format commands: export-pomdp, solve-pomdp-file; the certified solvers of ``solve``."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.table import Table

from ..errors import TrustseekError
from ..pomdp.problem import AssistancePOMDP
from ..model.presets import load_model, load_task
from ._app import app, console, print_json

SOLVERS = ("grid", "alpha", "point")
DEFAULT_GAP = {"alpha": 1e-6, "point": 1e-3}


def certified_policy(solver: str, pomdp: AssistancePOMDP, belief_update: str, gap: float | None = None):
    """Solve with the ``alpha`` or ``point`` solver; raises TrustseekError for unsupported cases."""
    if solver not in DEFAULT_GAP:
        raise TrustseekError([f"--solver must be one of {list(SOLVERS)}, got {solver!r}"])
    gap = DEFAULT_GAP[solver] if gap is None else gap
    if not gap > 0:
        raise TrustseekError([f"--gap must be positive, got {gap}"])
    if solver == "alpha":
        from ..solvers.alpha import AlphaSolver

        if pomdp.n_trust != 2:
            raise TrustseekError(
                [f"the alpha solver needs two trust levels; this model has {pomdp.n_trust}: use --solver point"]
            )
        return AlphaSolver(belief_update=belief_update, tol=gap).solve(pomdp)
    if solver == "point":
        from ..solvers.point import PointSolver

        if belief_update != "bayes":
            raise TrustseekError(
                [
                    "the point solver bounds the value of the Bayes filter (--belief-update bayes); "
                    "for the eq.-3 update use --solver alpha (two trust levels) or --solver grid"
                ]
            )
        return PointSolver(tol=gap).solve(pomdp)
    raise TrustseekError([f"--solver must be one of {list(SOLVERS)}, got {solver!r}"])


def certified_summary(policy, task) -> dict:
    """The JSON summary of a certified solve (any number of trust levels)."""
    from ..solvers.agnostic import trust_agnostic

    info = policy.info
    out = {
        "policy": "trust-aware",
        "solver": info.get("solver"),
        "belief_update": policy.belief_update,
        "certified_gap": info.get("certified_gap"),
        "value_bounds_at_initial_belief": info.get("value_bounds_at_initial_belief"),
        "initial_belief": dict(zip(policy.model.trust_levels, map(float, policy.model.initial))),
    }
    if policy.model.n_trust == 2:
        v1 = policy.q_values(1.0).max(axis=-1)
        out["thresholds"] = policy.thresholds()
        out["threshold_intervals"] = info.get("threshold_intervals")
        out["ask_intervals"] = {k: [list(iv) for iv in v] for k, v in policy.ask_intervals().items()}
        out["value_at_b1"] = {cn: float(v1[c]) for c, cn in enumerate(policy.complexities)}
    out["trust_agnostic"] = trust_agnostic(policy.model, task).to_dict()["p_ask"]
    out["info"] = {k: v for k, v in info.items() if k not in ("thresholds", "threshold_intervals")}
    return out


def report_certified(policy, task, out: Optional[Path], as_json: bool) -> None:
    """What ``trustseek solve --solver alpha|point`` prints."""
    summary = certified_summary(policy, task)
    if out is not None:
        policy.save(out)
        summary["policy_file"] = str(out)
    if as_json:
        print_json(summary)
        return
    info = policy.info
    title = f"Trust-aware policy ({summary['solver']} solver, belief update: {policy.belief_update})"
    if policy.model.n_trust == 2:
        table = Table(title=title, title_justify="left")
        for col in ("complexity", "asks when P(trust=high) in", "threshold", "certified interval", "V(b=1, C)"):
            table.add_column(col)
        intervals = summary.get("threshold_intervals") or {}
        for cn in policy.complexities:
            iv = summary["ask_intervals"][cn]
            ivs = ", ".join(f"[{lo:.6f}, {hi:.6f})" for lo, hi in iv) or "never asks"
            th = summary["thresholds"][cn]
            ci = intervals.get(cn)
            table.add_row(
                cn,
                ivs,
                "-" if th is None else f"{th:.6f}",
                "-" if not ci else f"[{ci[0]:.6f}, {ci[1]:.6f}]",
                f"{summary['value_at_b1'][cn]:.6f}",
            )
        console.print(table)
    else:
        console.print(f"{title}: {policy.describe()}")
    lo, hi = summary["value_bounds_at_initial_belief"]
    where = "over all beliefs" if summary["solver"] == "alpha" else "at the initial belief"
    console.print(
        f"V(b0) in [{lo:.6f}, {hi:.6f}]; certified gap {summary['certified_gap']:.2e} ({where}); "
        f"{info.get('method')}, {info['seconds'] * 1000:.1f} ms"
    )
    target = info.get("target_gap")
    if target is not None and summary["certified_gap"] > target:
        console.print(f"[yellow]the target gap {target:g} was not reached (time or size limit)[/]")
    if out is not None:
        console.print(f"policy written to {out}")


@app.command("export-pomdp", rich_help_panel="Files")
def export_pomdp(
    out: Path = typer.Argument(..., help="File to write: .pomdp (Cassandra) or .pomdpx (POMDPX)."),
    model: str = typer.Option("paper", "--model", "-m", help="Trust model: a preset name (paper) or a JSON file."),
    task: str = typer.Option("paper", "--task", "-t", help="Task: a preset name (paper) or a JSON file."),
    fmt: Optional[str] = typer.Option(None, "--format", help="pomdp or pomdpx (default: from the file suffix)."),
    initial_complexity: Optional[str] = typer.Option(
        None, "--initial-complexity", help="Start from this complexity instead of P(C) (.pomdp only)."
    ),
    verify: bool = typer.Option(False, "--verify", help="Also print finite-horizon values (1-3) of the file and of the belief MDP."),
) -> None:
    """Export the assistance POMDP to a standard file (state augmented with the last human action)."""
    from ..interop.files import export_assistance, flat_values_check

    m, t = load_model(model), load_task(task)
    pomdp = AssistancePOMDP(m, t)
    c0 = None
    if initial_complexity is not None:
        if initial_complexity not in t.complexities:
            raise TrustseekError([f"--initial-complexity must be one of {list(t.complexities)}, got {initial_complexity!r}"])
        c0 = t.complexities.index(initial_complexity)
    export_assistance(pomdp, out, fmt, c0)
    console.print(f"wrote {out}")
    if verify:
        if pomdp.n_trust != 2:
            raise TrustseekError(["--verify compares with the two-level alpha recursion; the model has more trust levels"])
        table = Table(title="Finite-horizon values from the initial belief", title_justify="left")
        for col in ("horizon", "complexity", "flat file", "belief MDP", "difference"):
            table.add_column(col, justify="right")
        for r in flat_values_check(pomdp):
            table.add_row(str(r["horizon"]), r["complexity"], f"{r['flat']:.12f}", f"{r['belief_mdp']:.12f}", f"{r['flat'] - r['belief_mdp']:.1e}")
        console.print(table)


@app.command("solve-pomdp-file", rich_help_panel="Files")
def solve_pomdp_file(
    path: Path = typer.Argument(..., help="A Cassandra .pomdp file (e.g. Tiger)."),
    gap: float = typer.Option(1e-3, "--gap", help="Target gap between the bounds at the start belief."),
    horizon: Optional[int] = typer.Option(None, "--horizon", min=1, max=8, help="Exact finite-horizon value instead (small files only)."),
    max_seconds: float = typer.Option(60.0, "--max-seconds", help="Time limit for the point solver."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Solve a standard .pomdp file: certified lower and upper bounds at its start belief."""
    from ..interop.files import read_pomdp
    from ..solvers.point import PointSolver

    flat = read_pomdp(path)
    if horizon is not None:
        v = flat.finite_horizon_value(flat.start, horizon)
        res = {"file": str(path), "horizon": horizon, "value": v}
    else:
        if flat.discount >= 1.0:
            raise TrustseekError([f"{path}: the point solver needs a discount below 1, got {flat.discount}"])
        if not gap > 0:
            raise TrustseekError([f"--gap must be positive, got {gap}"])
        sol = PointSolver(tol=gap, max_seconds=max_seconds).solve_bounds(flat.branch_model())
        res = {
            "file": str(path),
            "states": len(flat.states),
            "actions": len(flat.actions),
            "observations": len(flat.observations),
            "discount": flat.discount,
            "lower": sol.lower,
            "upper": sol.upper,
            "gap": sol.gap,
            "seconds": sol.seconds,
        }
    if as_json:
        print_json(res)
        return
    if horizon is not None:
        console.print(f"{path}: optimal {horizon}-step value at the start belief = {res['value']:.9f}")
    else:
        console.print(
            f"{path}: {res['states']} states, {res['actions']} actions, {res['observations']} observations, "
            f"discount {res['discount']:g}\nV(start) in [{res['lower']:.6f}, {res['upper']:.6f}] "
            f"(gap {res['gap']:.1e}, {res['seconds'] * 1000:.0f} ms)"
        )
