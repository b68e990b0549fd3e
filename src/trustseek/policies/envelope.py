"""Upper envelopes of lines on [0, 1]: the piecewise-linear convex functions of x = P(trust = high)
that alpha vectors represent for two trust levels.

An alpha vector (α(low), α(high)) is the line x -> α(low) (1 - x) + α(high) x; a set of
them stands for their maximum.  An *envelope* keeps only the lines on that maximum, ordered
by increasing x, with the breakpoints between them.  Here: building and evaluating one, and
what the exact alpha-vector backup is made of: sums and maxima of envelopes, thinning
(dropping lines worth less than a tolerance), and the exact extrema of the difference of two
envelopes.
"""

from __future__ import annotations

import numpy as np

WIDTH_EPS = 1e-13  # envelope pieces narrower than this are dropped


def envelope(vecs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The upper envelope over x in [0, 1] of the lines x -> v0 (1 - x) + v1 x.

    Returns (idx, xs): indices of the lines on the envelope ordered by increasing x,
    and the breakpoints xs (len(idx) + 1, from 0 to 1); line idx[i] is the maximum on
    [xs[i], xs[i + 1]].  Vectorized: lines sorted by slope, then lines that lie below
    their two neighbours (they cross the previous one after the next one) are removed
    in passes until none is left; lines active only outside [0, 1] are cut off.
    """
    v0 = vecs[:, 0]
    s = vecs[:, 1] - vecs[:, 0]
    order = np.lexsort((-v0, s))
    keep = np.concatenate([[True], s[order][1:] != s[order][:-1]])  # one line per slope: the highest
    idx = order[keep]
    while True:
        a, b = v0[idx], s[idx]
        if len(idx) == 1:
            return idx, np.array([0.0, 1.0])
        x = (a[:-1] - a[1:]) / (b[1:] - b[:-1])  # where line k+1 overtakes line k
        # cut lines that are active only left of 0 or right of 1
        first = int(np.argmax(x > WIDTH_EPS)) if np.any(x > WIDTH_EPS) else len(x)
        last = int(len(x) - np.argmax((x < 1 - WIDTH_EPS)[::-1])) if np.any(x < 1 - WIDTH_EPS) else 0
        if first > 0 or last < len(x):
            idx = idx[first : last + 1]
            continue
        bad = np.zeros(len(idx), dtype=bool)
        bad[1:-1] = x[:-1] >= x[1:] - WIDTH_EPS
        if not np.any(bad):
            return idx, np.concatenate([[0.0], x, [1.0]])
        idx = idx[~bad]


def active_piece(xs: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Index of the piece of breakpoints xs (xs[0] = 0, xs[-1] = 1) that contains each x."""
    return np.searchsorted(xs[1:-1], x, side="right")


def envelope_values(vecs: np.ndarray, xs: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Evaluate an envelope (vectors in order, breakpoints xs) at points x."""
    x = np.asarray(x, dtype=float)
    i = active_piece(xs, x)
    return vecs[i, 0] * (1 - x) + vecs[i, 1] * x


def union(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Sorted union of two sorted breakpoint arrays (exact duplicates removed)."""
    u = np.concatenate([a, b])
    u.sort(kind="mergesort")
    return u[np.concatenate([[True], u[1:] != u[:-1]])]


def cross_sum(xs1: np.ndarray, xs2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pieces of the sum of two envelopes: breakpoints and the active index in each."""
    u = union(xs1, xs2)
    keep = np.concatenate([[True], np.diff(u) > WIDTH_EPS])
    u = u[keep]
    if u[-1] < 1.0:
        u[-1] = 1.0
    if len(u) < 2:
        u = np.array([0.0, 1.0])
    mids = 0.5 * (u[:-1] + u[1:])
    return u, active_piece(xs1, mids), active_piece(xs2, mids)


def strip(u: np.ndarray, width: float = WIDTH_EPS) -> np.ndarray:
    """Sorted breakpoints with pieces narrower than ``width`` removed, from 0 to 1."""
    u = u[np.concatenate([[True], np.diff(u) > width])]
    u[0], u[-1] = 0.0, 1.0
    return u


def max_of(
    v1: np.ndarray, xs1: np.ndarray, v2: np.ndarray, xs2: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The upper envelope of two envelopes: (vectors, breakpoints, source (0/1), index)."""
    u = union(xs1, xs2)
    mids = 0.5 * (u[:-1] + u[1:])
    i1, i2 = active_piece(xs1, mids), active_piece(xs2, mids)
    a, b = v1[i1], v2[i2]
    d0 = a[:, 0] - b[:, 0]
    ds = (a[:, 1] - a[:, 0]) - (b[:, 1] - b[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(ds != 0, -d0 / ds, np.nan)
    inside = (r > u[:-1] + WIDTH_EPS) & (r < u[1:] - WIDTH_EPS)
    if np.any(inside):
        u = union(u, r[inside])  # the crossings lie strictly inside their pieces: still sorted
    u = strip(u)
    mids = 0.5 * (u[:-1] + u[1:])
    i1, i2 = active_piece(xs1, mids), active_piece(xs2, mids)
    val1 = v1[i1, 0] * (1 - mids) + v1[i1, 1] * mids
    val2 = v2[i2, 0] * (1 - mids) + v2[i2, 1] * mids
    src = (val2 > val1).astype(np.int64)
    idx = np.where(src == 1, i2, i1)
    vec = np.where(src[:, None] == 1, v2[i2], v1[i1])
    # merge consecutive pieces of the same line
    new = np.concatenate([[True], (src[1:] != src[:-1]) | (idx[1:] != idx[:-1])])
    return vec[new], np.concatenate([u[:-1][new], [1.0]]), src[new], idx[new]


def thin(vecs: np.ndarray, xs: np.ndarray, eta: float) -> tuple[np.ndarray, np.ndarray]:
    """Drop envelope lines whose removal lowers the envelope by less than ``eta`` (never two
    neighbours at once).  The result is below the input by at most ``eta``: still a lower bound."""
    keep = thin_mask(vecs, eta)
    if keep.all():
        return vecs, xs
    return refit(vecs, xs, np.nonzero(keep)[0])[:2]


def thin_mask(vecs: np.ndarray, eta: float) -> np.ndarray:
    """The lines of an envelope that :func:`thin` keeps (a boolean mask)."""
    keep = np.ones(len(vecs), dtype=bool)
    if len(vecs) < 3 or eta <= 0:
        return keep
    a = vecs[:, 0]
    b = vecs[:, 1] - vecs[:, 0]
    x = (a[:-2] - a[2:]) / (b[2:] - b[:-2])  # where the neighbours of line k meet
    err = (a[1:-1] + b[1:-1] * x) - (a[:-2] + b[:-2] * x)
    keep[1:-1] = ~((err < eta) & (np.arange(1, len(vecs) - 1) % 2 == 0))
    return keep


def refit(vecs: np.ndarray, xs: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The envelope of the kept lines (indices, in order) of an envelope: (lines, breakpoints,
    their indices in ``vecs``).  No two dropped lines are neighbours, so the kept lines stay in
    order and meet their new neighbours inside [0, 1]; degenerate cases are re-enveloped."""
    if len(keep) == len(vecs):
        return vecs, xs, keep
    nv = vecs[keep]
    a, b = nv[:, 0], nv[:, 1] - nv[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        nxs = np.concatenate([[0.0], (a[:-1] - a[1:]) / (b[1:] - b[:-1]), [1.0]])
    if not (np.all(np.isfinite(nxs)) and np.all(np.diff(nxs) > 0)):  # parallel neighbours
        idx, nxs = envelope(nv)
        return nv[idx], nxs, keep[idx]
    return nv, nxs, keep


def difference_extrema(v1: np.ndarray, xs1: np.ndarray, v2: np.ndarray, xs2: np.ndarray) -> tuple[float, float]:
    """(sup, inf) over [0, 1] of env1(x) - env2(x), both attained at a breakpoint of one of them."""
    pts = union(xs1, xs2)
    d = envelope_values(v1, xs1, pts) - envelope_values(v2, xs2, pts)
    return float(np.max(d)), float(np.min(d))
