"""Reading trustseek's JSON files with every problem reported at once: ``load_json`` (the file
itself), the checks of names, probability rows and nested tables that the model, task and
mixture readers share, and ``ModelError``, which carries all the problems found."""

from __future__ import annotations

import json
import math
import stat
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import fields
from pathlib import Path
from typing import Any, Self, TypeGuard, TypeVar

import numpy as np

from ..errors import TrustseekError

ATOL = 1e-9  # tolerance for a probability row to sum to one
T = TypeVar("T")


class ModelError(TrustseekError, ValueError):
    """A model, task or policy file is malformed.  ``problems`` lists every violation."""


def freeze_arrays(obj: Any, *names: str) -> None:
    """Each named field of the frozen dataclass ``obj`` as a read-only float64 array."""
    for name in names:
        arr = np.array(getattr(obj, name), dtype=np.float64)
        arr.setflags(write=False)
        object.__setattr__(obj, name, arr)


def build(problems: list[str], source: str | None, make: Callable[[], T]) -> T:
    """``make()`` once a reader found no ``problems`` (its arguments may rely on that): every problem,
    the reader's or the constructor's, raised as one :class:`ModelError` naming ``source``."""
    if problems:
        raise ModelError(problems, source)
    try:
        return make()
    except ModelError as exc:
        raise ModelError(exc.problems, source) from None


class UnknownComplexityError(ModelError, KeyError):
    """A complexity name that the model or task does not have (a ``KeyError`` too: it is a
    failed lookup by name)."""


def complexity_index(complexities: Sequence[str], name: str) -> int:
    """The index of complexity ``name`` among ``complexities`` (a model's or a task's)."""
    try:
        return complexities.index(name)
    except ValueError:
        raise UnknownComplexityError([f"unknown complexity {name!r}; expected one of {list(complexities)}"]) from None


def read_notes(d: Mapping[str, Any], problems: list[str]) -> str:
    """A file's ``notes`` (empty when absent): a string."""
    notes = d.get("notes", "")
    if not isinstance(notes, str):
        problems.append(f"notes must be a string, got {notes!r}")
    return notes


def json_safe(obj: Any) -> Any:
    """``obj`` as plain JSON values: every NaN or infinite float becomes None (e.g. a threshold
    that does not exist because a policy's ask region is not an interval), numpy scalars and
    arrays become Python numbers and lists, tuples become lists and mapping keys strings."""
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, Mapping):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return json_safe(obj.tolist())
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def is_number(v: Any) -> TypeGuard[int | float]:
    """Whether a JSON value is a number (``true`` and ``false`` are not)."""
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def fmt_number(x: float) -> str:
    return f"{x:.12g}"


def check_names(names: Any, what: str, problems: list[str], minimum: int = 2) -> list[str]:
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


def read_row(obj: Any, keys: Sequence[str], label: str, problems: list[str]) -> np.ndarray | None:
    """Read a probability row {key: p} and validate it; returns None if unusable."""
    if not isinstance(obj, Mapping):
        problems.append(f"{label} must be an object mapping {list(keys)} to probabilities, got {obj!r}")
        return None
    before = len(problems)
    unknown_keys(obj, keys, label, problems)
    row = np.full(len(keys), np.nan)
    for i, k in enumerate(keys):
        v = obj.get(k)
        if k not in obj:
            problems.append(f"{label}[{k}] is missing")
        elif not is_number(v):
            problems.append(f"{label}[{k}] must be a number, got {v!r}")
        elif not math.isfinite(v) or v < 0.0 or v > 1.0:
            problems.append(f"{label}[{k}] = {fmt_number(float(v))} is outside [0, 1]")
        else:
            row[i] = v
    if len(problems) > before:
        return None
    s = float(row.sum())
    if abs(s - 1.0) > ATOL:
        problems.append(f"{label} sums to {fmt_number(s)}")
        return None
    return row


def read_entry(obj: Any, key: str, label: str, keys: Sequence[str], problems: list[str]) -> np.ndarray | None:
    """The probability row ``obj[key]`` (``{key: p}`` over ``keys``), named ``label``; None if
    missing or unusable."""
    cell = get_key(obj, key, label, problems)
    return None if cell is None else read_row(cell, keys, label, problems)


def get_key(obj: Any, key: str, label: str, problems: list[str]) -> Any:
    if not isinstance(obj, Mapping):
        problems.append(f"{label} must be an object, got {obj!r}")
        return None
    if key not in obj:
        problems.append(f"{label} is missing")
        return None
    if obj[key] is None:
        problems.append(f"{label} is null")
    return obj[key]


def unknown_keys(obj: Any, allowed: Iterable[str], label: str, problems: list[str]) -> None:
    if isinstance(obj, Mapping):
        allowed = list(allowed)
        for k in obj:
            if k not in allowed:
                problems.append(f"{label} has unknown entry {k!r} (expected one of {allowed})")


def nested(arr: np.ndarray, levels: Sequence[Sequence[str]]) -> dict[str, Any]:
    """An array as nested {name: ...} objects, one level per axis."""
    if len(levels) == 1:
        return {n: float(arr[i]) for i, n in enumerate(levels[0])}
    return {n: nested(arr[i], levels[1:]) for i, n in enumerate(levels[0])}


def read_table(
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
            unknown_keys(node, names_in, label(parts), problems)
            for t, tn in enumerate(names_in):
                row = read_entry(node, tn, label(parts, tn), row_keys, problems)
                if row is not None:
                    out[idx + (t,)] = row
            return
        sym, names = outer[depth]
        unknown_keys(node, names, label(parts), problems)
        for i, n in enumerate(names):
            child = get_key(node, n, label(parts + [f"{sym}={n}"]), problems)
            if child is not None:
                walk(child, depth + 1, parts + [f"{sym}={n}"], idx + (i,))

    walk(obj, 0, [], ())


def check_row_array(arr: np.ndarray, label_of, problems: list[str]) -> None:
    """Validate the last axis of ``arr`` as probability rows (for arrays built in Python)."""
    if not np.all(np.isfinite(arr)):
        problems.append("contains NaN or infinite values")
        return
    for idx in np.ndindex(arr.shape[:-1]):
        row = arr[idx]
        if np.any(row < 0) or np.any(row > 1):
            problems.append(f"{label_of(idx)} has entries outside [0, 1]: {row.tolist()}")
        elif abs(row.sum() - 1.0) > ATOL:
            problems.append(f"{label_of(idx)} sums to {fmt_number(float(row.sum()))}")


def _pairs_hook(duplicates: list[str]):
    """A ``json.loads`` object hook that builds each object and records every key it holds twice
    (JSON readers differ on which value wins, so a file with one is ambiguous)."""

    def hook(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        obj: dict[str, Any] = {}
        for k, v in pairs:
            if k in obj:
                keys = list(dict.fromkeys(key for key, _ in pairs))
                shown = keys if len(keys) <= 8 else [*keys[:8], "..."]
                duplicates.append(f"the key {k[:80]!r} appears twice in one object (with keys {shown}); keep one")
            obj[k] = v
        return obj

    return hook


def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a valid JSON number (use a finite number or null where allowed)")


def special_file(path: Path) -> str:
    """What ``path`` is when it exists and is neither a regular file nor a folder (a FIFO, a
    socket, a device: reading it could wait forever); empty otherwise."""
    try:
        mode = path.stat().st_mode
    except OSError:
        return ""  # missing or unreadable: the read says which
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return ""
    if stat.S_ISFIFO(mode):
        return "a named pipe (FIFO), not a regular file"
    if stat.S_ISSOCK(mode):
        return "a socket, not a regular file"
    return "a device, not a regular file"


def read_text(path: str | Path, kind: str, error: type[TrustseekError], encoding: str = "utf-8", hint: str = "") -> str:
    """The text of the file at ``path``, or ``error`` naming the file and what is wrong with it:
    missing, a directory, unreadable, binary (a NUL byte), or not text in ``encoding`` (with the
    byte, then ``hint``).  ``kind`` names what was expected ("JSON", ".pomdp")."""
    source = str(path)
    special = special_file(Path(path))
    if special:
        raise error([f"is {special}, expected a {kind} file"], source)
    try:
        raw = Path(path).read_bytes()
    except FileNotFoundError:
        raise error(["file not found"], source) from None
    except IsADirectoryError:
        raise error([f"is a directory, expected a {kind} file"], source) from None
    except OSError as exc:
        raise error([f"cannot read file: {exc.strerror or exc}"], source) from None
    if b"\x00" in raw:
        raise error([f"is a binary file, expected {kind} text"], source)
    try:
        return raw.decode(encoding)
    except UnicodeDecodeError as exc:
        raise error([f"is not UTF-8 text (byte {exc.start}){hint}"], source) from None


def load_json(path: str | Path) -> tuple[Any, str]:
    """The parsed JSON object of the file at ``path`` and the file's name (for error messages).

    Every way a file can fail to be a JSON object is a :class:`ModelError` naming the file:
    missing, a directory, unreadable, not UTF-8 text (binary or another encoding), invalid JSON
    (with line and column), the non-standard ``NaN``/``Infinity`` literals, another top-level type.
    """
    source = str(path)
    text = read_text(path, "JSON", ModelError, encoding="utf-8-sig", hint=": save it as UTF-8 JSON")
    if not text.strip():
        raise ModelError(["is empty, expected JSON"], source)
    duplicates: list[str] = []
    try:
        data = json.loads(text, parse_constant=_reject_constant, object_pairs_hook=_pairs_hook(duplicates))
    except json.JSONDecodeError as exc:
        raise ModelError([f"invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}"], source) from None
    except ValueError as exc:  # NaN / Infinity
        raise ModelError([f"invalid JSON: {exc}"], source) from None
    except RecursionError:
        raise ModelError(["invalid JSON: nested too deeply"], source) from None
    if duplicates:
        raise ModelError(duplicates, source)
    if not isinstance(data, dict):
        raise ModelError([f"the top level must be an object ({{...}}), got {type(data).__name__}"], source)
    return data, source


def same_fields(a: Any, b: Any, skip: Sequence[str] = ()) -> bool:
    """True when the dataclasses ``a`` and ``b`` hold equal values in every field but ``skip``
    (arrays equal in shape and values)."""
    for f in fields(a):
        if f.name in skip:
            continue
        x, y = getattr(a, f.name), getattr(b, f.name)
        if not (np.array_equal(x, y) if isinstance(x, np.ndarray) else x == y):
            return False
    return True


class JsonFile:
    """``save`` and ``load`` for a frozen dataclass with ``to_dict()``, ``from_dict(d, source)`` and
    ``problems()``: the JSON written with two-space indents (NaN and infinities as null), and read
    with every problem located in the file (``load_json``, then ``from_dict`` naming the file).
    Two are equal when every field but the notes is (:func:`same_fields`)."""

    def _freeze_and_check(self, *arrays: str) -> None:
        """The named fields as read-only float64 arrays, then every problem ``problems()`` finds
        raised at once as one :class:`ModelError` (the end of ``__post_init__``)."""
        freeze_arrays(self, *arrays)
        problems = self.problems()
        if problems:
            raise ModelError(problems)

    def problems(self) -> list[str]:
        raise NotImplementedError

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return same_fields(self, other, skip=("notes",))

    def to_dict(self) -> dict[str, Any]:
        raise NotImplementedError

    @classmethod
    def from_dict(cls, d: Any, source: str | None = None) -> Self:
        raise NotImplementedError

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(json_safe(self.to_dict()), indent=2, allow_nan=False) + "\n", encoding="utf-8")

    @classmethod
    def load(cls, path: str | Path) -> Self:
        d, source = load_json(path)
        return cls.from_dict(d, source)
