"""The supervisor model (`TrustModel`) and the task (`Task`).

Vocabulary (fixed everywhere in trustseek):

* robot action ``a``: ``autonomous`` / ``ask``            (index 0 / 1)
* human action ``o``: ``intervene`` / ``rely``            (index 0 / 1)
* experience ``E``:   ``faulty`` / ``reliable``           (index 0 / 1)
* trust ``T`` and complexity ``C`` have user-chosen, ordered names; the paper
  uses ``low`` / ``high`` for both.  Trust levels are ordered from lowest to
  highest, so for two levels the belief is P(trust = high) = b[-1].

Array layouts (all ``numpy.float64``):

* ``TrustModel.initial[t]``                      P(T_1 = t)
* ``TrustModel.emission[c, a, t, o]``             P(o_t = o | T_t = t, C_t = c, a_t = a)
* ``TrustModel.transition[c, a, e, t, t2]``       P(T_{t+1} = t2 | T_t = t, E_{t+1} = e, C_t = c, a_t = a)
* ``TrustModel.rating.probs[t, r]``               P(self-reported rating = r | T_t = t) (optional table)
* ``Task.complexity_probs[c]``                   P(C = c), i.i.d. over trials
* ``Task.success[c]``                            P(autonomous collection succeeds | C = c)
* ``Task.ask_experience[c]``                     experience index recorded when the robot asks in complexity c

JSON formats are documented in ``docs/formats.md``.  Loading validates every
cell and reports every problem at once through :class:`ModelError`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import TrustseekError
from ..vocab import ACTIONS, ASK, AUTONOMOUS, EXPERIENCES, FAULTY, HUMAN_ACTIONS, INTERVENE, RELIABLE, RELY

__all__ = [  # the vocabulary is re-exported for convenience
    "ACTIONS",
    "ASK",
    "AUTONOMOUS",
    "EXPERIENCES",
    "FAULTY",
    "HUMAN_ACTIONS",
    "INTERVENE",
    "RELIABLE",
    "RELY",
    "ModelError",
    "RatingTable",
    "Rewards",
    "Task",
    "TrustModel",
    "UnknownComplexityError",
    "json_safe",
    "load_json",
]

ATOL = 1e-9  # tolerance for a probability row to sum to one

MODEL_FORMAT = "trustseek.trust-model/1"
IOHMM_FORMAT = "trustseek.iohmm/1"  # a general model with named inputs (model/iohmm.py)
PLANNING_INPUTS = ("complexity", "robot_action", "experience")  # the inputs of a trust model, which planning needs


def planning_refusal(inputs: Sequence[str]) -> str:
    """The one line said where a trust model is needed and a general model (with ``inputs``) is given."""
    named = ", ".join(inputs) if inputs else "none"
    return (
        f"a general IOHMM model ({IOHMM_FORMAT}, inputs: {named}) is not a trust model: planning "
        f"(solve, simulate, policies) needs a trust model ({MODEL_FORMAT}) whose inputs are among "
        f"{', '.join(PLANNING_INPUTS)} (fit with --transitions-on/--emissions-on naming only those)"
    )


TASK_FORMAT = "trustseek.task/1"


class ModelError(TrustseekError, ValueError):
    """A model, task or policy file is malformed.  ``problems`` lists every violation."""


class UnknownComplexityError(ModelError, KeyError):
    """A complexity name that the model or task does not have (a ``KeyError`` too: it is a
    failed lookup by name)."""


# --------------------------------------------------------------------------- helpers


def json_safe(obj: Any) -> Any:
    """``obj`` with every NaN or infinite float replaced by None, so that it is valid JSON
    (e.g. a threshold that does not exist because a policy's ask region is not an interval)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, Mapping):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    return obj


def _fmt(x: float) -> str:
    return f"{x:.12g}"


def _check_names(names: Any, what: str, problems: list[str], minimum: int = 2) -> list[str]:
    if names is None:  # already reported as missing
        return []
    if not isinstance(names, list) or not all(isinstance(n, str) and n for n in names):
        problems.append(f"{what} must be a list of non-empty strings, got {names!r}")
        return []
    if len(set(names)) != len(names):
        problems.append(f"{what} has duplicate names: {names!r}")
    if len(names) < minimum:
        problems.append(f"{what} needs at least {minimum} entries, got {len(names)}")
    return names


def _read_row(obj: Any, keys: Sequence[str], label: str, problems: list[str]) -> np.ndarray | None:
    """Read a probability row {key: p} and validate it; returns None if unusable."""
    if not isinstance(obj, Mapping):
        problems.append(f"{label} must be an object mapping {list(keys)} to probabilities, got {obj!r}")
        return None
    row = np.full(len(keys), np.nan)
    ok = True
    for k in obj:
        if k not in keys:
            problems.append(f"{label} has unknown entry {k!r} (expected one of {list(keys)})")
            ok = False
    for i, k in enumerate(keys):
        if k not in obj:
            problems.append(f"{label}[{k}] is missing")
            ok = False
            continue
        v = obj[k]
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            problems.append(f"{label}[{k}] must be a number, got {v!r}")
            ok = False
            continue
        v = float(v)
        if not math.isfinite(v) or v < 0.0 or v > 1.0:
            problems.append(f"{label}[{k}] = {_fmt(v)} is outside [0, 1]")
            ok = False
            continue
        row[i] = v
    if not ok:
        return None
    s = float(row.sum())
    if abs(s - 1.0) > ATOL:
        problems.append(f"{label} sums to {_fmt(s)}")
        return None
    return row


def _get(obj: Any, key: str, label: str, problems: list[str]) -> Any:
    if not isinstance(obj, Mapping):
        problems.append(f"{label} must be an object, got {obj!r}")
        return None
    if key not in obj:
        problems.append(f"{label} is missing")
        return None
    if obj[key] is None:
        problems.append(f"{label} is null")
    return obj[key]


def _unknown_keys(obj: Any, allowed: Iterable[str], label: str, problems: list[str]) -> None:
    if isinstance(obj, Mapping):
        allowed = list(allowed)
        for k in obj:
            if k not in allowed:
                problems.append(f"{label} has unknown entry {k!r} (expected one of {allowed})")


def _nested(arr: np.ndarray, levels: Sequence[Sequence[str]]) -> dict[str, Any]:
    """An array as nested {name: ...} objects, one level per axis."""
    if len(levels) == 1:
        return {n: float(arr[i]) for i, n in enumerate(levels[0])}
    return {n: _nested(arr[i], levels[1:]) for i, n in enumerate(levels[0])}


def _read_table(
    obj: Any,
    base: str,
    outer: Sequence[tuple[str, Sequence[str]]],
    inner: tuple[str, Sequence[str]],
    row_keys: Sequence[str],
    out: np.ndarray,
    problems: list[str],
) -> None:
    """Read nested probability rows into ``out``, naming each cell like
    ``transition[C=high, a=ask, E=reliable][T=low]``: the ``outer`` axes inside the first
    brackets, the ``inner`` (conditioning trust) axis in the second, then the row's keys."""
    sym_in, names_in = inner

    def label(parts: list[str], t: str | None = None) -> str:
        s = f"{base}[{', '.join(parts)}]" if parts else base
        return s if t is None else f"{s}[{sym_in}={t}]"

    def walk(node: Any, depth: int, parts: list[str], idx: tuple[int, ...]) -> None:
        if depth == len(outer):
            _unknown_keys(node, names_in, label(parts), problems)
            for t, tn in enumerate(names_in):
                cell = _get(node, tn, label(parts, tn), problems)
                if cell is not None:
                    row = _read_row(cell, row_keys, label(parts, tn), problems)
                    if row is not None:
                        out[idx + (t,)] = row
            return
        sym, names = outer[depth]
        _unknown_keys(node, names, label(parts), problems)
        for i, n in enumerate(names):
            child = _get(node, n, label(parts + [f"{sym}={n}"]), problems)
            if child is not None:
                walk(child, depth + 1, parts + [f"{sym}={n}"], idx + (i,))

    walk(obj, 0, [], ())


def _check_row_array(arr: np.ndarray, label_of, problems: list[str]) -> None:
    """Validate the last axis of ``arr`` as probability rows (for arrays built in Python)."""
    if not np.all(np.isfinite(arr)):
        problems.append("contains NaN or infinite values")
        return
    for idx in np.ndindex(arr.shape[:-1]):
        row = arr[idx]
        if np.any(row < 0) or np.any(row > 1):
            problems.append(f"{label_of(idx)} has entries outside [0, 1]: {row.tolist()}")
        elif abs(row.sum() - 1.0) > ATOL:
            problems.append(f"{label_of(idx)} sums to {_fmt(float(row.sum()))}")


def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a valid JSON number (use a finite number or null where allowed)")


def load_json(path: str | Path, expect: type | None = dict) -> tuple[Any, str]:
    """The parsed JSON of the file at ``path`` and the file's name (for error messages).

    Every way a file can fail to be JSON is a :class:`ModelError` naming the file: missing,
    a directory, unreadable, not UTF-8 text (binary or another encoding), invalid JSON (with
    line and column), the non-standard ``NaN``/``Infinity`` literals, and (with ``expect``,
    an object by default) the wrong top-level type.
    """
    path = Path(path)
    source = str(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ModelError(["file not found"], source) from None
    except IsADirectoryError:
        raise ModelError(["is a directory, expected a JSON file"], source) from None
    except OSError as exc:
        raise ModelError([f"cannot read file: {exc.strerror or exc}"], source) from None
    if b"\x00" in raw:
        raise ModelError(["is a binary file, expected JSON text"], source)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ModelError([f"is not UTF-8 text (byte {exc.start}): save it as UTF-8 JSON"], source) from None
    if not text.strip():
        raise ModelError(["is empty, expected JSON"], source)
    try:
        data = json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as exc:
        raise ModelError([f"invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}"], source) from None
    except ValueError as exc:  # NaN / Infinity
        raise ModelError([f"invalid JSON: {exc}"], source) from None
    except RecursionError:
        raise ModelError(["invalid JSON: nested too deeply"], source) from None
    if expect is not None and not isinstance(data, expect):
        kind = "an object" if expect is dict else expect.__name__
        raise ModelError([f"the top level must be {kind} ({{...}}), got {type(data).__name__}"], source)
    return data, source


def _paper_value(key: str) -> str:
    """The default of a Task field, as the error for a task file that lacks it shows it."""
    if key == "rewards":
        return json.dumps(Rewards().to_dict())
    return _fmt(Task.discount)


# --------------------------------------------------------------------------- TrustModel


@dataclass(frozen=True, eq=False)
class RatingTable:
    """A self-reported trust rating as a second emission of the hidden trust.

    ``levels`` are the rating's ordinal levels, lowest first (e.g. ``"1"`` .. ``"7"``, or
    labels); ``probs[t, r]`` is P(rating = levels[r] | trust level t), one free row per trust
    level.  The rating depends on the trust only (not on complexity or the robot action),
    and a trial without a rating contributes probability 1.
    """

    levels: tuple[str, ...]
    probs: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "levels", tuple(self.levels))
        arr = np.array(self.probs, dtype=np.float64)
        arr.setflags(write=False)
        object.__setattr__(self, "probs", arr)

    @property
    def n_levels(self) -> int:
        return len(self.levels)

    def problems(self, trust_levels: Sequence[str]) -> list[str]:
        """Every violation of the table's constraints for a model with ``trust_levels``."""
        problems: list[str] = []
        if not all(isinstance(n, str) and n for n in self.levels):
            problems.append(f"rating levels must be non-empty strings, got {list(self.levels)!r}")
        if len(set(self.levels)) != len(self.levels):
            problems.append(f"rating levels have duplicate names: {list(self.levels)}")
        if len(self.levels) < 2:
            problems.append(f"rating levels need at least 2 entries, got {len(self.levels)}")
        shape = (len(trust_levels), len(self.levels))
        if self.probs.shape != shape:
            problems.append(
                f"rating probabilities have shape {self.probs.shape}, expected {shape} (trust levels x rating levels)"
            )
            return problems
        _check_row_array(self.probs, lambda i: f"rating[T={trust_levels[i[0]]}]", problems)
        return problems

    def to_dict(self, trust_levels: Sequence[str]) -> dict[str, Any]:
        return {"levels": list(self.levels), "probs": _nested(self.probs, [trust_levels, self.levels])}

    @classmethod
    def read(cls, obj: Any, trust_levels: Sequence[str], problems: list[str]) -> RatingTable | None:
        """The ``rating`` entry of a model file (``{"levels": [...], "probs": {T: {level: p}}}``);
        every problem is appended to ``problems``."""
        if not isinstance(obj, Mapping):
            problems.append(f"rating must be an object with 'levels' and 'probs', got {obj!r}")
            return None
        _unknown_keys(obj, ["levels", "probs"], "rating", problems)
        levels = _check_names(_get(obj, "levels", "rating.levels", problems), "rating.levels", problems)
        raw = _get(obj, "probs", "rating.probs", problems)
        if not levels or raw is None:
            return None
        probs = np.full((len(trust_levels), len(levels)), np.nan)
        _unknown_keys(raw, trust_levels, "rating.probs", problems)
        for t, name in enumerate(trust_levels):
            cell = _get(raw, name, f"rating[T={name}]", problems)
            if cell is not None:
                row = _read_row(cell, levels, f"rating[T={name}]", problems)
                if row is not None:
                    probs[t] = row
        return cls(tuple(levels), probs)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, RatingTable):
            return NotImplemented
        return self.levels == other.levels and np.array_equal(self.probs, other.probs)


@dataclass(frozen=True, eq=False)
class TrustModel:
    """The supervisor: hidden trust, its dynamics, and how it drives the human action."""

    trust_levels: tuple[str, ...]
    complexities: tuple[str, ...]
    initial: np.ndarray
    emission: np.ndarray
    transition: np.ndarray
    notes: str = ""
    # rows no data ever estimated (e.g. every ask row of a model fitted from a study without
    # asking): ("emission", (c, a)) or ("transition", (c, a, e)); empty = all estimated
    not_estimated: tuple[tuple[str, tuple[int, ...]], ...] = ()
    # the optional second emission: a self-reported rating, P(rating | trust) (None: no ratings)
    rating: RatingTable | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "trust_levels", tuple(self.trust_levels))
        object.__setattr__(self, "complexities", tuple(self.complexities))
        object.__setattr__(
            self, "not_estimated", tuple(sorted({(str(t), tuple(int(i) for i in idx)) for t, idx in self.not_estimated}))
        )
        for name in ("initial", "emission", "transition"):
            arr = np.array(getattr(self, name), dtype=np.float64)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        problems = self.problems()
        if problems:
            raise ModelError(problems)

    # -- shape -------------------------------------------------------------
    @property
    def n_trust(self) -> int:
        return len(self.trust_levels)

    @property
    def n_complexity(self) -> int:
        return len(self.complexities)

    def problems(self) -> list[str]:
        """Every violation of the model's constraints, as human-readable lines."""
        K, N = len(self.trust_levels), len(self.complexities)
        problems: list[str] = []
        for what, names in (("trust_levels", self.trust_levels), ("complexities", self.complexities)):
            if len(set(names)) != len(names):
                problems.append(f"{what} has duplicate names: {list(names)}")
            if len(names) < 2:
                problems.append(f"{what} needs at least 2 entries, got {len(names)}")
        shapes = {
            "initial": (K,),
            "emission": (N, 2, K, 2),
            "transition": (N, 2, 2, K, K),
        }
        for name, shape in shapes.items():
            if getattr(self, name).shape != shape:
                problems.append(f"{name} has shape {getattr(self, name).shape}, expected {shape}")
        if problems:
            return problems
        T, C = self.trust_levels, self.complexities
        _check_row_array(self.initial[None, :], lambda idx: "initial", problems)
        _check_row_array(
            self.emission,
            lambda i: f"emission[C={C[i[0]]}, a={ACTIONS[i[1]]}][T={T[i[2]]}]",
            problems,
        )
        _check_row_array(
            self.transition,
            lambda i: f"transition[C={C[i[0]]}, a={ACTIONS[i[1]]}, E={EXPERIENCES[i[2]]}][T={T[i[3]]}]",
            problems,
        )
        row_shapes: dict[str, tuple[int, ...]] = {"emission": (N, 2), "transition": (N, 2, 2)}
        for table, idx in self.not_estimated:
            rshape = row_shapes.get(table)
            if rshape is None or len(idx) != len(rshape) or any(not 0 <= i < n for i, n in zip(idx, rshape, strict=False)):
                problems.append(f"not_estimated: {table}{list(idx)} is not a row of the model")
        if self.rating is not None:
            if not isinstance(self.rating, RatingTable):
                problems.append(f"rating must be a RatingTable, got {type(self.rating).__name__}")
            else:
                problems += self.rating.problems(T)
        return problems

    # -- convenience -------------------------------------------------------
    def trust_index(self, name: str) -> int:
        return self.trust_levels.index(name)

    def complexity_index(self, name: str) -> int:
        try:
            return self.complexities.index(name)
        except ValueError:
            raise UnknownComplexityError([f"unknown complexity {name!r}; expected one of {list(self.complexities)}"]) from None

    def row_name(self, table: str, idx: Sequence[int]) -> str:
        """``emission[C=high, a=ask]`` or ``transition[C=high, a=ask, E=reliable]``."""
        parts = [f"C={self.complexities[idx[0]]}", f"a={ACTIONS[idx[1]]}"]
        if table == "transition":
            parts.append(f"E={EXPERIENCES[idx[2]]}")
        return f"{table}[{', '.join(parts)}]"

    def not_estimated_rows(self) -> list[str]:
        """The rows no data estimated, by name (:meth:`row_name`)."""
        return [self.row_name(t, idx) for t, idx in self.not_estimated]

    def filled_from(self, other: TrustModel) -> TrustModel:
        """This model with every never-estimated row taken from ``other`` (same levels and complexities)."""
        if other.trust_levels != self.trust_levels or other.complexities != self.complexities:
            raise ModelError(
                [
                    f"cannot fill from a model with trust levels {list(other.trust_levels)} and complexities "
                    f"{list(other.complexities)}: this one has {list(self.trust_levels)} and {list(self.complexities)}"
                ]
            )
        em, tr = self.emission.copy(), self.transition.copy()
        for table, idx in self.not_estimated:
            (em if table == "emission" else tr)[idx] = (other.emission if table == "emission" else other.transition)[idx]
        still = tuple(r for r in self.not_estimated if r in other.not_estimated)
        return self.replace(emission=em, transition=tr, not_estimated=still)

    def p_intervene(self, belief: np.ndarray, c: int, a: int) -> float:
        """P(o = intervene | belief, C = c, a) for a belief vector over trust levels."""
        return float(np.asarray(belief) @ self.emission[c, a, :, INTERVENE])

    # -- JSON --------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        T, C = self.trust_levels, self.complexities
        return {
            "format": MODEL_FORMAT,
            "notes": self.notes,
            "trust_levels": list(T),
            "complexities": list(C),
            "initial": _nested(self.initial, [T]),
            "emission": _nested(self.emission, [C, ACTIONS, T, HUMAN_ACTIONS]),
            "transition": _nested(self.transition, [C, ACTIONS, EXPERIENCES, T, T]),
            **({"not_estimated": [_row_dict(t, idx, C) for t, idx in self.not_estimated]} if self.not_estimated else {}),
            **({"rating": self.rating.to_dict(T)} if self.rating is not None else {}),
        }

    @classmethod
    def from_dict(cls, d: Any, source: str | None = None) -> TrustModel:
        problems: list[str] = []
        if not isinstance(d, Mapping):
            raise ModelError([f"a trust model must be a JSON object, got {type(d).__name__}"], source)
        fmt = d.get("format", MODEL_FORMAT)
        if fmt == IOHMM_FORMAT:
            inputs = [*d.get("emission_inputs", []), *d.get("transition_inputs", [])]
            raise ModelError([planning_refusal([str(c) for c in dict.fromkeys(inputs)])], source)
        if fmt != MODEL_FORMAT:
            problems.append(f"format is {fmt!r}, expected {MODEL_FORMAT!r}")
        _unknown_keys(
            d,
            ["format", "notes", "trust_levels", "complexities", "initial", "emission", "transition", "not_estimated", "rating"],
            "model",
            problems,
        )
        T = _check_names(_get(d, "trust_levels", "trust_levels", problems), "trust_levels", problems)
        C = _check_names(_get(d, "complexities", "complexities", problems), "complexities", problems)
        if problems or not T or not C:
            raise ModelError(problems, source)
        K, N = len(T), len(C)
        initial = np.full(K, np.nan)
        emission = np.full((N, 2, K, 2), np.nan)
        transition = np.full((N, 2, 2, K, K), np.nan)

        init = _get(d, "initial", "initial", problems)
        if init is not None:
            row = _read_row(init, T, "initial", problems)
            if row is not None:
                initial[:] = row

        em = _get(d, "emission", "emission", problems)
        if em is not None:
            _read_table(em, "emission", [("C", C), ("a", ACTIONS)], ("T", T), HUMAN_ACTIONS, emission, problems)
        tr = _get(d, "transition", "transition", problems)
        if tr is not None:
            _read_table(tr, "transition", [("C", C), ("a", ACTIONS), ("E", EXPERIENCES)], ("T", T), T, transition, problems)
        notes = d.get("notes", "")
        if not isinstance(notes, str):
            problems.append(f"notes must be a string, got {notes!r}")
        not_estimated = _read_not_estimated(d.get("not_estimated", []), C, problems)
        rating = RatingTable.read(d["rating"], T, problems) if d.get("rating") is not None else None
        if problems:
            raise ModelError(problems, source)
        try:
            return cls(tuple(T), tuple(C), initial, emission, transition, notes=notes, not_estimated=not_estimated, rating=rating)
        except ModelError as exc:
            raise ModelError(exc.problems, source) from None

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n", encoding="utf-8")

    @classmethod
    def load(cls, path: str | Path) -> TrustModel:
        d, source = load_json(path)
        return cls.from_dict(d, source)

    def replace(self, **changes: Any) -> TrustModel:
        kw: dict[str, Any] = {
            "trust_levels": self.trust_levels,
            "complexities": self.complexities,
            "initial": self.initial,
            "emission": self.emission,
            "transition": self.transition,
            "notes": self.notes,
            "not_estimated": self.not_estimated,
            "rating": self.rating,
        }
        kw.update(changes)
        return TrustModel(**kw)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, TrustModel):
            return NotImplemented
        return (
            self.trust_levels == other.trust_levels
            and self.complexities == other.complexities
            and np.array_equal(self.initial, other.initial)
            and np.array_equal(self.emission, other.emission)
            and np.array_equal(self.transition, other.transition)
            and self.not_estimated == other.not_estimated
            and self.rating == other.rating
        )


def _row_dict(table: str, idx: tuple[int, ...], C: Sequence[str]) -> dict[str, str]:
    d = {"table": table, "C": C[idx[0]], "a": ACTIONS[idx[1]]}
    if table == "transition":
        d["E"] = EXPERIENCES[idx[2]]
    return d


def _read_not_estimated(raw: Any, C: Sequence[str], problems: list[str]) -> tuple[tuple[str, tuple[int, ...]], ...]:
    """``not_estimated``: a list of rows ``{"table": "emission"|"transition", "C": .., "a": .., ["E": ..]}``."""
    if not isinstance(raw, list):
        problems.append(f"not_estimated must be a list of rows, got {raw!r}")
        return ()
    out = []
    for i, row in enumerate(raw):
        where = f"not_estimated[{i}]"
        if not isinstance(row, Mapping) or row.get("table") not in ("emission", "transition"):
            problems.append(f"{where}: expected {{'table': 'emission' or 'transition', 'C': ..., 'a': ...}}, got {row!r}")
            continue
        keys = [("C", list(C)), ("a", list(ACTIONS))] + ([("E", list(EXPERIENCES))] if row["table"] == "transition" else [])
        extra = set(row) - {"table", *(k for k, _ in keys)}
        if extra:
            problems.append(f"{where}: unknown keys {sorted(extra)}")
        idx = []
        for k, names in keys:
            if row.get(k) not in names:
                problems.append(f"{where}: {k} = {row.get(k)!r} is not one of {names}")
            else:
                idx.append(names.index(row[k]))
        if len(idx) == len(keys):
            out.append((str(row["table"]), tuple(idx)))
    return tuple(out)


# --------------------------------------------------------------------------- Task


@dataclass(frozen=True)
class Rewards:
    """The per-trial team reward of eq. (1)."""

    autonomous_success: float = 2.0  # (autonomous, rely, reliable)
    ask: float = 1.0  # robot asked; human teleoperates
    intervene: float = 0.0  # (autonomous, intervene)
    autonomous_failure: float = -3.0  # (autonomous, rely, faulty)

    def to_dict(self) -> dict[str, float]:
        return {
            "autonomous_success": self.autonomous_success,
            "ask": self.ask,
            "intervene": self.intervene,
            "autonomous_failure": self.autonomous_failure,
        }

    def of(self, action: int, human_action: int, experience: int) -> float:
        """Reward of one trial from its robot action, human action and experience indices."""
        if action == ASK:
            return self.ask
        if human_action == INTERVENE:
            return self.intervene
        return self.autonomous_success if experience == RELIABLE else self.autonomous_failure


@dataclass(frozen=True, eq=False)
class Task:
    """The object-collection task: complexity distribution, robot skill, rewards, discount."""

    complexities: tuple[str, ...]
    complexity_probs: np.ndarray
    success: np.ndarray
    ask_experience: tuple[int, ...]
    rewards: Rewards = field(default_factory=Rewards)
    discount: float = 0.987

    def __post_init__(self) -> None:
        object.__setattr__(self, "complexities", tuple(self.complexities))
        object.__setattr__(self, "ask_experience", tuple(int(x) for x in self.ask_experience))
        for name in ("complexity_probs", "success"):
            arr = np.array(getattr(self, name), dtype=np.float64)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        problems = self.problems()
        if problems:
            raise ModelError(problems)

    @property
    def n_complexity(self) -> int:
        return len(self.complexities)

    def problems(self) -> list[str]:
        N = len(self.complexities)
        problems: list[str] = []
        if len(set(self.complexities)) != N:
            problems.append(f"complexities has duplicate names: {list(self.complexities)}")
        if N < 2:
            problems.append(f"complexities needs at least 2 entries, got {N}")
        if self.complexity_probs.shape != (N,) or self.success.shape != (N,) or len(self.ask_experience) != N:
            problems.append("complexity_probs, success and ask_experience need one entry per complexity")
            return problems
        _check_row_array(self.complexity_probs[None, :], lambda i: "complexity probabilities", problems)
        for c, cn in enumerate(self.complexities):
            s = self.success[c]
            if not (math.isfinite(s) and 0.0 <= s <= 1.0):
                problems.append(f"complexities[{cn}].success = {_fmt(float(s))} is outside [0, 1]")
            if self.ask_experience[c] not in (FAULTY, RELIABLE):
                problems.append(f"complexities[{cn}].ask_experience must be 'faulty' or 'reliable'")
        if not (math.isfinite(self.discount) and 0.0 <= self.discount < 1.0):
            problems.append(f"discount = {_fmt(self.discount)} must lie in [0, 1)")
        for k, v in self.rewards.to_dict().items():
            if not math.isfinite(v):
                problems.append(f"rewards[{k}] = {v!r} must be a finite number")
        return problems

    def complexity_index(self, name: str) -> int:
        try:
            return self.complexities.index(name)
        except ValueError:
            raise UnknownComplexityError([f"unknown complexity {name!r}; expected one of {list(self.complexities)}"]) from None

    def p_experience(self, c: int, a: int, o: int) -> np.ndarray:
        """P(E_{t+1} | o_t, C_t = c, a_t = a) as a length-2 array over (faulty, reliable)."""
        if a == ASK:
            e = self.ask_experience[c]
            return np.array([1.0 - e, float(e)])
        if o == INTERVENE:
            return np.array([1.0, 0.0])
        s = float(self.success[c])
        return np.array([1.0 - s, s])

    def experience_table(self) -> np.ndarray:
        """P(E' | o, C, a) as an array indexed [c, a, o, e]."""
        out = np.zeros((self.n_complexity, 2, 2, 2))
        for c in range(self.n_complexity):
            for a in range(2):
                for o in range(2):
                    out[c, a, o] = self.p_experience(c, a, o)
        return out

    def reward_table(self) -> np.ndarray:
        """Reward of eq. (1) as an array indexed [a, o, e]."""
        out = np.zeros((2, 2, 2))
        for a in range(2):
            for o in range(2):
                for e in range(2):
                    out[a, o, e] = self.rewards.of(a, o, e)
        return out

    def check_compatible(self, model: TrustModel) -> None:
        """Refuse a model whose complexities differ, or with never-estimated rows this task can reach."""
        if tuple(model.complexities) != tuple(self.complexities):
            raise ModelError(
                [
                    f"the model's complexities {list(model.complexities)} differ from the task's "
                    f"{list(self.complexities)} (names and order must match)"
                ]
            )
        used = self.unestimated_rows_used(model)
        if used:
            raise ModelError(
                [
                    f"{r} was never estimated (the data had no such trials) and planning or simulating with this task uses it"
                    for r in used
                ]
                + [
                    "supply those rows: refit with 'trustseek fit ... --fill-from paper' (or another model file), "
                    'or write them into the model file and remove them from its "not_estimated" list '
                    "(docs/formats.md)"
                ]
            )

    def unestimated_rows_used(self, model: TrustModel) -> list[str]:
        """Never-estimated rows of ``model`` a trial of this task can reach: every emission row, the
        transitions after acting autonomously (either experience) and after asking (its experience)."""
        out = []
        for table, idx in model.not_estimated:
            if table == "transition" and idx[1] == ASK and idx[2] != self.ask_experience[idx[0]]:
                continue
            out.append(model.row_name(table, idx))
        return out

    # -- JSON --------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return {
            "format": TASK_FORMAT,
            "complexities": {
                cn: {
                    "probability": float(self.complexity_probs[c]),
                    "success": float(self.success[c]),
                    "ask_experience": EXPERIENCES[self.ask_experience[c]],
                }
                for c, cn in enumerate(self.complexities)
            },
            "rewards": self.rewards.to_dict(),
            "discount": self.discount,
        }

    @classmethod
    def from_dict(cls, d: Any, source: str | None = None) -> Task:
        problems: list[str] = []
        if not isinstance(d, Mapping):
            raise ModelError([f"a task must be a JSON object, got {type(d).__name__}"], source)
        fmt = d.get("format", TASK_FORMAT)
        if fmt != TASK_FORMAT:
            problems.append(f"format is {fmt!r}, expected {TASK_FORMAT!r}")
        _unknown_keys(d, ["format", "complexities", "rewards", "discount"], "task", problems)
        cx = _get(d, "complexities", "complexities", problems)
        names: list[str] = []
        probs: list[float] = []
        succ: list[float] = []
        askx: list[int] = []
        if cx is not None:
            if not isinstance(cx, Mapping) or len(cx) < 2:
                problems.append("complexities must be an object with at least 2 named levels")
            else:
                for cn, spec in cx.items():
                    names.append(cn)
                    lab = f"complexities[{cn}]"
                    if not isinstance(spec, Mapping):
                        problems.append(f"{lab} must be an object, got {spec!r}")
                        continue
                    _unknown_keys(spec, ["probability", "success", "ask_experience"], lab, problems)
                    for key, store in (("probability", probs), ("success", succ)):
                        v = _get(spec, key, f"{lab}.{key}", problems)
                        if v is None:
                            continue
                        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (0.0 <= float(v) <= 1.0):
                            problems.append(f"{lab}.{key} = {v!r} must be a probability in [0, 1]")
                            continue
                        store.append(float(v))
                    ae = _get(spec, "ask_experience", f"{lab}.ask_experience", problems)
                    if ae is not None:
                        if ae not in EXPERIENCES:
                            problems.append(f"{lab}.ask_experience = {ae!r} must be one of {list(EXPERIENCES)}")
                        else:
                            askx.append(EXPERIENCES.index(ae))
                if not problems and abs(sum(probs) - 1.0) > ATOL:
                    problems.append(f"complexity probabilities sum to {_fmt(sum(probs))}")
        rw = d.get("rewards", {})
        rewards = Rewards()
        for key in ("rewards", "discount"):
            if key not in d:
                problems.append(
                    f"{key} is missing (the paper's task has {key} = {_paper_value(key)}; 'trustseek preset "
                    "--task-out task.json' writes a complete task to start from)"
                )
        if not isinstance(rw, Mapping):
            problems.append(f"rewards must be an object, got {rw!r}")
        else:
            _unknown_keys(rw, Rewards().to_dict().keys(), "rewards", problems)
            for k in Rewards().to_dict():
                if "rewards" in d and k not in rw:
                    problems.append(f"rewards[{k}] is missing")
            vals = {}
            for k, v in rw.items():
                if k in Rewards().to_dict():
                    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
                        problems.append(f"rewards[{k}] = {v!r} must be a finite number")
                    else:
                        vals[k] = float(v)
            rewards = Rewards(**vals)
        disc = d.get("discount", Task.discount)
        if isinstance(disc, bool) or not isinstance(disc, (int, float)) or not (0.0 <= float(disc) < 1.0):
            problems.append(f"discount = {disc!r} must be a number in [0, 1)")
        if problems:
            raise ModelError(problems, source)
        try:
            return cls(tuple(names), np.array(probs), np.array(succ), tuple(askx), rewards, float(disc))
        except ModelError as exc:
            raise ModelError(exc.problems, source) from None

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n", encoding="utf-8")

    @classmethod
    def load(cls, path: str | Path) -> Task:
        d, source = load_json(path)
        return cls.from_dict(d, source)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Task):
            return NotImplemented
        return (
            self.complexities == other.complexities
            and np.array_equal(self.complexity_probs, other.complexity_probs)
            and np.array_equal(self.success, other.success)
            and self.ask_experience == other.ask_experience
            and self.rewards == other.rewards
            and self.discount == other.discount
        )
