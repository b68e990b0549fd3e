"""Estimate the supervisor model (a :class:`~trustseek.model.TrustModel`) from logged trials.

* :func:`paper_spec` -- the IOHMM structure of Section V: two trust levels,
  transitions on (complexity, robot action, experience at the end of the trial),
  emissions on (complexity, robot action), P(intervene | ask) = 1 fixed, levels
  labelled so that ``high`` relies more in high complexity.
* :func:`fit_trust_model` -- restarts, the best fit, diagnostics, bootstrap CIs.
* :func:`decode` -- smoothed P(trust | data) and the Viterbi path per trial.
* :func:`select_levels` -- K = 1..4 by BIC and by participant-held-out log-likelihood.
"""

from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np
import pandas as pd

from ..data.trials import DEFAULT_COMPLEXITIES
from .estep import Workspace
from .iohmm import IOHMMFit, fit_iohmm
from .sequences import Sequences, encode
from .spec import FitError, Fixed, IOHMMSpec, Params
from .structure import Structure, describe_combination
from ..model.core import ACTIONS, EXPERIENCES, HUMAN_ACTIONS, TrustModel

PAPER_TRANSITION_INPUTS = ("complexity", "robot_action", "experience")
PAPER_EMISSION_INPUTS = ("complexity", "robot_action")
MODEL_INPUTS = ("complexity", "robot_action", "experience")
PRESETS = ("paper",)
MIN_EVENTS = 5  # fewer expected events than this behind a row: "not identified by this data"


def level_names(k: int) -> tuple[str, ...]:
    """Names of k trust levels, lowest first."""
    return {1: ("single",), 2: ("low", "high"), 3: ("low", "medium", "high"), 4: ("low", "medium-low", "medium-high", "high")}.get(
        k, tuple(f"level{i + 1}" for i in range(k))
    )


def paper_spec(
    complexities: Sequence[str] = DEFAULT_COMPLEXITIES,
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
    if isinstance(levels, int):
        levels = level_names(levels)
    complexities = tuple(complexities)
    cats = {"complexity": complexities, "robot_action": ACTIONS, "experience": EXPERIENCES}
    bad = [c for c in (*transition_inputs, *emission_inputs) if c not in cats]
    if bad:
        raise FitError([f"input {c!r} is not one of {list(MODEL_INPUTS)}" for c in bad])
    fixed = (Fixed({"robot_action": "ask"}, {"intervene": 1.0, "rely": 0.0}),) if "robot_action" in emission_inputs else ()
    where = {}
    if "complexity" in emission_inputs:
        where["complexity"] = complexities[-1]
    if "robot_action" in emission_inputs:
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


def preset_spec(preset: str | IOHMMSpec, frame: pd.DataFrame | None = None, prior: float = 0.0, **kw) -> IOHMMSpec:
    if isinstance(preset, IOHMMSpec):
        return preset
    if preset != "paper":
        raise FitError([f"unknown preset {preset!r}; presets: {list(PRESETS)}"])
    cx = kw.pop("complexities", None)
    if cx is None and frame is not None and frame["complexity"].notna().any():
        seen = [c for c in DEFAULT_COMPLEXITIES if c in set(frame["complexity"].dropna())]
        extra = sorted(set(frame["complexity"].dropna()) - set(DEFAULT_COMPLEXITIES))
        cx = tuple(DEFAULT_COMPLEXITIES) if not extra else tuple(seen + extra)
    return paper_spec(complexities=cx or DEFAULT_COMPLEXITIES, prior=prior, **kw)


# --------------------------------------------------------------------------- TrustModel <-> IOHMM tables


def _model_complexities(spec: IOHMMSpec) -> tuple[str, ...]:
    return tuple(spec.categories.get("complexity", DEFAULT_COMPLEXITIES))


def _check_convertible(spec: IOHMMSpec) -> None:
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


def _index_grid(spec: IOHMMSpec, inputs: Sequence[str], with_experience: bool) -> np.ndarray:
    """For every TrustModel cell (c, a[, e]) the combination index of ``inputs``."""
    C = len(_model_complexities(spec))
    shape = (C, 2, 2) if with_experience else (C, 2)
    out = np.zeros(shape, dtype=np.int64)
    sizes = [len(spec.categories[c]) for c in inputs]
    for idx in np.ndindex(shape):
        codes = {"complexity": idx[0], "robot_action": idx[1]}
        if with_experience:
            codes["experience"] = idx[2]
        out[idx] = np.ravel_multi_index(tuple(codes[c] for c in inputs), sizes) if inputs else 0
    return out


def to_trust_model(spec: IOHMMSpec, params: Params, notes: str = "") -> TrustModel:
    """Broadcast IOHMM tables to the TrustModel arrays (inputs a table ignores repeat)."""
    _check_convertible(spec)
    eg = _index_grid(spec, spec.emission_inputs, False)
    tg = _index_grid(spec, spec.transition_inputs, True)
    return TrustModel(
        trust_levels=spec.levels,
        complexities=_model_complexities(spec),
        initial=params.initial,
        emission=params.emission[eg],
        transition=params.transition[tg],
        notes=notes,
    )


def _broadcast(spec: IOHMMSpec, arrays: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Row-level arrays (U, K) to TrustModel shapes (cell value = its row's value)."""
    K = spec.n_levels
    eg = _index_grid(spec, spec.emission_inputs, False)
    tg = _index_grid(spec, spec.transition_inputs, True)
    return {
        "initial": np.asarray(arrays["initial"], dtype=float),
        "emission": np.repeat(arrays["emission"][eg][..., None], 2, axis=-1),
        "transition": np.repeat(arrays["transition"][tg][..., None], K, axis=-1),
    }


def from_trust_model(model: TrustModel) -> tuple[IOHMMSpec, Params]:
    """The paper-structured spec and tables that reproduce ``model`` exactly (for decoding)."""
    K, C = model.n_trust, model.n_complexity
    spec = paper_spec(complexities=model.complexities, levels=model.trust_levels)
    return spec, Params(
        np.array(model.initial, dtype=float),
        np.array(model.emission, dtype=float).reshape(C * 2, K, 2),
        np.array(model.transition, dtype=float).reshape(C * 4, K, K),
    )


# --------------------------------------------------------------------------- results


@dataclass
class FitResult:
    """A fitted trust model with its diagnostics (see :func:`fit_trust_model`)."""

    model: TrustModel
    fit: IOHMMFit
    counts: dict[str, np.ndarray]
    estimated: dict[str, np.ndarray]
    ci: dict[str, tuple[np.ndarray, np.ndarray]] | None = None
    bootstrap: int = 0
    seed: int = 0
    warnings: list[str] = field(default_factory=list)

    @property
    def loglik(self) -> float:
        return self.fit.loglik

    @property
    def restart_logliks(self) -> list[float]:
        return self.fit.restart_logliks

    @property
    def n_params(self) -> int:
        return self.fit.n_params

    @property
    def aic(self) -> float:
        return self.fit.aic

    @property
    def bic(self) -> float:
        return self.fit.bic

    def posteriors(self) -> pd.DataFrame:
        """Smoothed P(trust | all trials of the participant) and the Viterbi level, one row per trial."""
        return _posterior_frame(self.fit.seqs, self.fit.spec, self.fit.params)

    def to_dict(self) -> dict[str, Any]:
        spec = self.fit.spec
        runs = self.fit.runs
        return {
            "model": self.model.to_dict(),
            "loglik": self.loglik,
            "n_params": self.n_params,
            "aic": self.aic,
            "bic": self.bic,
            "n_participants": self.fit.seqs.n_participants,
            "n_trials": self.fit.seqs.n_trials,
            "n_observations": self.fit.n_observations,
            "restart_logliks": self.restart_logliks,
            "best_restart": self.fit.best,
            "iterations": [r.iterations for r in runs],
            "converged": [r.converged for r in runs],
            "seconds": [r.seconds for r in runs],
            "seed": self.seed,
            "bootstrap": self.bootstrap,
            "spec": spec.to_dict(),
            "counts": {k: v.tolist() for k, v in self.counts.items()},
            "estimated": {k: v.tolist() for k, v in self.estimated.items()},
            "ci": None if self.ci is None else {k: {"lower": lo.tolist(), "upper": hi.tolist()} for k, (lo, hi) in self.ci.items()},
            "warnings": list(self.warnings),
        }

    def cells(self) -> list[dict[str, Any]]:
        """One record per estimated cell: label, TrustModel index, estimate, CI, events.

        A model whose tables ignore some inputs lists each distinct row once, labelled
        by the inputs it depends on.
        """
        m, spec = self.model, self.fit.spec
        T = m.trust_levels
        short = {"complexity": "C", "robot_action": "a", "experience": "E'"}
        names = {"complexity": m.complexities, "robot_action": ACTIONS, "experience": EXPERIENCES}
        out: list[dict[str, Any]] = []
        seen: set = set()

        def add(table: str, idx: tuple, label: str, key) -> None:
            if not self.estimated[table][idx] or key in seen:
                return
            seen.add(key)
            rec = {"table": table, "index": list(idx), "cell": label, "estimate": float(getattr(m, table)[idx]), "events": float(self.counts[table][idx])}
            if self.ci is not None:
                rec["lower"], rec["upper"] = float(self.ci[table][0][idx]), float(self.ci[table][1][idx])
            out.append(rec)

        def cond(inputs, values) -> str:
            return "".join(f", {short[c]}={names[c][values[c]]}" for c in inputs)

        for t in range(1, m.n_trust) if m.n_trust == 2 else range(m.n_trust):
            add("initial", (t,), f"P(T1={T[t]})", ("i", t))
        eg = _index_grid(spec, spec.emission_inputs, False)
        for c in range(m.n_complexity):
            for a in range(2):
                for t in range(m.n_trust):
                    v = {"complexity": c, "robot_action": a}
                    add("emission", (c, a, t, 1), f"P(rely | T={T[t]}{cond(spec.emission_inputs, v)})", ("e", int(eg[c, a]), t))
        tg = _index_grid(spec, spec.transition_inputs, True)
        for c in range(m.n_complexity):
            for a in range(2):
                for e in range(2):
                    for t in range(m.n_trust):
                        for u in range(m.n_trust):
                            if m.n_trust == 2 and u == 0:
                                continue
                            v = {"complexity": c, "robot_action": a, "experience": e}
                            add("transition", (c, a, e, t, u), f"P(T'={T[u]} | T={T[t]}{cond(spec.transition_inputs, v)})", ("t", int(tg[c, a, e]), t, u))
        return out


def _posterior_frame(seqs: Sequences, spec: IOHMMSpec, params: Params) -> pd.DataFrame:
    from .iohmm import posteriors

    gamma, path, _ = posteriors(seqs, spec, params)
    valid = seqs.rows >= 0
    tt, nn = np.nonzero(valid)
    order = np.argsort(seqs.rows[valid], kind="stable")
    tt, nn = tt[order], nn[order]
    out = {
        "participant": [seqs.participants[i] for i in nn],
        "trial": tt + 1,
    }
    for k, name in enumerate(spec.levels):
        out[f"p_trust_{name}"] = gamma[tt, nn, k]
    out["viterbi_trust"] = np.array(spec.levels, dtype=object)[path[tt, nn]]
    return pd.DataFrame(out)


def _estimated_mask(structure: Structure) -> dict[str, np.ndarray]:
    """Row-level: True where a row is estimated (not fixed, not empty)."""
    em = ~np.all(structure.em.fixed, axis=-1)  # (Ue, K)
    tr = ~np.all(structure.tr.fixed, axis=-1)  # (Ut, K)
    return {"initial": np.full(structure.K, structure.K > 1), "emission": em.astype(float), "transition": tr.astype(float)}


def _warnings(fit: IOHMMFit, events: dict[str, np.ndarray]) -> list[str]:
    s, spec = fit.structure, fit.spec
    out = []
    for name, table, inputs in (("emission", s.em, spec.emission_inputs), ("transition", s.tr, spec.transition_inputs)):
        ev = events[name]
        for g in range(table.G):
            u = int(table.rep[g])
            for k in range(s.K):
                if np.all(table.fixed[u, k]):
                    continue
                n = float(ev[u, k])
                if n < MIN_EVENTS:
                    out.append(
                        f"{name}[{describe_combination(u, inputs, spec.categories)}][T={spec.levels[k]}]: "
                        f"{n:.1f} expected events, not identified by this data"
                    )
    return out


# --------------------------------------------------------------------------- fitting


def fit_sequences(
    seqs: Sequences,
    spec: IOHMMSpec,
    restarts: int = 10,
    seed: int = 0,
    bootstrap: int = 0,
    n_jobs: int | None = None,
    tol: float = 1e-8,
    max_iter: int = 1000,
    progress: Callable[[int, int], None] | None = None,
    init: Sequence[Params] = (),
) -> FitResult:
    """:func:`fit_trust_model` on already encoded sequences."""
    _check_convertible(spec)
    total = restarts + len(init) + bootstrap
    done = [0]

    def tick(*_):
        done[0] += 1
        if progress is not None:
            progress(done[0], total)

    fit = fit_iohmm(seqs, spec, restarts=restarts, seed=np.random.SeedSequence([seed, 0]), tol=tol, max_iter=max_iter, init=init, on_restart=tick)
    model = to_trust_model(spec, fit.params, notes=f"fitted by trustseek: {seqs.n_participants} participants, {seqs.n_trials} trials, log-likelihood {fit.loglik:.4f}")
    events = fit.expected_events()
    counts = _broadcast(spec, events)
    estimated = {k: v.astype(bool) for k, v in _broadcast(spec, _estimated_mask(fit.structure)).items()}
    result = FitResult(model, fit, counts, estimated, seed=seed, warnings=_warnings(fit, events))
    if bootstrap > 0:
        result.ci = bootstrap_ci(seqs, spec, fit.params, bootstrap, seed=seed, restarts=min(restarts, 3), n_jobs=n_jobs, tol=tol, max_iter=max_iter, progress=tick)
        result.bootstrap = bootstrap
    return result


def fit_trust_model(
    frame: pd.DataFrame,
    preset: str | IOHMMSpec = "paper",
    restarts: int = 10,
    seed: int = 0,
    bootstrap: int = 0,
    prior: float = 0.0,
    n_jobs: int | None = None,
    tol: float = 1e-8,
    max_iter: int = 1000,
    progress: Callable[[int, int], None] | None = None,
    **spec_options: Any,
) -> FitResult:
    """Fit a trust model to a trial table (the canonical columns, e.g. from :func:`read_trials`).

    ``preset`` is ``"paper"`` (optionally adjusted by ``levels``, ``transition_inputs``,
    ``emission_inputs``, ``complexities`` keyword options) or an :class:`IOHMMSpec`.
    ``prior`` adds that Dirichlet pseudo-count to every free cell (MAP).  With
    ``bootstrap`` > 0, participants are resampled that many times and 95 % percentile
    intervals are reported for every cell, computed over ``n_jobs`` processes
    (default: all cores); results do not depend on ``n_jobs``.
    """
    spec = preset_spec(preset, frame, prior=prior, **spec_options)
    if isinstance(preset, IOHMMSpec) and prior:
        from dataclasses import replace

        spec = replace(spec, prior=float(prior))
    seqs = encode(frame, spec)
    return fit_sequences(seqs, spec, restarts, seed, bootstrap, n_jobs, tol, max_iter, progress)


def _bootstrap_one(args) -> np.ndarray:
    seqs, spec, params, child, restarts, tol, max_iter = args
    rng = np.random.default_rng(child)
    idx = rng.integers(0, seqs.n_participants, seqs.n_participants)
    sub = seqs.subset(idx)
    fit = fit_iohmm(sub, spec, restarts=restarts, seed=child.spawn(1)[0], tol=tol, max_iter=max_iter, init=[params])
    m = to_trust_model(spec, fit.params)
    return np.concatenate([m.initial.ravel(), m.emission.ravel(), m.transition.ravel()])


def bootstrap_ci(
    seqs: Sequences,
    spec: IOHMMSpec,
    params: Params,
    replicates: int,
    seed: int = 0,
    restarts: int = 3,
    n_jobs: int | None = None,
    tol: float = 1e-8,
    max_iter: int = 1000,
    level: float = 0.95,
    progress: Callable[..., None] | None = None,
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Participant-level bootstrap: percentile intervals for every TrustModel cell.

    Each replicate resamples participants with replacement and refits from the point
    estimate and ``restarts`` random starts.  Replicate b always uses the b-th child
    of the seed, so the intervals are the same for any ``n_jobs``.
    """
    children = np.random.SeedSequence([seed, 1]).spawn(replicates)
    jobs = [(seqs, spec, params, ch, restarts, tol, max_iter) for ch in children]
    n_jobs = n_jobs or os.cpu_count() or 1
    results: list[np.ndarray | None] = [None] * replicates
    if n_jobs <= 1 or replicates == 1:
        for i, job in enumerate(jobs):
            results[i] = _bootstrap_one(job)
            if progress:
                progress()
    else:
        with ProcessPoolExecutor(max_workers=min(n_jobs, replicates)) as ex:
            futs = {ex.submit(_bootstrap_one, job): i for i, job in enumerate(jobs)}
            for f in as_completed(futs):
                results[futs[f]] = f.result()
                if progress:
                    progress()
    draws = np.vstack(results)
    alpha = (1 - level) / 2
    lo, hi = np.quantile(draws, [alpha, 1 - alpha], axis=0)
    ref = to_trust_model(spec, params)
    out = {}
    pos = 0
    for name in ("initial", "emission", "transition"):
        shape = getattr(ref, name).shape
        size = int(np.prod(shape))
        out[name] = (lo[pos : pos + size].reshape(shape), hi[pos : pos + size].reshape(shape))
        pos += size
    return out


# --------------------------------------------------------------------------- decoding and selection


def decode(frame: pd.DataFrame, model: TrustModel) -> pd.DataFrame:
    """Per-trial smoothed P(trust = level | all trials of the participant) and the Viterbi level."""
    from .iohmm import loglik

    spec, params = from_trust_model(model)
    seqs = encode(frame, spec)
    try:
        return _posterior_frame(seqs, spec, params)
    except FitError:
        bad = [seqs.participants[i] for i in range(seqs.n_participants) if not np.isfinite(loglik(seqs.subset([i]), spec, params))]
        raise FitError([f"participant {p!r}: the trials have probability zero under this model" for p in bad] or ["the data have probability zero under this model"]) from None


def select_levels(
    frame: pd.DataFrame,
    levels: Sequence[int] = (1, 2, 3, 4),
    folds: int = 5,
    restarts: int = 10,
    seed: int = 0,
    prior: float = 0.0,
    tol: float = 1e-6,
    max_iter: int = 1000,
    progress: Callable[[int, int], None] | None = None,
    **spec_options: Any,
) -> list[dict[str, Any]]:
    """Compare numbers of trust levels: BIC on all data and k-fold participant-held-out log-likelihood."""
    base = preset_spec("paper", frame, prior=prior, **spec_options)
    seqs0 = encode(frame, base)
    N = seqs0.n_participants
    folds = max(2, min(folds, N))
    perm = np.random.default_rng(np.random.SeedSequence([seed, 2])).permutation(N)
    fold_of = np.empty(N, dtype=np.int64)
    fold_of[perm] = np.arange(N) % folds
    total = len(levels) * (folds + 1)
    done = 0
    rows = []
    for K in levels:
        spec = base.with_levels(level_names(K))
        full = fit_iohmm(seqs0, spec, restarts=restarts, seed=np.random.SeedSequence([seed, 3, K]), tol=tol, max_iter=max_iter)
        done += 1
        if progress:
            progress(done, total)
        held = 0.0
        per_fold = []
        for f in range(folds):
            train, test = np.flatnonzero(fold_of != f), np.flatnonzero(fold_of == f)
            fit = fit_iohmm(seqs0.subset(train), spec, restarts=restarts, seed=np.random.SeedSequence([seed, 4, K, f]), tol=tol, max_iter=max_iter)
            ll = _test_loglik(seqs0.subset(test), spec, fit)
            per_fold.append(ll)
            held += ll
            done += 1
            if progress:
                progress(done, total)
        rows.append(
            {
                "levels": K,
                "loglik": full.loglik,
                "n_params": full.n_params,
                "aic": full.aic,
                "bic": full.bic,
                "heldout_loglik": held,
                "heldout_per_fold": per_fold,
                "restart_logliks": full.restart_logliks,
            }
        )
    best_bic = min(rows, key=lambda r: r["bic"])["levels"]
    best_cv = max(rows, key=lambda r: r["heldout_loglik"])["levels"]
    for r in rows:
        r["best_bic"] = r["levels"] == best_bic
        r["best_heldout"] = r["levels"] == best_cv
    return rows


HELDOUT_PSEUDOCOUNT = 0.5  # added to every free cell's training counts before held-out scoring


def _test_loglik(test: Sequences, spec: IOHMMSpec, fit: IOHMMFit) -> float:
    """Held-out log-likelihood under the training fit, smoothed so that it stays finite.

    A training fold can drive a cell to exactly 0 (no training participant ever did
    that) while a held-out participant does it: the held-out log-likelihood would be
    -inf, and every number of levels would tie at -inf.  The model is therefore scored
    with the training fit's expected counts plus :data:`HELDOUT_PSEUDOCOUNT` per free
    cell (one smoothed M-step from the maximum-likelihood point).  Input rows unseen in
    training keep their defaults.
    """
    s = fit.structure
    st = fit.workspace().estep(fit.params)
    a = spec.prior + HELDOUT_PSEUDOCOUNT
    c0 = st.initial + a
    params = Params(c0 / c0.sum(), s.em.mstep(st.emission, a, fit.params.emission), s.tr.mstep(st.transition, a, fit.params.transition))
    return float(Workspace(test, *s.dims).loglik(params))
