"""The design command: how many participants and trials a study needs (power and regret by design)."""

from __future__ import annotations

import socket
import threading
from pathlib import Path
from typing import Any

import typer
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from ..errors import TrustseekError
from ..parallel import MAX_JOBS
from ._app import check_output, command, console, make_table, print_json
from ._options import JsonOpt, QuietOpt, TaskOpt, belief_update_option, model_and_task, seed_option
from ._progress import bar_task, progress_bar


def _floats(text: str, option: str) -> tuple[float, ...]:
    try:
        vals = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise TrustseekError([f"{option}: expected comma-separated numbers, got {text!r}"]) from None
    if not vals:
        raise TrustseekError([f"{option}: expected at least one value"])
    return vals


def _ints(text: str, option: str) -> tuple[int, ...]:
    vals = _floats(text, option)
    if any(v != int(v) for v in vals):
        raise TrustseekError([f"{option}: expected comma-separated whole numbers, got {text!r}"])
    return tuple(int(v) for v in vals)


def _connect(scheduler: str | None) -> Any:
    """A client of the Dask scheduler at ``scheduler``; every way it cannot be one is a
    TrustseekError within :data:`CONNECT_SECONDS` (a port nothing listens on) or
    :data:`ANSWER_SECONDS` (a port where something else listens: dask's handshake would wait on
    a web server until it hangs up, and a reply in another protocol ended in a traceback)."""
    if scheduler is None:
        return None
    try:
        from dask.distributed import Client
    except ModuleNotFoundError:
        raise TrustseekError(
            ["--scheduler needs the optional 'design' dependencies (dask.distributed): pip install 'trustseek[design]'"]
        ) from None
    where = _address(scheduler)
    made: dict[str, Any] = {}

    def make() -> None:
        try:
            if where is not None:  # dask's Client retries a refused connection until its timeout
                socket.create_connection(where, timeout=CONNECT_SECONDS).close()
            made["client"] = Client(scheduler, timeout=ANSWER_SECONDS)
        except BaseException as exc:  # each kind is told apart below
            made["error"] = exc

    worker = threading.Thread(target=make, name="trustseek-dask-connect", daemon=True)  # daemon: a hung handshake ends with us
    worker.start()
    worker.join(ANSWER_SECONDS)
    exc = made.get("error")
    if "client" in made:
        return made["client"]
    if exc is None:
        raise TrustseekError(
            [f"--scheduler {scheduler}: something listens there but no Dask scheduler answered in {ANSWER_SECONDS} s "
             "(a scheduler listens on port 8786 unless told otherwise)"]
        )  # fmt: skip
    if isinstance(exc, OSError):
        raise TrustseekError([f"--scheduler {scheduler}: cannot connect ({exc})"])
    raise TrustseekError(
        [f"--scheduler {scheduler}: what answers there is not a Dask scheduler ({type(exc).__name__}: {str(exc)[:120]})"]
    )


def _address(scheduler: str) -> tuple[str, int] | None:
    """The host and port of a TCP or TLS scheduler address (None for dask's other schemes); an
    address dask cannot parse is refused, with its parser's reason."""
    from distributed.comm import parse_address, parse_host_port
    from distributed.comm.registry import get_backend

    try:
        scheme, where = parse_address(scheduler)
        get_backend(scheme).get_address_host(where)
        return parse_host_port(where) if scheme in ("tcp", "tls") else None
    except (ValueError, TypeError) as exc:
        raise TrustseekError(
            [f"--scheduler {scheduler!r}: {exc}; expected a scheduler address such as tcp://host:8786"]
        ) from None


CONNECT_SECONDS = 5  # a scheduler's port that does not take a connection in this time is not listening
ANSWER_SECONDS = 10  # a scheduler that has not taken the connection and answered dask's handshake in this time is none


@command("design")
def design(
    model: str = typer.Option(
        "paper", "--model", "-m", help="True population: a preset name (paper) or a trust-model JSON file."
    ),
    task: str = TaskOpt,
    replicates: int = typer.Option(100, "--replicates", "-r", help="Replicates per design point."),
    seed: int = seed_option("Sweep seed (replicate seeds derive from it, the design point and the index)."),
    participants_1: str = typer.Option("9", "--participants-1", help="Experiment 1: participants (comma-separated grid)."),
    trials_1: str = typer.Option("71", "--trials-1", help="Experiment 1: trials per participant (grid)."),
    share_high_1: str = typer.Option(
        "0.4225", "--share-high-1", help="Experiment 1: share of high-complexity trials (grid; 30/71)."
    ),
    ask_low: str = typer.Option("0.10", "--ask-low", help="Experiment 1: P(ask | low complexity) (grid)."),
    ask_high: str = typer.Option("0.40", "--ask-high", help="Experiment 1: P(ask | high complexity) (grid)."),
    participants_2: str = typer.Option("5,10,15,20,30,40,60", "--participants-2", help="Experiment 2: participants (grid)."),
    trials_2: str = typer.Option(
        "34", "--trials-2", help="Experiment 2: trials per block, split evenly over complexities (grid)."
    ),
    no_counterbalance: bool = typer.Option(
        False, "--no-counterbalance", help="Every participant meets the trust-aware policy first."
    ),
    alpha: float = typer.Option(0.05, "--alpha", help="Significance level of the paired tests."),
    test: str = typer.Option("wilcoxon", "--test", help="Test the power target uses: wilcoxon or t."),
    power_target: float = typer.Option(0.8, "--power-target", help="Target power of experiment 2."),
    regret_target: float = typer.Option(0.01, "--regret-target", help="Target mean regret, as a share of V*."),
    restarts: int = typer.Option(2, "--restarts", help="Random starts of each replicate's fit."),
    tol: float = typer.Option(1e-8, "--tol", help="Relative tolerance of each replicate's fit."),
    belief_update: str = belief_update_option("paper", " of the policies"),
    grid: int = typer.Option(201, "--grid", help="Belief grid points of each replicate's solve."),
    search_low: str | None = typer.Option(
        None, "--search-ask-low", help="Also search experiment 1's ask probabilities: P(ask | low) grid."
    ),
    search_high: str | None = typer.Option(
        None, "--search-ask-high", help="... and the P(ask | high) grid (default 0.1, 0.25, 0.4, 0.55, 0.7)."
    ),
    jobs: int = typer.Option(1, "--jobs", "-j", min=1, max=MAX_JOBS, help="Local processes (ignored with --scheduler)."),
    scheduler: str | None = typer.Option(
        None, "--scheduler", help="Run on this Dask distributed scheduler (e.g. tcp://host:8786)."
    ),
    out: Path | None = typer.Option(None, "--out", "-o", help="Write design.html, design.json and the figures to this folder."),
    as_json: bool = JsonOpt,
    quiet: bool = QuietOpt,
) -> None:
    from ..design import DesignConfig, FitSettings, ask_search_problems

    check_output(out, "--out", directory=True)
    cfg = DesignConfig(
        *model_and_task(model, task),  # the truth and the task
        seed=seed,
        replicates=replicates,
        participants_1=_ints(participants_1, "--participants-1"),
        trials_1=_ints(trials_1, "--trials-1"),
        share_high_1=_floats(share_high_1, "--share-high-1"),
        ask_low=_floats(ask_low, "--ask-low"),
        ask_high=_floats(ask_high, "--ask-high"),
        participants_2=_ints(participants_2, "--participants-2"),
        trials_2=_ints(trials_2, "--trials-2"),
        counterbalance=not no_counterbalance,
        alpha=alpha,
        test=test,
        power_target=power_target,
        regret_target=regret_target,
        fit=FitSettings(restarts=restarts, tol=tol, belief_update=belief_update, grid=grid),
    )
    search_grid = None
    if search_low is not None or search_high is not None:
        search_grid = (
            _floats("0.05,0.1,0.2,0.3" if search_low is None else search_low, "--search-ask-low"),
            _floats("0.1,0.25,0.4,0.55,0.7" if search_high is None else search_high, "--search-ask-high"),
        )
    problems = cfg.problems() or (ask_search_problems(cfg, *search_grid) if search_grid else [])
    if problems:
        raise TrustseekError(problems)
    result, search = _run(cfg, jobs, scheduler, quiet, search_grid)
    paths = None
    if out is not None:
        from ..report import write_design_report

        paths = write_design_report(result.summary, out, search)
    if as_json:
        doc: dict[str, Any] = {"design": result.summary, "ask_search": search}
        if paths is not None:
            doc["html"] = str(paths["html"])
        print_json(doc)
        return
    _print(result.summary, search)
    if paths is not None:
        console.print(f"report written to {paths['html']}")


def _run(cfg, jobs: int, scheduler: str | None, quiet: bool, search_grid: tuple[tuple[float, ...], tuple[float, ...]] | None):
    """The design's sweep (and the ask-probability search on ``search_grid``, the values of
    --search-ask-low and -high), on local processes or a Dask scheduler, with a progress bar
    unless ``quiet``."""
    from ..design import ask_search, run_design

    client = _connect(scheduler)
    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(), TimeRemainingColumn())
    try:
        with progress_bar(quiet, *columns) as bar:
            result = run_design(cfg, jobs=jobs, client=client, progress=bar_task(bar, "design replicates"))
            search = None
            if search_grid is not None:
                progress = bar_task(bar, "ask-probability search")
                search = ask_search(cfg, *search_grid, jobs=jobs, client=client, progress=progress)
    finally:
        if client is not None:
            client.close()
    return result, search


def _print(s: dict[str, Any], search: dict[str, Any] | None) -> None:
    from ..design import participants_needed
    from ..report import iv

    def _iv(d: dict[str, Any], scale: float = 1.0, unit: str = "") -> str:
        return escape(iv(d, ".3g", scale, unit))

    console.print(
        f"V* = {s['optimal']['value']:.4f} (optimal threshold {s['optimal']['threshold']:.4f}); "
        f"{s['config']['replicates']} replicates per design; α = {s['targets']['alpha']:g}"
    )
    columns = ("design", "failed", "regret", "regret, % of V*", "threshold error")
    t1 = make_table("Experiment 1: the estimated policy under the true model", *columns)
    for p in s["points"]:
        e = p["experiment1"]
        t1.add_row(
            f"{e['participants']} × {e['trials']} ({e['counts'][0]}/{e['counts'][1]}), ask {e['ask_low']:g}/{e['ask_high']:g}",
            str(len(p["failed"])),
            _iv(p["regret"]),
            _iv(p["relative_regret"], 100, " %"),
            _iv(p["threshold_error"]),
        )
    console.print(t1)
    for p in s["points"]:
        e1 = p["experiment1"]
        for e in p["experiment2"]:
            title = f"Experiment 2 after {e1['participants']} × {e1['trials']}: {e['trials_per_block']} trials per block"
            t = make_table(title, "participants", "mean difference", "power (Wilcoxon)", "power (t-test)", left=0)
            for c in e["curve"]:
                t.add_row(
                    str(c["participants"]),
                    _iv(c["mean_difference"]),
                    escape(f"{c['wilcoxon']['power']:.2f} [{c['wilcoxon']['lo']:.2f}, {c['wilcoxon']['hi']:.2f}]"),
                    escape(f"{c['t']['power']:.2f} [{c['t']['lo']:.2f}, {c['t']['hi']:.2f}]"),
                )
            console.print(t)
            needed = participants_needed(e, s["targets"]["power"], s["targets"]["test"])
            console.print(escape(f"participants for power {s['targets']['power']:g} ({s['targets']['test']}): {needed}"))
    sd = s["smallest_design"]
    if sd is None:
        console.print("no design of the grid meets the targets")
    else:
        e = sd["experiment1"]
        console.print(
            f"smallest design meeting the targets: experiment 1 {e['participants']} × {e['trials']}, "
            f"experiment 2 {sd['participants_2']} participants × 2 × {sd['trials_2']} trials ({sd['cost_trials']} trials)"
        )
    if search is not None:
        b, pp = search["best"], search["paper"]
        console.print(
            f"ask probabilities for {search['budget']['participants']} × {search['budget']['trials']} trials: best "
            f"{b['ask_low']:g}/{b['ask_high']:g} regret {_iv(b['regret'])}; paper 0.10/0.40 regret {_iv(pp['regret'])}"
            + ("; the paper's choice is near the best" if search["paper_near_best"] else "")
        )
