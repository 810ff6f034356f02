"""numpy's summation order, compiled: a sum or mean that a compiled sampling pass takes gives
numpy's numbers bit for bit, so moving a mean out of numpy changes no output file.

numpy sums a contiguous float64 array by pairwise summation (numpy/_core/src/umath/
loops_utils.h.src, `pairwise_sum`): fewer than 8 terms one by one; up to a block of 128 in
eight interleaved partial sums, combined as ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7)),
then the terms past the last multiple of 8; a longer run split in two at half its length
rounded down to a multiple of 8, each half summed so.  Its error grows as log n instead of n
(Higham 1993, SIAM J. Sci. Comput. 14, 783).  np.mean is that sum divided by the count.
"""
from __future__ import annotations

import numba as nb
import numpy as np

#: numpy's pairwise block (PW_BLOCKSIZE)
BLOCK = 128


@nb.njit(cache=True)
def _block(a, lo, n):
    """numpy's sum of a run of at most BLOCK terms a[lo:lo + n]."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    whole = n - n % 8
    while i < whole:
        p = lo + i
        r0 += a[p]
        r1 += a[p + 1]
        r2 += a[p + 2]
        r3 += a[p + 3]
        r4 += a[p + 4]
        r5 += a[p + 5]
        r6 += a[p + 6]
        r7 += a[p + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    for p in range(lo + i, lo + n):
        res += a[p]
    return res


@nb.njit(cache=True, inline="always")
def _half(n):
    """Where numpy splits a run of n > BLOCK terms: half of it, rounded down to a multiple
    of 8."""
    n2 = n // 2
    return n2 - n2 % 8


@nb.njit(cache=True)
def pairwise_sum(a, lo, n):
    """The sum of a[lo:lo + n] in numpy's order (module docstring); 0.0 for n = 0.  numpy's
    recursion is walked with a stack of its own (a recursive compiled function, loaded from
    numba's on-disk cache, crashes the process): each run over BLOCK is split at `_half`, its
    left half summed, then its right, then the two added, as numpy adds them."""
    if n <= BLOCK:
        return _block(a, lo, n)
    # the runs being split (start, length, halves done) and the sums waiting to be added;
    # a run's depth is at most log2(n / BLOCK) + 1 < 64
    runs = np.empty((64, 3), np.int64)
    sums = np.empty(64)
    top = 0
    runs[0, 0], runs[0, 1], runs[0, 2] = lo, n, 0
    nsum = 0
    while top >= 0:
        s, m, done = runs[top, 0], runs[top, 1], runs[top, 2]
        if m <= BLOCK:
            sums[nsum] = _block(a, s, m)
            nsum += 1
            top -= 1
        elif done < 2:
            half = _half(m)
            runs[top, 2] = done + 1
            top += 1
            if done == 0:
                runs[top, 0], runs[top, 1] = s, half
            else:
                runs[top, 0], runs[top, 1] = s + half, m - half
            runs[top, 2] = 0
        else:
            nsum -= 1
            sums[nsum - 1] = sums[nsum - 1] + sums[nsum]
            top -= 1
    return sums[0]


@nb.njit(cache=True)
def pairwise_mean(a, lo, n):
    """np.mean of a[lo:lo + n] (numpy's sum over n); NaN for n = 0, where numpy warns."""
    if n == 0:
        return np.nan
    return pairwise_sum(a, lo, n) / n
