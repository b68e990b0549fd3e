"""Run every benchmark (benchmarks/bench_*.py) and print its figures.

python benchmarks/run.py            # all
python benchmarks/run.py solve fit  # only those whose name contains a word
python benchmarks/run.py schedule   # trial scheduling, 17 + 17 (full control and a window of 3)
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(argv: list[str]) -> int:
    files = sorted(HERE.glob("bench_*.py"))
    if argv:
        files = [f for f in files if any(w in f.stem for w in argv)]
    failed = []
    for f in files:
        print(f"=== {f.stem}", flush=True)
        rc = subprocess.call([sys.executable, str(f)])
        if rc != 0:
            failed.append(f.stem)
    if failed:
        print(f"benchmarks that failed: {', '.join(failed)}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
