"""Compiled loop of the design study (numba): the exact null distribution of the signed-rank statistic.

:func:`signed_rank_counts` multiplies the generating polynomial prod_i (1 + z^w_i) out in
place, one weight at a time; every coefficient is updated by the same single addition as the
full-array numpy update ``counts[w:] = counts[w:] + counts[:-w]``, so the counts are the same
to the last bit (the tests compare with that transcription).  Without numba the function runs
as plain Python.
"""

from __future__ import annotations

from ..compiled import njit


@njit(cache=True, nogil=True)
def signed_rank_counts(weights, counts):
    """``counts`` (zeros but ``counts[0] = 1``, length >= sum(weights) + 1) times (1 + z^w) for
    every positive integer weight w, in place: the number of sign patterns giving each sum."""
    top = 1  # counts[top:] is still zero
    for w in weights:
        for k in range(top - 1, -1, -1):  # downwards: counts[k] is read before it is updated
            counts[k + w] += counts[k]
        top += w
