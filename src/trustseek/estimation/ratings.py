"""A self-reported rating as a second emission of the hidden level, through one joint output.

With a ``rating`` (:class:`~.spec.IOHMMSpec`) the E-step sees one output of (M + 1) x (R + 1)
categories, "missing" a category of each factor: joint[u, k, (y, r)] = P(y | k, u) P(r | k), a
missing factor contributing 1, so the compiled E-step runs unchanged.  The M-step marginalises the
expected counts to each factor: the output's rows with the spec's structure, the rating's rows free
(:class:`RatingStructure`); such fits run EM with SQUAREM and the stationarity check, without the
L-BFGS-B finish.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .estep import EStep
from .sequences import Sequences
from .spec import IOHMMSpec, Params
from .structure import FLOOR, PROJECT_FLOOR, Structure, normalised, random_rows


def split_joint(joint: np.ndarray, M: int, R: int) -> tuple[np.ndarray, np.ndarray]:
    """The factors of a joint table (..., U, K, (M+1)(R+1)): the output's (..., U, K, M) and the rating's (..., K, R)."""
    e = joint.reshape(*joint.shape[:-1], M + 1, R + 1)
    return e[..., :M, R].copy(), e[..., 0, :, M, :R].copy()


def compose_joint(action: np.ndarray, rating: np.ndarray) -> np.ndarray:
    """The joint table of an output table (..., U, K, M) and a rating table (..., K, R)."""
    M, R = action.shape[-1], rating.shape[-1]
    J = np.ones((*action.shape[:-1], M + 1, R + 1))
    J[..., :M, :R] = action[..., :, None] * rating[..., None, :, None, :]
    J[..., :M, R] = action
    J[..., M, :R] = rating[..., None, :, :]
    return J.reshape(*action.shape[:-1], (M + 1) * (R + 1))


def split_counts(counts: np.ndarray, M: int, R: int) -> tuple[np.ndarray, np.ndarray]:
    """Expected counts per joint category (..., U, K, (M+1)(R+1)) marginalised to each factor:
    the output's (..., U, K, M) (trials with that output, rated or not) and the rating's
    (..., K, R) (trials with that rating, over every input combination and output)."""
    c = counts.reshape(*counts.shape[:-1], M + 1, R + 1)
    return c[..., :M, :].sum(-1), c[..., :R].sum(-2).sum(-3)


class RatingStructure(Structure):
    """A spec with a rating compiled against data: the output's :class:`Structure` (its
    tables ``em`` and ``tr`` are the output's) plus a free rating row per level; parameters
    carry the joint emission table (see the module's description)."""

    joint = True

    def __init__(self, spec: IOHMMSpec, seqs: Sequences):
        M, R = spec.n_outputs, spec.n_ratings
        self.M_out, self.R = M, R
        y = seqs.y.astype(np.int32)
        action = np.where(y >= 0, y // (R + 1), -1)
        action = np.where(action == M, -1, action).astype(seqs.y.dtype)
        super().__init__(replace(spec, rating=None, rating_levels=()), replace(seqs, y=action))
        self.spec = spec
        self.n_free += spec.n_levels * (R - 1)

    @property
    def dims(self) -> tuple[int, int, int, int]:
        return self.K, (self.M_out + 1) * (self.R + 1), self.Ue, self.Ut

    def factors(self, p: Params) -> tuple[Params, np.ndarray]:
        """The output's parameters (a plain IOHMM's) and the rating table (..., K, R) of joint ``p``."""
        action, rating = split_joint(p.emission, self.M_out, self.R)
        return Params(p.initial, action, p.transition), rating

    def combined(self, p: Params, rating: np.ndarray) -> Params:
        """Joint parameters from the output's parameters ``p`` and a rating table."""
        return Params(p.initial, compose_joint(p.emission, rating), p.transition)

    def action_counts(self, counts: np.ndarray) -> np.ndarray:
        return split_counts(counts, self.M_out, self.R)[0]

    def rating_counts(self, counts: np.ndarray) -> np.ndarray:
        """Expected events behind each cell of the rating table, (..., K, R)."""
        return split_counts(counts, self.M_out, self.R)[1]

    def random(self, rng: np.random.Generator) -> Params:
        base = super().random(rng)
        return self.combined(base, random_rows(rng, self.R, self.K))

    def project(self, p: Params) -> Params:
        base, rating = self.factors(p)
        rating = np.clip(rating, PROJECT_FLOOR, None)
        return self.combined(super().project(base), rating / rating.sum(-1, keepdims=True))

    def mstep(self, stats: EStep, previous: Params, prior: float | None = None) -> Params:
        a = self.spec.prior if prior is None else prior
        action, rc = split_counts(stats.emission, self.M_out, self.R)
        prev, prev_rating = self.factors(previous)
        base = super().mstep(replace(stats, emission=action), prev, a)
        return self.combined(base, normalised(rc + a, prev_rating))

    def log_prior(self, p: Params) -> np.ndarray:
        base, rating = self.factors(p)
        out = super().log_prior(base)
        if self.spec.prior:
            out = out + self.spec.prior * np.log(np.maximum(rating, FLOOR)).sum((-2, -1))
        return out

    def order(self, p: Params) -> np.ndarray:
        """The output's rule (:meth:`Structure.order`); when no output was observed at all (a
        fit on ratings alone), the levels in ascending order of their mean rating position."""
        base, rating = self.factors(p)
        if not np.all(self.em.empty):
            return super().order(base)
        score = rating @ np.arange(self.R)
        return np.lexsort((np.arange(self.K), np.round(score, 9)))


def make_structure(spec: IOHMMSpec, seqs: Sequences) -> Structure:
    """The compiled structure of ``spec``: a :class:`RatingStructure` when it has a rating."""
    return RatingStructure(spec, seqs) if spec.rating is not None else Structure(spec, seqs)
