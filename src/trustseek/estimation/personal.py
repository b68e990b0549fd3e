"""Per-person trust models: each participant's MAP estimate, shrunk toward a centre model.

The centre is the pooled model, or with supervisor types (a
:class:`~trustseek.model.mixture.TypeMixture`) the participant's most probable type.  Every
free row of participant n's model gets a Dirichlet prior whose pseudo-counts are
``s * (the centre's row)`` (over the row's free cells, renormalised to sum to s), so the
M-step is ``(expected counts + s * centre row) / total``: a row the participant's trials
never reach stays the centre's, and a row they reach often moves toward their own counts.

**The strength s** is estimated from the data by empirical Bayes, **one s per table**
(initial, emission, transition): the value that maximises the Dirichlet-multinomial marginal
likelihood of every participant's expected counts (under the centre) given the centre rows,

    sum_n sum_rows  lgamma(s) - lgamma(s + c) + sum_j [lgamma(s t_j + c_j) - lgamma(s t_j)],

over s in [:data:`S_MIN`, :data:`S_MAX`] (log scale).  A large s says the participants do
not differ from the centre beyond chance; at :data:`S_MAX` the result is reported as at the
bound (the data show no individual differences in that table).

A limit of this estimate, measured (docs/types.md): the expected counts are split over the
hidden levels by the centre's posterior, which puts a participant who relies more than the
centre into its high level rather than into a different high-level row; so differences
between people largely show as differences in time spent at each level, not as
overdispersed rows, and s tends to the bound even on a population drawn around the pooled
model (``Supervisors.dirichlet`` with concentration 5).  Give ``strength`` to shrink less.

Each participant's MAP is the EM of the pooled fit (:func:`~.em.run_em`, SQUAREM), one
parameter set per participant, each run on that participant's trials only (the compiled
pass :meth:`~.kernels.Kernel.run_each`), from the centre.
"""

from __future__ import annotations

import json
import logging
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy.optimize import minimize_scalar
from scipy.special import gammaln

from ..model.core import TrustModel, json_safe
from ..model.mixture import TypeMixture
from . import kernels
from .em import run_em
from .estep import EStep, Workspace
from .mixture import MixtureStructure, MixtureWorkspace, mixture_params, type_posteriors
from .sequences import encode
from .spec import FitError, Params
from .structure import FLOOR, Structure, Table
from .trust_iohmm import to_trust_model

log = logging.getLogger(__name__)

TABLES = ("initial", "emission", "transition")
S_MIN, S_MAX = 1e-2, 1e6


class _PersonalWorkspace(Workspace):
    """Parameter set n on participant n only (a batch of N parameter sets)."""

    def estep(self, p: Params, active: np.ndarray | None = None, posteriors: bool = False) -> EStep:
        assert self._kernel is not None and p.batched
        Bx, Ax = self.tables(p)
        N = len(p.initial)
        ll, ci, ce, ct = self._kernel.run_each(np.arange(N), p.initial, Bx, Ax, active)
        em = ce[:, :-1].reshape(N, self.Ue, self.M, self.K).transpose(0, 1, 3, 2)
        return EStep(ll, ci, np.ascontiguousarray(em), np.ascontiguousarray(ct[:, :-1]))

    def loglik(self, p: Params) -> np.ndarray:
        return self.estep(p).loglik


class _PersonalStructure(Structure):
    """The pooled structure with per-participant pseudo-counts ``pseudo[table]`` (N, ...) on the free
    cells (placed at each tie group's representative row)."""

    pseudo: dict[str, np.ndarray]

    def mstep(self, stats: EStep, previous: Params) -> Params:
        c0 = stats.initial + self.pseudo["initial"]
        tot = c0.sum(-1, keepdims=True)
        pi = np.where(tot > 0, c0 / np.where(tot > 0, tot, 1.0), previous.initial)
        return Params(
            pi,
            self.em.mstep(stats.emission + self.pseudo["emission"], 0.0, previous.emission),
            self.tr.mstep(stats.transition + self.pseudo["transition"], 0.0, previous.transition),
        )

    def log_prior(self, p: Params) -> np.ndarray:
        out = (self.pseudo["initial"] * np.log(np.maximum(p.initial, FLOOR))).sum(-1)
        for name in ("emission", "transition"):
            out = out + (self.pseudo[name] * np.log(np.maximum(getattr(p, name), FLOOR))).sum((-3, -2, -1))
        return out


def _free_rows(table: Table, counts: np.ndarray, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per participant and free row (tie groups summed): counts (N, G, K, X), the centre's row
    renormalised over the usable cells, and the usable-cell mask (free, centre > 0, group reached)."""
    cg = np.einsum("nukx,ug->ngkx", counts, table.onehot)
    rows = centre[:, table.rep]  # (N, G, K, X)
    reached = ~table.empty[table.rep]
    mask = ~table.gfixed[None] & (rows > 0) & reached[None, :, None, None]
    t = np.where(mask, rows, 0.0)
    s = t.sum(-1, keepdims=True)
    t = t / np.where(s > 0, s, 1.0)
    return cg, t, mask


def dirichlet_multinomial(s: float, counts: np.ndarray, means: np.ndarray, mask: np.ndarray) -> float:
    """sum over rows of log DirMult(counts | s * means), up to the multinomial coefficient; rows
    (last axis = cells) with fewer than 2 usable cells or no counts add nothing."""
    use = (mask.sum(-1) >= 2) & (np.where(mask, counts, 0.0).sum(-1) > 0)
    c = np.where(mask, counts, 0.0)[use]
    t = means[use]
    m = mask[use]
    a = s * t
    cell = np.where(m, gammaln(np.where(m, a + c, 1.0)) - gammaln(np.where(m, a, 1.0)), 0.0).sum(-1)
    return float((gammaln(s) - gammaln(s + c.sum(-1)) + cell).sum())


def estimate_strength(counts: np.ndarray, means: np.ndarray, mask: np.ndarray) -> tuple[float, bool]:
    """The s in [S_MIN, S_MAX] maximising :func:`dirichlet_multinomial`; and whether it is at a bound."""
    if not ((mask.sum(-1) >= 2) & (np.where(mask, counts, 0.0).sum(-1) > 0)).any():
        return S_MAX, True
    lo, hi = math.log(S_MIN), math.log(S_MAX)
    res = minimize_scalar(lambda x: -dirichlet_multinomial(math.exp(x), counts, means, mask), bounds=(lo, hi), method="bounded")
    x = float(res.x)
    return math.exp(x), bool(x <= lo + 0.01 * (hi - lo) or x >= hi - 0.01 * (hi - lo))


@dataclass
class PersonalModels:
    """One trust model per participant (in the order of ``participants``, the study's values)."""

    participants: list[Any]
    models: list[TrustModel]
    centre: list[str]
    strength: dict[str, float]
    at_bound: dict[str, bool]
    loglik: np.ndarray
    centre_loglik: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray
    trials: np.ndarray
    warnings: list[str] = field(default_factory=list)

    def arrays(self) -> dict[str, Any]:
        """The models stacked as the arrays of a population of simulated supervisors
        (``Supervisors(**arrays)``: participant i is row i)."""
        first = self.models[0]
        return {
            "trust_levels": first.trust_levels,
            "complexities": first.complexities,
            "initial": np.stack([m.initial for m in self.models]),
            "emission": np.stack([m.emission for m in self.models]),
            "transition": np.stack([m.transition for m in self.models]),
            "index": np.arange(len(self.models), dtype=np.int64),
        }

    def frame(self) -> pd.DataFrame:
        """One row per participant: the centre, trials, log-likelihood under the centre and own model."""
        return pd.DataFrame(
            {
                "participant": self.participants,
                "centre": self.centre,
                "trials": self.trials,
                "loglik_centre": self.centre_loglik,
                "loglik_personal": self.loglik,
                "iterations": self.iterations,
                "converged": self.converged,
            }
        )

    def file_names(self) -> list[str]:
        """A file name per participant: the participant value made safe, made unique if needed."""
        out: list[str] = []
        seen: set[str] = set()
        for i, p in enumerate(self.participants):
            base = re.sub(r"[^A-Za-z0-9._-]+", "_", str(p)).strip("._") or f"participant{i + 1}"
            name = base
            while name.lower() in seen:
                name = f"{base}-{i + 1}"
            seen.add(name.lower())
            out.append(f"{name}.json")
        return out

    def save(self, folder: str | Path) -> None:
        """``<participant>.json`` per participant, ``participants.csv`` (with the file of each) and
        ``strength.json``, into ``folder`` (created)."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        names = self.file_names()
        for name, m in zip(names, self.models, strict=True):
            m.save(folder / name)
        table = self.frame()
        table.insert(1, "file", names)
        table.to_csv(folder / "participants.csv", index=False)
        (folder / "strength.json").write_text(
            json.dumps(json_safe({"strength": self.strength, "at_bound": self.at_bound, "warnings": self.warnings}), indent=2)
            + "\n",
            encoding="utf-8",
        )


def personalize(
    frame: pd.DataFrame,
    model: TrustModel | TypeMixture,
    strength: float | Mapping[str, float] | None = None,
    tol: float = 1e-8,
    max_iter: int = 1000,
    n_jobs: int | None = 1,
) -> PersonalModels:
    """Per-participant MAP models shrunk toward ``model`` (the pooled model, or a mixture: each
    participant's most probable type).  ``strength``: one s for every table, or per table
    (``initial``, ``emission``, ``transition``); None estimates each table's s by empirical Bayes."""
    if not kernels.AVAILABLE:
        raise FitError(["per-person models need the numba package"])
    mixture = model if isinstance(model, TypeMixture) else TypeMixture.single(model)
    spec, mp = mixture_params(mixture)
    seqs = encode(frame, spec)
    base = Structure(spec, seqs)
    N = seqs.n_participants
    if mixture.n_types > 1:
        mstruct = MixtureStructure(spec, seqs, mixture.n_types)
        pidx = type_posteriors(MixtureWorkspace(seqs, mstruct), mp).argmax(1)
    else:
        pidx = np.zeros(N, dtype=np.int64)
    types = [mp.type_params(m) for m in range(mixture.n_types)]
    centre = Params(
        np.stack([types[i].initial for i in pidx]),
        np.stack([types[i].emission for i in pidx]),
        np.stack([types[i].transition for i in pidx]),
    )
    work = _PersonalWorkspace(seqs, *base.dims, method="numba", threads=n_jobs or 1)
    start = base.project(centre)
    centre_ll = work.estep(start).loglik
    structure = _PersonalStructure(spec, seqs)
    init_mask = (centre.initial > 0) & (base.K > 1)
    it = np.where(init_mask, centre.initial, 0.0)
    means = {
        "initial": (it / it.sum(-1, keepdims=True), init_mask),
        "emission": _free_rows(base.em, np.zeros_like(centre.emission), centre.emission)[1:],
        "transition": _free_rows(base.tr, np.zeros_like(centre.transition), centre.transition)[1:],
    }

    def fit_with(s_tab: Mapping[str, float]) -> tuple[Params, list]:
        # pseudo-counts s * centre row on the usable free cells, at each tie group's representative row
        t, mask = means["initial"]
        structure.pseudo = {"initial": s_tab["initial"] * np.where(mask, t, 0.0)}
        for name, table in (("emission", base.em), ("transition", base.tr)):
            t, mask = means[name]
            pseudo = np.zeros(getattr(centre, name).shape)
            pseudo[:, table.rep] = s_tab[name] * np.where(mask, t, 0.0)
            structure.pseudo[name] = pseudo
        runs = run_em(structure, work, [start.take(n) for n in range(N)], tol=tol, max_iter=max_iter)
        return Params.stack([r.params for r in runs]), runs

    def strengths(params: Params) -> tuple[dict[str, float], dict[str, bool]]:
        st = work.estep(params)
        rows = {
            "initial": (st.initial, *means["initial"]),
            "emission": _free_rows(base.em, st.emission, centre.emission),
            "transition": _free_rows(base.tr, st.transition, centre.transition),
        }
        out = {name: estimate_strength(*rows[name]) for name in TABLES}
        return {k: v[0] for k, v in out.items()}, {k: v[1] for k, v in out.items()}

    if strength is None:
        s_tab, bound = strengths(start)
        params, runs = fit_with(s_tab)
    else:
        s_tab, bound = {}, {}
        for name in TABLES:
            value = strength[name] if isinstance(strength, Mapping) else strength
            if not (math.isfinite(value) and value >= 0):
                raise FitError([f"strength must be a finite number >= 0, got {value!r}"])
            s_tab[name], bound[name] = float(value), False
        params, runs = fit_with(s_tab)
    # rows no trial of the log reaches are the structure's defaults during the fit: the centre's instead
    params.emission[:, base.em.empty] = centre.emission[:, base.em.empty]
    params.transition[:, base.tr.empty] = centre.transition[:, base.tr.empty]
    models = [to_trust_model(spec, params.take(n)) for n in range(N)]
    warnings = [
        f"{name}: the strength is at its bound ({s_tab[name]:.3g}): the data show no individual differences there"
        for name in TABLES
        if bound[name] and strength is None
    ]
    unconverged = sum(not r.converged for r in runs)
    if unconverged:
        warnings.append(f"{unconverged} of {N} participants' fits stopped at the E-step cap")
    return PersonalModels(
        participants=list(seqs.participants),
        models=models,
        centre=[mixture.names[i] for i in pidx],
        strength=s_tab,
        at_bound=bound,
        loglik=work.estep(params).loglik,
        centre_loglik=centre_ll,
        iterations=np.array([r.iterations for r in runs]),
        converged=np.array([r.converged for r in runs]),
        trials=seqs.lengths.astype(np.int64),
        warnings=warnings,
    )
