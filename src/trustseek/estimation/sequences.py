"""Trial tables encoded for the IOHMM: one padded, time-major integer array per quantity.

:func:`encode` turns a validated trial table (one row per trial, a participant and a
trial column counted from 1 or 0) into :class:`Sequences`: the output code and the emission- and
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
    base: int = 1  # the index of a participant's first trial (1, or 0 in a table counting from 0)

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
            self.base,
        )


def _combination(codes: list[np.ndarray], sizes: list[int], n: int) -> np.ndarray:
    """Per row, the index of the value combination of several coded columns (C order)."""
    if not codes:
        return np.zeros(n, dtype=np.int64)
    return np.ravel_multi_index(tuple(codes), tuple(sizes)).astype(np.int64)


def _codes(frame: pd.DataFrame, spec: IOHMMSpec) -> dict[str, np.ndarray]:
    """Category codes of the model's columns (-1 = missing output); every bad value is reported.

    A categorical column (as :func:`~trustseek.data.read_trials` returns) is recoded through
    its few categories; any other column through its distinct values.
    """
    problems: list[str] = []
    codes: dict[str, np.ndarray] = {}
    for col in dict.fromkeys((*spec.emission_inputs, *spec.transition_inputs, spec.output)):
        if col not in frame.columns:
            problems.append(f"column {col!r} is missing (needed by the model)")
            continue
        cats = list(spec.output_categories if col == spec.output else spec.categories[col])
        values = frame[col]
        raw, uniques = pd.factorize(values, use_na_sentinel=True)
        lookup = np.full(len(uniques) + 1, -1, dtype=np.int64)  # the last entry: a missing value
        unknown = np.zeros(len(uniques) + 1, dtype=bool)
        for j, u in enumerate(np.asarray(uniques, dtype=object)):
            if u in cats:
                lookup[j] = cats.index(u)
            else:
                unknown[j] = True
        raw = np.asarray(raw, dtype=np.int64)
        raw[raw < 0] = len(uniques)
        c = lookup[raw]
        for i in np.flatnonzero(unknown[raw])[:MAX_LISTED]:
            problems.append(f"row {i + 1}, column {col!r}: value {values.iloc[i]!r} is not one of {cats}")
        if col != spec.output:
            for i in np.flatnonzero(raw == len(uniques))[:MAX_LISTED]:
                problems.append(f"row {i + 1}, column {col!r}: value is missing")
        codes[col] = c
    if problems:
        raise FitError(problems)
    return codes


def encode(frame: pd.DataFrame, spec: IOHMMSpec, participant: str = "participant", trial: str = "trial") -> Sequences:
    """Encode a validated trial table (one row per trial) for ``spec``.

    Participants keep their order of first appearance; trials are placed by their
    index, counted from 1 (or from 0 in a table whose smallest index is 0; ``base``
    records which).  A missing output value is unobserved.
    """
    n = len(frame)
    codes = _codes(frame, spec)
    pcode_raw, order_p = pd.factorize(frame[participant], use_na_sentinel=False)
    pcode = np.asarray(pcode_raw, dtype=np.int64)
    participants = [str(p) for p in np.asarray(order_p, dtype=object)]
    trials = frame[trial].to_numpy().astype(np.int64)
    base = 0 if n and int(trials.min()) == 0 else 1
    tpos = trials - base
    lengths = np.bincount(pcode, minlength=len(participants)).astype(np.int64)
    T, N = int(lengths.max()) if n else 1, len(participants)
    if n and (tpos.min() < 0 or np.any(tpos >= lengths[pcode])):
        raise FitError([f"trial indices must run {base}..n within each participant"])

    def combination(inputs: tuple[str, ...]) -> np.ndarray:
        return _combination([codes[c] for c in inputs], [len(spec.categories[c]) for c in inputs], n)

    arrays = []
    for vals in (codes[spec.output], combination(spec.emission_inputs), combination(spec.transition_inputs), np.arange(n)):
        arr = np.full((T, N), -1, dtype=np.int64)
        arr[tpos, pcode] = vals
        arrays.append(arr)
    y, ue, ut, rows = arrays
    if n and int((rows >= 0).sum()) != n:
        raise FitError(["a participant has the same trial index twice"])
    return Sequences(participants, lengths, y, ue, ut, rows, n, base)
