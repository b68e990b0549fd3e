from typing import Any

import numpy as np

ARMIJO: float
ENDED_STATIONARY: int
ENDED_CAPPED: int
ENDED_ZERO: int

def bind(addresses: tuple[int | None, int | None, int | None]) -> None: ...
def run_one(
    start: np.ndarray,
    model: tuple[Any, ...],
    data: tuple[np.ndarray, ...],
    C: int,
    PE: int,
    settings: tuple[float, int, float, float, bool, bool, int],
    qn: tuple[tuple[np.ndarray, ...], int, np.ndarray, bool],
) -> tuple[np.ndarray, np.ndarray, int, int, int, np.ndarray]: ...
