import numpy as np

def base_many(
    B: np.ndarray, pc: np.ndarray, beta: np.ndarray, lo: np.ndarray, hi: np.ndarray, vt: np.ndarray, qt: np.ndarray
) -> np.ndarray: ...
