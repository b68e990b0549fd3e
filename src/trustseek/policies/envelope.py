"""Upper envelopes of lines on [0, 1]: the piecewise-linear convex functions of x = P(trust = high)
that alpha vectors represent for two trust levels.

An alpha vector (α(low), α(high)) is the line x -> α(low) (1 - x) + α(high) x; a set of
them stands for their maximum.  An *envelope* keeps only the lines on that maximum, ordered
by increasing x, with the breakpoints between them.
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
