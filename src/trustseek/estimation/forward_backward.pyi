import numpy as np

RESCALE: int

def step_codes(eidx: np.ndarray, tidx: np.ndarray, PE: int) -> np.ndarray: ...
def estep_items(
    first: int,
    last: int,
    C: int,
    chunk: int,
    tables: tuple[np.ndarray, np.ndarray, np.ndarray],
    data: tuple[np.ndarray, ...],
    active: np.ndarray,
    sums: tuple[np.ndarray, ...],
) -> None: ...
def mixture_items(
    first: int,
    last: int,
    C: int,
    chunk: int,
    M: int,
    tables: tuple[np.ndarray, np.ndarray, np.ndarray],
    data: tuple[np.ndarray, ...],
    active: np.ndarray,
    sums: tuple[np.ndarray, ...],
    seq_ll: np.ndarray,
) -> None: ...
def each_items(
    lo: int,
    hi: int,
    pidx: np.ndarray,
    tables: tuple[np.ndarray, np.ndarray, np.ndarray],
    data: tuple[np.ndarray, ...],
    active: np.ndarray,
    out: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
) -> None: ...
def reduce_items(
    active: np.ndarray,
    sums: tuple[np.ndarray, ...],
    loglik: np.ndarray,
    c_init: np.ndarray,
    c_emit: np.ndarray,
    c_trans: np.ndarray,
) -> None: ...
