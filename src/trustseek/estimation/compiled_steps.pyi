from typing import Any

import numpy as np

CHUNK: int
PARALLEL_ITEMS: int

class EStepBuffers:
    tables: tuple[np.ndarray, np.ndarray, np.ndarray]
    sums: tuple[np.ndarray, ...]
    active: np.ndarray
    totals: np.ndarray
    C: int
    threads: int
    def __init__(self, K: int, PE: int, U1: int, C: int, threads: int) -> None: ...
    def run_items(self) -> None: ...

def estep_buffers(K: int, PE: int, U1: int, C: int, threads: int) -> EStepBuffers: ...
def evaluate(
    flat: np.ndarray, model: tuple[Any, ...], ev: tuple[Any, EStepBuffers], counts: np.ndarray
) -> tuple[float, float]: ...
def em_step(flat: np.ndarray, counts: np.ndarray, model: tuple[Any, ...], out: np.ndarray) -> None: ...
def extrapolate(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray, model: tuple[Any, ...], out: np.ndarray) -> bool: ...
