"""Simulation commands: simulate (simulated supervisors) and reproduce (the paper end to end)."""

from __future__ import annotations

import time
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from .. import solvers
from ..errors import TrustseekError
from ..parallel import MAX_JOBS
from ..vocab import PAPER_ASK_PROBABILITIES, POLICY_SPEC_KINDS
from ._app import (
    atomic_output,
    check_output,
    check_outputs,
    command,
    console,
    make_table,
    print_json,
    print_written,
    write_atomic,
)
from ._options import (
    JsonOpt,
    QuietOpt,
    TaskOpt,
    belief_update_option,
    bootstrap_option,
    json_option,
    mixture_of,
    need_two_levels,
    parse_counts,
    people_option,
    restarts_option,
    seed_option,
)
from ._progress import progress_bar
from ._reading import write_log

if TYPE_CHECKING:
    from ..model.core import TrustModel
    from ..model.task import Task
    from ..policies.base import Policy

#: --policy for a person of unknown supervisor type (solved for the mixture of --model or --policy-model)
TYPE_AWARE = "type-aware"


@command("simulate")
def simulate(
    ctx: typer.Context,
    model: str = typer.Option(
        "paper",
        "--model",
        "-m",
        help="Supervisors' trust model: a preset name (paper) or a JSON file; a mixture of supervisor types "
        "(paper+conservative or a mixture file) gives each participant a type in the mixture's shares.",
    ),
    types: str | None = typer.Option(
        None,
        "--types",
        help="Supervisors of several types, as 'solve --types' takes them: a mixture preset (paper+conservative) "
        "or a mixture JSON file (the same as giving the mixture with --model).",
    ),
    task: str = TaskOpt,
    policy: str = typer.Option(
        "trust-aware",
        "--policy",
        "-p",
        help=f"Robot policy: {', '.join(POLICY_SPEC_KINDS)}, {TYPE_AWARE} (for a mixture of supervisor types), "
        "or a policy JSON file (e.g. from 'trustseek solve --out').",
    ),
    participants: int = people_option(9, "--participants", "-n", help="Number of simulated participants."),
    counts: str | None = typer.Option(
        None,
        "--counts",
        help="Trials per complexity in random order, e.g. 41,30 or low=41,high=30 (the paper's design). "
        "Default: 41,30 unless --trials is given.",
    ),
    trials: int | None = typer.Option(
        None,
        "--trials",
        min=1,
        max=100_000,
        help="Number of trials with i.i.d. complexities from the task's probabilities (instead of --counts).",
    ),
    belief_update: str = belief_update_option("bayes", " of the trust-aware policy"),
    policy_model: str | None = typer.Option(
        None, "--policy-model", help="Model the trust-aware policy is solved for (default: the supervisors' model)."
    ),
    grid: int = typer.Option(1001, "--grid", min=3, max=1_000_001, help="Belief grid points for solving the trust-aware policy."),
    ask_low: float = typer.Option(
        PAPER_ASK_PROBABILITIES["low"], "--ask-low", min=0.0, max=1.0, help="Randomized policy: P(ask) in the first complexity."
    ),
    ask_high: float = typer.Option(
        PAPER_ASK_PROBABILITIES["high"],
        "--ask-high",
        min=0.0,
        max=1.0,
        help="Randomized policy: P(ask) in the second complexity.",
    ),
    concentration: float | None = typer.Option(
        None,
        "--concentration",
        help="Heterogeneous population: each participant's probability rows ~ Dirichlet(concentration x pooled row + pseudo).",
    ),
    pseudo: float = typer.Option(
        0.0, "--pseudo", min=0.0, help="Dirichlet pseudo-count added to every cell (with --concentration)."
    ),
    seed: int = seed_option("Random seed (same seed, same supervisors and luck for any policy)."),
    out: Path | None = typer.Option(
        None,
        "--out",
        "-o",
        help="Write every trial (canonical trial log + true_trust, belief, reward, block, policy) to this CSV/Parquet file.",
    ),
    summary_out: Path | None = typer.Option(
        None, "--summary-out", help="Write the per-participant summary to this CSV/Parquet file."
    ),
    as_json: bool = JsonOpt,
) -> None:
    from ..simulation.engine import simulate as run_simulation

    if counts is not None and trials is not None:
        raise TrustseekError(["give either --counts or --trials, not both"])
    given = _given(ctx, "belief_update", "--belief-update", "policy_model", "--policy-model")  # a policy file's own
    inputs = ((model, "--model file"), (task, "--task file"), (policy, "--policy file"), (policy_model, "--policy-model file"))
    tables = (".csv", ".parquet")
    check_outputs((out, "--out", tables), (summary_out, "--summary-out", tables), inputs=inputs)
    pop = _population(ctx, model, types, policy_model, concentration, task)
    t = pop.task
    cnt = _trial_counts(counts, trials, participants, t)
    pol = pop.policy(policy, belief_update, grid, ask_low, ask_high, given)
    sup = pop.supervisors(participants, seed, concentration, pseudo)
    t0 = time.perf_counter()
    sim = run_simulation(
        sup, t, pol, participants, counts=cnt, trials=trials, seed=seed, record=out is not None, belief_model=pop.pm
    )
    dt = time.perf_counter() - t0
    write_atomic(out, lambda tmp: write_log(sim.trials(), tmp))
    summ = sim.summary()
    write_atomic(summary_out, lambda tmp: write_log(summ, tmp))
    _report_simulation(summ, pol, participants, seed, dt, out, summary_out, as_json)


def _given(ctx: typer.Context, *names: str) -> list[str]:
    """Of ``names`` (a parameter and its option each), the options given on the command line."""
    out = []
    for name, option in zip(names[::2], names[1::2], strict=True):
        source = ctx.get_parameter_source(name)
        if source is not None and source.name != "DEFAULT":
            out.append(option)
    return out


@dataclass
class _Population:
    """The simulated supervisors' model (and types), and the model the robot's policy is solved for."""

    model: TrustModel
    mixture: Any  # TypeMixture of more than one type, or None
    policy_types: Any  # the types the policy is solved for, or None
    pm: TrustModel  # the model the policy's belief runs on
    task: Task

    def policy(self, spec: str, belief_update: str, grid: int, ask_low: float, ask_high: float, given: list[str]) -> Policy:
        """The policy ``--policy`` names: a kind (with the options of this command) or a policy JSON file.

        A solved policy file fixes its belief update and model: the ``given`` options among
        --belief-update and --policy-model are refused with it rather than ignored."""
        from ..model.jsonfile import load_json
        from ..solvers import policy_from_spec

        if spec == TYPE_AWARE:
            if self.policy_types is None:
                raise TrustseekError(
                    [f"--policy {TYPE_AWARE} needs supervisor types: a mixture with --types, --model or --policy-model"]
                )
            return solvers.solve_type_aware(self.policy_types, self.task, belief_update=belief_update)
        if spec == "trust-aware" and self.policy_types is not None:
            raise TrustseekError(
                [f"the supervisors are a mixture of types: use --policy {TYPE_AWARE}, or --policy-model MODEL for one model"]
            )
        if spec == "trust-aware":
            need_two_levels(self.pm, "simulate")
        if spec in POLICY_SPEC_KINDS:
            p_ask = dict(zip(self.task.complexities, [ask_low, ask_high], strict=False))  # --ask-low, --ask-high: the first two
            options = {"belief_update": belief_update, "grid": grid, "p_ask": p_ask}
            return policy_from_spec({"kind": spec, **options}, self.pm, self.task, where="--policy")
        p = Path(spec)
        if p.suffix.lower() == ".json" or p.exists():
            d, source = load_json(p)
            if "format" in d and given:
                message = "does not apply to a solved policy file: it fixes its own belief update and model"
                raise TrustseekError([f"{option} {message}" for option in given], source)
            return policy_from_spec(d, self.pm, self.task, where=source)
        raise TrustseekError([f"--policy must be one of {list(POLICY_SPEC_KINDS)} or a policy JSON file, got {spec!r}"])

    def supervisors(self, participants: int, seed: int, concentration: float | None, pseudo: float):
        import numpy as np

        from ..simulation.engine import Supervisors

        if concentration is not None:
            return Supervisors.dirichlet(self.model, participants, concentration, np.random.default_rng([seed, 7]), pseudo=pseudo)
        if self.mixture is None:
            return Supervisors.pooled(self.model, participants)
        return Supervisors.from_mixture(self.mixture, participants, rng=seed)


def _population(
    ctx: typer.Context, model: str, types: str | None, policy_model: str | None, concentration, task: str
) -> _Population:
    """--model or --types (one of them), --policy-model, --concentration and --task read and checked."""
    from ..model.presets import load_model, load_task
    from ..pomdp.supervisor_types import product_model

    if types is not None and _given(ctx, "model", "--model"):
        raise TrustseekError(["give the supervisors with --model or with --types, not both"])
    mixture = mixture_of(model, types)
    m = mixture.models[0] if mixture is not None else load_model(model)
    if mixture is not None and mixture.n_types == 1:  # one supervisor type is a trust model
        mixture = None
    policy_types = mixture_of(policy_model) if policy_model else mixture
    if mixture is not None and concentration is not None:
        raise TrustseekError(["--concentration draws around one model; the supervisor types of a mixture are fixed"])
    t = load_task(task)
    t.check_compatible(m)
    pm = product_model(policy_types) if policy_types is not None else (load_model(policy_model) if policy_model else m)
    return _Population(m, mixture, policy_types, pm, t)


def _trial_counts(counts: str | None, trials: int | None, participants: int, task: Task) -> list[int] | None:
    """The trials per complexity (None: --trials i.i.d. trials), refused when the run is too large."""
    from ..simulation.populations import check_size

    cnt = None if trials is not None else list(parse_counts("41,30" if counts is None else counts, task.complexities))
    check_size(participants, sum(cnt) if cnt is not None else (trials or 0), "--participants, --trials or --counts")
    return cnt


def _report_simulation(summ, pol: Policy, participants: int, seed: int, dt: float, out, summary_out, as_json: bool) -> None:
    """The per-participant statistics, as JSON or a table, and the files written."""
    from ..simulation.results import SUMMARY_QUANTITIES

    sd = (lambda c: float(c.std(ddof=1))) if len(summ) > 1 else (lambda c: 0.0)
    stats = {c: {"mean": float(summ[c].mean()), "median": float(summ[c].median()), "sd": sd(summ[c])} for c in SUMMARY_QUANTITIES}
    n_trials = int(summ["trials"].sum())
    if as_json:
        files = {"trials_file": str(out) if out else None, "summary_file": str(summary_out) if summary_out else None}
        print_json(
            {"policy": pol.overview(), "participants": participants, "trials": n_trials, "seed": seed, "statistics": stats}
            | files
        )
        return
    title = f"{participants:,} simulated participants, {n_trials // participants} trials each, policy {escape(pol.describe())}"
    out_table = make_table(title, "per participant", "mean", "median", "sd")
    for c, figures in stats.items():
        out_table.add_row(c.replace("_", " "), *(f"{figures[k]:.2f}" for k in ("mean", "median", "sd")))
    console.print(out_table)
    console.print(f"{n_trials:,} trials in {dt:.2f} s ({n_trials / max(dt, 1e-9) / 1e6:.1f} M trials/s), seed {seed}")
    print_written(("trials", out), ("summary", summary_out))


@command("reproduce")
def reproduce(
    out: Path = typer.Option(Path("report"), "--out", "-o", help="Report folder (report.html, PNGs, summary.json, data)."),
    seed: int = seed_option("Random seed: the same seed gives the same numbers."),
    replicates: int = typer.Option(
        20, "--replicates", "-r", min=0, max=10_000, help="Replicate experiments of the whole pipeline."
    ),
    large_n: int = people_option(10_000, "--large-n", help="Participants of the large experiment 2 and of the cost studies."),
    bootstrap: int = bootstrap_option(200, "Bootstrap resamples for the fitted model's intervals."),
    restarts: int = restarts_option(10, "--restarts", help="EM restarts of the main fit."),
    replicate_restarts: int = restarts_option(4, "--replicate-restarts", help="EM restarts per replicate fit."),
    replicate_large_n: int = people_option(
        2_000, "--replicate-large-n", help="Participants of each replicate's large experiment 2."
    ),
    belief_update: str = belief_update_option("paper", " of the trust-aware policy"),
    jobs: int = typer.Option(
        2,
        "--jobs",
        "-j",
        min=1,
        max=MAX_JOBS,
        help="Processes (the bootstrap, the replicates, the steps beside the fit); numbers do not depend on it.",
    ),
    schedule_participants: int = people_option(
        10_000,
        "--schedule-participants",
        help="Simulated participants of the trial-scheduling section (0: leave the section out).",
        least=0,
    ),
    types_participants: int = people_option(
        2_000,
        "--types-participants",
        help="Simulated participants of the supervisor-types section (Remark 1; 0: leave the section out).",
        least=0,
    ),
    as_json: bool = json_option("Print summary.json to stdout instead of tables."),
    quiet: bool = QuietOpt,
) -> None:
    from ..report import write_report
    from ..reproduction.pipeline import ReproduceConfig
    from ..reproduction.pipeline import reproduce as run_reproduce

    given = locals()  # the options named as the configuration's fields
    cfg = ReproduceConfig(**{f.name: given[f.name] for f in fields(ReproduceConfig) if f.name in given})
    problems = cfg.problems()
    if problems:
        raise TrustseekError(problems)
    check_output(out, "--out", directory=True)
    t0 = time.perf_counter()
    with _stages_bar(quiet or as_json) as bar:
        task = bar.add_task("experiment 1", total=1000)

        def progress(label: str, done: int, total: int) -> None:
            bar.update(task, completed=int(980 * done / max(total, 1)), description=f"{label}: {done}/{total}")

        rep = run_reproduce(cfg, progress=progress)
        bar.update(task, description="report", completed=990)
        with atomic_output(out, directory=True) as tmp:
            paths = {k: out / Path(v).relative_to(tmp) for k, v in write_report(rep, tmp).items()}
        bar.update(task, description="done", completed=1000)
    if as_json:
        print_json(rep.summary)
        return
    _print_reproduction(rep.summary)
    console.print(f"report: {paths['html']}  ({time.perf_counter() - t0:.1f} s)")


def _stages_bar(quiet: bool) -> Progress:
    """The reproduction's progress bar: the stage and its count, the share done, the time."""
    columns = (TextColumn("[bold]{task.description:<44}"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"))
    return progress_bar(quiet, *columns, TimeElapsedColumn())


def _print_reproduction(s: dict) -> None:
    """Paper vs reproduction, experiment 2's difference, the disagreements and the verdicts."""
    from ..report import stat

    print_comparison(s)
    large, small = s["experiment2"]["large"], s["experiment2"]["small"]
    lo, hi = large["mean_difference_ci"]
    console.print(
        f"Experiment 2, {large['participants']:,} participants: mean aware − agnostic "
        f"{large['mean_difference']:.2f} [{lo:.2f}, {hi:.2f}] per block; "
        f"Wilcoxon p = {stat(large['wilcoxon']['p_value'])}; 5 participants: p = {stat(small['wilcoxon']['p_value'])}"
    )
    if s["disagreements"]:
        console.print("[bold red]Where the simulation disagrees with the paper:[/]")
        for d in s["disagreements"]:
            console.print(f"  • {escape(d)}", highlight=False)
    console.print("Rows: " + "; ".join(f"{n} {v}" for v, n in s["verdict_counts"].items()))


def print_comparison(summary: dict) -> None:
    """The console table 'paper vs reproduction'."""
    from ..report import fmt

    table = make_table("Paper vs reproduction", "quantity", "paper", "ours", "95% interval", "verdict")
    table.columns[-1].justify = "left"
    for r in summary["comparison"]:
        iv = r["interval"]
        ivs = f"[{fmt(iv[0])}, {fmt(iv[1])}]" if iv else (r["note"] or "–")
        verdict = {"agrees": "[green]agrees[/]", "DISAGREES": "[bold red]DISAGREES[/]"}.get(r["verdict"], r["verdict"])
        table.add_row(escape(r["quantity"]), escape(fmt(r["paper"])), escape(fmt(r["ours"])), escape(ivs), verdict)
    out = console if console.is_terminal else Console(width=max(console.width, 150))
    out.print(table)
    out.print(
        f"[dim]intervals: bootstrap 95% for trust-model cells, else min–max of {summary['replicates']['n']} replicate "
        "experiments (not a 95% interval); the report states how rows are judged[/]"
    )
