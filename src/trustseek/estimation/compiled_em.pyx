"""The compiled run of one start (Cython, built with the package): EM with SQUAREM, the quasi-Newton
finish and the stationarity check in one call, with the decisions of :func:`~.em.run_em` and
:func:`~.em.converge` (:mod:`.compiled_run` runs the starts).

The steps are :mod:`.compiled_steps`' on flat cells; the finish works on the stick-breaking
fractions of :mod:`.stick_maps`.  Dot products, the matrix-vector product and the linear solve
are BLAS's ``ddot`` and ``dgemv`` and LAPACK's ``dgesv``, scipy's (:mod:`.blas`, bound at import).
"""

import numpy as np

from libc.math cimport fabs, isfinite, sqrt
from libc.stdint cimport int64_t
from libc.stdlib cimport free
from ..minmax cimport py_max, py_min

from .compiled_steps cimport EStep, Model, copy, em_step_at, estep_from, evaluate_at, extrapolate_at, model_from, size
from .forward_backward cimport scratch
from .stick_maps cimport Layout, gradient_of, layout_from, theta_of, values_of

from .blas import routines
from .compiled_steps import estep_buffers
from .stick_maps import EPS as _EPS

# the Fortran calling convention of scipy.linalg.cython_blas and cython_lapack (32-bit integers)
ctypedef double (*ddot_t)(int* n, double* x, int* incx, double* y, int* incy) noexcept nogil
ctypedef void (*dgemv_t)(char* trans, int* m, int* n, double* alpha, double* a, int* lda, double* x, int* incx,
                         double* beta, double* y, int* incy) noexcept nogil
ctypedef void (*dgesv_t)(int* n, int* nrhs, double* a, int* lda, int* ipiv, double* b, int* ldb, int* info) noexcept nogil
cdef ddot_t ddot = NULL
cdef dgemv_t dgemv = NULL
cdef dgesv_t dgesv = NULL


def bind(addresses):
    """Call the ``ddot``, ``dgemv`` and ``dgesv`` at these addresses (:func:`.blas.routines`)."""
    global ddot, dgemv, dgesv
    a, b, c = (int(x or 0) for x in addresses)
    if not (a and b and c):
        raise ValueError(f"a BLAS or LAPACK routine without an address: {addresses}")
    ddot, dgemv, dgesv = <ddot_t><size_t>a, <dgemv_t><size_t>b, <dgesv_t><size_t>c


bind(routines())

cdef enum:
    BACKTRACKS = 30  # halvings of the step before the line search gives up
    STATIONARY_ = 0  # how a run ended
    CAPPED_ = 1
    ZERO_ = 2

ARMIJO = 1e-4  # sufficient decrease of the finish's line search
ENDED_STATIONARY, ENDED_CAPPED, ENDED_ZERO = STATIONARY_, CAPPED_, ZERO_
cdef double C_ARMIJO = ARMIJO
cdef double C_EPS = _EPS


cdef inline double _dot(Py_ssize_t n, const double* x, const double* y) noexcept nogil:
    """BLAS's ``x . y`` (what ``np.dot`` of two vectors runs)."""
    cdef int n_ = <int>n, one = 1
    return ddot(&n_, <double*>x, &one, <double*>y, &one)


cdef struct Run:
    # one start's run: the model, the E-step, the sticks' layout; the current point (flat cells,
    # counts, stat = (log-likelihood, objective)) and the history of accepted objectives
    Model model
    EStep ev
    Layout sticks
    Py_ssize_t L, n
    double* flat
    double* counts
    double* stat
    double* history
    Py_ssize_t nh


cdef void _take(Run* run, const double* p, const double* c, double ll, double f) noexcept nogil:
    """The point ``p`` with E-step counts ``c``, log-likelihood ``ll`` and objective ``f`` into the run."""
    copy(run.flat, p, run.L)
    copy(run.counts, c, run.L)
    run.stat[0] = ll
    run.stat[1] = f


cdef int _fg(Run* run, const double* theta, const double* base, double* flat, double* counts, double* grad,
             double* ll, double* f, double* w) except -1 nogil:
    """The cells of ``theta`` (on ``base``) into ``flat``, their E-step counts into ``counts`` and
    the gradient of the objective into ``grad``; the log-likelihood and objective into ``ll``, ``f``
    (``w``: the gradient's work space)."""
    cdef Py_ssize_t a = run.model.K, b = a + run.model.Ue * run.model.K * run.model.M
    copy(flat, base, run.L)
    values_of(theta, &run.sticks, flat, flat + a, flat + b)
    evaluate_at(flat, &run.model, &run.ev, counts, ll, f)
    if isfinite(f[0]):
        gradient_of(theta, run.model.prior, &run.sticks, counts, counts + a, counts + b, grad, w)
    return 0


cdef enum:
    SOLVED = 0
    NOT_FINITE = 1  # np.linalg.solve's errors
    SINGULAR = 2


cdef int _solve(Py_ssize_t nf, const double* A, double* r) noexcept nogil:
    """``r`` becomes the solution x of A x = r (``A`` (nf, nf), C order), as ``np.linalg.solve``
    does it: LAPACK's ``dgesv`` on a copy of ``A`` in Fortran order.  SOLVED, or NOT_FINITE (a
    cell of ``A`` or ``r`` infinite or NaN) or SINGULAR, numpy's two errors."""
    cdef Py_ssize_t a, c
    cdef int n_ = <int>nf, nrhs = 1, info = 0
    for a in range(nf * nf):
        if not isfinite(A[a]):
            return NOT_FINITE
    for a in range(nf):
        if not isfinite(r[a]):
            return NOT_FINITE
    cdef double* F = <double*>scratch(sizeof(double) * nf * nf)
    cdef int* ipiv = <int*>scratch(sizeof(int) * nf)
    for a in range(nf):
        for c in range(nf):
            F[c * nf + a] = A[a * nf + c]
    dgesv(&n_, &nrhs, F, &n_, ipiv, r, &n_, &info)
    free(F)
    free(ipiv)
    return SOLVED if info == 0 else SINGULAR


cdef int _box_qp(Py_ssize_t n, const double* g, const double* B, const double* lo, const double* hi,
                 double* d) except -1 nogil:
    """Minimise g.d + d'Bd / 2 over lo <= d <= hi (B (n, n) positive definite) into ``d``: a primal
    active-set method from d = 0 (feasible: lo <= 0 <= hi).  The linear solve's failure raises
    ``np.linalg.LinAlgError``, as ``np.linalg.solve`` does."""
    cdef int64_t* bound = <int64_t*>scratch(sizeof(int64_t) * n)  # -1 at lo, +1 at hi, 0 free
    cdef Py_ssize_t* free_ = <Py_ssize_t*>scratch(sizeof(Py_ssize_t) * n)
    cdef double* work = <double*>scratch(sizeof(double) * (n * n + 2 * n))
    cdef int status = _active_set(n, g, B, lo, hi, d, bound, free_, work)
    free(bound)
    free(free_)
    free(work)
    if status == NOT_FINITE:
        with gil:
            raise np.linalg.LinAlgError("Array must not contain infs or NaNs.")
    if status == SINGULAR:
        with gil:
            raise np.linalg.LinAlgError("Matrix is singular to machine precision.")
    return 0


cdef int _active_set(Py_ssize_t n, const double* g, const double* B, const double* lo, const double* hi, double* d,
                     int64_t* bound, Py_ssize_t* free_, double* work) noexcept nogil:
    """:func:`_box_qp`'s iterations (``bound`` zeroed; ``free_`` (n,) and ``work`` (n * n + 2 n) work
    space); SOLVED, or the linear solve's failure."""
    cdef double* target = work
    cdef double* r = target + n
    cdef double* A = r + n
    cdef Py_ssize_t i, j, a, c, nf, hit, rel, it
    cdef int status
    cdef double acc, t, ti, worst, gi, v
    for i in range(n):
        d[i] = 0.0
        if lo[i] == 0.0 and g[i] > 0.0:
            bound[i] = -1
        elif hi[i] == 0.0 and g[i] < 0.0:
            bound[i] = 1
    for it in range(4 * n + 10):
        nf = 0
        for i in range(n):
            if bound[i] == 0:
                free_[nf] = i
                nf += 1
        copy(target, d, n)
        if nf > 0:
            # B_FF d_F = -(g_F + B_FA d_A)
            for a in range(nf):
                i = free_[a]
                acc = g[i]
                for j in range(n):
                    if bound[j] != 0:
                        acc += B[i * n + j] * d[j]
                r[a] = -acc
                for c in range(nf):
                    A[a * nf + c] = B[i * n + free_[c]]
            status = _solve(nf, A, r)
            if status != SOLVED:
                return status
            for a in range(nf):
                target[free_[a]] = r[a]
        # the step from d to target, cut at the first bound it crosses
        t = 1.0
        hit = -1
        for a in range(nf):
            i = free_[a]
            if target[i] < lo[i] and target[i] < d[i]:
                ti = (lo[i] - d[i]) / (target[i] - d[i])
                if ti < t:
                    t, hit = ti, i
            elif target[i] > hi[i] and target[i] > d[i]:
                ti = (hi[i] - d[i]) / (target[i] - d[i])
                if ti < t:
                    t, hit = ti, i
        for a in range(nf):
            i = free_[a]
            d[i] = py_min(py_max(d[i] + t * (target[i] - d[i]), lo[i]), hi[i])
        if hit >= 0:
            if target[hit] < lo[hit]:
                d[hit], bound[hit] = lo[hit], -1
            else:
                d[hit], bound[hit] = hi[hit], 1
            continue
        # optimal on this face: release the bound variable whose multiplier has the wrong sign
        worst = 0.0
        rel = -1
        for i in range(n):
            if bound[i] != 0:
                gi = g[i] + _dot(n, B + i * n, d)
                v = -gi if bound[i] < 0 else gi  # positive: the objective decreases moving inward
                if v > worst:
                    worst, rel = v, i
        if rel < 0:
            return SOLVED
        bound[rel] = 0
    return SOLVED


cdef struct Finish:
    # the finish's result: E-steps, whether the budget stopped it
    Py_ssize_t calls
    bint capped


cdef int _finish(Run* run, Py_ssize_t budget, double ftol, double* B, bint warm, Finish* out) except -1 nogil:
    """The quasi-Newton finish from the run's point (updated in place to the best accepted point): a
    dense BFGS model of the objective over the fractions in [EPS, 1 - EPS], its best step inside the
    box (:func:`_box_qp`), a backtracking line search; stops when an iteration changes the objective
    by at most ``ftol`` (relative), no step decreases it, or at ``budget`` E-steps.  The model's
    matrix is left in ``B`` (n, n); with ``warm`` it starts from ``B``, else from a multiple of the
    identity."""
    cdef Py_ssize_t n = run.n, L = run.L
    cdef double* vec = <double*>scratch(sizeof(double) * (11 * n + 5 * L + run.sticks.widest + 1))
    cdef int status = _quasi_newton(run, budget, ftol, B, warm, out, vec)
    free(vec)
    return status


cdef int _quasi_newton(Run* run, Py_ssize_t budget, double ftol, double* B, bint warm, Finish* out,
                       double* vec) except -1 nogil:
    """:func:`_finish`'s iterations, on the work space ``vec``."""
    cdef Py_ssize_t n = run.n, L = run.L, K = run.model.K, i, j, it
    cdef double lo = C_EPS, hi = 1 - C_EPS
    cdef double* x = vec
    cdef double* g = x + n
    cdef double* d = g + n
    cdef double* dl = d + n
    cdef double* dh = dl + n
    cdef double* xn = dh + n
    cdef double* gn = xn + n
    cdef double* s_ = gn + n
    cdef double* y_ = s_ + n
    cdef double* Bs = y_ + n
    cdef double* base = Bs + n
    cdef double* fl = base + L
    cdef double* cn = fl + L
    cdef double* fln = cn + L
    cdef double* cnn = fln + L
    cdef double* w = cnn + L
    cdef double ll, f, F, Fn, fn, lln, gg, slope, step, sy, sBs, yy, one = 1.0, zero = 0.0
    cdef bint scaled = warm, accepted, small
    cdef int n_ = <int>n, inc = 1
    cdef char trans = b't'
    copy(base, run.flat, L)
    theta_of(base, base + K, base + K + run.model.Ue * K * run.model.M, &run.sticks, x)
    _fg(run, x, base, fl, cn, g, &ll, &f, w)
    out.calls = 1
    out.capped = False
    if not isfinite(f):
        return 0
    F = -f
    for i in range(n):
        g[i] *= -1.0
    while True:
        if not scaled:  # before the first pair: a steepest-descent step of length at most 1
            gg = sqrt(_dot(n, g, g))
            if gg == 0.0:
                break
            for i in range(n):
                for j in range(n):
                    B[i * n + j] = 0.0
                B[i * n + i] = py_max(gg, 1e-300)
        for i in range(n):
            dl[i] = lo - x[i]
            dh[i] = hi - x[i]
        _box_qp(n, g, B, dl, dh, d)
        slope = _dot(n, g, d)
        if not slope < 0.0:
            break
        step = 1.0
        accepted = False
        Fn = 0.0
        lln = 0.0
        for it in range(BACKTRACKS):
            if out.calls >= budget:
                out.capped = True
                return 0
            for i in range(n):
                xn[i] = py_min(py_max(x[i] + step * d[i], lo), hi)
            _fg(run, xn, base, fln, cnn, gn, &lln, &fn, w)
            out.calls += 1
            Fn = -fn
            if isfinite(Fn) and Fn <= F + C_ARMIJO * step * slope:
                accepted = True
                break
            step *= 0.5
        if not accepted:
            break
        for i in range(n):
            gn[i] *= -1.0
            s_[i] = xn[i] - x[i]
            y_[i] = gn[i] - g[i]
        sy = _dot(n, s_, y_)
        if sy > 1e-12 * sqrt(_dot(n, s_, s_) * _dot(n, y_, y_)):
            if not scaled:
                for i in range(n):
                    for j in range(n):
                        B[i * n + j] = 0.0
                    B[i * n + i] = _dot(n, y_, y_) / sy
                scaled = True
            dgemv(&trans, &n_, &n_, &one, B, &n_, s_, &inc, &zero, Bs, &inc)  # B @ s_ (B in C order)
            sBs = _dot(n, s_, Bs)
            if sBs > 0.0:
                for i in range(n):
                    for j in range(n):
                        B[i * n + j] += y_[i] * y_[j] / sy - Bs[i] * Bs[j] / sBs
        # a shortened step's small change says little about the distance to the maximum
        small = step == 1.0 and F - Fn <= ftol * py_max(py_max(fabs(F), fabs(Fn)), 1.0)
        copy(x, xn, n)
        copy(g, gn, n)
        F = Fn
        if -Fn > run.stat[1]:
            _take(run, fln, cnn, lln, -Fn)
            run.history[run.nh] = -Fn
            run.nh += 1
        if small:
            break
    return 0


cdef struct EM:
    # EM's result: E-steps so far, whether it converged
    Py_ssize_t its
    bint converged


cdef int _em(Run* run, double tol, Py_ssize_t max_iter, bint accelerate, double* vec, EM* out) except -1 nogil:
    """EM with SQUAREM from the run's point (its counts known; updated in place), as :func:`.em.run_em`
    decides, from ``out.its`` E-steps; ``vec``: work space (7 L)."""
    cdef Py_ssize_t L = run.L
    cdef double* p1 = vec
    cdef double* c1 = p1 + L
    cdef double* p2 = c1 + L
    cdef double* c2 = p2 + L
    cdef double* pe = c2 + L
    cdef double* ce = pe + L
    cdef double* p0 = ce + L
    cdef double f0, f1, f2, fe, ll1, ll2, lle
    cdef bint small
    copy(p0, run.flat, L)
    out.converged = False
    while True:
        if out.its >= max_iter:
            out.converged = False
            return 0
        f0 = run.stat[1]
        em_step_at(run.flat, run.counts, &run.model, p1)
        evaluate_at(p1, &run.model, &run.ev, c1, &ll1, &f1)
        out.its += 1
        if not f1 >= f0:  # only rounding does this at a fixed point: keep the better point
            out.converged = True
            return 0
        run.history[run.nh] = f1
        run.nh += 1
        small = f1 - f0 <= tol * fabs(f0)
        if small or not accelerate or out.its >= max_iter:
            _take(run, p1, c1, ll1, f1)
            if small or out.its >= max_iter:
                out.converged = small
                return 0
            continue
        copy(p0, run.flat, L)
        em_step_at(p1, c1, &run.model, p2)
        evaluate_at(p2, &run.model, &run.ev, c2, &ll2, &f2)
        out.its += 1
        if not f2 >= f1:
            _take(run, p1, c1, ll1, f1)
            out.converged = True
            return 0
        run.history[run.nh] = f2
        run.nh += 1
        _take(run, p2, c2, ll2, f2)
        if f2 - f1 <= tol * fabs(f1):
            out.converged = True
            return 0
        if out.its < max_iter and extrapolate_at(p0, p1, p2, &run.model, pe):
            evaluate_at(pe, &run.model, &run.ev, ce, &lle, &fe)
            out.its += 1
            if fe >= f2 and isfinite(fe):
                run.history[run.nh] = fe
                run.nh += 1
                _take(run, pe, ce, lle, fe)


cdef struct Ending:
    # how a run ended: E-steps, ENDED_*, finishes
    Py_ssize_t its
    int ended
    Py_ssize_t finishes


cdef int _run(Run* run, double tol, Py_ssize_t max_iter, double em_tol, double finish_tol, bint use_qn,
              bint accelerate, double* B, bint warm, double* vec, Ending* out) except -1 nogil:
    """One start from its first E-step to its end (see :func:`run_one`); ``vec``: work space (9 L)."""
    cdef Py_ssize_t L = run.L
    cdef double* q = vec
    cdef double* cq = q + L
    cdef double llq, fq, f
    cdef EM em
    cdef Finish fin
    out.finishes = 0
    evaluate_at(run.flat, &run.model, &run.ev, run.counts, &run.stat[0], &run.stat[1])
    if not isfinite(run.stat[1]):
        out.its, out.ended = 1, ZERO_
        return 0
    run.history[0] = run.stat[1]
    run.nh = 1
    em.its = 1
    _em(run, em_tol, max_iter, accelerate, cq + L, &em)
    while True:
        if not em.converged:
            break
        if use_qn and run.n > 0 and max_iter - em.its >= 2 and isfinite(run.stat[1]):
            _finish(run, max_iter - em.its, finish_tol, B, warm, &fin)
            em.its += fin.calls
            out.finishes += 1
            if fin.capped:
                break
        if em.its + 1 > max_iter or not isfinite(run.stat[1]):
            break
        # the check: one EM step from the end point (its counts are known)
        em_step_at(run.flat, run.counts, &run.model, q)
        evaluate_at(q, &run.model, &run.ev, cq, &llq, &fq)
        em.its += 1
        f = run.stat[1]
        if not fq - f > tol * fabs(f):
            out.its, out.ended = em.its, STATIONARY_
            return 0
        _take(run, q, cq, llq, fq)
        run.history[run.nh] = fq
        run.nh += 1
        _em(run, em_tol, max_iter, accelerate, cq + L, &em)
    out.its, out.ended = em.its, CAPPED_
    return 0


def run_one(const double[::1] start, tuple model, tuple data, Py_ssize_t C, Py_ssize_t PE, tuple settings, tuple qn):
    """One start from its first E-step to its end: the end point's flat cells, (log-likelihood,
    objective), E-steps, how it ended, finishes, and the history.  ``model``: (K, Ue, M, Ut, prior,
    emission table, transition table); ``data``: the kernel's index arrays, in ``C`` items with
    ``PE`` emission rows; ``settings``: (tol, max_iter, em_tol, finish_tol, quasi-Newton, accelerate,
    the E-step's threads); ``qn``: (the sticks' layout, their number n, ``B`` (n, n), ``warm``): the
    finish's model matrix is left in ``B``; with ``warm`` it starts from ``B``."""
    cdef Run run
    cdef Ending ending
    tol, max_iter, em_tol, finish_tol, use_qn, accelerate, threads = settings
    layout, n, B, warm = qn
    keep = []
    model_from(model, &run.model, keep)
    bufs = estep_buffers(run.model.K, PE, run.model.Ut + 1, C, threads)
    estep_from((data, bufs), &run.ev, keep)
    layout_from(layout, &run.sticks, keep)
    run.L, run.n = start.shape[0], n
    if run.L != size(&run.model):
        raise ValueError("the start does not have the model's number of cells")
    flat, counts, stat = np.array(start), np.empty(run.L), np.empty(2)
    history = np.empty(max_iter + 2)
    vec = np.empty(9 * run.L)
    cdef double[::1] flat_, counts_, stat_, history_, vec_, B_
    flat_, counts_, stat_, history_, vec_ = flat, counts, stat, history, vec
    B_ = B.reshape(-1)
    run.flat, run.counts, run.stat, run.history = &flat_[0], &counts_[0], &stat_[0], &history_[0]
    run.nh = 0
    cdef double tol_ = tol, em_tol_ = em_tol, finish_tol_ = finish_tol
    cdef Py_ssize_t max_iter_ = max_iter
    cdef bint use_qn_ = use_qn, accelerate_ = accelerate, warm_ = warm
    with nogil:
        _run(&run, tol_, max_iter_, em_tol_, finish_tol_, use_qn_, accelerate_, &B_[0], warm_, &vec_[0], &ending)
    return flat, stat, ending.its, ending.ended, ending.finishes, history[: run.nh]
