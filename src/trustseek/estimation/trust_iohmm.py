"""The supervisor's trust model as an IOHMM: the paper's structure, and tables to and from a TrustModel.

* :func:`paper_spec` -- Section V: trust ``low``/``high``, transitions on (complexity, robot action,
  experience at the end of the trial), emissions on (complexity, robot action), P(intervene | ask) = 1;
* :func:`to_model` / :func:`from_model` -- IOHMM tables to a :class:`~trustseek.model.TrustModel` and
  back: a trust model's (broadcast to the paper's inputs) or a general model's with any named inputs
  (:func:`general_spec`), its structure kept with them (:func:`spec_of` reads it back).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import pandas as pd

from ..model.core import RatingTable, TrustModel, trust_model
from ..model.files import EMISSION_INPUTS, PLANNING_INPUTS, STRUCTURE_KEYS
from ..vocab import ACTIONS, EXPERIENCES, HUMAN_ACTIONS, LEVELS
from .ratings import compose_joint, split_joint
from .spec import FitError, Fixed, IOHMMSpec, Params

PAPER_TRANSITION_INPUTS = MODEL_INPUTS = PLANNING_INPUTS  # a trust model's inputs, the paper's transitions'
PAPER_EMISSION_INPUTS = EMISSION_INPUTS
PRESETS = ("paper",)


def model_categories(complexities: Sequence[str] = LEVELS) -> dict[str, tuple[str, ...]]:
    """A trust model's inputs and their levels, with these complexities."""
    return {"complexity": tuple(complexities), "robot_action": ACTIONS, "experience": EXPERIENCES}


def level_names(k: int) -> tuple[str, ...]:
    """Names of k trust levels, lowest first."""
    names = {1: ("single",), 2: ("low", "high"), 3: ("low", "medium", "high"), 4: ("low", "medium-low", "medium-high", "high")}
    return names.get(k, tuple(f"level{i + 1}" for i in range(k)))


def paper_spec(
    complexities: Sequence[str] = LEVELS,
    prior: float = 0.0,
    levels: Sequence[str] | int = ("low", "high"),
    transition_inputs: Sequence[str] = PAPER_TRANSITION_INPUTS,
    emission_inputs: Sequence[str] = PAPER_EMISSION_INPUTS,
) -> IOHMMSpec:
    """The ``paper`` preset (Section V), optionally with other inputs or another number of levels.

    Inputs are canonical columns among complexity, robot_action, experience.  The
    row ``P(intervene | ask) = 1`` is fixed whenever emissions depend on the robot
    action.  Levels are ordered by P(rely) in high complexity without asking (as far
    as the emission inputs resolve it), lowest first.
    """
    cats = model_categories(complexities)
    bad = [c for c in (*transition_inputs, *emission_inputs) if c not in cats]
    if bad:
        raise FitError([f"input {c!r} is not one of {list(MODEL_INPUTS)}" for c in bad])
    return _human_action_spec(levels, emission_inputs, transition_inputs, cats, prior)


def preset_spec(
    preset: str | IOHMMSpec,
    frame: pd.DataFrame | None = None,
    prior: float = 0.0,
    complexities: Sequence[str] | None = None,
    levels: Sequence[str] | int = ("low", "high"),
    transition_inputs: Sequence[str] = PAPER_TRANSITION_INPUTS,
    emission_inputs: Sequence[str] = PAPER_EMISSION_INPUTS,
) -> IOHMMSpec:
    """The spec named by ``preset`` (an :class:`IOHMMSpec` is returned as is, with ``prior`` if given).

    The ``paper`` preset takes the options of :func:`paper_spec`, and its complexities
    from ``frame`` when not given (:func:`declared_levels`: a categorical column's
    categories in their declared order).
    """
    if isinstance(preset, IOHMMSpec):
        return replace(preset, prior=float(prior)) if prior else preset
    if preset != "paper":
        raise FitError([f"unknown preset {preset!r}; presets: {list(PRESETS)}"])
    if complexities is None and frame is not None:
        complexities = declared_levels(frame, "complexity", LEVELS)
    return paper_spec(complexities or LEVELS, prior, levels, transition_inputs, emission_inputs)


def declared_levels(frame: pd.DataFrame, column: str, default: Sequence[str] = ()) -> tuple[str, ...] | None:
    """The levels of an input column, in order: a categorical column's categories as declared
    (:func:`~trustseek.data.read_trials` keeps a mapping's order), else ``default``'s levels
    in their order followed by any other values present in sorted order; None for a column
    absent or empty."""
    if column not in frame.columns:
        return None
    values = frame[column]
    if isinstance(values.dtype, pd.CategoricalDtype):
        cats = tuple(str(c) for c in values.cat.categories)
        return cats or None
    if not values.notna().any():
        return None
    present = {str(v) for v in values.dropna().unique()}
    known = [c for c in default if c in present]
    extra = sorted(present - set(default))
    return tuple(default) if not extra else tuple(known + extra)


def model_complexities(spec: IOHMMSpec) -> tuple[str, ...]:
    return tuple(spec.categories.get("complexity", LEVELS))


def check_convertible(spec: IOHMMSpec) -> None:
    """Raise a :class:`FitError` unless ``spec``'s tables can be written as a TrustModel."""
    problems = []
    if spec.output != "human_action" or tuple(spec.output_categories) != HUMAN_ACTIONS:
        problems.append(f"a trust model needs the output human_action {list(HUMAN_ACTIONS)}")
    for c in (*spec.emission_inputs, *spec.transition_inputs):
        if c not in MODEL_INPUTS:
            problems.append(f"a trust model has no input {c!r} (inputs: {list(MODEL_INPUTS)})")
    if spec.n_levels < 2:
        problems.append("a trust model needs at least 2 trust levels")
    if problems:
        raise FitError(problems)


def index_grid(spec: IOHMMSpec, inputs: Sequence[str], with_experience: bool) -> np.ndarray:
    """For every TrustModel cell (c, a[, e]) the combination index of ``inputs``."""
    C = len(model_complexities(spec))
    shape = (C, 2, 2) if with_experience else (C, 2)
    out = np.zeros(shape, dtype=np.int64)
    sizes = [len(spec.categories[c]) for c in inputs]
    for idx in np.ndindex(shape):
        codes = {"complexity": idx[0], "robot_action": idx[1]}
        if with_experience:
            codes["experience"] = idx[2]
        out[idx] = np.ravel_multi_index(tuple(codes[c] for c in inputs), sizes) if inputs else 0
    return out


def to_model(spec: IOHMMSpec, params: Params, notes: str = "", general: bool = False) -> TrustModel:
    """The fitted tables as a model: with ``general``, a general model (the spec's structure kept
    with them), else a trust model (inputs a table ignores repeat); a spec with a rating gives the
    model its rating table."""
    emission, rating = params.emission, None
    if spec.rating is not None:
        emission, probs = split_joint(emission, spec.n_outputs, spec.n_ratings)
        rating = RatingTable(spec.rating_levels, probs)
    if not general:
        check_convertible(spec)
        eg = index_grid(spec, spec.emission_inputs, False)
        tg = index_grid(spec, spec.transition_inputs, True)
        levels, complexities = spec.levels, model_complexities(spec)
        return trust_model(levels, complexities, params.initial, emission[eg], params.transition[tg], notes, rating=rating)
    d = spec.to_dict()
    inputs = {c: tuple(spec.categories[c]) for c in dict.fromkeys((*spec.emission_inputs, *spec.transition_inputs))}

    def named(rows: np.ndarray, on: Sequence[str]) -> np.ndarray:
        """A table by input combination (U, K, ·) with one axis per input of ``on``."""
        return rows.reshape(*(len(inputs[c]) for c in on), *rows.shape[1:])

    return TrustModel(
        levels=spec.levels,
        output=spec.output,
        output_categories=spec.output_categories,
        inputs=inputs,
        emission_inputs=spec.emission_inputs,
        transition_inputs=spec.transition_inputs,
        initial=params.initial,
        emission=named(emission, spec.emission_inputs),
        transition=named(params.transition, spec.transition_inputs),
        structure={k: d[k] for k in STRUCTURE_KEYS},
        rating=rating,
        rating_column=spec.rating,
        notes=notes,
    )


def broadcast(spec: IOHMMSpec, arrays: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Row-level arrays (U, K) to TrustModel shapes (cell value = its row's value)."""
    K = spec.n_levels
    eg = index_grid(spec, spec.emission_inputs, False)
    tg = index_grid(spec, spec.transition_inputs, True)
    return {
        "initial": np.asarray(arrays["initial"], dtype=float),
        "emission": np.repeat(arrays["emission"][eg][..., None], 2, axis=-1),
        "transition": np.repeat(arrays["transition"][tg][..., None], K, axis=-1),
    }


def from_model(model: TrustModel, rating: str | None = None) -> tuple[IOHMMSpec, Params]:
    """The spec and tables that reproduce ``model`` exactly (for decoding): a trust model's the
    paper-structured spec, a general model's its own (:func:`spec_of`).

    With ``rating`` (a column name) and a model with a rating table, the spec has that
    rating and the tables are the joint ones (:mod:`.ratings`)."""
    spec = spec_of(model) if model.general else paper_spec(complexities=model.complexities, levels=model.trust_levels)
    emission = np.array(model.emission_rows, dtype=float)
    if rating is not None:
        if model.rating is None:
            level = "level" if model.general else "trust"
            raise FitError([f"the model has no rating table (P(rating | {level})): it cannot use ratings"])
        spec = replace(spec, rating=rating, rating_levels=model.rating.levels)
        emission = compose_joint(emission, np.array(model.rating.probs, dtype=float))
    return spec, Params(np.array(model.initial, dtype=float), emission, np.array(model.transition_rows, dtype=float))


# --------------------------------------------------------------------------- the general model: any named inputs


def is_trust_structure(transition_inputs: Sequence[str], emission_inputs: Sequence[str]) -> bool:
    """True when every input is one a trust model has (the paper's preset and its variants)."""
    return all(c in MODEL_INPUTS for c in (*transition_inputs, *emission_inputs))


def input_levels(frame: pd.DataFrame, inputs: Sequence[str]) -> dict[str, tuple[str, ...]]:
    """Every input's levels in their order (:func:`declared_levels`; the canonical inputs' own
    names first); an input absent from ``frame`` or without values is an error."""
    out, problems = {}, []
    for c in dict.fromkeys(inputs):
        levels = declared_levels(frame, c, model_categories().get(c, ()))
        if levels is None:
            problems.append(f"input {c!r}: no such column with values in the log")
        else:
            out[c] = levels
    if problems:
        raise FitError(problems)
    return out


def general_spec(
    frame: pd.DataFrame,
    emission_inputs: Sequence[str],
    transition_inputs: Sequence[str],
    levels: Sequence[str] | int = ("low", "high"),
    prior: float = 0.0,
    categories: Mapping[str, Sequence[str]] | None = None,
) -> IOHMMSpec:
    """The IOHMM of the human action with any named inputs: the paper preset's rules where its
    inputs are present (P(intervene | ask) = 1 when emissions depend on the robot action; levels
    named by P(rely) without asking in the last complexity), every other input free.  The
    inputs' levels are ``categories``, else the frame's (:func:`input_levels`)."""
    cats = dict(categories) if categories is not None else input_levels(frame, (*emission_inputs, *transition_inputs))
    return _human_action_spec(levels, emission_inputs, transition_inputs, {c: tuple(v) for c, v in cats.items()}, prior)


def inputs_spec(
    frame: pd.DataFrame,
    preset: str | IOHMMSpec = "paper",
    prior: float = 0.0,
    transition_inputs: Sequence[str] = PAPER_TRANSITION_INPUTS,
    emission_inputs: Sequence[str] = PAPER_EMISSION_INPUTS,
    **spec_options: Any,
) -> IOHMMSpec:
    """The structure for these inputs: the ``preset`` (a trust model, ``spec_options`` as for
    :func:`preset_spec`) for the canonical inputs, :func:`general_spec` when an input is a study's
    own (of ``spec_options`` only ``levels`` applies there; any other is refused)."""
    if isinstance(preset, IOHMMSpec) or is_trust_structure(transition_inputs, emission_inputs):
        return preset_spec(
            preset, frame, prior=prior, transition_inputs=transition_inputs, emission_inputs=emission_inputs, **spec_options
        )
    extra = sorted(set(spec_options) - {"levels"})
    if extra:
        raise ValueError(f"options {extra} apply to the paper preset only, not to a model of named inputs")
    return general_spec(frame, emission_inputs, transition_inputs, spec_options.get("levels", ("low", "high")), prior)


def _human_action_spec(
    levels: Sequence[str] | int,
    emission_inputs: Sequence[str],
    transition_inputs: Sequence[str],
    cats: Mapping[str, tuple[str, ...]],
    prior: float,
) -> IOHMMSpec:
    """The IOHMM of the human action on these inputs (levels ``cats``): P(intervene | ask) = 1 when
    emissions depend on the robot action; levels named by P(rely) without asking in the last complexity."""
    if isinstance(levels, int):
        levels = level_names(levels)
    fixed: tuple[Fixed, ...] = ()
    if "robot_action" in emission_inputs and "ask" in cats["robot_action"]:
        fixed = (Fixed({"robot_action": "ask"}, {"intervene": 1.0, "rely": 0.0}),)
    where = {}
    if "complexity" in emission_inputs:
        where["complexity"] = cats["complexity"][-1]
    if "robot_action" in emission_inputs and "autonomous" in cats["robot_action"]:
        where["robot_action"] = "autonomous"
    return IOHMMSpec(
        levels=tuple(levels),
        output="human_action",
        output_categories=HUMAN_ACTIONS,
        emission_inputs=tuple(emission_inputs),
        transition_inputs=tuple(transition_inputs),
        categories={c: cats[c] for c in (*transition_inputs, *emission_inputs)},
        fixed_emissions=fixed,
        order_by=(where, "rely"),
        prior=float(prior),
    )


def _where(raw: object) -> dict[str, str]:
    return {str(k): str(v) for k, v in raw.items()} if isinstance(raw, Mapping) else {}


def spec_of(model: TrustModel) -> IOHMMSpec:
    """The spec a general model file was fitted with (its structure read back)."""
    st = model.structure or {}
    try:
        fixed = {
            name: tuple(
                Fixed(_where(f.get("where", {})), f["probs"] if isinstance(f["probs"], str) else dict(f["probs"]))
                for f in st.get(name, [])
            )
            for name in ("fixed_emissions", "fixed_transitions")
        }
        tied = {
            name: tuple(tuple(_where(w) for w in g) for g in st.get(name, [])) for name in ("tied_emissions", "tied_transitions")
        }
        ob = st.get("order_by")
        order_by = None if ob is None else (_where(ob.get("where", {})), str(ob["category"]))
        prior = float(st.get("prior", 0.0))
    except (KeyError, TypeError, AttributeError, ValueError) as exc:
        raise FitError([f"the model's structure cannot be read: {exc!r}"]) from None
    spec = IOHMMSpec(
        levels=model.levels,
        output=model.output,
        output_categories=model.output_categories,
        emission_inputs=model.emission_inputs,
        transition_inputs=model.transition_inputs,
        categories=dict(model.inputs),
        fixed_emissions=fixed["fixed_emissions"],
        fixed_transitions=fixed["fixed_transitions"],
        tied_emissions=tied["tied_emissions"],
        tied_transitions=tied["tied_transitions"],
        order_by=order_by,
        prior=prior,
    )
    problems = spec.problems()
    if problems:
        raise FitError(problems)
    return spec
