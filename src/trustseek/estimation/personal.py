"""Per-person trust models: each participant's MAP estimate, shrunk toward a centre model.

The centre is the pooled model, or with supervisor types (a
:class:`~trustseek.model.mixture.TypeMixture`) the participant's most probable type.  Every
free row of participant n's model gets a Dirichlet prior Dirichlet(s t) with t the centre's
row (over the row's usable cells: free, and positive in the centre, renormalised), so the
M-step is ``(expected counts + s t) / total``: a row the participant's trials never reach
stays the centre's, and a row they reach often moves toward their own counts.  Tied rows
share one prior and one estimate; fixed cells stay fixed; a zero of the centre stays zero.

**The strength s** is estimated from the data, **one s per table** (initial, emission,
transition), by variational empirical Bayes (MacKay 1997; Beal 2003, ch. 3): for given
strengths, each participant's posterior is approximated by q(theta_n) q(levels_n), with
q(theta_n) a Dirichlet per row whose parameters are ``s t + expected counts`` and q(levels_n)
the forward-backward posterior under the sub-normalised tables exp(E_q[log theta_n]); the
bound on log p(trials of n | s),

    F_n(s) = log Z_n - KL(q(theta_n) || Dirichlet(s t)),

(Z_n: the forward-backward normaliser under those tables) is maximised over q by alternating
the two updates (it never decreases), and ``sum_n F_n`` over log s in [:data:`S_MIN`,
:data:`S_MAX`]: a coarse grid of common strengths, then L-BFGS-B on each table's own s with
the gradient sum_n dE_q[log Dirichlet(theta_n | s t)]/ds (exact at the converged q).  Unlike
a marginal likelihood of counts computed under the centre, the bound sees a participant's
differences through their own q(theta_n): a participant who relies more than the centre gets
rows that explain it, not more time at a level.  A large s says the participants do not
differ from the centre beyond what their trials can show; at :data:`S_MAX` the result is
reported as at the bound (and the personal models are the centre).  The bound is below the
evidence by a gap that grows as s gets small (the approximation ignores how the levels and
the rows depend on each other), so it errs toward shrinking more.  Give ``strength`` to set s.

Each participant's MAP is the EM of the pooled fit (:func:`~.em.run_em`, SQUAREM), one
parameter set per participant, each run on that participant's trials only (the compiled
pass :meth:`~.kernels.Kernel.run_each`), from the centre; the variational E-steps use the
same pass.
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
from scipy.optimize import minimize
from scipy.special import digamma, gammaln

from ..model.core import TrustModel, json_safe
from ..model.mixture import TypeMixture
from . import kernels
from .em import run_em
from .estep import EStep, Workspace
from .mixture import MixtureStructure, MixtureWorkspace, mixture_params, type_posteriors
from .sequences import Sequences, encode
from .spec import FitError, IOHMMSpec, Params
from .structure import FLOOR, Structure, Table
from .trust_iohmm import to_trust_model

log = logging.getLogger(__name__)

TABLES = ("initial", "emission", "transition")
S_MIN, S_MAX = 1e-2, 1e6
GRID = 9  # strengths tried per table from S_MAX down to S_MIN (log-spaced) before the joint search
INNER_TOL = 1e-10  # relative gain of the summed bound below which the variational E-steps stop
TINY = 1e-300  # the prior's parameters are at least this
# how a table's strength was chosen (PersonalModels.method)
EB = "variational empirical Bayes"
NOTHING = "no free row the trials reach"
GIVEN = "given"


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


class _Rows:
    """The Dirichlet rows of one table for N participants, tie groups as one row (the representative's).

    A row's usable cells are its free cells where the centre is positive (a zero of the centre is a
    zero of every personal model); a row with two or more usable cells, in a group the log reaches,
    gets the prior Dirichlet(s t) with t the centre's row renormalised over those cells, scaled to
    the row's free mass.  A row with one usable cell is that cell at the free mass; fixed cells keep
    their values.  ``centre``: (N, U, K, X), or (N, K) for the initial table (``table`` None).
    """

    def __init__(self, centre: np.ndarray, table: Table | None):
        if table is None:
            rows = centre[:, None, None, :]
            X = centre.shape[-1]
            self.group, self.onehot = np.zeros(1, dtype=np.int64), np.ones((1, 1))
            fixed, values = np.zeros((1, 1, X), dtype=bool), np.zeros((1, 1, X))
            mass, reached = np.ones((1, 1)), np.ones(1, dtype=bool)
        else:
            rows = centre[:, table.rep]
            self.group, self.onehot = table.group, table.onehot
            fixed, values, mass, reached = table.gfixed, table.gvalues, table.mass, ~table.empty[table.rep]
        usable = ~fixed[None] & (rows > 0) & reached[None, :, None, None]
        self.dirichlet = usable.sum(-1) >= 2  # (N, G, K)
        self.mask = usable & self.dirichlet[..., None]
        t = np.where(self.mask, rows, 0.0)
        total = t.sum(-1, keepdims=True)
        self.t = t / np.where(total > 0, total, 1.0)
        self.single = usable & ~self.dirichlet[..., None]
        self.fixed = np.where(fixed, values, 0.0)
        self.mass = mass[..., None]

    def grouped(self, counts: np.ndarray) -> np.ndarray:
        """Expected counts (N, U, K, X) summed over each tie group: (N, G, K, X) on the usable cells."""
        return np.where(self.mask, np.einsum("nukx,ug->ngkx", counts, self.onehot), 0.0)

    def prior(self, s: float) -> np.ndarray:
        """The prior's Dirichlet parameters s t (N, G, K, X), zero off the usable cells."""
        return np.where(self.mask, np.maximum(s * self.t, TINY), 0.0)

    def expected_log(self, alpha: np.ndarray) -> np.ndarray:
        """E[log phi] under Dirichlet(alpha) on the usable cells (0 elsewhere)."""
        a = np.where(self.mask, alpha, 1.0)
        total = np.where(self.mask, alpha, 0.0).sum(-1, keepdims=True)
        return np.where(self.mask, digamma(a) - digamma(np.where(self.dirichlet[..., None], total, 1.0)), 0.0)

    def tilde(self, alpha: np.ndarray) -> np.ndarray:
        """The sub-normalised table exp(E[log theta]) under q = Dirichlet(alpha), rows (N, U, K, X)."""
        g = np.where(self.mask, self.mass * np.exp(self.expected_log(alpha)), np.where(self.single, self.mass, self.fixed))
        return g[:, self.group]

    def kl(self, alpha: np.ndarray, beta: np.ndarray) -> np.ndarray:
        """KL(Dirichlet(alpha) || Dirichlet(beta)) summed over the rows of each participant (N,)."""
        m, d = self.mask, self.dirichlet
        a, b = np.where(m, alpha, 1.0), np.where(m, beta, 1.0)
        A = np.where(d, np.where(m, alpha, 0.0).sum(-1), 1.0)
        B = np.where(d, np.where(m, beta, 0.0).sum(-1), 1.0)
        cells = np.where(m, gammaln(b) - gammaln(a) + (a - b) * (digamma(a) - digamma(A)[..., None]), 0.0).sum(-1)
        return np.where(d, gammaln(A) - gammaln(B) + cells, 0.0).sum((-2, -1))

    def gradient(self, alpha: np.ndarray, s: float) -> float:
        """d/ds of sum_n E_q[log Dirichlet(theta_n | s t)] (rows where q is the prior add zero)."""
        m, d = self.mask, self.dirichlet
        st = np.where(m, np.maximum(s * self.t, TINY), 1.0)
        cells = np.where(m, self.t * (self.expected_log(alpha) - digamma(st)), 0.0).sum(-1)
        return float(np.where(d, digamma(s) + cells, 0.0).sum())


@dataclass
class _Variational:
    """Where the variational E-steps of one set of strengths ended."""

    bound: np.ndarray  # (N,) each participant's lower bound on log p(trials | s)
    alpha: dict[str, np.ndarray]  # q(theta_n) per table
    counts: dict[str, np.ndarray]  # the expected counts that q(theta_n) came from (warm start)
    iterations: int


class _Evidence:
    """Variational Bayes (MacKay 1997; Beal 2003, ch. 3) for every participant's model at once.

    For strengths s (per table), q(theta_n) is Dirichlet(s t + expected counts) per row and
    q(levels of n) the forward-backward posterior under the sub-normalised tables
    exp(E_q[log theta_n]); the bound ``log Z_n - KL(q(theta_n) || prior)`` (Z_n: the
    forward-backward normaliser under those tables) never decreases along the updates and is
    at most log p(trials of n | s).
    """

    def __init__(self, work: _PersonalWorkspace, rows: dict[str, _Rows]):
        self.work, self.rows = work, rows
        self.active = np.ones(work.N, dtype=bool)
        # participants whose trials the centre's zeros make impossible take no part
        self.active = np.isfinite(self.estep({k: rows[k].prior(S_MAX) for k in TABLES}).loglik)

    def estep(self, alpha: Mapping[str, np.ndarray]) -> EStep:
        """The forward-backward pass under the sub-normalised tables of q(theta_n) = Dirichlet(alpha)."""
        tilde = {k: self.rows[k].tilde(alpha[k]) for k in TABLES}
        return self.work.estep(Params(tilde["initial"][:, 0, 0], tilde["emission"], tilde["transition"]), self.active)

    def counts(self, st: EStep) -> dict[str, np.ndarray]:
        return {
            "initial": self.rows["initial"].grouped(st.initial[:, None, None, :]),
            "emission": self.rows["emission"].grouped(st.emission),
            "transition": self.rows["transition"].grouped(st.transition),
        }

    def run(self, s: Mapping[str, float], counts: Mapping[str, np.ndarray], tol: float, max_iter: int) -> _Variational:
        """Variational E-steps from q(theta_n) = Dirichlet(s t + ``counts``) until the summed bound
        gains less than ``tol`` (relative) in a step, or ``max_iter`` steps."""
        previous = -math.inf
        it = 0
        while True:
            it += 1
            alpha = {k: self.rows[k].prior(s[k]) + counts[k] for k in TABLES}
            st = self.estep(alpha)
            kl = sum(self.rows[k].kl(alpha[k], self.rows[k].prior(s[k])) for k in TABLES)
            bound = np.where(np.isfinite(st.loglik), st.loglik - kl, 0.0)
            counts = self.counts(st)
            total = float(bound.sum())
            if it >= max_iter or total - previous <= tol * abs(total):
                return _Variational(bound, alpha, counts, it)
            previous = total


def _strengths(
    evidence: _Evidence, start: dict[str, np.ndarray], tol: float, max_iter: int
) -> tuple[dict[str, float], dict[str, bool], dict[str, str], float, float]:
    """The strengths maximising the summed variational bound (log scale, within [S_MIN, S_MAX]); whether
    each is at a bound, how it was chosen, the bound there and at s = S_MAX (the centre itself)."""
    rows = evidence.rows
    # a table whose Dirichlet rows no participant's trials reach: the data say nothing about its s
    free = [k for k in TABLES if (np.where(rows[k].dirichlet[..., None], start[k], 0.0).sum() > 0)]
    s = dict.fromkeys(TABLES, S_MAX)
    how = {k: (EB if k in free else NOTHING) for k in TABLES}
    lo, hi = math.log(S_MIN), math.log(S_MAX)
    state = {"counts": dict(start)}

    def evaluate(x: np.ndarray) -> tuple[float, np.ndarray]:
        for k, v in zip(free, x, strict=True):
            s[k] = math.exp(float(v))
        res = evidence.run(s, state["counts"], INNER_TOL, max_iter)
        state["counts"] = res.counts
        grad = np.array([rows[k].gradient(res.alpha[k], s[k]) * s[k] for k in free])
        return -float(res.bound.sum()), -grad

    at_max, _ = evaluate(np.full(len(free), hi))
    if not free:
        return s, dict.fromkeys(TABLES, True), how, -at_max, -at_max
    # a coarse grid for each table in turn (the others at their best so far), from the centre down;
    # then all tables' s together by L-BFGS-B from there
    x0 = np.full(len(free), hi)
    for i in range(len(free)):
        tried = []
        for v in np.linspace(hi, lo, GRID):
            x0[i] = v
            tried.append((evaluate(x0)[0], v))
        x0[i] = min(tried)[1]
    evaluate(x0)
    res = minimize(evaluate, x0, jac=True, method="L-BFGS-B", bounds=[(lo, hi)] * len(free), options={"ftol": tol})
    x = np.asarray(res.x, dtype=float)
    value, _ = evaluate(x)
    near = 0.01 * (hi - lo)
    bound = dict.fromkeys(TABLES, True)
    bound.update({k: bool(v <= lo + near or v >= hi - near) for k, v in zip(free, x, strict=True)})
    return s, bound, how, -value, -at_max


@dataclass
class PersonalModels:
    """One trust model per participant (in the order of ``participants``, the study's values)."""

    participants: list[Any]
    models: list[TrustModel]
    centre: list[str]
    strength: dict[str, float]
    at_bound: dict[str, bool]
    method: dict[str, str]
    evidence_bound: float
    evidence_bound_centre: float
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


@dataclass
class _Prepared:
    """The log encoded against the centre: each participant's centre (the pooled model, or their most
    probable type), the E-step of every participant under it, and the rows of the priors."""

    spec: IOHMMSpec
    seqs: Sequences
    base: Structure
    mixture: TypeMixture
    types: np.ndarray  # (N,) each participant's type
    centre: Params  # (N, ...) each participant's centre
    work: _PersonalWorkspace
    start: Params  # the centre, projected (no exact zero): where each participant's EM starts
    first: EStep  # each participant's E-step under ``start``
    rows: dict[str, _Rows]

    @classmethod
    def of(cls, frame: pd.DataFrame, model: TrustModel | TypeMixture, n_jobs: int | None = 1) -> _Prepared:
        if not kernels.AVAILABLE:
            raise FitError(["per-person models need the numba package"])
        mixture = model if isinstance(model, TypeMixture) else TypeMixture.single(model)
        spec, mp = mixture_params(mixture)
        seqs = encode(frame, spec)
        base = Structure(spec, seqs)
        N = seqs.n_participants
        if mixture.n_types > 1:
            mstruct = MixtureStructure(spec, seqs, mixture.n_types)
            types = type_posteriors(MixtureWorkspace(seqs, mstruct), mp).argmax(1)
        else:
            types = np.zeros(N, dtype=np.int64)
        each = [mp.type_params(m) for m in range(mixture.n_types)]
        centre = Params(
            np.stack([each[i].initial for i in types]),
            np.stack([each[i].emission for i in types]),
            np.stack([each[i].transition for i in types]),
        )
        work = _PersonalWorkspace(seqs, *base.dims, method="numba", threads=n_jobs or 1)
        start = base.project(centre)
        rows = {
            "initial": _Rows(centre.initial, None),
            "emission": _Rows(centre.emission, base.em),
            "transition": _Rows(centre.transition, base.tr),
        }
        return cls(spec, seqs, base, mixture, types, centre, work, start, work.estep(start), rows)

    def evidence(self) -> _Evidence:
        return _Evidence(self.work, self.rows)


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
    (``initial``, ``emission``, ``transition``); None estimates each table's s by variational
    empirical Bayes."""
    prep = _Prepared.of(frame, model, n_jobs)
    spec, seqs, base, centre, work, start, rows = prep.spec, prep.seqs, prep.base, prep.centre, prep.work, prep.start, prep.rows
    N = seqs.n_participants
    structure = _PersonalStructure(spec, seqs)
    warnings: list[str] = []

    def fit_with(s_tab: Mapping[str, float]) -> tuple[Params, list]:
        # pseudo-counts s * centre row on the usable cells, at each tie group's representative row
        structure.pseudo = {"initial": rows["initial"].prior(s_tab["initial"])[:, 0, 0]}
        for name, table in (("emission", base.em), ("transition", base.tr)):
            pseudo = np.zeros(getattr(centre, name).shape)
            pseudo[:, table.rep] = rows[name].prior(s_tab[name])
            structure.pseudo[name] = pseudo
        runs = run_em(structure, work, [start.take(n) for n in range(N)], tol=tol, max_iter=max_iter)
        return Params.stack([r.params for r in runs]), runs

    bound_at = {"estimate": math.nan, "centre": math.nan}
    if strength is None:
        evidence = prep.evidence()
        left_out = int(N - np.count_nonzero(evidence.active))
        if left_out:
            warnings.append(
                f"{left_out} of {N} participants' trials are impossible where the centre has "
                "a zero: they are left out of the strength estimate"
            )
        s_tab, bound, method, bound_at["estimate"], bound_at["centre"] = _strengths(
            evidence, evidence.counts(prep.first), tol, max_iter
        )
        warnings += [
            f"{name}: the strength is at its bound ({s_tab[name]:.3g}): the data show no individual differences there"
            for name in TABLES
            if bound[name] and method[name] == EB
        ]
    else:
        s_tab, bound, method = {}, {}, {}
        for name in TABLES:
            value = strength[name] if isinstance(strength, Mapping) else strength
            if not (math.isfinite(value) and value >= 0):
                raise FitError([f"strength must be a finite number >= 0, got {value!r}"])
            s_tab[name], bound[name], method[name] = float(value), False, GIVEN
    params, runs = fit_with(s_tab)
    # rows no trial of the log reaches are the structure's defaults during the fit: the centre's instead
    params.emission[:, base.em.empty] = centre.emission[:, base.em.empty]
    params.transition[:, base.tr.empty] = centre.transition[:, base.tr.empty]
    models = [to_trust_model(spec, params.take(n)) for n in range(N)]
    unconverged = sum(not r.converged for r in runs)
    if unconverged:
        warnings.append(f"{unconverged} of {N} participants' fits stopped at the E-step cap")
    return PersonalModels(
        participants=list(seqs.participants),
        models=models,
        centre=[prep.mixture.names[i] for i in prep.types],
        strength=s_tab,
        at_bound=bound,
        method=method,
        evidence_bound=bound_at["estimate"],
        evidence_bound_centre=bound_at["centre"],
        loglik=work.estep(params).loglik,
        centre_loglik=prep.first.loglik,
        iterations=np.array([r.iterations for r in runs]),
        converged=np.array([r.converged for r in runs]),
        trials=seqs.lengths.astype(np.int64),
        warnings=warnings,
    )
