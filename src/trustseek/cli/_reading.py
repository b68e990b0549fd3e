"""Reading a model or supervisor types and the log they need, for the analysis commands (decode,
predict, validate, personalize), or the log with the inputs --transitions-on and --emissions-on
name, for those that fit; carrying the log's --keep columns into their output; the note on a rating
that looks copied over a block's trials; the widened-range note of the selection commands."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from rich.markup import escape

from .. import estimation  # its names load on first use, when a command runs
from ..errors import TrustseekError
from ._app import err_console
from ._options import log_name

if TYPE_CHECKING:
    from ..model.core import TrustModel
    from ._options import LogReading


def model_inputs(model: TrustModel) -> tuple[str, ...]:
    """The inputs whose value changes some probability of ``model`` (a model fitted with
    fewer inputs has identical tables along the others): the log columns decoding needs."""
    import numpy as np

    em = np.asarray(model.emission)  # [C, a, T, o]
    tr = np.asarray(model.transition)  # [C, a, E, T, T']

    def varies(arr: np.ndarray, axis: int) -> bool:
        return bool(np.ptp(arr, axis=axis).max(initial=0.0) > 0.0) if arr.shape[axis] > 1 else False

    used = []
    if varies(em, 0) or varies(tr, 0):
        used.append("complexity")
    if varies(em, 1) or varies(tr, 1):
        used.append("robot_action")
    if varies(tr, 2):
        used.append("experience")
    return tuple(used)


def fill_unused(frame, model: TrustModel, used: tuple[str, ...]):
    """The log with the inputs ``model`` ignores filled with one valid value where absent."""
    fill = {"complexity": model.complexities[0], "robot_action": "autonomous", "experience": "reliable"}
    frame = frame.copy()
    for col, value in fill.items():
        if col not in used and frame[col].isna().all():
            frame[col] = value
    return frame


def widened_note(rows, key: str, asked: int) -> list[str]:
    """The line saying that the comparison went past the largest number asked, and why."""
    more = [int(r[key]) for r in rows if r.get("widened")]
    if not more:
        return []
    unit = key[:-1] if asked == 1 else key
    return [f"the best was at {asked} {unit}, the largest asked: compared up to {max(more)} (--no-widen: only the range asked)"]


def load_types(path: Path):
    """Supervisor types (a mixture), or a trust or general model as one type, by the file's format;
    or a preset name (paper, paper+conservative)."""
    from ..model.core import TrustModel
    from ..model.files import is_iohmm_file
    from ..model.jsonfile import load_json
    from ..model.mixture import TypeMixture
    from ..model.presets import MIXTURE_PRESETS, load_mixture

    if str(path) in MIXTURE_PRESETS and not path.exists():
        return load_mixture(str(path))
    d, source = load_json(path)
    if is_iohmm_file(d):
        return TypeMixture.single(TrustModel.from_dict(d, source, general=True))
    return TypeMixture.from_dict(d, source, general=True)


def read_for_types(log: Sequence[Path], types, reading: LogReading):
    """The log read for supervisor types or one model (a trust or general model): the columns they
    use, those a trust model ignores filled."""
    from ..model.mixture import TypeMixture

    if not isinstance(types, TypeMixture):
        types = TypeMixture.single(types)
    if types.general:
        return read_for_model(log, types.models[0], reading)
    used = tuple(dict.fromkeys(c for t in types.models for c in model_inputs(t)))
    return fill_unused(reading.read(log, used), types.models[0], used)


def read_for_model(log: Sequence[Path], model, reading: LogReading):
    """The log read with the columns a general model's inputs need: the canonical ones it uses,
    and the others declared as the mapping's ``inputs``."""
    from ..model.files import PLANNING_INPUTS

    canonical = tuple(c for c in model.used_inputs if c in PLANNING_INPUTS)
    frame = reading.read(log, canonical)
    absent = [c for c in model.used_inputs if c not in frame.columns]
    if absent:
        raise TrustseekError(
            [
                f"the model's input {c!r} is not a column of the log: declare it in the mapping's 'inputs' "
                f'(e.g. "inputs": {{"{c}": {{"column": "...", "levels": {list(model.inputs[c])}}}}})'
                for c in absent
            ]
        )
    return frame


def keep_columns(out, frame, keep: list[str] | None):
    """``out`` (one row per row of ``frame``, in its order) with the ``--keep`` columns of ``frame`` added."""
    if not keep:
        return out
    absent = [c for c in keep if c not in frame.columns or c in out.columns]
    if absent:
        cols = list(frame.columns)
        raise TrustseekError([f"--keep {c!r}: not an extra column of the log; its columns: {cols}" for c in absent])
    out = out.copy()
    for c in keep:
        out[c] = frame[c].to_numpy()
    return out


def note_copied_rating(frame, log: Sequence[Path], column: str, markers: frozenset[str] = frozenset(), shown=None) -> None:
    """A note on stderr when the rating ``column`` looks like one per block copied onto the block's
    trials, unless the mapping's rating says so ("per"); ``shown`` its name in the log."""
    from ..data.levels import copied_per_block

    note = None if frame.attrs.get("rating_per") else copied_per_block(frame, column, markers, shown)
    if note:
        err_console.print(f"{log_name(log)}: note: {escape(note)}", highlight=False)


def write_log(frame, path: Path) -> None:
    """A table (of trials, or per participant) written as CSV or Parquet, by the suffix."""
    from ..data.trials import write_trials

    write_trials(frame, path)


def named_inputs(reading: LogReading, transitions_on, emissions_on) -> tuple[tuple[str, ...], tuple[str, ...], tuple[str, ...]]:
    """The transition and emission inputs named by the flags (canonical ones or the --mapping
    file's ``inputs``), and the canonical columns they need."""
    declared = () if reading.column_mapping is None else tuple(reading.column_mapping.inputs)
    tr = _inputs(transitions_on, estimation.PAPER_TRANSITION_INPUTS, "--transitions-on", declared)
    em = _inputs(emissions_on, estimation.PAPER_EMISSION_INPUTS, "--emissions-on", declared)
    return tr, em, tuple(c for c in dict.fromkeys((*tr, *em)) if c in estimation.MODEL_INPUTS)


def read_with_inputs(log: Sequence[Path], reading: LogReading, transitions_on: str | None, emissions_on: str | None):
    """The inputs named by the flags (:func:`named_inputs`) and the log with the columns they need."""
    tr, em, needed = named_inputs(reading, transitions_on, emissions_on)
    return tr, em, reading.read(log, needed)


def general_inputs(tr: tuple[str, ...], em: tuple[str, ...]) -> bool:
    """True when the inputs are not a trust model's: the fit is a general model (trustseek.iohmm/1)."""
    return not estimation.trust_iohmm.is_trust_structure(tr, em)


#: the file suffixes of a per-trial output (posteriors, predictions)
POSTERIOR_SUFFIXES = (".csv", ".parquet", ".pq")


def _inputs(text: str | None, default: tuple[str, ...], flag: str, declared: tuple[str, ...] = ()) -> tuple[str, ...]:
    """The inputs ``flag`` names (``default`` when not given, none for 'none')."""
    if text is None:
        return default
    if text.strip().lower() in ("", "none", "-"):
        return ()
    cols = tuple(c.strip() for c in text.split(",") if c.strip())
    allowed = [*estimation.MODEL_INPUTS, *declared]
    bad = [c for c in cols if c not in allowed]
    if bad:
        where = f"the mapping's inputs {list(declared)}" if declared else "the inputs a --mapping file declares ('inputs')"
        raise TrustseekError([f"{flag}: {c!r} is not one of {list(estimation.MODEL_INPUTS)}, {where} (or 'none')" for c in bad])
    if len(set(cols)) != len(cols):
        raise TrustseekError([f"{flag}: an input is named twice: {list(cols)}"])
    return cols
