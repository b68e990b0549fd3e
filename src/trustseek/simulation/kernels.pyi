from typing import Any

import numpy as np

THRESHOLD: int
FIXED: int
NO_BELIEF: int
PAPER: int
BAYES: int

def run_block(
    sched: np.ndarray,
    uniforms: tuple[np.ndarray, np.ndarray, np.ndarray],
    policy: tuple[int, np.ndarray],
    beliefs: tuple[Any, ...],
    x: np.ndarray,
    tables: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    trust: np.ndarray,
    codes: np.ndarray,
    t0: int,
    records: tuple[Any, ...],
) -> None: ...
def urn_schedule(u: np.ndarray, first: float, out: np.ndarray) -> None: ...
