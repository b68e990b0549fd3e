"""Trial tables encoded for the IOHMM: one padded, time-major integer array per quantity.

:func:`encode` turns a validated trial table (one row per trial, a participant and a
1-based trial column) into :class:`Sequences`: the output code and the emission- and
transition-input combination of every trial, participants side by side.  Every
E-step, M-step and bootstrap resample works on these arrays, never on the frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from .spec import FitError, IOHMMSpec

MAX_LISTED = 10  # problems listed per column before the rest is summarised


@dataclass
class Sequences:
    """Trials encoded as padded, time-major integer arrays (built by :func:`encode`)."""

    participants: list[str]
    lengths: np.ndarray  # (N,)
    y: np.ndarray  # (T, N) output code, -1 = unobserved or padding
    ue: np.ndarray  # (T, N) emission-input combination, -1 = padding
    ut: np.ndarray  # (T, N) transition-input combination of row t (t -> t+1), -1 = padding
    rows: np.ndarray  # (T, N) index of the source row in the frame, -1 = padding
    n_rows: int

    @property
    def n_participants(self) -> int:
        return len(self.participants)

    @property
    def n_trials(self) -> int:
        return int(self.lengths.sum())

    @property
    def n_observed(self) -> int:
        return int((self.y >= 0).sum())

    def has_successor(self) -> np.ndarray:
        """(T-1, N): True where row t is followed by a row t+1 of the same participant."""
        T = self.y.shape[0]
        return np.arange(T - 1)[:, None] < (self.lengths[None, :] - 1)

    def subset(self, idx: Sequence[int] | np.ndarray) -> Sequences:
        """Sequences ``idx`` (repeats allowed: the bootstrap resamples participants)."""
        idx = np.asarray(idx, dtype=np.int64)
        T = int(self.lengths[idx].max()) if len(idx) else 1
        return Sequences(
            [self.participants[i] for i in idx],
            self.lengths[idx],
            np.ascontiguousarray(self.y[:T, idx]),
            np.ascontiguousarray(self.ue[:T, idx]),
            np.ascontiguousarray(self.ut[:T, idx]),
            np.ascontiguousarray(self.rows[:T, idx]),
            self.n_rows,
        )


def _combination(codes: list[np.ndarray], sizes: list[int], n: int) -> np.ndarray:
    """Per row, the index of the value combination of several coded columns (C order)."""
    if not codes:
        return np.zeros(n, dtype=np.int64)
    return np.ravel_multi_index(tuple(codes), tuple(sizes)).astype(np.int64)


def _codes(frame: pd.DataFrame, spec: IOHMMSpec) -> dict[str, np.ndarray]:
    """Category codes of the model's columns (-1 = missing output); every bad value is reported."""
    problems: list[str] = []
    codes: dict[str, np.ndarray] = {}
    for col in dict.fromkeys((*spec.emission_inputs, *spec.transition_inputs, spec.output)):
        if col not in frame.columns:
            problems.append(f"column {col!r} is missing (needed by the model)")
            continue
        cats = list(spec.output_categories if col == spec.output else spec.categories[col])
        values = frame[col]
        missing = values.isna().to_numpy()
        cat = pd.Categorical(values.astype(object).where(~missing, None), categories=cats)
        c = np.asarray(cat.codes, dtype=np.int64)
        for i in np.flatnonzero((c < 0) & ~missing)[:MAX_LISTED]:
            problems.append(f"row {i + 1}, column {col!r}: value {values.iloc[i]!r} is not one of {cats}")
        if col != spec.output:
            for i in np.flatnonzero(missing)[:MAX_LISTED]:
                problems.append(f"row {i + 1}, column {col!r}: value is missing")
        codes[col] = c
    if problems:
        raise FitError(problems)
    return codes


def encode(frame: pd.DataFrame, spec: IOHMMSpec, participant: str = "participant", trial: str = "trial") -> Sequences:
    """Encode a validated trial table (one row per trial) for ``spec``.

    Participants keep their order of first appearance; trials are placed by their
    1-based index.  A missing output value is unobserved.
    """
    n = len(frame)
    codes = _codes(frame, spec)
    pid = frame[participant].astype(str).to_numpy()
    uniq, first = np.unique(pid, return_index=True)
    order_p = uniq[np.argsort(first)]
    pcode = pd.Categorical(pid, categories=order_p).codes.astype(np.int64)
    tpos = frame[trial].to_numpy().astype(np.int64) - 1
    lengths = np.bincount(pcode, minlength=len(order_p)).astype(np.int64)
    T, N = int(lengths.max()) if n else 1, len(order_p)
    if n and (tpos.min() < 0 or np.any(tpos >= lengths[pcode])):
        raise FitError(["trial indices must run 1..n within each participant"])

    def combination(inputs: tuple[str, ...]) -> np.ndarray:
        return _combination([codes[c] for c in inputs], [len(spec.categories[c]) for c in inputs], n)

    arrays = []
    for vals in (codes[spec.output], combination(spec.emission_inputs), combination(spec.transition_inputs), np.arange(n)):
        arr = np.full((T, N), -1, dtype=np.int64)
        arr[tpos, pcode] = vals
        arrays.append(arr)
    y, ue, ut, rows = arrays
    return Sequences([str(p) for p in order_p], lengths, y, ue, ut, rows, n)
