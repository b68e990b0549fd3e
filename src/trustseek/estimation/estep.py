"""The E-step of the IOHMM: scaled forward-backward and the expected counts, for R parameter sets at once.

One index layout serves every implementation: trial t of sequence n reads emission row ``eidx[t, n]``
(emission-input combination * M + output; a last row of ones for an unobserved output or padding)
and, towards trial t+1, transition row ``tidx[t, n]`` (a last identity where the sequence ended).

* compiled (:mod:`.kernels`): one pass per sequence and parameter set, stopped sets skipped;
* numpy time loop: the R copies of the data side by side (column r*N + n), a Python loop over
  trials; the reference the compiled pass is tested against, and the path of small data;
* numpy scan: prefix and suffix products of the step matrices in log2(T) rounds (few, long sequences).

Per-trial posteriors come from a numpy method.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from . import kernels
from .sequences import Sequences
from .spec import FitError, Params

METHODS = ("auto", "compiled", "loop", "scan")
SCAN_RATIO = 20  # sequences at least this many times longer than their number: numpy E-step by prefix products
LOCKSTEP_COLUMNS = 1000  # the numpy time loop runs parameter sets x participants up to this side by side
_add = np.add.reduce  # the ufunc method directly: the time loop is call-overhead bound


@dataclass
class EStep:
    """Log-likelihood and expected counts (leading axis R for R parameter sets; probability zero: ``-inf``
    and zero counts); ``gamma``, the smoothed posteriors per trial (T, N, K), when asked for."""

    loglik: np.ndarray  # () or (R,)
    initial: np.ndarray  # expected counts (K,)
    emission: np.ndarray  # (Ue, K, M)
    transition: np.ndarray  # (Ut, K, K)
    gamma: np.ndarray | None = None

    def take(self, r: int | slice) -> EStep:
        """The E-step of parameter set ``r`` of a batch (a slice: those sets, a batch)."""
        return EStep(
            self.loglik[r], self.initial[r], self.emission[r], self.transition[r], None if self.gamma is None else self.gamma[r]
        )

    def where(self, mask: np.ndarray, other: EStep) -> EStep:
        """Per parameter set of a batch: this E-step where ``mask`` (R,) holds, else ``other`` (no posteriors)."""
        m3 = mask[:, None, None, None]
        return EStep(
            np.where(mask, self.loglik, other.loglik),
            np.where(mask[:, None], self.initial, other.initial),
            np.where(m3, self.emission, other.emission),
            np.where(m3, self.transition, other.transition),
        )


class EStepper(Protocol):
    """What EM and its finish ask of a workspace (:class:`Workspace`, or E-steps pooled over runs)."""

    def estep(self, p: Params, active: np.ndarray | None = None, posteriors: bool = False) -> EStep: ...

    def loglik(self, p: Params) -> np.ndarray: ...


class Workspace:
    """Index arrays of one data set and one model size, reused by every E-step.

    ``method``: ``compiled``, ``loop``, ``scan`` or ``auto``: compiled (built with the package: at
    any size), and for posteriors (or else) the scan for few, long sequences, else the loop (the
    numpy reference).  ``threads``: for a compiled E-step (the result does not depend on it).
    """

    def __init__(self, seqs: Sequences, K: int, M: int, Ue: int, Ut: int, method: str = "auto", threads: int = 1):
        if method not in METHODS:
            raise FitError([f"method must be one of {list(METHODS)}, got {method!r}"])
        self.seqs, self.K, self.M, self.Ue, self.Ut = seqs, K, M, Ue, Ut
        self.threads = max(1, int(threads))
        self.T, self.N = seqs.y.shape
        self.PE = Ue * M + 1  # emission rows + "nothing observed"
        self.eidx = np.where(seqs.y >= 0, seqs.ue * M + seqs.y, Ue * M)  # (T, N)
        self.tidx = np.where(seqs.has_successor(), seqs.ut[:-1], Ut)  # (T-1, N); row Ut = identity, not counted
        self.compiled = method in ("compiled", "auto")
        self.scan = method == "scan" or (method in ("auto", "compiled") and self.T > 1 and self.T >= SCAN_RATIO * self.N)
        self._eye = np.eye(K)
        self._kernel = kernels.Kernel(self.eidx, self.tidx, seqs.lengths, K, self.PE, Ut + 1, threads) if self.compiled else None
        self._numpy: dict[int, _TimeLoop | _Scan] = {}

    def as_own(self, p: Params) -> Params:
        """``p`` as this workspace's parameter sets (a mixture's workspace makes its own of plain tables)."""
        return p

    def lockstep(self, n: int) -> int:
        """How many of ``n`` parameter sets to run side by side (the rest in further groups)."""
        if self.compiled:
            return max(n, 1)
        return 1 if self.scan else max(1, min(n, LOCKSTEP_COLUMNS // max(self.N, 1)))

    def tables(self, p: Params) -> tuple[np.ndarray, np.ndarray]:
        """Emission rows (R, PE, K) and transition matrices (R, Ut + 1, K, K) of a batch, padding rows included."""
        R, K = p.initial.shape
        Bx = np.ones((R, self.PE, K))
        Bx[:, :-1] = p.emission.transpose(0, 1, 3, 2).reshape(R, self.Ue * self.M, K)
        Ax = np.empty((R, self.Ut + 1, K, K))
        Ax[:, :-1] = p.transition
        Ax[:, -1] = self._eye
        return Bx, Ax

    def estep(self, p: Params, active: np.ndarray | None = None, posteriors: bool = False) -> EStep:
        """Log-likelihood and expected counts of ``p`` (one parameter set, or a batch); the compiled pass
        skips the sets where ``active`` is false (0 and no counts), the numpy methods compute all."""
        batch = p if p.batched else p.as_batch()
        Bx, Ax = self.tables(batch)
        if self._kernel is not None and not posteriors:
            ll, ci, ce, ct = self._kernel.run(batch.initial, Bx, Ax, active)
            em = ce[:, :-1].reshape(len(ll), self.Ue, self.M, self.K).transpose(0, 1, 3, 2)
            if not p.batched:
                return EStep(ll[0], ci[0], np.ascontiguousarray(em[0]), ct[0, :-1])
            return EStep(ll, ci, np.ascontiguousarray(em), np.ascontiguousarray(ct[:, :-1]))
        st = self._reference(len(batch.initial)).estep(batch.initial, Bx, Ax, posteriors)
        return st if p.batched else st.take(0)

    def loglik(self, p: Params) -> np.ndarray:
        """Log-likelihood of ``p`` (a 0-d array for one parameter set, (R,) for a batch)."""
        if not p.batched:
            return self.loglik(p.as_batch())[0]
        if self._kernel is not None:
            return self.estep(p).loglik
        Bx, Ax = self.tables(p)
        return self._reference(len(p.initial)).loglik(p.initial, Bx, Ax)

    def _reference(self, R: int) -> _TimeLoop | _Scan:
        """The numpy E-step for R parameter sets (built once per R)."""
        if R not in self._numpy:
            self._numpy[R] = _Scan(self, R) if self.scan else _TimeLoop(self, R)
        return self._numpy[R]


class _Columns:
    """The workspace's index arrays for R parameter sets side by side: column r*N + n."""

    def __init__(self, w: Workspace, R: int):
        T, N, PE, U1 = w.T, w.N, w.PE, w.Ut + 1
        off = np.arange(R)[None, :, None]
        self.R, self.N, self.K, self.PE, self.U1 = R, N, w.K, PE, U1
        self.Ue, self.M = w.Ue, w.M
        self.eidx = (w.eidx[:, None, :] + off * PE).reshape(T, R * N)  # rows of (R * PE, K)
        self.tidx = (w.tidx[:, None, :] + off * U1).reshape(T - 1, R * N)  # rows of (R * U1, K, K)
        self.midx = (w.tidx[:, None, :] * PE + w.eidx[1:, None, :] + off * (U1 * PE)).reshape(T - 1, R * N)

    def _forward(self, initial: np.ndarray, Bx: np.ndarray, Ax: np.ndarray) -> tuple[np.ndarray, ...]:
        raise NotImplementedError

    def loglik(self, initial: np.ndarray, Bx: np.ndarray, Ax: np.ndarray) -> np.ndarray:
        return self._forward(initial, Bx, Ax)[3]

    def step_table(self, Bx: np.ndarray, Ax: np.ndarray) -> np.ndarray:
        """(R * U1 * PE, K, K): A[i, j] * B[j] for every (set, transition row, emission row)."""
        K = self.K
        return (Ax[:, :, None, :, :] * Bx[:, None, :, None, :]).reshape(-1, K, K)

    def result(self, ll: np.ndarray, init: np.ndarray, em: np.ndarray, tr: np.ndarray, gamma: np.ndarray | None) -> EStep:
        """Counts per set, (R, PE, K) emission rows and (R, U1, K, K) transitions, cut to the model's tables."""
        R, K = self.R, self.K
        em = em[:, :-1].reshape(R, self.Ue, self.M, K).transpose(0, 1, 3, 2)
        tr = tr[:, :-1]
        bad = ~np.isfinite(ll)
        if bad.any():  # the data have probability zero under these sets: no counts, no posteriors
            ll = np.where(bad, -np.inf, ll)
            em[bad], tr[bad], init[bad] = 0.0, 0.0, 0.0
            gamma = None
        return EStep(ll, np.ascontiguousarray(init), np.ascontiguousarray(em), np.ascontiguousarray(tr), gamma)


class _TimeLoop(_Columns):
    """The numpy reference: a loop over trial index, arrays laid out level-major, (K, T, R*N)."""

    def __init__(self, w: Workspace, R: int):
        super().__init__(w, R)
        K, T, NR = self.K, w.T, R * self.N
        self.ebins = (self.eidx[None] + (np.arange(K) * R * self.PE)[:, None, None]).ravel()
        self.tbins = (self.tidx[None] + (np.arange(K * K) * R * self.U1)[:, None, None]).ravel()
        # work buffers, reused by every E-step (fresh multi-megabyte arrays cost page faults)
        self._Mt = np.empty((K, K, max(T - 1, 0), NR))
        self._alpha = np.empty((K, T, NR))
        self._beta = np.empty((K, T, NR))
        self._gamma = np.empty((K, T, NR))
        self._xi = np.empty((K, K, max(T - 1, 0), NR))
        self._bs = np.empty((K, max(T - 1, 0), NR))
        self._c = np.empty((T, NR))

    def _forward(
        self, initial: np.ndarray, Bx: np.ndarray, Ax: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Scaled forward pass: alpha (K, T, RN), scales c (T, RN), step matrices Mt, log-likelihood (R,)."""
        K, R, N = self.K, self.R, self.N
        T = self._c.shape[0]
        mtab = self.step_table(Bx, Ax).reshape(-1, K * K).T  # (K*K, R*U1*PE)
        Mt = self._Mt
        np.take(mtab, self.midx, axis=1, out=Mt.reshape(K * K, T - 1, R * N), mode="clip")
        alpha, c = self._alpha, self._c
        a = np.repeat(initial.T, N, axis=1) * Bx.reshape(R * self.PE, K)[self.eidx[0]].T
        with np.errstate(invalid="ignore", divide="ignore"):
            for t in range(T):
                s = _add(a, 0, out=c[t])
                np.divide(a, s, out=alpha[:, t])
                if t + 1 < T:
                    a = _add(alpha[:, None, t] * Mt[:, :, t], 0)
            ll = np.log(c).sum(0).reshape(R, N).sum(1)
        return alpha, c, Mt, ll

    def estep(self, initial: np.ndarray, Bx: np.ndarray, Ax: np.ndarray, posteriors: bool) -> EStep:
        K, R, N = self.K, self.R, self.N
        alpha, c, Mt, ll = self._forward(initial, Bx, Ax)
        T = c.shape[0]
        beta = self._beta  # scaled: beta[:, t] = P(y_{>t} | S_t) / prod_{s>t} c_s
        with np.errstate(invalid="ignore", divide="ignore"):
            beta[:, T - 1] = 1.0
            for t in range(T - 1, 0, -1):
                b = beta[:, t] / c[t]
                _add(Mt[:, :, t - 1] * b[None], 1, out=beta[:, t - 1])
            gamma = np.multiply(alpha, beta, out=self._gamma)
            xi = np.multiply(alpha[:, None, :-1], Mt, out=self._xi)
            xi *= np.divide(beta[:, 1:], c[1:], out=self._bs)[None]
        em = np.bincount(self.ebins, weights=gamma.ravel(), minlength=K * R * self.PE).reshape(K, R, self.PE).transpose(1, 2, 0)
        tr = (
            np.bincount(self.tbins, weights=xi.ravel(), minlength=K * K * R * self.U1)
            .reshape(K, K, R, self.U1)
            .transpose(2, 3, 0, 1)
        )
        init = gamma[:, 0].reshape(K, R, N).sum(2).T
        post = gamma.reshape(K, T, R, N).transpose(2, 1, 3, 0).copy() if posteriors else None
        return self.result(ll, init, em, tr, post)


class _Scan(_Columns):
    """The numpy E-step by prefix and suffix products of M_t = A_t diag(B_{t+1}) (RN, T-1, K, K):
    F_t = M_0 ... M_t and G_t = M_t ... M_{T-2} in log2(T) rounds, each product rescaled to sum 1
    (its log-scale kept); alpha_t ∝ alpha_0 F_{t-1}, beta_t ∝ G_t 1."""

    def __init__(self, w: Workspace, R: int):
        super().__init__(w, R)
        K = self.K
        self.midx_s = np.ascontiguousarray(self.midx.T)  # (RN, T-1)
        self.ebins = (np.ascontiguousarray(self.eidx.T)[:, :, None] * K + np.arange(K)).ravel()
        self.tbins = (np.ascontiguousarray(self.tidx.T)[:, :, None] * (K * K) + np.arange(K * K)).ravel()

    def _forward(
        self, initial: np.ndarray, Bx: np.ndarray, Ax: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """alpha_0 (RN, K), step matrices Mt (RN, T-1, K, K), prefix products F, log-likelihood (R,)."""
        K, R, N = self.K, self.R, self.N
        Mt = self.step_table(Bx, Ax)[self.midx_s]
        a0 = np.repeat(initial, N, axis=0) * Bx.reshape(R * self.PE, K)[self.eidx[0]]
        with np.errstate(divide="ignore", invalid="ignore"):
            s0 = a0.sum(1)
            a0 = a0 / s0[:, None]
            F, logF = _prefix_products(Mt)
            ll = np.log(s0)
            if Mt.shape[1]:
                ll = ll + np.log(np.einsum("nk,nkj->n", a0, F[:, -1])) + logF[:, -1]
        return a0, Mt, F, ll.reshape(R, N).sum(1)

    def estep(self, initial: np.ndarray, Bx: np.ndarray, Ax: np.ndarray, posteriors: bool) -> EStep:
        K, R, N = self.K, self.R, self.N
        a0, Mt, F, ll = self._forward(initial, Bx, Ax)
        NR, T = len(a0), Mt.shape[1] + 1
        with np.errstate(divide="ignore", invalid="ignore"):
            alpha = np.empty((NR, T, K))
            alpha[:, 0] = a0
            alpha[:, 1:] = np.matmul(a0[:, None, None, :], F)[:, :, 0, :]
            alpha[:, 1:] /= alpha[:, 1:].sum(-1, keepdims=True)
            beta = np.ones((NR, T, K))
            beta[:, :-1] = _suffix_products(Mt).sum(-1)
            beta[:, :-1] /= beta[:, :-1].sum(-1, keepdims=True)
            gamma = alpha * beta
            gamma /= gamma.sum(-1, keepdims=True)
            xi = alpha[:, :-1, :, None] * Mt * beta[:, 1:, None, :]
            xi /= xi.sum((-2, -1), keepdims=True)
        em = np.bincount(self.ebins, weights=gamma.ravel(), minlength=R * self.PE * K).reshape(R, self.PE, K)
        tr = np.bincount(self.tbins, weights=xi.ravel(), minlength=R * self.U1 * K * K).reshape(R, self.U1, K, K)
        init = gamma[:, 0].reshape(R, N, K).sum(1)
        post = gamma.reshape(R, N, T, K).transpose(0, 2, 1, 3).copy() if posteriors else None
        return self.result(ll, init, em, tr, post)


def _prefix_products(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inclusive prefix products along axis 1 (Hillis-Steele), rescaled: (F, log scale)."""
    F = M.copy()
    logs = np.zeros(M.shape[:2])
    n, d = M.shape[1], 1
    while d < n:
        prod = np.matmul(F[:, :-d], F[:, d:])
        sc = prod.sum((-2, -1))
        prod /= sc[..., None, None]
        logs[:, d:] = logs[:, :-d] + logs[:, d:] + np.log(sc)
        F[:, d:] = prod
        d *= 2
    return F, logs


def _suffix_products(M: np.ndarray) -> np.ndarray:
    """Inclusive suffix products along axis 1 (G_t = M_t ... M_last), each rescaled to sum 1."""
    G = M / M.sum((-2, -1), keepdims=True)
    n, d = M.shape[1], 1
    while d < n:
        prod = np.matmul(G[:, :-d], G[:, d:])
        prod /= prod.sum((-2, -1), keepdims=True)
        G[:, :-d] = prod
        d *= 2
    return G
