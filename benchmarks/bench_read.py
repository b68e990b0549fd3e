"""Benchmark of reading and encoding a large trial log (read_trials + encode).

    python benchmarks/bench_read.py                     # 100,000 participants x 71 trials, CSV and Parquet
    python benchmarks/bench_read.py --participants 10000
    python benchmarks/bench_read.py --repeat 5          # the median of 5 runs of each (a shared machine)

The log is generated once (random trials that follow the data format's experience
rule, with an extra column) and cached under the temporary directory.  Every
measurement runs in its own process and prints wall time and peak RSS: plain
``pandas.read_csv`` with categorical dtypes (the baseline), then ``read_trials`` +
``encode`` for the CSV and the Parquet file, against the target (< 5 s, < 1 GB).  With
``--repeat N`` each is run N times in turn and the median is shown with the range.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

TRIALS = 71
TARGET_S, TARGET_MB = 5.0, 1024.0


def generate(n: int, path: Path) -> None:
    """A canonical log of ``n`` participants x 71 trials, written in chunks."""
    import pandas as pd

    rng = np.random.default_rng(0)
    first = True
    step = 10_000
    for lo in range(0, n, step):
        m = min(step, n - lo)
        rows = m * TRIALS
        pid = np.repeat([f"P{i:06d}" for i in range(lo, lo + m)], TRIALS)
        trial = np.tile(np.arange(1, TRIALS + 1), m)
        cx = rng.random(rows) < 0.42
        ask = rng.random(rows) < 0.3
        intervene = ~ask & (rng.random(rows) < 0.2)
        success = rng.random(rows) < np.where(cx, 0.83, 0.97)
        reliable = np.where(ask, cx, ~intervene & success)
        human = np.where(ask | intervene, "intervene", "rely").astype(object)
        human[rng.random(rows) < 0.02] = ""
        frame = pd.DataFrame(
            {
                "participant": pid,
                "trial": trial,
                "complexity": np.where(cx, "high", "low"),
                "robot_action": np.where(ask, "ask", "autonomous"),
                "human_action": human,
                "experience": np.where(reliable, "reliable", "faulty"),
                "block": (trial - 1) // 10 + 1,
            }
        )
        frame.to_csv(path, mode="w" if first else "a", header=first, index=False)
        first = False


def cached_logs(n: int) -> tuple[Path, Path]:
    import pyarrow.csv as pcsv
    import pyarrow.parquet as pq

    folder = Path(tempfile.gettempdir()) / "trustseek-bench-read"
    folder.mkdir(exist_ok=True)
    csv, parquet = folder / f"log_{n}.csv", folder / f"log_{n}.parquet"
    if not csv.exists():
        print(f"generating {csv} ...", flush=True)
        tmp = csv.with_suffix(".part")
        generate(n, tmp)
        tmp.rename(csv)
    if not parquet.exists():
        pq.write_table(pcsv.read_csv(csv), parquet)
    return csv, parquet


def child(kind: str, path: str) -> None:
    """One measurement; the imports come before the clock starts (their memory is in the peak)."""
    import pandas as pd

    from trustseek.data import read_trials
    from trustseek.estimation import encode, paper_spec

    t0 = time.perf_counter()
    if kind == "pandas":
        cat = dict.fromkeys(("participant", "complexity", "robot_action", "human_action", "experience"), "category")
        frame = pd.read_csv(path, dtype={**cat, "trial": "int64"})
        what = f"{len(frame)} rows"
    else:
        frame = read_trials(path)
        t1 = time.perf_counter()
        seqs = encode(frame, paper_spec())
        what = f"{seqs.n_participants} participants, {seqs.n_trials} trials; read {t1 - t0:.2f} s"
    dt = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"{dt:.3f} {peak:.1f} {what}")


def measure(kind: str, path: Path) -> tuple[float, float, str]:
    out = subprocess.run([sys.executable, __file__, "--child", kind, str(path)], capture_output=True, text=True, check=True)
    t, mb, what = out.stdout.strip().splitlines()[-1].split(" ", 2)
    return float(t), float(mb), what


def measure_all(runs: list[tuple[str, Path]], repeat: int) -> list[tuple[float, float, str, str]]:
    """Each measurement ``repeat`` times, in turn (a, b, c, a, b, c, ...): per measurement the
    median time, the median peak, the median run's note and the range of the times."""
    seen: list[list[tuple[float, float, str]]] = [[] for _ in runs]
    for _ in range(repeat):
        for i, (kind, path) in enumerate(runs):
            seen[i].append(measure(kind, path))
    out = []
    for results in seen:
        ordered = sorted(results)
        t, _, what = ordered[len(ordered) // 2]
        mb = sorted(r[1] for r in results)[len(results) // 2]
        spread = f" ({ordered[0][0]:.2f}-{ordered[-1][0]:.2f})" if repeat > 1 else ""
        out.append((t, mb, what, spread))
    return out


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--participants", type=int, default=100_000)
    ap.add_argument("--repeat", type=int, default=1, help="runs of each measurement (the median is shown)")
    ap.add_argument("--child", nargs=2, metavar=("KIND", "PATH"))
    args = ap.parse_args()
    if args.child:
        child(*args.child)
        return 0
    csv, parquet = cached_logs(args.participants)
    rows = args.participants * TRIALS
    runs = max(1, args.repeat)
    print(
        f"{args.participants} participants x {TRIALS} trials = {rows:,} rows ({csv.stat().st_size / 2**20:.0f} MB CSV)"
        + (f"; the median of {runs} runs each, in turn (range)" if runs > 1 else "")
    )
    (t, mb, what, spread), *ours = measure_all([("pandas", csv), ("trustseek", csv), ("trustseek", parquet)], runs)
    print(f"  pandas.read_csv (categorical)  {t:6.2f} s{spread}  peak {mb:7.0f} MB  [{what}]")
    ok = True
    for label, (t, mb, what, spread) in zip(("CSV", "Parquet"), ours, strict=True):
        scale = rows / (100_000 * TRIALS)
        hit = t < TARGET_S * max(scale, 0.01) and mb < TARGET_MB
        ok &= hit
        print(
            f"  read_trials + encode ({label:7s}) {t:6.2f} s{spread}  peak {mb:7.0f} MB  "
            f"{mb * 2**20 / rows:5.0f} B/trial  [{what}]  {'ok' if hit else 'MISSED'} "
            f"(target < {TARGET_S:g} s at 7.1 M rows, < {TARGET_MB:g} MB)"
        )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
