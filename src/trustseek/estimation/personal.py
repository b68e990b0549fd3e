"""Per-person trust models: each participant's MAP estimate, shrunk toward a centre model.

The centre is the pooled model, or with supervisor types (a :class:`~trustseek.model.mixture.TypeMixture`)
the participant's most probable type.  Every free row of participant n's model gets the prior
Dirichlet(s t), t the centre's row over its usable cells (free, and positive in the centre): the
M-step is ``(expected counts + s t) / total``; tied rows share one prior, fixed cells and the
centre's zeros stay.  One strength s per table (emission, transition; the initial table keeps the
centre's, a single draw per participant carries no information on it), estimated ``held-out``
(:class:`_CrossValidation`: blocks of each participant's trials, a log grid of s, the one-standard-error
rule) or ``variational`` (:class:`_Evidence`: variational empirical Bayes, MacKay 1997; Beal 2003,
ch. 3), as docs/types.md describes and measures.  Each participant's MAP is the pooled fit's EM
(:func:`~.em.run_em`) on their trials only (the compiled pass :meth:`~.kernels.Kernel.run_each`).
"""

from __future__ import annotations

import json
import logging
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy.optimize import minimize
from scipy.special import digamma, gammaln

from ..model.core import TrustModel
from ..model.files import planning_refusal
from ..model.jsonfile import json_safe
from ..model.mixture import TypeMixture
from .em import RunResult, run_em
from .estep import EStep, Workspace
from .mixture import general_types, mixture_params, type_posteriors
from .mixture_em import MixtureStructure, MixtureWorkspace
from .options import SERIAL, FitOptions
from .sequences import Sequences, encode
from .spec import MAX_PSEUDOCOUNT, TABLES, FitError, IOHMMSpec, Params
from .structure import FLOOR, Structure, Table
from .trust_iohmm import to_model

log = logging.getLogger(__name__)

S_MIN, S_MAX = 1e-2, 1e6
GRID = 9  # strengths tried per table from S_MAX down to S_MIN (log-spaced) before the joint search
INNER_TOL = 1e-10  # relative gain of the summed bound below which the variational E-steps stop
TINY = 1e-300  # the prior's parameters are at least this
ESTIMATES = ("held-out", "variational")  # how personalize estimates s
FOLDS = 5  # cross-validation: blocks of consecutive trials per participant
NEGLIGIBLE = 1e-3  # a gain in the criterion this small per participant is none (s stays at S_MAX)
HELD_FLOOR = 1e6  # a held-out block of probability zero scores -HELD_FLOOR
# how a table's strength was chosen (PersonalModels.method)
EB = "variational empirical Bayes"
CV = "held-out log-likelihood, {folds} blocks of trials per participant"
NOTHING = "nothing to estimate (no row with two or more free cells that the trials reach)"
GIVEN = "given"
ONE_DRAW = "the centre's (one sequence per participant is one draw from it: no information on s)"


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

    def mstep(self, stats: EStep, previous: Params, prior: float | None = None) -> Params:
        """The pooled M-step of the expected counts plus the pseudo-counts (in place of any ``prior``)."""
        counts = {name: getattr(stats, name) + self.pseudo[name] for name in TABLES}
        return super().mstep(replace(stats, **counts), previous, prior=0.0)

    def log_prior(self, p: Params) -> np.ndarray:
        out = (self.pseudo["initial"] * np.log(np.maximum(p.initial, FLOOR))).sum(-1)
        for name in ("emission", "transition"):
            out = out + (self.pseudo[name] * np.log(np.maximum(getattr(p, name), FLOOR))).sum((-3, -2, -1))
        return out


class _Rows:
    """The Dirichlet rows of one table for N participants, tie groups as one row (the representative's):
    a row with two or more usable cells (free, positive in the centre) in a group the log reaches gets
    Dirichlet(s t), t the centre's row over them scaled to the free mass; a row with one is that cell at
    the free mass; fixed cells keep their values.  ``centre``: (N, U, K, X), or (N, K) for the initial
    table (``table`` None)."""

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
    """Variational Bayes (MacKay 1997; Beal 2003, ch. 3) for every participant's model at once: q(theta_n)
    Dirichlet(s t + expected counts) per row, q(levels of n) the forward-backward posterior under
    exp(E_q[log theta_n]); the bound ``log Z_n - KL(q(theta_n) || prior)`` never decreases along the
    updates and is at most log p(trials of n | s)."""

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
        by = {"initial": st.initial[:, None, None, :], "emission": st.emission, "transition": st.transition}
        return {k: self.rows[k].grouped(by[k]) for k in TABLES}

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


def _estimable(rows: Mapping[str, _Rows], counts: Mapping[str, np.ndarray]) -> list[str]:
    """The tables whose s the data inform: a Dirichlet row some participant's trials reach, and not
    the initial table (each participant's trials are one draw from their initial row, and the
    probability of a single draw is the centre's whatever s is)."""
    return [k for k in TABLES if k != "initial" and np.where(rows[k].dirichlet[..., None], counts[k], 0.0).sum() > 0]


def _strengths(
    evidence: _Evidence, start: dict[str, np.ndarray], free: list[str], tol: float, max_iter: int
) -> tuple[dict[str, float], float, float]:
    """The strengths of the tables ``free`` maximising the summed variational bound (log scale, within
    [S_MIN, S_MAX]; the others at S_MAX), the bound there and at s = S_MAX (the centre itself)."""
    rows = evidence.rows
    s = dict.fromkeys(TABLES, S_MAX)
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
        return s, -at_max, -at_max
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
    # a table whose s gains next to nothing over S_MAX (NEGLIGIBLE per participant) keeps the centre
    for i in range(len(free)):
        at_top = x.copy()
        at_top[i] = hi
        top, _ = evaluate(at_top)
        if top - value <= NEGLIGIBLE * int(np.count_nonzero(evidence.active)):
            x, value = at_top, top
    value, _ = evaluate(x)
    s.update({k: S_MAX for k, v in zip(free, x, strict=True) if v >= hi - 1e-9})
    return s, -value, -at_max


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
        centre = Params.stack([each[i] for i in types])
        work = _PersonalWorkspace(seqs, *base.dims, method="compiled", threads=n_jobs or 1)
        start = base.project(centre)
        rows = {
            "initial": _Rows(centre.initial, None),
            "emission": _Rows(centre.emission, base.em),
            "transition": _Rows(centre.transition, base.tr),
        }
        return cls(spec, seqs, base, mixture, types, centre, work, start, work.estep(start), rows)

    def evidence(self) -> _Evidence:
        return _Evidence(self.work, self.rows)

    def structure(self, s: Mapping[str, float]) -> _PersonalStructure:
        """The MAP structure with pseudo-counts s t on the usable cells, at each tie group's
        representative row (empty elsewhere)."""
        structure = _PersonalStructure(self.spec, self.seqs)
        structure.pseudo = {"initial": self.rows["initial"].prior(s["initial"])[:, 0, 0]}
        for name, table in (("emission", self.base.em), ("transition", self.base.tr)):
            pseudo = np.zeros(getattr(self.centre, name).shape)
            pseudo[:, table.rep] = self.rows[name].prior(s[name])
            structure.pseudo[name] = pseudo
        return structure

    def fit(self, s: Mapping[str, float], work: Workspace, starts: Params, tol: float, max_iter: int) -> list[RunResult]:
        """Each participant's MAP at strengths ``s`` on the trials of ``work``, from ``starts``."""
        N = self.seqs.n_participants
        return run_em(self.structure(s), work, [starts.take(n) for n in range(N)], tol=tol, max_iter=max_iter)


def blocks(lengths: np.ndarray, T: int, folds: int) -> np.ndarray:
    """(T, N): the block (0 .. folds - 1) of each position of each sequence, ``folds`` runs of
    consecutive trials of sizes differing by at most one (a sequence shorter than ``folds`` leaves
    some blocks empty); padding positions get ``folds`` or more."""
    L = np.asarray(lengths, dtype=np.int64)[None, :]
    return np.where(np.arange(T)[:, None] < L, (np.arange(T)[:, None] * folds) // np.maximum(L, 1), folds)


class _CrossValidation:
    """Held-out log-likelihood of each participant's MAP: the trials of each participant split into
    ``folds`` consecutive blocks; fold f's models are fitted with block f's actions unobserved, and
    score log p(all actions) - log p(the others'), i.e. log p(block f | the other blocks)."""

    def __init__(self, prep: _Prepared, folds: int, tol: float, max_iter: int):
        self.prep, self.tol, self.max_iter = prep, tol, max_iter
        seqs = prep.seqs
        block = blocks(seqs.lengths, seqs.y.shape[0], folds)
        self.works = [
            _PersonalWorkspace(
                replace(seqs, y=np.where(block == f, -1, seqs.y).astype(seqs.y.dtype)),
                *prep.base.dims,
                method="compiled",
                threads=prep.work.threads,
            )
            for f in range(folds)
        ]
        self.starts = [prep.start] * folds  # each fold's last fit: the next one starts there

    def score(self, s: Mapping[str, float]) -> np.ndarray:
        """Each participant's held-out log-likelihood at strengths ``s``, summed over the folds (N,)."""
        total = np.zeros(self.prep.seqs.n_participants)
        for f, work in enumerate(self.works):
            runs = self.prep.fit(s, work, self.starts[f], self.tol, self.max_iter)
            params = Params.stack([r.params for r in runs])
            held = self.prep.work.estep(params).loglik - np.array([r.loglik for r in runs])
            total += np.where(np.isfinite(held), held, -HELD_FLOOR)
            self.starts[f] = params
        return total


def _cv_strengths(
    prep: _Prepared, free: list[str], folds: int, tol: float, max_iter: int
) -> tuple[dict[str, float], float, float]:
    """Each table's s by the held-out log-likelihood (:class:`_CrossValidation`), one table at a time
    (the others at their choice so far): a decade grid from S_MAX down to S_MIN, refined by half and
    quarter decades around the best, then the largest s tried whose score is within one standard
    error of the best's (the paired differences over participants; the one-standard-error rule).
    The strengths of the tables ``free`` (the others at S_MAX), the score there and at s = S_MAX everywhere."""
    cv = _CrossValidation(prep, folds, tol, max_iter)
    s = dict.fromkeys(TABLES, S_MAX)
    current = cv.score(s)
    centre = float(current.sum())
    lo, hi = math.log10(S_MIN), math.log10(S_MAX)
    N = len(current)
    for k in free:
        tried = {hi: current}
        grid = [float(x) for x in np.linspace(hi, lo, GRID)[1:]]
        for step in (None, 0.5, 0.25):  # the decade grid, then half and quarter decades either side of the best
            x_best = max(tried, key=lambda x: (tried[x].sum(), x))
            for v in grid if step is None else [x_best + step, x_best - step]:
                if lo <= v <= hi and v not in tried:
                    tried[v] = cv.score({**s, k: 10.0**v})
        x_best = max(tried, key=lambda x: (tried[x].sum(), x))
        best = tried[x_best]

        # the largest s no worse than the best by more than one standard error of the difference
        # (or than NEGLIGIBLE per participant)
        x_pick = x_best
        for x in sorted(tried, reverse=True):
            d = best - tried[x]
            se = math.sqrt(N) * float(np.std(d, ddof=1)) if N > 1 else 0.0
            if x > x_best and d.sum() <= max(se, NEGLIGIBLE * N):
                x_pick = x
                break
        s[k], current = 10.0**x_pick, tried[x_pick]
    return s, float(current.sum()), centre


@dataclass
class PersonalModels:
    """One trust model per participant (in the order of ``participants``, the study's values)."""

    participants: list[Any]
    models: list[TrustModel]  # general models for a centre with a study's named inputs
    centre: list[str]
    strength: dict[str, float]
    at_bound: dict[str, bool]
    method: dict[str, str]  # how each table's s was chosen
    estimate: str  # "held-out", "variational" or "given"
    score: float  # the criterion at the chosen strengths (held-out log-likelihood, or variational bound)
    score_centre: float  # the same at s = S_MAX in every table (the centre)
    loglik: np.ndarray
    centre_loglik: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray
    trials: np.ndarray
    warnings: list[str] = field(default_factory=list)

    def arrays(self) -> dict[str, Any]:
        """The models stacked as the arrays of a population of simulated supervisors
        (``Supervisors(**arrays)``: participant i is row i); trust models only."""
        first = self.models[0]
        if first.general:
            raise FitError([planning_refusal(first.used_inputs)])
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

    def summary(self) -> dict[str, Any]:
        """The strengths, how they were chosen and the criterion (as ``strength.json`` holds them)."""
        return {k: getattr(self, k) for k in ("strength", "at_bound", "method", "estimate", "score", "score_centre", "warnings")}

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
            json.dumps(json_safe(self.summary()), indent=2) + "\n",
            encoding="utf-8",
        )


def personalize(
    frame: pd.DataFrame,
    model: TrustModel | TypeMixture,
    strength: float | Mapping[str, float] | None = None,
    options: FitOptions = SERIAL,
    estimate: str = "held-out",
    folds: int = FOLDS,
) -> PersonalModels:
    """Per-participant MAP models shrunk toward ``model`` (the pooled model, or a mixture: each
    participant's most probable type).  ``strength``: one s for every table, or per table
    (``initial``, ``emission``, ``transition``); None estimates each table's s, by ``estimate``:
    ``held-out`` (the held-out log-likelihood over ``folds`` blocks of each participant's trials)
    or ``variational`` (variational empirical Bayes).  Each participant's EM runs to ``options.tol``
    (relative) or ``options.max_iter`` E-steps, the participants' E-steps on ``options.n_jobs``
    threads (:class:`~.options.FitOptions`; by default one)."""
    tol, max_iter = options.tol, options.max_iter
    given = [] if strength is None else list(strength.values()) if isinstance(strength, Mapping) else [strength]
    for value in given:  # before the participants' data are prepared
        if not 0 <= value <= MAX_PSEUDOCOUNT:
            raise FitError([f"strength (--strength) must be a pseudo-count between 0 and {MAX_PSEUDOCOUNT:g}, got {value!r}"])
    if strength is None and estimate not in ESTIMATES:
        raise FitError([f"estimate must be one of {list(ESTIMATES)}, got {estimate!r}"])
    if strength is None and estimate == "held-out" and not (isinstance(folds, int) and folds >= 2):
        raise FitError([f"folds must be an integer >= 2, got {folds!r}"])
    prep = _Prepared.of(frame, model, options.n_jobs)
    spec, seqs, base, centre, work, start = prep.spec, prep.seqs, prep.base, prep.centre, prep.work, prep.start
    N = seqs.n_participants
    warnings: list[str] = []
    if strength is None:
        evidence = prep.evidence()
        left_out = int(N - np.count_nonzero(evidence.active))
        counts = evidence.counts(prep.first)
        free = _estimable(prep.rows, counts)  # the other tables' s: the data say nothing about it
        how = EB if estimate == "variational" else CV.format(folds=folds)
        method = {k: how if k in free else ONE_DRAW if k == "initial" else NOTHING for k in TABLES}
        if estimate == "variational":
            if left_out:
                warnings.append(
                    f"{left_out} of {N} participants' trials are impossible where the centre has "
                    "a zero: they are left out of the strength estimate"
                )
            s_tab, score, centre_score = _strengths(evidence, counts, free, tol, max_iter)
        else:
            s_tab, score, centre_score = _cv_strengths(prep, free, folds, tol, max_iter)
        bound = {k: k not in free or s_tab[k] >= S_MAX for k in TABLES}
        warnings += [
            f"{name}: the strength is at its bound ({s_tab[name]:.3g}): the data show no individual differences there"
            for name in free
            if bound[name]
        ]
        warnings += [
            f"{name}: the strength is at its lower bound ({s_tab[name]:.3g}): each participant's rows are their own counts"
            for name in TABLES
            if s_tab[name] <= S_MIN * (1 + 1e-9)
        ]
    else:
        s_tab = {name: float(strength[name] if isinstance(strength, Mapping) else strength) for name in TABLES}
        bound, method, score, centre_score = dict.fromkeys(TABLES, False), dict.fromkeys(TABLES, GIVEN), math.nan, math.nan
    runs = prep.fit(s_tab, work, start, tol, max_iter)
    params = Params.stack([r.params for r in runs])
    # rows no trial of the log reaches are the structure's defaults during the fit: the centre's instead
    params.emission[:, base.em.empty] = centre.emission[:, base.em.empty]
    params.transition[:, base.tr.empty] = centre.transition[:, base.tr.empty]
    models = [to_model(spec, params.take(n), general=general_types(spec)) for n in range(N)]
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
        estimate=estimate if strength is None else GIVEN,
        score=score,
        score_centre=centre_score,
        loglik=work.estep(params).loglik,
        centre_loglik=prep.first.loglik,
        iterations=np.array([r.iterations for r in runs]),
        converged=np.array([r.converged for r in runs]),
        trials=seqs.lengths.astype(np.int64),
        warnings=warnings,
    )
