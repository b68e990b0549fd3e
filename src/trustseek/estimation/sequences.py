"""Trial tables encoded for the IOHMM: one padded, time-major integer array per quantity.

:func:`encode` turns a validated trial table (one row per trial, a participant and a
trial column counted from 1 or 0) into :class:`Sequences`: the output code and the emission- and
transition-input combination of every trial, participants side by side.  Every
E-step, M-step and bootstrap resample works on these arrays, never on the frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

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
    # y, ue and ut hold int16 codes (int32 for very many input combinations), rows int32
    n_rows: int
    base: int = 1  # the index of a participant's first trial (1, or 0 in a table counting from 0)
    trial_of_row: np.ndarray | None = None  # (n_rows,) every row's trial index, as in the table

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
            self.trial_of_row,
        )

    def spread(self, values: np.ndarray, fill: float = np.nan) -> np.ndarray:
        """Values of the frame's rows laid out (T, N) like these arrays (``fill`` at padding)."""
        out = np.full(self.rows.shape, fill, dtype=float)
        valid = self.rows >= 0
        out[valid] = values[self.rows[valid]]
        return out

    def per_row(self, arr: np.ndarray, fill: Any = np.nan, dtype: Any = float) -> np.ndarray:
        """The inverse of :meth:`spread`: a (T, N) array as the values of the frame's rows (``fill`` elsewhere)."""
        out = np.full(self.n_rows, fill, dtype=dtype)
        valid = self.rows >= 0
        out[self.rows[valid]] = arr[valid]
        return out

    def row_participants(self) -> np.ndarray:
        """Every row of the frame's participant (an index into ``participants``)."""
        return self.per_row(np.broadcast_to(np.arange(self.n_participants), self.rows.shape), 0, np.int64)

    def trial_numbers(self, t: np.ndarray, i: np.ndarray) -> np.ndarray:
        """The table's trial index of position ``t`` of sequence ``i`` (arrays of positions)."""
        if self.trial_of_row is None:
            return np.asarray(t) + self.base
        return self.trial_of_row[self.rows[t, i]]


def _code_dtype(size: int) -> type[np.signedinteger]:
    """The smallest signed integer type holding codes 0..size (and -1)."""
    return np.int16 if size < 2**15 else np.int32


def _combination(codes: list[np.ndarray], sizes: list[int], n: int) -> np.ndarray:
    """Per row, the index of the value combination of several coded columns (C order)."""
    dtype = _code_dtype(int(np.prod(sizes)) if sizes else 1)
    if not codes:
        return np.zeros(n, dtype=dtype)
    out = np.zeros(n, dtype=np.int32)
    for c, size in zip(codes, sizes, strict=True):
        out *= size
        out += c
    return out.astype(dtype, copy=False)


def _codes(frame: pd.DataFrame, spec: IOHMMSpec) -> dict[str, np.ndarray]:
    """Category codes of the model's columns (-1 = missing output); every bad value is reported.

    A categorical column (as :func:`~trustseek.data.read_trials` returns) is recoded through
    its few categories; any other column through its distinct values.
    """
    problems: list[str] = []
    codes: dict[str, np.ndarray] = {}
    outputs = (spec.output,) if spec.rating is None else (spec.output, spec.rating)
    for col in dict.fromkeys((*spec.emission_inputs, *spec.transition_inputs, *outputs)):
        if col not in frame.columns:
            problems.append(f"column {col!r} is missing (needed by the model)")
            continue
        if col == spec.rating:
            cats = list(spec.rating_levels)
        else:
            cats = list(spec.output_categories if col == spec.output else spec.categories[col])
        values = frame[col]
        if isinstance(values.dtype, pd.CategoricalDtype):  # codes into a few categories: no per-row hashing
            raw, uniques = values.cat.codes.to_numpy(), values.cat.categories
            if list(uniques) == cats and (col in outputs or not (raw < 0).any()):
                codes[col] = raw.astype(np.int16)  # the model's categories already, in its order
                continue
        else:
            raw, uniques = pd.factorize(values, use_na_sentinel=True)
        lookup = np.full(len(uniques) + 1, -1, dtype=np.int16)  # the last entry: a missing value
        unknown = np.zeros(len(uniques) + 1, dtype=bool)
        for j, u in enumerate(np.asarray(uniques, dtype=object)):
            if col == spec.rating and not isinstance(u, str):  # a numeric rating matches its level by text
                u = _level_text(u)
            if u in cats:
                lookup[j] = cats.index(u)
            else:
                unknown[j] = True
        raw = np.where(raw < 0, len(uniques), raw)
        c = lookup[raw]
        for i in np.flatnonzero(unknown[raw])[:MAX_LISTED]:
            problems.append(f"row {i + 1}, column {col!r}: value {values.iloc[i]!r} is not one of {cats}")
        if col not in outputs:
            for i in np.flatnonzero(raw == len(uniques))[:MAX_LISTED]:
                problems.append(f"row {i + 1}, column {col!r}: value is missing")
        codes[col] = c
    if problems:
        raise FitError(problems)
    return codes


def _level_text(v: object) -> object:
    """A number as a rating level's text (7.0 -> '7'); anything else unchanged."""
    if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
        return str(int(v))
    if isinstance(v, (float, np.floating)) and float(v).is_integer():
        return str(int(v))
    return str(v) if isinstance(v, (float, np.floating)) else v


def joint_codes(action: np.ndarray, rating: np.ndarray, n_outputs: int, n_ratings: int) -> np.ndarray:
    """The joint output code of (output, rating) codes, each -1 where missing: output * (R + 1) +
    rating, with a missing output counted as category M and a missing rating as R; -1 where both
    are missing (the trial then contributes probability 1, as any unobserved output)."""
    a = np.where(action < 0, n_outputs, action).astype(np.int32)
    r = np.where(rating < 0, n_ratings, rating).astype(np.int32)
    out = a * (n_ratings + 1) + r
    return np.where((action < 0) & (rating < 0), -1, out)


def participant_codes(values: pd.Series) -> tuple[np.ndarray, list[str]]:
    """Per row the participant's index, participants in order of first appearance."""
    if isinstance(values.dtype, pd.CategoricalDtype) and not values.isna().any():
        c = values.cat.codes.to_numpy()
        k = len(values.cat.categories)
        first = np.full(k, len(c), dtype=np.int64)
        if len(c):  # the first row of each code: the rows where the code changes are enough
            change = np.flatnonzero(np.r_[True, c[1:] != c[:-1]])
            np.minimum.at(first, c[change], change)
        used = np.flatnonzero(first < len(c))
        used = used[np.argsort(first[used], kind="stable")]
        remap = np.full(k, -1, dtype=np.int32)
        remap[used] = np.arange(len(used), dtype=np.int32)
        names = np.asarray(values.cat.categories, dtype=object)[used]
        return remap[c], [str(p) for p in names]
    codes, uniques = pd.factorize(values, use_na_sentinel=False)
    return np.asarray(codes, dtype=np.int32), [str(p) for p in np.asarray(uniques, dtype=object)]


def encode(frame: pd.DataFrame, spec: IOHMMSpec, participant: str = "participant", trial: str = "trial") -> Sequences:
    """Encode a validated trial table (one row per trial) for ``spec``.

    Participants keep their order of first appearance; a participant's trials are ordered by their
    index, and a gap in the numbers is not a trial of its own.  ``base`` records whether the table
    counts from 0 or 1, ``trial_of_row`` every row's index.  A missing output is unobserved; with a
    rating ``y`` holds the joint code (:func:`joint_codes`).
    """
    n = len(frame)
    codes = _codes(frame, spec)
    pcode, participants = participant_codes(frame[participant])
    trials = frame[trial].to_numpy()
    if trials.dtype.kind not in "iu":
        trials = trials.astype(np.int64)
    N = len(participants)
    lengths = np.bincount(pcode, minlength=N).astype(np.int64)
    T = int(lengths.max()) if n else 1
    base = 0 if n and int(trials.min()) == 0 else 1
    flat = np.zeros(0, dtype=np.int64)
    if n:
        lo = int(trials.min())
        if lo < 0:
            raise FitError(["trial indices must be integers >= 0"])
        span = int(trials.max()) - lo + 1
        key = pcode.astype(np.int64) * span + (trials - lo)
        order = np.argsort(key, kind="stable") if np.any(key[1:] <= key[:-1]) else None
        ks = key if order is None else key[order]
        if np.any(ks[1:] == ks[:-1]):
            raise FitError(["a participant has the same trial index twice"])
        del key, ks
        ps = pcode if order is None else pcode[order]
        offsets = np.cumsum(lengths) - lengths
        flat = (np.arange(n, dtype=np.int64) - offsets[ps]) * N + ps  # position within participant, time-major
        if order is not None:
            placed = np.empty(n, dtype=np.int64)
            placed[order] = flat
            flat = placed
        del ps

    def combination(inputs: tuple[str, ...]) -> np.ndarray:
        return _combination([codes[c] for c in inputs], [len(spec.categories[c]) for c in inputs], n)

    def spread(values: np.ndarray, dtype: type[np.signedinteger]) -> np.ndarray:
        arr = np.full((T, N), -1, dtype=dtype)
        arr.reshape(-1)[flat] = values
        return arr

    out = codes[spec.output]
    if spec.rating is not None:
        out = joint_codes(out, codes[spec.rating], spec.n_outputs, spec.n_ratings)
    y = spread(out, _code_dtype(spec.n_emitted))
    ue_codes = combination(spec.emission_inputs)
    ue = spread(ue_codes, ue_codes.dtype.type)
    del ue_codes
    ut_codes = combination(spec.transition_inputs)
    ut = spread(ut_codes, ut_codes.dtype.type)
    del ut_codes
    row_type = np.int32 if n < 2**31 else np.int64
    rows = spread(np.arange(n, dtype=row_type), row_type)
    return Sequences(participants, lengths, y, ue, ut, rows, n, base, np.asarray(trials, dtype=np.int64))


def deal_folds(n_participants: int, folds: int, key: Sequence[int]) -> np.ndarray:
    """The fold (0..folds-1) of every participant: a permutation seeded by ``key`` (a
    :class:`numpy.random.SeedSequence`'s entropy) dealt round-robin, so fold sizes differ by at
    most one.  At least 2 folds, and no more than participants (each fold holds one)."""
    if folds < 2:
        raise FitError([f"--folds must be at least 2, got {folds}"])
    if folds > n_participants:
        raise FitError([f"--folds {folds} is more than the {n_participants} participants of the log (folds are by participant)"])
    perm = np.random.default_rng(np.random.SeedSequence(list(key))).permutation(n_participants)
    fold_of = np.empty(n_participants, dtype=np.int64)
    fold_of[perm] = np.arange(n_participants) % folds
    return fold_of
