"""File-format commands: export-pomdp and solve-pomdp-file."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from ..errors import TrustseekError
from ._app import check_outputs, check_positive, command, console, err_console, make_table, print_json, write_atomic
from ._options import ModelOpt, PrintJsonOpt, TaskOpt, model_and_task

#: exit code of solve-pomdp-file when the point solver stops before its target gap
GAP_NOT_REACHED = 3


@command("export-pomdp")
def export_pomdp(
    out: Path = typer.Argument(..., help="File to write: .pomdp (Cassandra) or .pomdpx (POMDPX)."),
    model: str = ModelOpt,
    task: str = TaskOpt,
    fmt: str | None = typer.Option(None, "--format", help="pomdp or pomdpx (default: from the file suffix)."),
    initial_complexity: str | None = typer.Option(
        None, "--initial-complexity", help="Start from this complexity instead of P(C) (.pomdp only)."
    ),
    verify: bool = typer.Option(
        False, "--verify", help="Also print finite-horizon values (1-3) of the file and of the belief MDP."
    ),
) -> None:
    from ..interop.files import export_assistance, flat_values_check
    from ..pomdp.problem import AssistancePOMDP

    if fmt is not None and fmt not in ("pomdp", "pomdpx"):
        raise TrustseekError([f"--format must be 'pomdp' or 'pomdpx', got {fmt!r}"])
    inputs = ((model, "--model file"), (task, "--task file"))
    check_outputs((out, "OUT", None if fmt else (".pomdp", ".pomdpx")), inputs=inputs)
    m, t = model_and_task(model, task)
    pomdp = AssistancePOMDP(m, t)
    c0 = None
    if initial_complexity is not None:
        if initial_complexity not in t.complexities:
            raise TrustseekError([f"--initial-complexity must be one of {list(t.complexities)}, got {initial_complexity!r}"])
        c0 = t.complexities.index(initial_complexity)
    write_atomic(out, lambda tmp: export_assistance(pomdp, tmp, fmt or out.suffix.lower().lstrip("."), c0))
    console.print(f"wrote {out}")
    if verify:
        columns = ("horizon", "complexity", "flat file", "belief MDP", "difference")
        table = make_table("Finite-horizon values from the initial belief", *columns, left=0)
        for r in flat_values_check(pomdp):
            table.add_row(
                str(r["horizon"]),
                r["complexity"],
                f"{r['flat']:.12f}",
                f"{r['belief_mdp']:.12f}",
                f"{r['flat'] - r['belief_mdp']:.1e}",
            )
        console.print(table)


@command("solve-pomdp-file")
def solve_pomdp_file(
    path: Path = typer.Argument(..., help="A Cassandra .pomdp file (e.g. Tiger)."),
    gap: float = typer.Option(1e-3, "--gap", help="Target gap between the bounds at the start belief."),
    horizon: int | None = typer.Option(
        None, "--horizon", min=1, max=8, help="Exact finite-horizon value instead (small files only)."
    ),
    max_seconds: float = typer.Option(60.0, "--max-seconds", help="Time limit for the point solver."),
    as_json: bool = PrintJsonOpt,
) -> None:
    """Exit code 3 when the solver stops (time or size limit) before the gap between the bounds
    reaches --gap: the bounds printed are still valid, only looser than asked; 2 for bad input."""
    from ..interop.files import read_pomdp
    from ..solvers import UnsupportedProblem, make_solver

    check_positive(gap, "--gap")
    check_positive(max_seconds, "--max-seconds")
    flat = read_pomdp(path)
    res: dict[str, Any]
    if horizon is not None:
        try:
            v = flat.finite_horizon_value(flat.start, horizon)
        except TrustseekError as exc:  # the tree's size: name the option and the file
            raise TrustseekError([f"{path}: --{line}" for line in exc.lines()]) from None
        res = {"file": str(path), "horizon": horizon, "value": v}
    else:
        try:
            info = make_solver("point", gap=gap, max_seconds=max_seconds).solve(flat).info
        except UnsupportedProblem as exc:
            raise TrustseekError(exc.problems, str(path)) from None
        lower, upper = info["value_bounds_at_initial_belief"]
        res = {
            "file": str(path),
            "states": len(flat.states),
            "actions": len(flat.actions),
            "observations": len(flat.observations),
            "discount": flat.discount,
            "lower": lower,
            "upper": upper,
            "gap": info["certified_gap"],
            "target_gap": gap,
            "gap_reached": bool(info["certified_gap"] <= gap),
            "seconds": info["seconds"],
        }
    if as_json:
        print_json(res)
    elif horizon is not None:
        console.print(f"{path}: optimal {horizon}-step value at the start belief = {res['value']:.9f}")
    else:
        console.print(
            f"{path}: {res['states']} states, {res['actions']} actions, {res['observations']} observations, "
            f"discount {res['discount']:g}\nV(start) in [{res['lower']:.6f}, {res['upper']:.6f}] "
            f"(gap {res['gap']:.1e}, {res['seconds'] * 1000:.0f} ms)"
        )
    if not res.get("gap_reached", True):
        err_console.print(
            f"[yellow]{path}: the solver stopped at gap {res['gap']:.2e} above the target {gap:g} "
            "(time or size limit; raise --max-seconds)[/]",
            highlight=False,
            soft_wrap=True,
        )
        raise typer.Exit(GAP_NOT_REACHED)
