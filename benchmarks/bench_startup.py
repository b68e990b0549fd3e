"""What a person waits for: each command run as a fresh process, end to end (wall time).

    python benchmarks/bench_startup.py            # every row, best of 3 runs each
    python benchmarks/bench_startup.py --repeat 5
    python benchmarks/bench_startup.py --no-big   # without the 100,000 x 71 fit (its log takes a minute to make once)
    python benchmarks/bench_startup.py --reproduce   # also ``trustseek reproduce`` (minutes)

Rows: ``trustseek --help`` and every command's ``--help``, ``import trustseek``, ``trustseek
solve``, ``trustseek check model.json``, ``trustseek fit`` on the shipped example (as installed,
and in a fresh environment: no bytecode cached, of the package or of its dependencies) and on
100,000 x 71 trials with one restart (the compiled path: its code is built with the
package, so a first run after installation compiles nothing either), and the static checks
(``make lint``, with empty mypy and ruff caches as on a clean clone), which ``make test`` runs
beside the tests.  With ``--reproduce``, ``make reproduce``'s command (``trustseek reproduce``).
``trustseek simulate`` of 100,000 participants into a CSV file.  The in-run baseline is the bare
interpreter (``python -c pass``) and ``import numpy, pandas``.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
BIN = Path(sys.executable).parent
TRUSTSEEK = str(BIN / "trustseek")


def wall(argv: list[str], repeat: int, fresh: tuple[str, ...] = ()) -> tuple[float, float, float]:
    """The best wall time of ``argv`` over ``repeat`` runs, each a fresh process (``fresh``:
    variables each pointed at an empty folder of its own), that run's CPU time (user + system:
    what the run costs when the machine is busy with other work), and the median wall time."""
    best = (float("inf"), float("inf"))
    times = []
    for _ in range(repeat):
        # as an installed package runs: its modules' bytecode cached (an environment that sets
        # PYTHONDONTWRITEBYTECODE, as some sandboxes and CI images do, compiles 200 modules on every start)
        env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
        with tempfile.TemporaryDirectory(prefix="trustseek-bench-") as cache:
            for i, var in enumerate(fresh):
                env[var] = os.path.join(cache, str(i))
                os.makedirs(env[var])
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            t = time.perf_counter()
            subprocess.run(argv, env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=cache)
            seconds = time.perf_counter() - t
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
            best = min(best, (seconds, cpu))
            times.append(seconds)
    return (*best, statistics.median(times))


LINT_CACHES = ("MYPY_CACHE_DIR", "RUFF_CACHE_DIR")  # as on a clean clone


def row(what: str, seconds: tuple[float, float, float], target: float | None) -> None:
    """The best run's wall and CPU time, the median's wall time, and the best against ``target``."""
    wall_s, cpu, median = seconds
    verdict = "" if target is None else f"< {target:g} s  {'met' if wall_s < target else 'NOT MET'}"
    print(f"  {what:60} {wall_s:7.2f} s  (cpu {cpu:6.2f} s, median {median:6.2f} s)  {verdict}", flush=True)


def python(code: str) -> list[str]:
    return [sys.executable, "-c", code]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-big", action="store_true", help="leave out the 100,000 x 71 fit")
    ap.add_argument("--reproduce", action="store_true", help="add trustseek reproduce")
    args = ap.parse_args(argv)
    n = args.repeat
    from trustseek.cli._lazy import COMMANDS
    from trustseek.data import example_path

    print(
        f"wall time of fresh processes, best of {n} (the 100,000 x 71 fit: of {max(n, 3)}) and their median; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"
    )
    row("baseline: python -c pass", wall(python("pass"), n), None)
    row("baseline: python -c 'import numpy, pandas'", wall(python("import numpy, pandas"), n), None)
    row("trustseek --help", wall([TRUSTSEEK, "--help"], n), 0.3)
    helps = {name: wall([TRUSTSEEK, name, "--help"], n) for name in COMMANDS}
    slowest = max(helps, key=helps.__getitem__)
    met = sum(t < 0.3 for t, _, _ in helps.values())
    row(f"trustseek CMD --help, slowest of {len(helps)} ({slowest}; {met} under 0.3 s)", helps[slowest], 0.3)
    over = sorted((name for name, (t, _, _) in helps.items() if t >= 0.3), key=lambda name: -helps[name][0])
    if over:
        print("    over 0.3 s: " + ", ".join(f"{name} {helps[name][0]:.2f} s (cpu {helps[name][1]:.2f})" for name in over))
    row("import trustseek", wall(python("import trustseek"), n), 0.5)
    row("trustseek solve (paper preset)", wall([TRUSTSEEK, "solve"], n), 0.7)
    with tempfile.TemporaryDirectory(prefix="trustseek-bench-") as tmp:
        model = Path(tmp) / "model.json"
        subprocess.run([TRUSTSEEK, "preset", "paper", "--model-out", str(model)], check=True, stdout=subprocess.DEVNULL)
        row("trustseek check model.json", wall([TRUSTSEEK, "check", str(model)], n), 0.5)
        fit = [TRUSTSEEK, "fit", str(example_path()), "--preset", "paper", "--out", str(Path(tmp) / "fit.json")]
        row("trustseek fit (shipped example, 9 x 71)", wall(fit, n), 1.0)
        # a fresh environment: no compiled-code cache of any kind, not even Python's bytecode of
        # numpy, pandas or trustseek (an empty PYTHONPYCACHEPREFIX each run; the package's loops
        # are compiled by its installation, so nothing else is compiled at run time)
        row("  the same in a fresh environment (no bytecode cached)", wall(fit, n, fresh=("PYTHONPYCACHEPREFIX",)), 5.0)
        if not args.no_big:
            sys.path.insert(0, str(HERE))
            from bench_read import cached_logs

            log, _ = cached_logs(100_000)
            big = [TRUSTSEEK, "fit", str(log), "--preset", "paper", "--restarts", "1", "--out", str(Path(tmp) / "big.json")]
            row("trustseek fit 100,000 x 71, one restart", wall(big, max(n, 3)), 6.0)
    with tempfile.TemporaryDirectory(prefix="trustseek-bench-") as tmp:
        # what the 28 M trials/s of bench_simulate become for a person who wants the trials in a file
        sim = [TRUSTSEEK, "simulate", "-n", "100000", "--out", str(Path(tmp) / "trials.csv")]
        row("trustseek simulate -n 100000 --out trials.csv (7.1 M trials, 522 MB)", wall(sim, 1), None)
    lint = ["make", "-s", "-C", str(HERE.parent), "lint"]
    row("make lint, empty mypy and ruff caches", wall(lint, 1, fresh=LINT_CACHES), None)
    if args.reproduce:
        with tempfile.TemporaryDirectory(prefix="trustseek-bench-") as tmp:
            reproduce = [TRUSTSEEK, "reproduce", "--out", str(Path(tmp) / "report")]
            row("make reproduce's command", wall(reproduce, 1), 90.0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
