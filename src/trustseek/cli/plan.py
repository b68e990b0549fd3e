"""Planning commands: solve, agnostic, plot-q, preset, check."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, cast

import typer

from .. import solvers
from ..errors import TrustseekError
from ..solvers.defaults import DEFAULT_GRID, DEFAULT_TYPE_AWARE_SOLVER, METHODS
from ._app import (
    FIGURE_SUFFIXES,
    check_outputs,
    check_positive,
    command,
    console,
    make_table,
    print_json,
    print_written,
    write_atomic,
)
from ._options import (
    FROM_OPTIONS,
    JsonOpt,
    LogReading,
    ModelOpt,
    PolicyOutOpt,
    PrintJsonOpt,
    TaskOpt,
    belief_update_option,
    log_options,
    mixture_of,
    model_and_task,
    need_two_levels,
    tol_option,
)

if TYPE_CHECKING:
    from ..model.mixture import TypeMixture
    from ..policies.base import Policy

UpdateOpt = belief_update_option("bayes")
GridOpt = typer.Option(DEFAULT_GRID, "--grid", "-g", min=3, max=1_000_001, help="Number of belief grid points on [0, 1].")


def type_posterior(mixture: TypeMixture, history: Path, participant: str | None, session: str | None):
    """The type posterior of one person from their earlier trials (--history, --participant, --session)."""
    from ..pomdp.supervisor_types import type_belief_from_log

    frame = LogReading().read([history], ("complexity", "robot_action", "experience"))
    return type_belief_from_log(mixture, frame, participant=participant, session=session)


@command("solve")
def solve(
    model: str = ModelOpt,
    task: str = TaskOpt,
    belief_update: str = UpdateOpt,
    grid: int = GridOpt,
    method: str = typer.Option("policy-iteration", "--method", help=f"Grid solver method: {', '.join(METHODS)}."),
    tol: float = tol_option(1e-9, "Value iteration: stop when the certified error bound is below this (> 0)."),
    out: Path | None = PolicyOutOpt,
    as_json: bool = JsonOpt,
    solver: str | None = typer.Option(
        None,
        "--solver",
        help="grid (belief grid, the default), alpha (certified alpha vectors, two trust levels), point (point-based "
        "bounds, any number of trust levels; the default with supervisor types), reachable (search over the beliefs "
        "reachable from the start, any number of trust levels), types (point with the supervisor types' bounds), "
        "certified-grid (eq. 3, certified) or trust-agnostic.",
    ),
    gap: float | None = typer.Option(
        None, "--gap", help="alpha, point, types, reachable: target certified gap between the value bounds (default 1e-6 / 1e-3)."
    ),
    max_seconds: float | None = typer.Option(
        None, "--max-seconds", help="point, types, reachable: stop after this many seconds (default 60) with the bounds reached."
    ),
    types: str | None = typer.Option(
        None,
        "--types",
        help="Plan for a person whose supervisor type is unknown: a mixture preset (paper+conservative) or a mixture "
        "JSON file; the belief is over (type, trust). A mixture given with --model does the same.",
    ),
    history: Path | None = typer.Option(
        None, "--history", help="With types: the person's earlier trials (a trial log); the plan starts from their type belief."
    ),
    participant: str | None = typer.Option(None, "--participant", help="With --history: the person's participant id."),
    session: str | None = typer.Option(
        None, "--session", help="With --history: the column that separates sessions (trust restarts in each)."
    ),
) -> None:
    from ..model.presets import load_task
    from ..pomdp.problem import AssistancePOMDP
    from ..pomdp.supervisor_types import type_aware_problem, type_marginal
    from ..solvers import make_solver, summarize

    _check_solve(method, solver, gap, max_seconds)
    inputs = ((model, "--model file"), (task, "--task file"), (types, "--types file"), (history, "--history log"))
    check_outputs((out, "--out", (".json",)), inputs=inputs)
    mixture = mixture_of(model, types)
    if mixture is None and (history is not None or participant is not None or session is not None):
        raise TrustseekError(["--history, --participant and --session need supervisor types (--types or a mixture with --model)"])
    options = {"belief_update": belief_update, "grid": grid, "method": method, "tol": tol, "max_seconds": max_seconds}
    if mixture is not None:
        solver = solver or DEFAULT_TYPE_AWARE_SOLVER
        prior = None if history is None else type_posterior(mixture, history, participant, session)
        t = load_task(task)
        policy = solvers.solve_type_aware(mixture, t, solver, gap or 1e-3, type_belief=prior, **options)
        pomdp = type_aware_problem(mixture if prior is None else mixture.with_weights(list(prior)), t)
    else:
        solver = solver or "grid"
        pomdp = AssistancePOMDP(*model_and_task(model, task))
        if solver == "grid":
            need_two_levels(pomdp.model, "solve")
        policy = make_solver(solver, gap=gap, **options).solve(pomdp)
    summary = summarize(policy, pomdp)
    if mixture is not None:
        summary["type_belief"] = dict(
            zip(mixture.names, map(float, type_marginal(pomdp.model.initial, mixture.n_types)), strict=True)
        )
    write_atomic(out, policy.save)
    if out is not None:
        summary["policy_file"] = str(out)
    if as_json:
        print_json(summary)
        return
    if "certified_gap" in summary:
        _print_certified(policy, summary)
    else:
        _print_solution(policy, summary)
    if mixture is not None:
        start = ", ".join(f"{name} {p:.3f}" for name, p in summary["type_belief"].items())
        console.print(f"supervisor types at the start: {start}; the belief is over (type, trust)")
    print_written(("policy", out))


def _check_solve(method: str, solver: str | None, gap: float | None, max_seconds: float | None) -> None:
    """solve's options refused before anything is loaded."""
    from ..solvers import solver_names

    if method not in METHODS:
        raise TrustseekError([f"--method must be one of {list(METHODS)}, got {method!r}"])
    if solver is not None and solver not in solver_names():
        raise TrustseekError([f"--solver must be one of {list(solver_names())}, got {solver!r}"])
    check_positive(gap, "--gap")
    check_positive(max_seconds, "--max-seconds")


def _print_solution(policy: Policy, summary: dict) -> None:
    """The table of ``solve`` for a solver without a certificate."""
    info = policy.info
    name = summary["policy"][:1].upper() + summary["policy"][1:]
    grid = f", grid {info['grid_points']}" if "grid_points" in info else ""
    title = f"{name} policy (belief update: {policy.belief_update}{grid})"
    table = make_table(title, "complexity", "asks when P(trust=high) in", "threshold", "V(b=1, C)", "trust-agnostic", left=2)
    table.columns[-1].justify = "left"
    for cn in policy.complexities:
        iv = summary["ask_intervals"].get(cn, [])
        ivs = ", ".join(f"[{lo:.4f}, {hi:.4f})" for lo, hi in iv) or "never asks"
        th = (summary["thresholds"] or {}).get(cn)
        ths = "-" if th is None else ("none: see intervals" if th != th else f"{th:.4f}")
        v1 = summary.get("value_at_b1", {}).get(cn)
        table.add_row(
            cn, ivs, ths, "-" if v1 is None else f"{v1:.3f}", "always ask" if summary["trust_agnostic"][cn] == 1 else "never ask"
        )
    console.print(table)
    if "iterations" in info:
        console.print(
            f"V(b0 = {summary['initial_belief']:g}) = {summary['value_at_initial_belief']:.3f} over P(C); "
            f"{info['method']}: {info['iterations']} iterations, Bellman residual {info['bellman_residual']:.1e}, "
            f"{info['seconds'] * 1000:.1f} ms"
        )
    else:
        console.print(policy.describe())


def _print_certified(policy: Policy, summary: dict) -> None:
    """The table of ``solve`` for a certified solver (any number of trust levels)."""
    info = policy.info
    title = f"Trust-aware policy ({summary['solver']} solver, belief update: {policy.belief_update})"
    if "thresholds" in summary:
        columns = ("complexity", "asks when P(trust=high) in", "threshold", "certified interval", "V(b=1, C)")
        table = make_table(title, *columns, left=5)
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
    where = "at the initial belief" if info.get("gap_at") == "initial belief" else "over all beliefs"
    console.print(
        f"V(b0) in [{lo:.6f}, {hi:.6f}]; certified gap {summary['certified_gap']:.2e} ({where}); "
        f"{info.get('method')}, {info['seconds'] * 1000:.1f} ms"
    )
    target = info.get("target_gap")
    if target is not None and summary["certified_gap"] > target:
        console.print(f"[yellow]the target gap {target:g} was not reached (time or size limit)[/]")


@command("agnostic")
@log_options(names=("mapping", "column", "label", "sheet", "order"))
def agnostic(
    model: str = ModelOpt,
    task: str = TaskOpt,
    data: Path | None = typer.Option(None, "--data", help="Estimate P(intervene | C) from this trial log instead of the model."),
    out: Path | None = PolicyOutOpt,
    as_json: bool = PrintJsonOpt,
    reading: LogReading = FROM_OPTIONS,
) -> None:
    from ..model.presets import load_model, load_task
    from ..pomdp.problem import AssistancePOMDP
    from ..solvers import make_solver, trust_agnostic_from_data
    from ..vocab import ACTIONS

    if data is None and (reading.mapping is not None or reading.column or reading.label or reading.sheet or reading.order):
        raise TrustseekError(["--mapping, --column, --label, --sheet and --order apply to a log: give it with --data"])
    inputs = ((model, "--model file"), (task, "--task file"), (data, "--data log"), *reading.inputs())
    check_outputs((out, "--out", (".json",)), inputs=inputs)
    t = load_task(task)
    pol: Policy
    if data is not None:
        frame = reading.read([data], ("complexity", "robot_action"))
        pol = trust_agnostic_from_data(frame, t)
    else:
        pol = make_solver("trust-agnostic").solve(AssistancePOMDP(load_model(model), t))
    write_atomic(out, pol.save)
    if as_json:
        print_json(pol.to_dict())
        return
    columns = ("complexity", "P(intervene | C, autonomous)", "E\\[r | autonomous]", "E\\[r | ask]", "action")
    table = make_table("Trust-agnostic policy", *columns, left=5)
    for cn in t.complexities:
        er = pol.info["expected_reward"][cn]
        action = ACTIONS[pol.action(None, cn)]
        table.add_row(cn, f"{pol.info['p_intervene'][cn]:.3f}", f"{er['autonomous']:.3f}", f"{er['ask']:.3f}", action)
    console.print(table)
    console.print(f"P(intervene | C) from the {pol.info['source']}")


@command("plot-q")
def plot_q_cmd(
    model: str = ModelOpt,
    task: str = TaskOpt,
    belief_update: str = UpdateOpt,
    grid: int = GridOpt,
    policy_file: Path | None = typer.Option(None, "--policy", help="Plot a solved policy file instead of solving."),
    out: Path = typer.Option(Path("q.png"), "--out", "-o", help="PNG file to write."),
) -> None:
    from ..plots.q import plot_q
    from ..policies import PolicyError, TrustAwarePolicy, load_policy
    from ..pomdp.problem import AssistancePOMDP
    from ..solvers import make_solver

    inputs = ((model, "--model file"), (task, "--task file"), (policy_file, "--policy file"))
    check_outputs((out, "--out", FIGURE_SUFFIXES), inputs=inputs)
    if policy_file is not None:
        try:
            policy = TrustAwarePolicy.tabulate(load_policy(policy_file))
        except PolicyError as exc:
            raise TrustseekError([f"{p} to plot" for p in exc.problems], str(policy_file)) from None
    else:
        pomdp = AssistancePOMDP(*model_and_task(model, task))
        need_two_levels(pomdp.model, "plot-q")
        policy = cast(TrustAwarePolicy, make_solver("grid", grid=grid, belief_update=belief_update).solve(pomdp))
    write_atomic(out, lambda tmp: plot_q(policy, tmp))
    console.print(f"wrote {out}")


@command("preset")
def preset(
    name: str = typer.Argument("paper", help="Preset name."),
    model_out: Path | None = typer.Option(None, "--model-out", help="Write the preset's trust model here."),
    task_out: Path | None = typer.Option(None, "--task-out", help="Write the preset's task here."),
) -> None:
    from ..model.presets import MODEL_PRESETS, TASK_PRESETS

    if name not in MODEL_PRESETS:
        raise TrustseekError([f"unknown preset {name!r}; presets: {sorted(MODEL_PRESETS)}"])
    check_outputs((model_out, "--model-out", (".json",)), (task_out, "--task-out", (".json",)))
    m, t = MODEL_PRESETS[name](), TASK_PRESETS[name]()
    for path, made in ((model_out, m), (task_out, t)):
        if path:
            write_atomic(path, made.save)
            console.print(f"wrote {path}")
    if not model_out and not task_out:
        print_json({"model": m.to_dict(), "task": t.to_dict()})


@command("check")
@log_options()
def check(
    files: list[Path] = typer.Argument(
        ..., help="Trust model, task, policy or mapping files, or trial logs (CSV, Parquet, JSON, Excel, a folder)."
    ),
    reading: LogReading = FROM_OPTIONS,
) -> None:
    """Validate model (trust or general), task, policy and mapping files, and trial logs as the fit
    reads them (with the log options); print every problem found, and what each log holds."""
    problems: list[str] = []
    for f in files:
        try:
            console.print(f"{f}: {_check_file(f, reading)}", soft_wrap=True, highlight=False)
        except TrustseekError as exc:
            problems.extend(exc.lines())
    if problems:
        raise TrustseekError(problems)


def _check_file(f: Path, reading: LogReading) -> str:
    """What ``check`` says of one file that holds no problem (a note before it, for a model some of
    whose rows were never estimated); its problems raised."""
    from ..data.suffixes import file_kind
    from ..model.core import TrustModel
    from ..model.files import IOHMM_FORMAT
    from ..model.jsonfile import load_json
    from ..model.task import Task
    from ..policies import load_policy

    kind = file_kind(f)
    if kind == "log":
        return f"ok: {_log_summary(reading.read([f], ('complexity', 'robot_action', 'experience')))}"
    if kind == "mapping":
        from ..data.mapping import ColumnMapping

        ColumnMapping.load(f)
        return "ok (a column mapping, for --mapping)"
    text, _ = load_json(f)
    fmt = text.get("format", "")
    if not isinstance(fmt, str):
        raise TrustseekError([f"{f}: format must be a string, got {fmt!r}"])
    if "task" in fmt:
        Task.from_dict(text, str(f))
    elif "policy" in fmt:
        load_policy(f)
    elif fmt == IOHMM_FORMAT:
        g = TrustModel.from_dict(text, str(f), general=True)
        console.print(
            f"{f}: a general model, inputs: {', '.join(g.used_inputs) or 'none'} (decode, predict and validate "
            "read it; solve and simulate need a trust model)",
            soft_wrap=True,
            highlight=False,
        )
    else:
        rows = TrustModel.from_dict(text, str(f)).not_estimated_rows()
        if rows:
            console.print(
                f"[yellow]warning:[/] {f}: never estimated (copies or defaults, not data): {', '.join(rows)}; "
                "solve, plot-q and simulate refuse the ones a task can reach until they are supplied "
                "('trustseek fit ... --fill-from paper', or by hand: docs/formats.md)",
                soft_wrap=True,
                highlight=False,
            )
    return "ok"


def _log_summary(frame) -> str:
    """What a trial log holds, as a line: trials, participants and the count of each label."""
    per = frame.groupby("participant", observed=True).size()
    people = f"{len(per):,} participant{'s' if len(per) != 1 else ''}"
    each = f"{per.min()} each" if per.min() == per.max() else f"{per.min()} to {per.max()} each"
    parts = [f"{len(frame):,} trials of {people} ({each})"]
    for c in ("human_action", "complexity", "robot_action", "experience"):
        counts = frame[c].value_counts(dropna=False, sort=False)
        shown = [f"{'not recorded' if label != label else label} {n:,}" for label, n in counts.items() if n]
        parts.append(f"{c}: {', '.join(shown)}")
    from ..vocab import TRIAL_COLUMNS

    extra = [str(c) for c in frame.columns if c not in TRIAL_COLUMNS]
    return "; ".join(parts + ([f"other columns: {', '.join(extra)}"] if extra else []))
